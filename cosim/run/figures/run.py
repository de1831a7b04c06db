"""The figure of one run (``plot.png`` of ``cosim run``, :func:`draw_run`): speed and reference
against position with the command on a second axis, the tracking error in a panel under it,
the last 20 m in an inset and coupler forces below; or the outputs against time. The helpers
that the sweep's and perturbation's figures share with it (:func:`fit_band`,
:func:`legend_below`) are here too. Labels and units come from the declarations
(:mod:`cosim.run.columns`)."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from cosim.run.columns import axis_label, display_unit, is_held, variable_info
from cosim.run.figures import reference_curve, save_figure
from cosim.run.metrics import matching_columns

MAX_CM_DECIMALS = 6  # a stop error is written to 0.01 um at finest
LABEL_WIDTH = 40  # characters per line of an axis label
LEGEND_DROP = 0.5  # in, from an axes' bottom edge to the top of the legend under it
INSET_LEFT = 1.27  # axes widths, the stop inset's left edge (clear of a one-line twin label)
INSET_LEFT_PER_LINE = 0.04  # axes widths further right per further line of the twin's label
# Line styles of the run figure: what was measured solid and wide, what it tracks thinner, in
# black (as the controller holds it) and grey (the continuous curve it samples).
# Drawn over the measured curve, a thin reference stays visible where the two coincide.
MEASURED = {"color": "C0", "ls": "-", "lw": 2.0, "zorder": 2}
REFERENCE = {"color": "k", "ls": "-", "lw": 0.8, "zorder": 3}
REFERENCE_CURVE = {"color": "0.5", "ls": "-", "lw": 0.8, "zorder": 3}


def format_stop_error(error_m: float) -> str:
    """A stop error in m from 1 m up (two decimals), in cm below: one decimal from 0.1 cm
    up, two significant digits below that (so a sub-millimetre error is not shown as 0.0);
    an error that rounds to zero is written unsigned (never ``-0.0``)."""
    if abs(error_m) >= 1.0:
        return f"{error_m:+.2f} m"
    cm = error_m * 100.0
    decimals = 1 if abs(cm) >= 0.1 or cm == 0.0 else min(1 - math.floor(math.log10(abs(cm))),
                                                       MAX_CM_DECIMALS)
    text = f"{cm:+.{decimals}f}"
    return f"{text.lstrip('+-')} cm" if float(text) == 0.0 else f"{text} cm"


def _stop_inset(ax: Any, pos: np.ndarray, speed_kmh: np.ndarray, stop: float,
                label_lines: int = 1) -> Any:
    """A zoom on the last 20 m before the stop point: speed against the distance to the stop
    point in metres (plain numbers, no offset), right of the axes (and of a twin axis's
    labels, ``label_lines`` lines of them), where it covers no curve; the legend is outside the
    axes."""
    from matplotlib.ticker import MaxNLocator

    near = pos >= stop - 20.0
    if not near.any() or len(pos) < 2:
        return None
    inset = ax.inset_axes([INSET_LEFT + INSET_LEFT_PER_LINE * (label_lines - 1), 0.25, 0.28, 0.6])
    inset.set_facecolor("white")
    inset.set_zorder(10)
    inset.plot(pos[near] - stop, speed_kmh[near], color=MEASURED["color"], lw=1.0)
    inset.axvline(0.0, color="C3", lw=0.8, ls="-.")
    right = max(float(pos[near].max()) - stop, 2.0)
    inset.set_xlim(-20.0, right)
    inset.set_xlabel("to stop point (m)", fontsize=7)
    inset.set_ylabel("speed (km/h)", fontsize=7)
    inset.set_title("last 20 m", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.ticklabel_format(useOffset=False, style="plain")
    inset.xaxis.set_major_locator(MaxNLocator(5))
    inset.grid(True, alpha=0.3)
    return inset


def fit_band(ax: Any, values: Any, lo: float, hi: float, zoom: float = 0.2) -> bool:
    """Draw the band [lo, hi] (dotted lines) on ``ax`` and fit the y axis: the band and the
    data when the data reach beyond ``zoom`` of the band's half width, else the data alone
    (with a note that the band lies outside the view), so sub-band results are not flat
    lines. Returns True when zoomed in."""
    data = np.asarray(values, dtype=float)
    data = data[np.isfinite(data)]
    for edge in (lo, hi):
        ax.axhline(edge, color="red", linestyle=":", linewidth=1)
    half = 0.5 * (hi - lo)
    if data.size and np.max(np.abs(data - 0.5 * (lo + hi))) < zoom * half:
        span = max(float(data.max() - data.min()), 1e-4 * half)
        ax.set_ylim(float(data.min()) - 0.15 * span, float(data.max()) + 0.15 * span)
        ax.text(0.01, 0.98, f"band [{lo:g}, {hi:g}] outside the view", transform=ax.transAxes,
                va="top", fontsize=7, color="red")
        return True
    top = max(hi, float(data.max()) if data.size else hi)
    bottom = min(lo, float(data.min()) if data.size else lo)
    pad = 0.05 * (top - bottom)
    ax.set_ylim(bottom - pad, top + pad)
    return False


def legend_below(ax: Any, handles: list[Any], labels: list[str]) -> Any:
    """The legend under the axes, ``LEGEND_DROP`` below their bottom edge (clear of the tick
    labels and the x label; outside the axes: no curve, inset or twin axis can cover it)."""
    from matplotlib.transforms import ScaledTranslation

    below = ax.transAxes + ScaledTranslation(0.0, -LEGEND_DROP, ax.figure.dpi_scale_trans)
    return ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                     bbox_transform=below, ncol=min(len(labels), 4), fontsize=8,
                     frameon=False)


def plot_run(result: Any, path: Path) -> None:
    """:func:`draw_run` saved to ``path`` (its suffix: png at 200 dpi, svg or pdf;
    :func:`cosim.run.figures.save_figure`)."""
    save_figure(draw_run(result), Path(path))


def wrapped_label(text: str) -> str:
    """An axis label broken into lines of at most ``LABEL_WIDTH`` characters, so a long
    declared description stays within its axes' height (clear of the title)."""
    return textwrap.fill(text, LABEL_WIDTH, break_long_words=False)


def _draw_tracking(result: Any, ax: Any, error_ax: Any | None) -> None:
    """Speed vs position on ``ax``: the measured speed solid and wide, the reference as its
    continuous curve over it (black, thinner; steps where the controller holds it, with the
    curve it samples in grey), the speed limit dotted, the stop point, the command on a twin
    axis and the last 20 m in an inset; ``reference - measured`` on ``error_ax`` below (shared
    x), and the legend under the lowest of the two."""
    cfg, frame = result.scenario.summary, result.frame
    pos, speed = cfg["position"], cfg["speed"]
    x = frame[pos].to_numpy(dtype=float)
    xlabel = "position (m)"
    if np.nanmax(np.abs(x)) > 5000:
        x, xlabel = x / 1e3, "position (km)"
    v_kmh = frame[speed].to_numpy(dtype=float) * 3.6
    ax.plot(x, v_kmh, label="speed", **MEASURED)
    reference = None
    ref = cfg.get("reference_speed")
    if ref in frame.columns:
        held = is_held(result.scenario, ref)
        reference = frame[ref].to_numpy(dtype=float) * 3.6
        ax.plot(x, reference, label="reference" + (" (as held by the controller)" if held
                                                   else ""),
                drawstyle="steps-post" if held else "default", **REFERENCE)
        curve = reference_curve(result.scenario, frame, ref) if held else None
        if curve is not None:  # the stopping curve itself, beside what was held
            reference = curve * 3.6
            ax.plot(x, reference, label="reference curve", **REFERENCE_CURVE)
    limit = cfg.get("speed_limit")
    if limit in frame.columns:
        ax.plot(x, frame[limit] * 3.6, ":", color="C3", lw=1.0, label="speed limit",
                drawstyle="steps-post" if is_held(result.scenario, limit) else "default")
    ax.set_ylabel("speed (km/h)")
    ax.ticklabel_format(useOffset=False, style="plain")
    stop = None
    if "stop_point" in cfg:
        stop = float(cfg["stop_point"]) / (1e3 if xlabel.endswith("(km)") else 1.0)
        ax.axvline(stop, color="C3", lw=0.8, ls="-.", label="stop point")
    handles, labels = ax.get_legend_handles_labels()
    top = ax
    command = cfg.get("command")
    if command in frame.columns:
        top = ax.twinx()
        text, unit = variable_info(result.scenario, command)
        top.plot(x, frame[command] * display_unit(unit)[0], color="C2", lw=1.0, label=text,
                 drawstyle="steps-post" if is_held(result.scenario, command) else "default")
        top.set_ylabel(wrapped_label(axis_label(text, unit)))
        top.ticklabel_format(useOffset=False, style="plain")
        more, more_labels = top.get_legend_handles_labels()
        handles, labels = handles + more, labels + more_labels
    ax.set_zorder(top.get_zorder() + 1)  # the speed curves above the command's
    ax.patch.set_visible(False)
    if stop is not None:  # on the topmost axes, opaque
        _stop_inset(ax, frame[pos].to_numpy(), v_kmh, float(cfg["stop_point"]),
                    top.get_ylabel().count("\n") + 1 if top is not ax else 1)
    lowest = ax
    if error_ax is not None and reference is not None:
        error_ax.plot(x, reference - v_kmh, label="reference − speed", **MEASURED)
        error_ax.axhline(0.0, color="0.3", lw=0.6)
        if stop is not None:
            error_ax.axvline(stop, color="C3", lw=0.8, ls="-.")
        error_ax.set_ylabel("reference − speed\n(km/h)")
        error_ax.ticklabel_format(useOffset=False, style="plain")
        error_ax.grid(True, alpha=0.3)
        ax.tick_params(labelbottom=False)
        lowest = error_ax
    lowest.set_xlabel(xlabel)
    legend_below(lowest, handles, labels)


def draw_run(result: Any) -> Any:
    """The run's figure: speed and reference vs position with the command on a second axis
    and the tracking error (reference minus speed) in a panel under it, as the papers'
    figures; coupler forces below when the scenario names them; otherwise outputs vs time.
    Curves and axes are labelled with the declared descriptions and units; outputs of sampled
    or self-triggered FMUs (held between events) are drawn as steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = result.scenario.summary
    frame = result.frame
    couplers = matching_columns(frame, cfg.get("coupler_forces"))
    pos, speed = cfg.get("position"), cfg.get("speed")
    tracking = not frame.empty and pos in frame.columns and speed in frame.columns
    error = tracking and cfg.get("reference_speed") in frame.columns
    groups = [5.5 if error else 4.0] + ([3.5] if couplers else [])
    fig = plt.figure(figsize=(9, sum(groups) + 1.0 * len(groups)), layout="constrained")
    grid = fig.add_gridspec(len(groups), 1, height_ratios=groups)
    top = grid[0].subgridspec(2, 1, height_ratios=[3.0, 1.2]) if error else grid
    ax = fig.add_subplot(top[0])
    if frame.empty:
        ax.text(0.5, 0.5, "nothing recorded", ha="center", va="center",
                transform=ax.transAxes)
    elif tracking:
        _draw_tracking(result, ax, fig.add_subplot(top[1], sharex=ax) if error else None)
    else:
        t = frame["time"]
        units = set()
        for col in frame.columns[1:9]:
            text, unit = variable_info(result.scenario, col)
            scale = display_unit(unit)[0]
            units.add(display_unit(unit)[1])
            ax.plot(t, frame[col] * scale, label=axis_label(text, unit),
                    drawstyle="steps-post" if is_held(result.scenario, col) else "default")
        ax.set_xlabel("time (s)")
        if len(units) == 1 and None not in units:
            ax.set_ylabel(units.pop())
        ax.ticklabel_format(useOffset=False, style="plain")
        legend_below(ax, *ax.get_legend_handles_labels())
    summary = result.summary
    title = result.scenario.name
    if summary.get("stop_error_m") is not None:
        title += f"  stop error {format_stop_error(summary['stop_error_m'])}"
    if summary.get("command_switches") is not None:
        title += f"  switches {summary['command_switches']}"
    if not summary.get("completed", True):
        error_text = str(summary.get("error") or "failed")
        title += ("\nincomplete ("
                  f"{error_text if error_text.startswith('interrupted') else 'failed'})")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if couplers:
        axc = fig.add_subplot(grid[-1])
        t = frame["time"].to_numpy()
        forces = frame[couplers].to_numpy() / 1e3
        if len(couplers) <= 3:
            for i, col in enumerate(couplers):
                axc.plot(t, forces[:, i], lw=0.8, label=variable_info(result.scenario, col)[0])
        else:  # many couplers oscillating: one readable envelope, not a solid band of lines
            hi, lo = forces.max(axis=1), forces.min(axis=1)
            axc.fill_between(t, lo, hi, color="C0", alpha=0.25, lw=0,
                             label=f"range over {len(couplers)} couplers")
            axc.plot(t, hi, color="C3", lw=0.9, label="largest draft")
            axc.plot(t, lo, color="C2", lw=0.9, label="largest buff")
        axc.set_xlabel("time (s)")
        axc.set_ylabel("coupler force (kN)")
        axc.grid(True, alpha=0.3)
        axc.ticklabel_format(useOffset=False, style="plain")
        legend_below(axc, *axc.get_legend_handles_labels())
    return fig
