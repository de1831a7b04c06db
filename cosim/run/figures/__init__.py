"""Every figure, drawn from recorded series; it imports none of the runners, and the runners
and :mod:`cosim.reproduce` import it. Here: a reproduction's figures (the runs' overlays and
panels, the ensembles' medians and bands) and the helpers every figure shares (labels and
units from the declarations, the roles and drawing styles of measured and reference curves,
legends right of the axes); :mod:`cosim.run.figures.run` a run's figure (``plot.png``),
:mod:`cosim.run.figures.sweep` a sweep's, :mod:`cosim.run.figures.perturb` a perturbation
study's. Figures are matplotlib figures saved at :data:`PLOT_DPI` (png), or as svg / pdf by
the file's suffix (:func:`save_figure`: the same bytes on every draw). No figure is an input
of a record's simulation digest (:mod:`cosim.run.provenance`): a figure is redrawn from the
record.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cosim.fmu.profiles import StoppingCurve
from cosim.run.columns import display_unit, is_held, variable_info
from cosim.run.metrics import graded_allowance, matching_columns

PLOT_DPI = 200  # raster figures (png) at print resolution


class FigureError(ValueError):
    """A figure that cannot be drawn from what was recorded (the message names the figure,
    the run and the column)."""


SVG_HASHSALT = "ato-cosim"  # matplotlib's svg.hashsalt: the svg's element ids, fixed
UNDATED: dict[str, dict[str, Any]] = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}


def save_figure(fig: Any, path: Path, vector: bool = False) -> list[Path]:
    """Save ``fig`` to ``path`` by its suffix (png at :data:`PLOT_DPI`, svg or pdf) and, with
    ``vector``, an svg beside a png (the same stem), then close it; the paths written. The
    bytes are the same on every draw of the same figure: the svg's element ids hashed from
    :data:`SVG_HASHSALT`, no date in the svg's or pdf's metadata (:data:`UNDATED`)."""
    import matplotlib
    import matplotlib.pyplot as plt

    path = Path(path)
    paths = [path, *([path.with_suffix(".svg")] if vector and path.suffix == ".png" else [])]
    with matplotlib.rc_context({"svg.hashsalt": SVG_HASHSALT}):
        for target in paths:
            kind = target.suffix.lstrip(".") or "png"
            fig.savefig(target, dpi=PLOT_DPI, format=kind, bbox_inches="tight",
                        metadata=UNDATED.get(kind))
    plt.close(fig)
    return paths


def draw_figure(spec: dict[str, Any], frames: dict[str, Any], path: Path,
                scenarios: dict[str, Any] | None = None, vector: bool = False) -> list[Path]:
    """:func:`figure_of` the runs' recorded series (run name -> frame), saved to ``path`` (its
    suffix: png at 200 dpi, svg or pdf) and, with ``vector``, as svg beside a png
    (:func:`save_figure`); the paths written."""
    names = list(spec.get("runs", list(frames)))
    fig = figure_of(spec, {n: frames[n] for n in names}, scenarios or {})
    return save_figure(fig, path, vector)


def series_style(scenario: Any, ref: str, references: list[str] | tuple[str, ...] = ()
                 ) -> dict[str, Any]:
    """How a figure draws the column ``ref`` of a run of ``scenario``: a reference (one of the
    figure's ``references``, or the scenario's ``[summary]`` ``reference_speed`` or
    ``reference_accel``) as its continuous curve (:data:`REFERENCE_STYLE`), an output of a
    sampled or self-triggered FMU (held between its events) as steps, anything else (the
    plant's continuous states) as a line; with the legend text from the declaration (its
    description)."""
    if scenario is None:
        return {"drawstyle": "default", "text": f"reference: {ref}" if ref in references
                else ref, "reference": ref in references}
    summary = scenario.summary
    reference = ref in (*references, summary.get("reference_speed"),
                        summary.get("reference_accel"))
    text = variable_info(scenario, ref)[0]
    if reference:
        return {"drawstyle": "default", "text": f"reference: {text}", "reference": True}
    return {"drawstyle": "steps-post" if is_held(scenario, ref) else "default", "text": text,
            "reference": False}


def axis_text(spec: dict[str, Any], axis: str, scenario: Any, column: str
              ) -> tuple[str, float]:
    """(label, factor) of an axis: the entry's ``xlabel`` / ``ylabel`` and ``y_scale`` where
    given, else the declared description of ``column`` in its display unit (km/h for m/s, kN
    for N, ...) and the factor to that unit; ``time (s)`` for the time."""
    scale = float(spec.get("y_scale", 1.0)) if axis == "y" else 1.0
    given = spec.get(f"{axis}label")
    if column == "time":
        return str(given or "time (s)"), 1.0
    text, unit = variable_info(scenario, column) if scenario is not None else (column, None)
    if given:
        return str(given), scale
    if scale != 1.0:  # the entry's factor, without its unit's name
        return f"{text} ({unit or '1'} x {scale:g})", scale
    factor, shown = display_unit(unit)
    return (f"{text} ({shown})" if shown and shown != "1" else text), factor


def finish_axes(ax: Any, spec: dict[str, Any], title: str | None, ylabel: str,
                first: bool) -> None:
    """A panel's title (its run), the y label, the grid, the zoom (once per axes: ``first``)
    and plain tick labels."""
    if title is not None:
        ax.set_title(title, fontsize=9)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if first:
        zoom(ax, spec)
    plain_axes(ax)


def zoom(ax: Any, spec: dict[str, Any]) -> None:
    """The figure's ``xlim`` / ``ylim`` (drawn units) and shaded ``band_x`` [lo, hi, label]."""
    if "band_x" in spec:
        lo, hi, *label = spec["band_x"]
        ax.axvspan(float(lo), float(hi), color="0.85", zorder=0,
                   label=str(label[0]) if label else None)
    if "xlim" in spec:
        ax.set_xlim(*(float(v) for v in spec["xlim"]))
    if "ylim" in spec:
        ax.set_ylim(*(float(v) for v in spec["ylim"]))


def plain_axes(ax: Any) -> None:
    """Tick labels without offset or scientific notation ("+1.999e1") on linear axes."""
    for axis in ("x", "y"):
        scale = ax.get_xscale() if axis == "x" else ax.get_yscale()
        if scale == "linear":
            ax.ticklabel_format(axis=axis, useOffset=False, style="plain")


def legend_outside(ax: Any, handles: list[Any] | None = None,
                   labels: list[str] | None = None) -> Any:
    """The legend right of the axes, where no curve can be under it (inside the figure: the
    constrained layout makes room for it); of ``handles`` and ``labels`` where given, in that
    order, else of every labelled artist of the axes; each label wrapped at
    ``LEGEND_WIDTH`` characters."""
    import textwrap

    if handles is None or labels is None:
        handles, labels = ax.get_legend_handles_labels()
    wrapped = [textwrap.fill(text, LEGEND_WIDTH) for text in labels]
    legend = ax.legend(handles, wrapped, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                       fontsize=9, frameon=False, borderaxespad=0.0)
    fit_legend_height(ax, legend)
    return legend


def fit_legend_height(ax: Any, legend: Any) -> None:
    """Make the figure tall enough for ``legend`` (right of ``ax``) to fit beside the axes'
    rows: a legend taller than its rows' share of the figure would squeeze the axes to
    nothing under the constrained layout. The figure's height becomes at least the legend's
    height over the rows' share of the height ratios, plus :data:`TITLE_AND_AXIS_LABEL`."""
    fig = ax.figure
    height = legend.get_window_extent(fig.canvas.get_renderer()).height / fig.dpi  # inches
    rows = ax.get_subplotspec()
    grid = rows.get_gridspec()
    ratios = list(grid.get_height_ratios() or [1.0] * grid.nrows)
    share = sum(ratios[rows.rowspan.start:rows.rowspan.stop]) / sum(ratios)
    need = height / share + TITLE_AND_AXIS_LABEL
    if need > fig.get_figheight():
        fig.set_figheight(need)


LEGEND_WIDTH = 36  # characters of a legend line: a long declared description wraps
TITLE_AND_AXIS_LABEL = 0.8  # inches of a figure's height above and below its axes


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")  # per measured series of one axes
MEASURED_WIDTH = 1.4  # measured curves: solid, coloured, a marker every MARKER_EVERY
REFERENCE_WIDTH = 1.0  # reference curves: solid, mid grey, thinner, drawn beneath the measured
REFERENCE_COLOUR = "0.5"  # mid grey (matplotlib's grey level)
REFERENCE_ZORDER = 1.8  # above the grid (1.5) and bands (0), beneath measured curves (2)
MARKER_EVERY = 0.12  # the markers' spacing along a curve, a fraction of the axes' diagonal
MAX_PANELS = 5  # axes of one figure (error panels included): a printed page's height
PANEL_HEIGHT = 2.2  # inches of a tracking or panels axes
ERROR_HEIGHT = 1.3  # inches of an error panel
KM_FROM_M = 10_000.0  # a position axis spanning at least this (m) is drawn in km


def x_axis(spec: dict[str, Any], scenario: Any, frames: dict[str, Any]) -> tuple[str, float]:
    """(label, factor) of a figure's x axis: :func:`axis_text`, with a position declared in m
    drawn in km where the runs span at least ``KM_FROM_M`` (no 6-digit tick labels)."""
    label, factor = axis_text(spec, "x", scenario, spec["x"])
    if spec["x"] == "time" or spec.get("xlabel") or scenario is None:
        return label, factor
    text, unit = variable_info(scenario, spec["x"])
    span = max((float(np.nanmax(np.abs(f[spec["x"]].to_numpy(dtype=float))))
                for f in frames.values() if spec["x"] in f and len(f)), default=0.0)
    if unit == "m" and span >= KM_FROM_M:
        return f"{text} (km)", 1e-3
    return label, factor


def series_label(spec: dict[str, Any], scenario: Any, y: str, style: dict[str, Any]) -> str:
    """The legend text of one series: its declared description (:func:`series_style`), with
    ``y_reduce`` ("mean of ...") and ``y_minus`` ("... - <its description>") said."""
    text = style["text"]
    if "y_reduce" in spec:
        text = f"{spec['y_reduce']} of {y}"
    if "y_minus" in spec:
        minus = variable_info(scenario, spec["y_minus"])[0] if scenario is not None \
            else spec["y_minus"]
        text = f"{text} - {minus}"
    return text


def measured_style(k: int) -> dict[str, Any]:
    """How the ``k``-th measured series of one axes is drawn: solid, in the ``k``-th colour of
    the colour cycle, with the ``k``-th marker every ``MARKER_EVERY`` of the axes' diagonal
    (staggered, so curves that coincide, such as cars with the same force, stay visible and
    tell apart in grey print)."""
    return {"color": f"C{k % 10}", "linestyle": "-", "linewidth": MEASURED_WIDTH,
            "marker": MARKERS[k % len(MARKERS)], "markersize": 4.0,
            "markevery": ((k * MARKER_EVERY / 7.0) % MARKER_EVERY, MARKER_EVERY), "zorder": 2}


REFERENCE_STYLE: dict[str, Any] = {"color": REFERENCE_COLOUR, "linestyle": "-",
                                   "linewidth": REFERENCE_WIDTH, "zorder": REFERENCE_ZORDER}


def measured_line(artist: Any) -> bool:
    """Whether a legend's ``artist`` is a measured curve (drawn with markers,
    :func:`measured_style`); the legend lists those first."""
    return getattr(artist, "get_marker", lambda: None)() not in (None, "None", "")


def first_scenario(names: list[str], scenarios: dict[str, Any]) -> Any:
    """The scenario of the first run of ``names`` (None without runs or declarations)."""
    return scenarios.get(names[0]) if names else None


def panel_count(spec: dict[str, Any], runs: int) -> int:
    """The axes a line figure draws for ``runs`` runs: one (``overlay``) or one per run
    (``panels``), each with an error panel under it where ``error`` is given."""
    per_run = 2 if spec.get("error") else 1
    return per_run * (runs if spec.get("kind", "overlay") == "panels" else 1)


ERROR_FROM_REFERENCE = "reference"  # error = this: the reference minus the measured series
ERROR_FROM_REFERENCE_TEXT = "reference − measured"


def error_label(spec: dict[str, Any], scenario: Any, ylabel: str) -> str:
    """The error panel's y label: the ``error`` column's declared description (or
    :data:`ERROR_FROM_REFERENCE_TEXT`) in the unit of the tracking axes' label ``ylabel`` (the
    error is drawn with the same factor)."""
    column = spec["error"]
    text = (ERROR_FROM_REFERENCE_TEXT if column == ERROR_FROM_REFERENCE
            else variable_info(scenario, column)[0] if scenario is not None else column)
    unit = ylabel.rsplit("(", 1)[1].rstrip(")") if ylabel.endswith(")") and "(" in ylabel \
        else None
    return f"{text} ({unit})" if unit else text


def legend_once(label: str, seen: set[str], role: str | None = None) -> str:
    """``label`` the first time a figure's legend would show its ``role`` (default: the label
    itself), else hidden (``_``-prefixed): one legend entry for the references (and limits)
    of several runs."""
    key = label if role is None else role
    if key in seen:
        return f"_{label}"
    seen.add(key)
    return label


def figure_of(spec: dict[str, Any], frames: dict[str, Any], scenarios: dict[str, Any]) -> Any:
    """One ``[[figures]]`` figure (kind ``overlay``: every run on one axes; ``panels``: one
    axes per run), with an error panel (the ``error`` column, zero drawn as its reference)
    under each tracking axes where ``error`` is given, from the runs' recorded frames;
    ``scenarios``: run name -> its loaded scenario (the declarations behind labels, roles and
    drawing styles, :func:`series_style`).

    A series is a reference where its scenario's ``[summary]`` declares it so
    (``reference_speed`` / ``reference_accel``): drawn as its continuous curve, solid, mid
    grey and thinner, beneath the measured ones (:data:`REFERENCE_STYLE`: where tracking is
    tight the measured curve stays visible); every other series is measured: solid, in its own
    colour and marker (:func:`measured_style`; the runs of an overlay, or the series of a
    panel, each their own). At most ``MAX_PANELS`` axes (:func:`panel_count`). The legend sits
    right of the first axes, inside the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(frames)
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    panels = spec.get("kind", "overlay") == "panels"
    error = spec.get("error")
    references = list(spec.get("reference", []))
    if unknown := [r for r in references if r not in ys]:
        raise FigureError(f"figure {spec['file']}: reference = {unknown!r} not among its y "
                          f"{ys!r}")
    count = panel_count(spec, len(names))
    measured = max(1, len([y for y in ys if y not in references and (
        "y_reduce" in spec or not series_style(first_scenario(names, scenarios), y,
                                               references)["reference"])]))
    if count > MAX_PANELS:
        raise FigureError(
            f"figure {spec['file']}: {count} panels ({len(names)} runs, kind "
            f"{spec.get('kind', 'overlay')!r}{', each with an error panel' if error else ''}); "
            f"at most {MAX_PANELS} fit a page: name fewer runs, or draw kind = \"overlay\"")
    heights = [PANEL_HEIGHT, ERROR_HEIGHT] * (count // 2) if error else [PANEL_HEIGHT] * count
    fig, axes = plt.subplots(count, 1, squeeze=False, sharex=True,
                             figsize=(9, sum(heights) + TITLE_AND_AXIS_LABEL),
                             height_ratios=heights,
                             layout="constrained")  # room for the title and the legend
    per_run = 2 if error else 1
    xlabel, xfactor = x_axis(spec, first_scenario(names, scenarios), frames)
    seen: set[str] = set()
    for i, name in enumerate(names):
        frame, scenario = frames[name], scenarios.get(name)
        row = i * per_run if panels else 0
        ax = axes[row][0]
        x = (frame["time"] if spec["x"] == "time" else frame[spec["x"]]) * xfactor
        ylabel, scale = axis_text(spec, "y", scenario, ys[0])
        k = 0 if panels else i * measured  # the measured series' style index
        run_style: dict[str, Any] | None = None
        drawn: dict[str, Any] = {}  # "reference" / "measured": the first of each, unscaled
        for y in ys:
            style = series_style(scenario, y, references) if "y_reduce" not in spec else \
                {"drawstyle": "default", "text": y, "reference": False}
            text = series_label(spec, scenario, y, style)
            values = figure_series(frame, spec, y, name)
            if style["reference"] and "y_minus" not in spec:
                curve = reference_curve(scenario, frame, y)
                values = values if curve is None else curve
                drawn.setdefault("reference", values)
                ax.plot(x, values * scale, label=legend_once(text, seen, "reference"),
                        **REFERENCE_STYLE)
                continue
            drawn.setdefault("measured", values)
            label = text if panels else (name if measured == 1 else f"{name}: {text}")
            kwargs = measured_style(k)
            k += 1
            run_style = run_style or kwargs
            ax.plot(x, values * scale, label=label,
                    drawstyle=style["drawstyle"], **kwargs)
        if "limit_ref" in spec:
            draw_limits(ax, spec, frame, x, name, seen)
        finish_axes(ax, spec, name if panels else None, ylabel, panels or i == 0)
        if error:
            draw_error(axes[row + 1][0], spec, error_values(spec, frame, name, drawn), x,
                       scenario, ylabel, scale, run_style or measured_style(k), i == 0 or panels)
    labelled = [ax for ax in fig.axes if len(ax.get_legend_handles_labels()[1]) > 1]
    if labelled:  # one legend: the runs' (or series') styles are the same in every axes
        handles, labels = labelled[0].get_legend_handles_labels()
        order = sorted(range(len(labels)), key=lambda n: not measured_line(handles[n]))
        legend_outside(labelled[0], [handles[n] for n in order], [labels[n] for n in order])
    axes[-1][0].set_xlabel(xlabel)
    fig.suptitle(spec.get("title", ""))
    return fig


def error_values(spec: dict[str, Any], frame: Any, run: str, drawn: dict[str, Any]) -> Any:
    """The error one run's panel shows (before ``y_scale``): its recorded ``error`` column, or
    with ``error = "reference"`` (:data:`ERROR_FROM_REFERENCE`) the run's reference as drawn
    (its continuous curve where the scenario declares one) minus its first measured series
    (``drawn``: "reference" / "measured" -> values); :class:`FigureError` naming the figure
    and the run when what it needs is missing."""
    column = spec["error"]
    if column == ERROR_FROM_REFERENCE:
        if missing := [role for role in ("reference", "measured") if role not in drawn]:
            raise FigureError(f"figure {spec['file']}: error = {column!r} needs a reference "
                              f"and a measured series; run {run!r} has no {missing[0]} among "
                              f"y {spec['y']!r}")
        return drawn["reference"] - drawn["measured"]
    if column not in frame:
        raise FigureError(f"figure {spec['file']}: run {run!r} recorded no {column!r} "
                          f"(key error)")
    return frame[column].to_numpy(dtype=float)


def draw_error(ax: Any, spec: dict[str, Any], values: Any, x: Any, scenario: Any,
               ylabel: str, scale: float, style: dict[str, Any], first: bool) -> None:
    """The error panel of one run: its error ``values`` (:func:`error_values`) times ``scale``
    (the tracking axes' factor) solid in the run's colour (without markers), and the zero
    error (its reference) as a reference (:data:`REFERENCE_STYLE`)."""
    ax.plot(x, values * scale,
            **{**style, "marker": None, "linewidth": 1.0})  # spikes would crowd the markers
    if first:
        ax.axhline(0.0, **REFERENCE_STYLE)
        ax.set_ylabel(error_label(spec, scenario, ylabel))
        ax.grid(True, alpha=0.3)
        plain_axes(ax)


def draw_limits(ax: Any, spec: dict[str, Any], frame: Any, x: Any, run: str,
                seen: set[str] | None = None) -> None:
    """The zero-error reference (:data:`REFERENCE_STYLE`) and the +- allowance (dashed black:
    ``limit_kmh`` at or below ``limit_below_kmh``, ``limit_fraction`` of the speed above) of
    the ``limit_ref`` speed (times ``y_scale``) on an error figure's axes; each named once in
    the legend of a figure whose labels ``seen`` collects."""
    ref_col = spec["limit_ref"]
    if ref_col not in frame:
        raise FigureError(f"figure {spec['file']}: run {run!r} recorded no {ref_col!r}")
    ref = frame[ref_col].to_numpy(dtype=float) * float(spec.get("y_scale", 1.0))
    allowed = graded_allowance(ref, float(spec.get("limit_kmh", 2.0)),
                               float(spec.get("limit_below_kmh", 30.0)),
                               float(spec.get("limit_fraction", 0.02))).astype(float)
    allowed[ref <= 0.0] = float("nan")  # standing: no allowance drawn
    seen = set() if seen is None else seen
    ax.axhline(0.0, **REFERENCE_STYLE, label=legend_once("reference (zero error)", seen))
    ax.plot(x, allowed, color="black", linestyle="--", linewidth=0.8,
            label=legend_once("limit", seen))
    ax.plot(x, -allowed, color="black", linestyle="--", linewidth=0.8)


def reference_curve(scenario: Any, frame: Any, y: str) -> Any:
    """The continuous reference behind a held ``reference_speed`` column: the stopping curve
    ``v_ref(s) = sqrt(2 a0 (s_stop - s))`` at the recorded positions where ``[summary]``
    declares ``reference_decel`` and ``stop_point`` (as the speed metrics use it); None
    otherwise (the recorded column is the curve)."""
    import numpy as np

    cfg = getattr(scenario, "summary", {}) or {}
    position = cfg.get("position")
    if (y != cfg.get("reference_speed") or "reference_decel" not in cfg
            or "stop_point" not in cfg or position not in frame):
        return None
    curve = StoppingCurve(float(cfg["reference_decel"]), float(cfg["stop_point"]))
    return np.array([curve.speed(x) for x in frame[position].to_numpy(dtype=float)])


def figure_series(frame: Any, spec: dict[str, Any], y: str, run: str) -> Any:
    """The values a figure plots for ``y`` of one run (before ``y_scale``): the column, or with
    ``y_reduce = "mean"`` the mean of the columns ``y`` names (``"plant.v[*]"``; a column of
    that name is that mean as recorded), minus the ``y_minus`` column where given."""
    if "y_reduce" in spec and y in frame:  # the reduction as recorded (cosim.reproduce.record)
        cols = [y]
    else:
        cols = matching_columns(frame, y) if "y_reduce" in spec else [y] if y in frame else []
    minus = spec.get("y_minus")
    for missing in ([] if cols else [y]) + ([minus] if minus and minus not in frame else []):
        raise FigureError(f"figure {spec['file']}: run {run!r} recorded no {missing!r}")
    values = frame[cols].to_numpy(dtype=float).mean(axis=1)
    return values - frame[minus].to_numpy(dtype=float) if minus else values


def speed_class_errors(frame: Any, spec: dict[str, Any]) -> list[dict[str, Any]]:
    """Graded speed error of one run (a ``speed_classes`` figure).

    Per class (lo, hi] of the reference speed (samples with the reference above zero): the
    max |error| over the ``y`` columns, the class's strictest allowance (at its lowest sample
    speed) and whether every sample keeps its own allowance (all in the figure's units)."""
    import numpy as np

    scale = float(spec.get("y_scale", 1.0))
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    for col in [*ys, spec["ref"]]:
        if col not in frame:
            raise FigureError(f"figure {spec['file']}: no recorded {col!r}")
    ref = frame[spec["ref"]].to_numpy(dtype=float) * scale
    vals = frame[ys].to_numpy(dtype=float) * scale
    err = np.abs(vals - ref[:, None]).max(axis=1)
    edges = [float(e) for e in spec["classes"]]
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (ref > max(lo, 0.0)) & (ref <= hi)
        row: dict[str, Any] = {"class": f"{lo:g}-{hi:g}", "samples": int(sel.sum()),
                               "max_abs_error": None, "limit": None, "met": None}
        if np.any(sel):
            allowed = graded_allowance(ref[sel], float(spec["limit_kmh"]),
                                       float(spec["limit_below_kmh"]),
                                       float(spec["limit_fraction"]))
            row.update(max_abs_error=float(err[sel].max()), limit=float(allowed.min()),
                       met=bool(np.all(err[sel] <= allowed + 1e-12)))
        rows.append(row)
    return rows


def figure_columns(spec: dict[str, Any], scenario: Any, columns: list[str]) -> set[str]:
    """The recorded columns a ``[[figures]]`` entry reads from one run's results (of
    ``columns``): time, x, the y columns (patterns expanded), ``y_minus``, ``limit_ref``,
    ``ref``, ``error`` and the position behind a stopping-curve reference
    (:func:`reference_curve`)."""
    import pandas as pd

    empty = pd.DataFrame(columns=columns)
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    wanted = {"time", spec.get("x", "time"), spec.get("y_minus"), spec.get("limit_ref"),
              spec.get("ref"), spec.get("error"),
              (getattr(scenario, "summary", {}) or {}).get("position")}
    for y in ys:
        wanted.update(matching_columns(empty, y) if "y_reduce" in spec else [y])
    return {c for c in wanted if c in columns}


def draw_ensemble_figure(spec: dict[str, Any], frames: dict[str, list[Any]], path: Path,
                         scenarios: dict[str, Any] | None = None, vector: bool = False
                         ) -> list[Path]:
    """:func:`ensemble_figure_of` the members' recorded series (run name -> one frame per
    member), saved to ``path`` (png at 200 dpi, svg or pdf by its suffix) and, with
    ``vector``, as svg beside a png (:func:`save_figure`); the paths written."""
    return save_figure(ensemble_figure_of(spec, frames, scenarios or {}), path, vector)


def ensemble_figure_of(spec: dict[str, Any], frames: dict[str, list[Any]],
                       scenarios: dict[str, Any]) -> Any:
    """An overlay figure over an ensemble: per run the median over the members and a 5-95 %
    band (members sampled on the first member's x grid; x = "time" or a recorded column;
    a reference column the members did not record and no declared curve gives is left out);
    held signals as steps, the measured medians solid in their colours, the reference as its
    continuous curve (solid, mid grey, beneath: :data:`REFERENCE_STYLE`), labels and units from
    the declarations (:func:`series_style`), a long position axis in km (:func:`x_axis`), the
    legend outside."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    first = scenarios.get(next(iter(frames))) if frames else None
    ylabel, scale = axis_text(spec, "y", first, ys[0])
    panels = spec.get("kind", "overlay") == "panels"
    fig, axes = plt.subplots(len(frames) if panels else 1, 1, squeeze=False, sharex=True,
                             figsize=(9, 2.6 * len(frames) if panels else 4.5),
                             layout="constrained")  # room for the title and outside legends
    xlabel, xfactor = x_axis(spec, first, {n: m[0] for n, m in frames.items() if m})
    for j, (name, members_) in enumerate(frames.items()):
        ax = axes[j if panels else 0][0]
        x0 = (members_[0]["time"] if spec["x"] == "time" else members_[0][spec["x"]]) * xfactor
        k = 0 if panels else j * len(ys)  # the measured series' style index
        for y in ys:
            style = ({"drawstyle": "default", "text": y, "reference": False}
                     if "y_reduce" in spec
                     else series_style(scenarios.get(name), y, spec.get("reference", ())))
            if "y_minus" in spec:  # a difference: measured, labelled as one
                style = {**style, "reference": False}
            curves = []
            for frame in members_:
                x = (frame["time"] if spec["x"] == "time" else frame[spec["x"]]) * xfactor
                curve = (reference_curve(scenarios.get(name), frame, y) if style["reference"]
                         else None)
                if curve is None and style["reference"] and y not in frame:
                    break  # a reference the members did not record: left out
                values = figure_series(frame, spec, y, name) if curve is None else curve
                curves.append(np.interp(x0, x, values * scale))
            if len(curves) < len(members_):
                continue
            stack = np.vstack(curves)
            text = series_label(spec, scenarios.get(name), y, style)
            label = text if panels else name if len(ys) == 1 else f"{name}: {text}"
            kwargs: dict[str, Any] = {"drawstyle": style["drawstyle"]}
            kwargs.update(REFERENCE_STYLE if style["reference"] else
                          {**measured_style(k), "marker": None})
            k += 0 if style["reference"] else 1
            line, = ax.plot(x0, np.median(stack, axis=0),
                            label=f"{label} (median of {len(members_)})", **kwargs)
            ax.fill_between(x0, np.percentile(stack, 5, axis=0),
                            np.percentile(stack, 95, axis=0), color=line.get_color(),
                            alpha=0.25, linewidth=0, rasterized=True,
                            step="post" if style["drawstyle"] == "steps-post" else None)
        if "limit_ref" in spec and (panels or j == 0):
            draw_limits(ax, spec, members_[0], x0, name)
        finish_axes(ax, spec, name if panels else None, ylabel, panels or j == 0)
        legend_outside(ax)
    axes[-1][0].set_xlabel(xlabel)
    fig.suptitle(f"{spec.get('title', '')} (median, 5-95 % band over the seeds)")
    return fig


