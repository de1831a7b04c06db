"""The figures and sweeps of a reproduction entry's page: each ``[[figures]]`` drawn from the
recorded series (lines by :mod:`cosim.run.figures`; the graded speed-error bars of
``kind = "speed_classes"`` with their table here), each ``[[sweeps]]``' table and figure, and
the page's markdown of both. A figure drawn as png (shown on the page) is also written as svg
beside it (:func:`cosim.run.figures.save_figure`), linked under the figure for a reader who
wants the vector figure (:func:`figure_lines`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from cosim.reproduce.entry import Figure, Sweep, slug
from cosim.reproduce.tables import fmt, frame_markdown, md_row
from cosim.run.figures import draw_figure, legend_outside, save_figure, speed_class_errors
from cosim.run.figures.sweep import draw_sweep, key_labels
from cosim.run.scenario import Scenario, load_scenario


def figure_section(figure: Figure, frames: dict[str, pd.DataFrame], out: Path, plot_format: str,
                   scenarios: dict[str, Scenario]) -> list[str]:
    """Draw ``figure`` from the runs' series ``frames`` into ``out`` (``plot_format``; a png
    with its svg beside it); the page's lines of it (:func:`figure_lines`, and the table of a
    speed-classes figure)."""
    file = figure_file(figure, plot_format)
    title = figure.title if figure.title is not None else file
    if figure.kind == "speed_classes":
        table_md, written = draw_speed_classes(figure, frames, out / file)
        return [*figure_lines(title, written, out), "", table_md]
    written = draw_figure(figure.spec(), frames, out / file, scenarios, vector=True)
    return figure_lines(title, written, out)


def ensemble_lines(figure: Figure, written: list[Path], out: Path, seeds: int) -> list[str]:
    """The page's lines of ``figure``'s ensemble figure (``written``: its png, then its svg),
    placed under the single run's figure: the same runs over the claims' disturbance
    ensemble of ``seeds`` report seeds, each run's median with its 5-95 % band
    (:func:`cosim.run.figures.ensemble_figure_of`)."""
    title = figure.title if figure.title is not None else figure.file
    return ["", f"The same runs over the claims' {seeds} report seeds (median and 5-95 % band):",
            *figure_lines(f"{title}, over {seeds} seeds", written, out)]


def figure_lines(title: str, written: list[Path], out: Path) -> list[str]:
    """The page's lines of one figure drawn to ``written`` (paths under ``out``): the first
    shown as the image, each further one (its svg) linked under it by its format's name."""
    shown, *others = (p.relative_to(out).as_posix() for p in written)
    links = " ".join(f"[{Path(p).suffix.lstrip('.').upper()}]({p})" for p in others)
    return ["", f"![{title}]({shown})", *(["", links] if links else [])]


SWEEP_COLUMNS = ("stop_error_m", "controller_executions", "command_switches", "qp_infeasible")


def sweep_section(sweep: Sweep, stored: dict[str, Any], out: Path, plot_format: str
                  ) -> list[str]:
    """Write ``sweep``'s table (``<slug>/sweep.csv``) and figure from its recorded result
    ``stored`` (columns and rows); the page's lines of it."""
    import pandas as pd

    frame = pd.DataFrame(stored["rows"], columns=stored["columns"])
    keys = list(sweep.grid)
    target = out / slug(sweep.name)
    target.mkdir(parents=True, exist_ok=True)
    frame.to_csv(target / "sweep.csv", index=False)
    ok = frame[frame["status"] == "ok"]
    written = [target / f"sweep.{plot_format}"]
    if len(ok):
        first = load_scenario(sweep.scenarios[0])
        named = {Path(p).stem: load_scenario(p).description for p in sweep.scenarios}
        named = {n: v for n, v in named.items() if v} | sweep.labels
        written = save_figure(draw_sweep(ok, keys, key_labels(first, keys), named),
                              written[0], vector=True)
    keep = [c for c in ("scenario", *keys, *SWEEP_COLUMNS) if c in frame]
    return ["", f"#### Sweep {sweep.name}", "", frame_markdown(frame[keep]),
            *figure_lines(sweep.name, written, out)]


def draw_speed_classes(figure: Figure, frames: dict[str, pd.DataFrame], path: Path
                       ) -> tuple[str, list[Path]]:
    """Grouped bars of :func:`cosim.run.figures.speed_class_errors` per run with each class's
    limit, drawn to ``path`` (and an svg beside a png); writes ``<file>.csv`` beside the
    figure; returns the markdown table and the figure's paths."""
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
    written = save_figure(fig, path, vector=True)
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
    return "\n".join(lines), written


def figure_file(figure: Figure, plot_format: str = "png") -> str:
    """The file a ``[[figures]]`` entry is drawn to: its ``file`` in ``plot_format``."""
    return f"{Path(figure.file).stem}.{plot_format}"
