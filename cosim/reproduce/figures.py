"""The figures and sweeps of a reproduction entry's page: each ``[[figures]]`` drawn from the
recorded series (lines by :mod:`cosim.run.figures`; the graded speed-error bars of
``kind = "speed_classes"`` with their table here), each ``[[sweeps]]``' table and figure, and
the page's markdown of both."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cosim.reproduce.entry import Figure, Sweep, slug
from cosim.reproduce.tables import fmt, frame_markdown, md_row
from cosim.run.figures import draw_figure, legend_outside, speed_class_errors
from cosim.run.results import PLOT_DPI


def figure_section(figure: Figure, frames: dict[str, Any], out: Path, plot_format: str,
                   scenarios: dict[str, Any]) -> list[str]:
    """Draw ``figure`` from the runs' series ``frames`` into ``out`` (``plot_format``); the
    page's lines of it (the image, and the table of a speed-classes figure)."""
    file = figure_file(figure, plot_format)
    title = figure.title if figure.title is not None else file
    if figure.kind == "speed_classes":
        table_md = draw_speed_classes(figure, frames, out / file)
        return ["", f"![{title}]({file})", "", table_md]
    draw_figure(figure.spec(), frames, out / file, scenarios)
    return ["", f"![{title}]({file})"]


SWEEP_COLUMNS = ("stop_error_m", "controller_executions", "command_switches", "qp_infeasible")


def sweep_section(sweep: Sweep, stored: dict[str, Any], out: Path, plot_format: str
                  ) -> list[str]:
    """Write ``sweep``'s table (``<slug>/sweep.csv``) and figure from its recorded result
    ``stored`` (columns and rows); the page's lines of it."""
    import pandas as pd

    from cosim.run.scenario import load_scenario
    from cosim.run.sweep import key_labels, plot_sweep

    frame = pd.DataFrame(stored["rows"], columns=stored["columns"])
    keys = list(sweep.grid)
    target = out / slug(sweep.name)
    target.mkdir(parents=True, exist_ok=True)
    frame.to_csv(target / "sweep.csv", index=False)
    ok = frame[frame["status"] == "ok"]
    if len(ok):
        first = load_scenario(sweep.scenarios[0])
        named = {Path(p).stem: load_scenario(p).description for p in sweep.scenarios}
        named = {n: v for n, v in named.items() if v} | sweep.labels
        plot_sweep(ok, keys, target / f"sweep.{plot_format}", key_labels(first, keys), named)
    keep = [c for c in ("scenario", *keys, *SWEEP_COLUMNS) if c in frame]
    return ["", f"#### Sweep {sweep.name}", "", frame_markdown(frame[keep]), "",
            f"![{sweep.name}]({target.name}/sweep.{plot_format})"]


def draw_speed_classes(figure: Figure, frames: dict[str, Any], path: Path) -> str:
    """Grouped bars of :func:`cosim.run.figures.speed_class_errors` per run with each class's
    limit; writes ``<file>.csv`` beside the figure and returns the markdown table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    spec = figure.spec()
    names = list(figure.runs or frames)
    per_run = {n: speed_class_errors(frames[n], spec) for n in names}
    classes = [r["class"] for r in per_run[names[0]]]
    limits = [next((per_run[n][k]["limit"] for n in names if per_run[n][k]["limit"]
                    is not None), None) for k in range(len(classes))]
    pd.DataFrame([{"run": n, **r} for n in names for r in per_run[n]]).to_csv(
        path.with_suffix(".csv"), index=False)
    fig, ax = plt.subplots(figsize=(10.5, 4.5), layout="constrained")
    x = np.arange(len(classes))
    width = 0.8 / (len(names) + 1)
    for i, n in enumerate(names):
        heights = [r["max_abs_error"] or 0.0 for r in per_run[n]]
        bars = ax.bar(x + (i - len(names) / 2) * width, heights, width, label=n)
        for bar, r in zip(bars, per_run[n], strict=True):
            if r["met"] is False:
                ax.annotate("x", (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                            ha="center", va="bottom", color="red", fontsize=8)
    lim = [v if v is not None else np.nan for v in limits]
    ax.bar(x + (len(names) / 2) * width, lim, width, color="none", edgecolor="black",
           hatch="//", label="limit (strictest in class)")
    ax.set_yscale("log")
    ax.set_xticks(x, classes)
    ax.set_xlabel("reference speed class (km/h)")
    ax.set_ylabel(figure.ylabel if figure.ylabel is not None else "max |speed error|")
    ax.grid(True, axis="y", alpha=0.3)
    legend_outside(ax)
    fig.suptitle(figure.title or "")
    fig.savefig(path, dpi=PLOT_DPI, format=Path(path).suffix.lstrip(".") or "png",
                bbox_inches="tight")
    plt.close(fig)
    lines = [md_row(["class", "limit", *names]), "|" + " --- |" * (len(names) + 2)]
    for k, cls in enumerate(classes):
        cells = []
        for n in names:
            r = per_run[n][k]
            cells.append("-" if r["max_abs_error"] is None else
                         f"{fmt(r['max_abs_error'])} {'✓' if r['met'] else '✗'}")
        lines.append(md_row([cls, fmt(limits[k]) if limits[k] is not None else "-", *cells]))
    lines += ["", "max |error| per class of the reference speed over the units (✓ / ✗: every "
              "sample within its own allowance); limit: the class's strictest allowance."]
    if figure.paper:
        lines += ["", f"Paper: {figure.paper}"]
    return "\n".join(lines)


def figure_file(figure: Figure, plot_format: str = "png") -> str:
    """The file a ``[[figures]]`` entry is drawn to: its ``file`` in ``plot_format``."""
    return f"{Path(figure.file).stem}.{plot_format}"
