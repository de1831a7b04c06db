"""Every figure of a reproduction drawn from recorded series: the runs' overlays and panels,
the ensembles' medians and bands, and the helpers they share (labels and units from the
declarations, drawing styles, legends outside the axes). It imports none of the runners; the
runners and :mod:`cosim.reproduce` import it. Figures are matplotlib figures saved at
:data:`cosim.run.results.PLOT_DPI` (png), or as svg / pdf by the file's suffix.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.results import PLOT_DPI


class FigureError(ValueError):
    """A figure that cannot be drawn from what was recorded (the message names the figure,
    the run and the column)."""


def draw_figure(spec: dict[str, Any], frames: dict[str, Any], path: Path,
                scenarios: dict[str, Any] | None = None) -> None:
    """:func:`figure_of` the runs' recorded series (run name -> frame), saved to ``path`` (its
    suffix: png at 200 dpi, svg or pdf)."""
    import matplotlib.pyplot as plt

    names = list(spec.get("runs", list(frames)))
    fig = figure_of(spec, {n: frames[n] for n in names}, scenarios or {})
    fig.savefig(path, dpi=PLOT_DPI, format=Path(path).suffix.lstrip(".") or "png",
                bbox_inches="tight")
    plt.close(fig)


def series_style(scenario: Any, ref: str) -> dict[str, Any]:
    """How a figure draws the column ``ref`` of a run of ``scenario``: the scenario's
    reference (``[summary]`` ``reference_speed`` or ``reference_accel``) as a continuous
    dashed curve, an output of a sampled or self-triggered FMU (held between its events) as
    steps, anything else (the plant's continuous states) as a line; with the legend text from
    the declaration (its description)."""
    from cosim.run.results import _held, variable_info

    if scenario is None:
        return {"drawstyle": "default", "text": ref, "reference": False}
    summary = scenario.summary
    reference = ref in (summary.get("reference_speed"), summary.get("reference_accel"))
    text = variable_info(scenario, ref)[0]
    if reference:
        return {"drawstyle": "default", "text": f"reference: {text}", "reference": True}
    return {"drawstyle": "steps-post" if _held(scenario, ref) else "default", "text": text,
            "reference": False}


def axis_text(spec: dict[str, Any], axis: str, scenario: Any, column: str
              ) -> tuple[str, float]:
    """(label, factor) of an axis: the entry's ``xlabel`` / ``ylabel`` and ``y_scale`` where
    given, else the declared description of ``column`` in its display unit (km/h for m/s, kN
    for N, ...) and the factor to that unit; ``time (s)`` for the time."""
    from cosim.run.results import display_unit, variable_info

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


def legend_outside(ax: Any) -> Any:
    """The legend right of the axes, where no curve can be under it."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False,
                     borderaxespad=0.0)


LINESTYLES = ("-", "--", ":", "-.")  # per series of one axes: coinciding curves stay visible
KM_FROM_M = 10_000.0  # a position axis spanning at least this (m) is drawn in km


def x_axis(spec: dict[str, Any], scenario: Any, frames: dict[str, Any]) -> tuple[str, float]:
    """(label, factor) of a figure's x axis: :func:`axis_text`, with a position declared in m
    drawn in km where the runs span at least ``KM_FROM_M`` (no 6-digit tick labels)."""
    from cosim.run.results import variable_info

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
    from cosim.run.results import variable_info

    text = style["text"]
    if "y_reduce" in spec:
        text = f"{spec['y_reduce']} of {y}"
    if "y_minus" in spec:
        minus = variable_info(scenario, spec["y_minus"])[0] if scenario is not None \
            else spec["y_minus"]
        text = f"{text} - {minus}"
    return text


def figure_of(spec: dict[str, Any], frames: dict[str, Any], scenarios: dict[str, Any]) -> Any:
    """One ``[[figures]]`` figure (kind ``overlay``: every run on one axes; ``panels``: one
    axes per run) from the runs' recorded frames; ``scenarios``: run name -> its loaded
    scenario (the declarations behind labels and drawing styles, :func:`series_style`).

    The series of one axes cycle through ``LINESTYLES``, so curves that coincide (cars with the
    same force) stay distinguishable; a legend is drawn where an axes has more than one
    labelled curve (a single-curve panel is named by its title and y label)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(frames)
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    panels = spec.get("kind", "overlay") == "panels"
    fig, axes = plt.subplots(len(names) if panels else 1, 1, squeeze=False, sharex=True,
                             figsize=(9, 2.6 * len(names) if panels else 4.5),
                             layout="constrained")  # room for the title and outside legends
    first = scenarios.get(names[0]) if names else None
    xlabel, xfactor = x_axis(spec, first, frames)
    for i, name in enumerate(names):
        frame, scenario = frames[name], scenarios.get(name)
        ax = axes[i if panels else 0][0]
        x = (frame["time"] if spec["x"] == "time" else frame[spec["x"]]) * xfactor
        ylabel, scale = axis_text(spec, "y", scenario, ys[0])
        for j, y in enumerate(ys):
            style = series_style(scenario, y) if "y_reduce" not in spec else \
                {"drawstyle": "default", "text": y, "reference": False}
            text = series_label(spec, scenario, y, style)
            label = text if panels else (name if len(ys) == 1 else f"{name}: {text}")
            kwargs: dict[str, Any] = {"linewidth": 1.0, "drawstyle": style["drawstyle"]}
            if panels or len(ys) > 1:
                kwargs["linestyle"] = LINESTYLES[j % len(LINESTYLES)]
            values = figure_series(frame, spec, y, name)
            if style["reference"] and "y_minus" not in spec:
                kwargs.update(color="black", linestyle="--", linewidth=0.9)
                curve = reference_curve(scenario, frame, y)
                values = values if curve is None else curve
            ax.plot(x, values * scale, label=label, **kwargs)
        if "limit_ref" in spec:
            draw_limits(ax, spec, frame, x, name)
        finish_axes(ax, spec, name if panels else None, ylabel, panels or i == 0)
        if len(ax.get_legend_handles_labels()[1]) > 1:
            legend_outside(ax)
    axes[-1][0].set_xlabel(xlabel)
    fig.suptitle(spec.get("title", ""))
    return fig


def draw_limits(ax: Any, spec: dict[str, Any], frame: Any, x: Any, run: str) -> None:
    """The zero-error reference and the +- allowance (``limit_kmh`` at or below
    ``limit_below_kmh``, ``limit_fraction`` of the speed above) of the ``limit_ref`` speed
    (times ``y_scale``) on an error figure's axes."""
    from cosim.run.metrics import graded_allowance

    ref_col = spec["limit_ref"]
    if ref_col not in frame:
        raise FigureError(f"figure {spec['file']}: run {run!r} recorded no {ref_col!r}")
    ref = frame[ref_col].to_numpy(dtype=float) * float(spec.get("y_scale", 1.0))
    allowed = graded_allowance(ref, float(spec.get("limit_kmh", 2.0)),
                               float(spec.get("limit_below_kmh", 30.0)),
                               float(spec.get("limit_fraction", 0.02))).astype(float)
    allowed[ref <= 0.0] = float("nan")  # standing: no allowance drawn
    ax.axhline(0.0, color="black", linewidth=0.6, label="reference (zero error)")
    ax.plot(x, allowed, color="black", linestyle="--", linewidth=0.8, label="limit")
    ax.plot(x, -allowed, color="black", linestyle="--", linewidth=0.8)


def reference_curve(scenario: Any, frame: Any, y: str) -> Any:
    """The continuous reference behind a held ``reference_speed`` column: the stopping curve
    ``v_ref(s) = sqrt(2 a0 (s_stop - s))`` at the recorded positions where ``[summary]``
    declares ``reference_decel`` and ``stop_point`` (as the speed metrics use it); None
    otherwise (the recorded column is the curve)."""
    import numpy as np

    from cosim.fmu.profiles import StoppingCurve

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
    from cosim.run.metrics import matching_columns

    if "y_reduce" in spec and y in frame:  # the reduction as recorded (cosim.run.record)
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

    from cosim.run.metrics import graded_allowance

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
    ``ref`` and the position behind a stopping-curve reference (:func:`reference_curve`)."""
    import pandas as pd

    from cosim.run.metrics import matching_columns

    empty = pd.DataFrame(columns=columns)
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    wanted = {"time", spec.get("x", "time"), spec.get("y_minus"), spec.get("limit_ref"),
              spec.get("ref"), (getattr(scenario, "summary", {}) or {}).get("position")}
    for y in ys:
        wanted.update(matching_columns(empty, y) if "y_reduce" in spec else [y])
    return {c for c in wanted if c in columns}


def draw_ensemble_figure(spec: dict[str, Any], frames: dict[str, list[Any]], path: Path,
                         scenarios: dict[str, Any] | None = None) -> None:
    """:func:`ensemble_figure_of` the members' recorded series (run name -> one frame per
    member), saved to ``path`` (png at 200 dpi, svg or pdf by its suffix)."""
    import matplotlib.pyplot as plt

    from cosim.run.results import PLOT_DPI

    fig = ensemble_figure_of(spec, frames, scenarios or {})
    fig.savefig(path, dpi=PLOT_DPI, format=Path(path).suffix.lstrip(".") or "png",
                bbox_inches="tight")
    plt.close(fig)


def ensemble_figure_of(spec: dict[str, Any], frames: dict[str, list[Any]],
                       scenarios: dict[str, Any]) -> Any:
    """An overlay figure over an ensemble: per run the median over the members and a 5-95 %
    band (members sampled on the first member's x grid; x = "time" or a recorded column);
    held signals as steps, the reference as a dashed continuous curve, labels and units from
    the declarations (:func:`series_style`), the legend outside."""
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
    for j, (name, members_) in enumerate(frames.items()):
        ax = axes[j if panels else 0][0]
        x0 = members_[0]["time"] if spec["x"] == "time" else members_[0][spec["x"]]
        for y in ys:
            plain = "y_reduce" in spec or "y_minus" in spec
            style = ({"drawstyle": "default", "text": y, "reference": False} if plain
                     else series_style(scenarios.get(name), y))
            curves = []
            for frame in members_:
                x = frame["time"] if spec["x"] == "time" else frame[spec["x"]]
                values = figure_series(frame, spec, y, name)
                curve = (reference_curve(scenarios.get(name), frame, y) if style["reference"]
                         else None)
                values = values if curve is None else curve
                curves.append(np.interp(x0, x, values * scale))
            stack = np.vstack(curves)
            label = (style["text"] if panels else name if len(ys) == 1
                     else f"{name}: {style['text']}")
            kwargs: dict[str, Any] = {"linewidth": 1.0, "drawstyle": style["drawstyle"]}
            if style["reference"]:
                kwargs.update(color="black", linestyle="--", linewidth=0.9)
            line, = ax.plot(x0, np.median(stack, axis=0),
                            label=f"{label} (median of {len(members_)})", **kwargs)
            ax.fill_between(x0, np.percentile(stack, 5, axis=0),
                            np.percentile(stack, 95, axis=0), color=line.get_color(),
                            alpha=0.25, linewidth=0,
                            step="post" if style["drawstyle"] == "steps-post" else None)
        if "limit_ref" in spec and (panels or j == 0):
            draw_limits(ax, spec, members_[0], x0, name)
        finish_axes(ax, spec, name if panels else None, ylabel, panels or j == 0)
        legend_outside(ax)
    axes[-1][0].set_xlabel(axis_text(spec, "x", first, spec["x"])[0])
    fig.suptitle(f"{spec.get('title', '')} (median, 5-95 % band over the seeds)")
    return fig


