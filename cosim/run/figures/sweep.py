"""The figure of a sweep (``sweep.png`` of ``cosim sweep``, :func:`draw_sweep`): stop error and
command switches / controller executions against the first grid key, one series per scenario
and further key; axis labels from the declarations (:func:`key_labels`)."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import pandas as pd

from cosim.run.columns import axis_label, variable_info
from cosim.run.figures import save_figure
from cosim.run.figures.run import fit_band
from cosim.run.metrics import STOP_WINDOW_M


def key_labels(scenario: Any, keys: list[str]) -> dict[str, str]:
    """Axis labels of grid keys: the declared description and unit of each ``FMU.parameter``
    (the key itself where there is none)."""
    labels = {}
    for key in keys:
        text, unit = variable_info(scenario, key)
        labels[key] = f"{axis_label(text, unit)} [{key}]" if text != key else key
    return labels


def plot_sweep(frame: pd.DataFrame, keys: list[str], path: str | Path,
               labels: dict[str, str] | None = None,
               series_labels: dict[str, str] | None = None) -> None:
    """:func:`draw_sweep` saved to ``path`` (its suffix: png at 200 dpi, svg or pdf;
    :func:`cosim.run.figures.save_figure`)."""
    save_figure(draw_sweep(frame, keys, labels, series_labels), Path(path))


def draw_sweep(frame: pd.DataFrame, keys: list[str],
               labels: dict[str, str] | None = None,
               series_labels: dict[str, str] | None = None) -> Any:
    """Stop error (cm) and command switches / executions vs the first key (its axis label
    from ``labels``, e.g. :func:`key_labels`; each scenario's series named by
    ``series_labels``, wrapped to 40 characters, else by the scenario's name); the stop
    window drawn, the axis zoomed to the data when they lie far inside it; legends right of
    the axes; no offset notation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = keys[0]
    others = [k for k in keys[1:] if frame[k].nunique(dropna=False) > 1]  # held values: no series
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.5, 8), sharex=True, layout="constrained")
    for label, group in frame.groupby(["scenario", *others], sort=False):
        label = label if isinstance(label, tuple) else (label,)
        scenario = str(label[0])
        name = " ".join([(series_labels or {}).get(scenario, scenario)]
                        + [f"{k}={v}" for k, v in zip(others, label[1:], strict=True)])
        name = "\n".join(textwrap.wrap(name, 40))
        group = group.sort_values(x)
        ax1.plot(group[x], 100.0 * group["stop_error_m"], marker="o", label=name)
        line, = ax2.plot(group[x], group["command_switches"], marker="s",
                         label=f"{name}: switches")
        if group["controller_executions"].notna().all():
            ax2.plot(group[x], group["controller_executions"], marker="^", linestyle="--",
                     color=line.get_color(), label=f"{name}: executions")
    fit_band(ax1, 100.0 * frame["stop_error_m"], -100 * STOP_WINDOW_M, 100 * STOP_WINDOW_M)
    ax1.set_ylabel("stop error (cm)")
    ax1.set_title("Stop error and command switches vs "
                  + (labels or {}).get(x, x).partition(" [")[0])
    ax1.grid(True, alpha=0.3)
    ax1.ticklabel_format(useOffset=False, style="plain", axis="y")
    ax1.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax2.set_xlabel((labels or {}).get(x, x))
    ax2.set_ylabel("count")
    ax2.ticklabel_format(useOffset=False, style="plain", axis="both")
    ax2.grid(True, alpha=0.3)
    ax2.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax2.xaxis.set_tick_params(labelbottom=True)
    return fig
