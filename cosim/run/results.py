"""Writing a run: ``results.csv`` (time series), ``summary.json`` and ``plot.png``.

Files are written to a temporary name and renamed, so an interrupted write never leaves a
half-written result next to a complete one.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    write(tmp)
    os.replace(tmp, path)


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_results(result: Any, out_dir: Path, plot: bool = True) -> list[Path]:
    """Write results.csv, summary.json and (unless ``plot`` is False) plot.png."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / "results.csv"
    summary_path = out_dir / "summary.json"
    _atomic_write(csv_path, lambda p: result.frame.to_csv(p, index=False, float_format="%.10g"))
    _atomic_write(summary_path, lambda p: p.write_text(
        json.dumps(_json_safe(result.summary), indent=2) + "\n"))
    written = [csv_path, summary_path]
    if plot:
        plot_path = out_dir / "plot.png"
        _atomic_write(plot_path, lambda p: plot_run(result, p))
        written.append(plot_path)
    return written


def plot_run(result: Any, path: Path) -> None:
    """Speed (and reference) vs position with the command on a second axis, as the papers'
    figures; coupler forces below when the scenario names them; otherwise outputs vs time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cosim.run.metrics import _columns

    cfg = result.scenario.summary
    frame = result.frame
    couplers = _columns(frame, cfg.get("coupler_forces"))
    rows = 2 if couplers else 1
    fig, axes = plt.subplots(rows, 1, figsize=(9, 4.5 * rows), squeeze=False)
    ax = axes[0][0]
    pos, speed = cfg.get("position"), cfg.get("speed")
    if pos in frame.columns and speed in frame.columns:
        x = frame[pos].to_numpy()
        xlabel = "position (m)"
        if np.nanmax(np.abs(x)) > 5000:
            x, xlabel = x / 1e3, "position (km)"
        ax.plot(x, frame[speed] * 3.6, label="speed", color="C0")
        for key, style, label in (("reference_speed", "--", "reference"),
                                  ("speed_limit", ":", "speed limit")):
            ref = cfg.get(key)
            if ref in frame.columns:
                ax.plot(x, frame[ref] * 3.6, style, label=label,
                        color="k" if key == "reference_speed" else "C3")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("speed (km/h)")
        if "stop_point" in cfg:
            stop = float(cfg["stop_point"]) / (1e3 if xlabel.endswith("(km)") else 1.0)
            ax.axvline(stop, color="C3", lw=0.8, ls="-.", label="stop point")
        command = cfg.get("command")
        if command in frame.columns:
            ax2 = ax.twinx()
            ax2.step(x, frame[command], where="post", color="C2", lw=1.0, label="command")
            ax2.set_ylabel(command)
            lines = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
            labels = ax.get_legend_handles_labels()[1] + ax2.get_legend_handles_labels()[1]
            ax.legend(lines, labels, loc="best", fontsize=8)
        else:
            ax.legend(loc="best", fontsize=8)
    else:
        t = frame["time"]
        for col in frame.columns[1:9]:
            ax.plot(t, frame[col], label=col)
        ax.set_xlabel("time (s)")
        ax.legend(loc="best", fontsize=8)
    summary = result.summary
    title = result.scenario.name
    if summary.get("stop_error_m") is not None:
        title += f"  stop error {summary['stop_error_m'] * 100:+.1f} cm"
    if summary.get("command_switches") is not None:
        title += f"  switches {summary['command_switches']}"
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if couplers:
        axc = axes[1][0]
        t = frame["time"].to_numpy()
        forces = frame[couplers].to_numpy() / 1e3
        for i, col in enumerate(couplers[:12]):
            axc.plot(t, forces[:, i], lw=0.8, label=col.split(".", 1)[1])
        if len(couplers) > 12:
            axc.plot(t, forces.max(axis=1), "k", lw=1.2, label="max")
            axc.plot(t, forces.min(axis=1), "k", lw=1.2, label="min")
        axc.set_xlabel("time (s)")
        axc.set_ylabel("coupler force (kN)")
        axc.grid(True, alpha=0.3)
        axc.legend(loc="best", fontsize=7, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
