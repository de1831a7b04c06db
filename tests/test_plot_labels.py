"""Plots a person reads: the command axis in a physical unit (kN, %, m/s²), never a variable
name and raw N; the stop error in cm under 1 m, otherwise in m; a partial run marked
incomplete; a zoom on the last 20 m of a stop; many couplers as one envelope."""

from __future__ import annotations

import pytest

from cosim.run.columns import display_unit, variable_info, variable_unit
from cosim.run.figures.run import format_stop_error
from cosim.run.scenario import load_scenario


@pytest.mark.parametrize("error,text", [(0.149, "+14.9 cm"), (-0.004, "-0.4 cm"),
                                        (3.4, "+3.40 m"), (-340.2, "-340.20 m"),
                                        (-0.000185, "-0.018 cm"), (0.0005, "+0.050 cm"),
                                        (0.0, "0.0 cm"), (-0.0, "0.0 cm"),
                                        (-1e-12, "0.000000 cm")])
def test_stop_error_in_cm_under_a_metre_else_in_m(error, text):
    assert format_stop_error(error) == text


@pytest.mark.parametrize("error", [s * 10.0 ** k * m for s in (1, -1) for k in range(-8, 0)
                                   for m in (1.0, 1.85, 4.99, 9.5)])
def test_stop_error_text_is_never_negative_zero_and_keeps_two_digits(error):
    """Below 1 m: the number read back is within half its last digit of the error in cm,
    written to 1 mm from 1 mm up and with two significant digits below (down to the finest
    decimal written), and signed only when it is not zero."""
    from cosim.run.figures.run import MAX_CM_DECIMALS

    text = format_stop_error(error)
    number = text.removesuffix(" cm")
    decimals = len(number.split(".")[1])
    assert abs(float(number) - 100.0 * error) <= 0.5 * 10.0 ** -decimals * (1 + 1e-9)
    if float(number) == 0.0:
        assert number[0] not in "+-"
    if abs(100.0 * error) >= 0.1:
        assert decimals == 1
    elif abs(100.0 * error) >= 10.0 ** (1 - MAX_CM_DECIMALS):
        assert len(number.lstrip("+-").replace(".", "").lstrip("0")) >= 2, text


@pytest.mark.parametrize("scenario,command,shown", [
    ("seed000_stop_pid", "controller.brake_command", (1.0, "%")),
    ("seed004_crh3_pid", None, (1e-3, "kN")),
])
def test_command_axis_has_a_physical_unit(built_fmus, scenario, command, shown):
    sc = load_scenario(scenario)
    ref = command or sc.summary["command"]
    assert display_unit(variable_unit(sc, ref)) == shown


def _figure_of(result, monkeypatch, tmp_path):
    """The matplotlib figure plot_run draws for ``result`` (captured at savefig)."""
    from matplotlib.figure import Figure

    from cosim.run.figures.run import plot_run

    drawn = []
    real = Figure.savefig

    def keep(self, *args, **kwargs):
        drawn.append(self)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    plot_run(result, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").stat().st_size > 0
    return drawn[0]


def _stub(summary_cfg, frame, summary):
    from types import SimpleNamespace

    return SimpleNamespace(scenario=SimpleNamespace(name="stub", summary=summary_cfg),
                           frame=frame, summary=summary)


def test_partial_stopping_run_is_marked_and_zoomed(monkeypatch, tmp_path):
    """An interrupted stopping run: the title says "incomplete (interrupted at t = ...)", and
    an inset shows the last 20 m before the stop point."""
    import numpy as np
    import pandas as pd

    s = np.linspace(0.0, 390.0, 200)
    frame = pd.DataFrame({"time": np.arange(200) * 0.2, "plant.s": s,
                          "plant.v": np.sqrt(np.maximum(400.0 - s, 0.0))})
    cfg = {"position": "plant.s", "speed": "plant.v", "stop_point": 400.0}
    fig = _figure_of(_stub(cfg, frame, {"completed": False, "stop_error_m": -10.0,
                                        "error": "interrupted at t = 39.8 s"}),
                     monkeypatch, tmp_path)
    titles = [ax.get_title() for ax in fig.axes]
    assert any("incomplete (interrupted at t = 39.8 s)" in t for t in titles)
    assert any("-10.00 m" in t for t in titles)
    inset = [child for ax in fig.axes for child in ax.child_axes
             if child.get_title() == "last 20 m"]
    assert len(inset) == 1 and inset[0].get_xlim()[0] == pytest.approx(-20.0)  # m to stop


def test_many_couplers_are_one_envelope(monkeypatch, tmp_path):
    """Seven oscillating coupler forces: one filled range and the two extreme lines (largest
    draft and buff), in kN, instead of a solid band of seven lines."""
    import numpy as np
    import pandas as pd

    t = np.arange(300) * 0.2
    forces = {f"plant.coupler_force[{j}]": 1e4 * np.sin(t * (j + 1)) for j in range(1, 8)}
    frame = pd.DataFrame({"time": t, "plant.s": 10.0 * t, "plant.v": np.full_like(t, 10.0),
                          **forces})
    cfg = {"position": "plant.s", "speed": "plant.v",
           "coupler_forces": "plant.coupler_force[*]"}
    fig = _figure_of(_stub(cfg, frame, {"completed": True}), monkeypatch, tmp_path)
    panel = next(ax for ax in fig.axes if ax.get_ylabel() == "coupler force (kN)")
    assert len(panel.collections) == 1 and len(panel.get_lines()) == 2
    top = panel.get_lines()[0].get_ydata()
    assert np.max(top) == pytest.approx(np.max(np.stack(list(forces.values()))) / 1e3)


@pytest.fixture(scope="module")
def rsmpc_run(built_fmus):
    """A whole self-triggered stopping run (seconds)."""
    from cosim.run.simulate import run_scenario

    return run_scenario("seed000_stop_rsmpc", build=False)


def test_run_figure_reads_as_a_paper_figure(rsmpc_run):
    """Legend outside the axes and clear of the 'last 20 m' inset; the command axis named by
    its declared description and unit; held signals (the command, the self-triggered
    controller's v_ref) drawn as steps, the measured speed as a line; no offset notation."""
    import matplotlib.pyplot as plt

    from cosim.run.figures.run import draw_run

    fig = draw_run(rsmpc_run)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    main, error, twin = fig.axes
    legend = error.get_legend()  # under the lowest panel of the tracking plot
    assert legend is not None and main.get_legend() is None
    inset = next(c for ax in fig.axes for c in ax.child_axes if c.get_title() == "last 20 m")
    box_legend = legend.get_window_extent(renderer)
    assert not box_legend.overlaps(inset.get_window_extent(renderer))
    for ax in (main, error):  # outside the axes, below the x label
        assert not box_legend.overlaps(ax.get_window_extent(renderer))
    assert box_legend.y1 <= error.xaxis.get_tightbbox(renderer).y0
    assert not inset.get_tightbbox(renderer).overlaps(main.get_window_extent(renderer))
    assert not inset.get_tightbbox(renderer).overlaps(twin.yaxis.get_tightbbox(renderer))
    labels = [t.get_text() for t in legend.get_texts()]
    assert "speed" in labels and "stop point" in labels
    assert not any(name.startswith(("plant.", "controller.")) for name in labels), labels
    assert twin.get_ylabel() == "brake command u (%)"
    lines = {line.get_label(): line for ax in fig.axes for line in ax.get_lines()}
    assert lines["speed"].get_drawstyle() == "default"
    assert lines["reference (as held by the controller)"].get_drawstyle() == "steps-post"
    assert lines["reference curve"].get_drawstyle() == "default"  # the continuous v_ref(s)
    assert lines["brake command u"].get_drawstyle() == "steps-post"
    for ax in (main, twin, inset):
        for axis in (ax.xaxis, ax.yaxis):
            assert axis.get_major_formatter().get_offset() == "", (ax, axis)
    plt.close(fig)


def test_run_figure_draws_measured_solid_references_continuous_and_the_error(rsmpc_run):
    """Two panels sharing the position axis (tracking, error) and the command's twin axis;
    the measured speed solid and wider than the references, which are solid, black (as
    held) and grey (the curve), drawn over it; the error panel is reference curve minus
    measured speed in km/h; every axis labelled with its unit."""
    import matplotlib.colors as mcolors
    import matplotlib.pyplot as plt
    import numpy as np

    from cosim.run.figures import reference_curve
    from cosim.run.figures.run import draw_run

    fig = draw_run(rsmpc_run)
    main, error, twin = fig.axes
    assert error.get_shared_x_axes().joined(main, error)
    lines = {line.get_label(): line for line in main.get_lines()}
    speed = lines["speed"]
    held, curve = lines["reference (as held by the controller)"], lines["reference curve"]
    for line in (speed, held, curve):
        assert line.get_linestyle() == "-"
    assert speed.get_linewidth() > max(held.get_linewidth(), curve.get_linewidth())
    assert min(held.get_zorder(), curve.get_zorder()) > speed.get_zorder()
    assert mcolors.to_hex(held.get_color()) == "#000000"
    r, g, b = mcolors.to_rgb(curve.get_color())
    assert r == g == b  # grey
    [drawn] = [ln for ln in error.get_lines() if ln.get_label() == "reference − speed"]
    frame, cfg = rsmpc_run.frame, rsmpc_run.scenario.summary
    expected = 3.6 * (reference_curve(rsmpc_run.scenario, frame, cfg["reference_speed"])
                      - frame[cfg["speed"]].to_numpy())
    assert np.allclose(drawn.get_ydata(), expected)
    assert drawn.get_linestyle() == "-"
    assert main.get_xlabel() == "" and error.get_xlabel() == "position (m)"
    for ax in (main, error, twin):
        assert ax.get_ylabel().endswith(")") and "(" in ax.get_ylabel()
    plt.close(fig)


def test_long_command_label_stays_clear_of_the_title():
    """A command with a long description (seed 002's locomotive force demand): its axis label
    is wrapped to the axes' height, so no title, label or inset box overlaps another."""
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    from cosim.run.figures.run import draw_run

    command = "controller.locomotive force demand (> 0 traction, < 0 electric brake) (kN)"
    s = np.linspace(0.0, 20000.0, 400)
    v = np.sqrt(np.maximum(20000.0 - s, 0.0)) / 10.0
    frame = pd.DataFrame({"time": np.arange(400.0), "plant.s": s, "plant.v": v,
                          "controller.v_ref": v + 0.1, command: np.sin(s / 1e3)})
    cfg = {"position": "plant.s", "speed": "plant.v", "reference_speed": "controller.v_ref",
           "command": command, "stop_point": 20000.0}
    fig = draw_run(_stub(cfg, frame, {"stop_error_m": 0.433, "command_switches": 6818}))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    main, error, twin = fig.axes
    assert main.get_title() == "stub  stop error +43.3 cm  switches 6818"
    inset = main.child_axes[0]
    boxes = {"title": main.title.get_window_extent(renderer),
             "twin label": twin.yaxis.label.get_window_extent(renderer),
             "speed label": main.yaxis.label.get_window_extent(renderer),
             "error label": error.yaxis.label.get_window_extent(renderer),
             "inset": inset.get_tightbbox(renderer)}
    for i, (a, box_a) in enumerate(boxes.items()):
        for b, box_b in list(boxes.items())[i + 1:]:
            assert not box_a.overlaps(box_b), (a, b)
    assert twin.get_ylabel().count("\n") >= 1
    for ax, label in ((twin, "twin label"), (error, "error label")):
        box, axes_box = boxes[label], ax.get_window_extent(renderer)
        assert axes_box.y0 <= box.y0 and box.y1 <= axes_box.y1  # within its panel's height
    plt.close(fig)


@pytest.mark.parametrize("fmt", ["png", "svg", "pdf"])
def test_plot_format_and_resolution(rsmpc_run, tmp_path, fmt):
    from cosim.run.figures import PLOT_DPI
    from cosim.run.results import write_results

    written = write_results(rsmpc_run, tmp_path, plot_format=fmt)
    assert tmp_path / f"plot.{fmt}" in written
    if fmt == "png":
        from matplotlib.image import imread

        height, width = imread(tmp_path / "plot.png").shape[:2]
        # a 9-inch-wide figure at PLOT_DPI, its white margins cropped (bbox_inches="tight")
        assert PLOT_DPI >= 200 and width >= 8 * PLOT_DPI
    with pytest.raises(ValueError, match="plot format 'gif'"):
        write_results(rsmpc_run, tmp_path / "x", plot_format="gif")


def test_sweep_keys_are_named_by_their_declarations(built_fmus):
    from cosim.run.figures.sweep import key_labels

    sc = load_scenario("seed000_stop_rmpc")
    text, unit = variable_info(sc, "controller.N")
    assert text != "controller.N"  # the FMU declares a description
    assert key_labels(sc, ["controller.N"]) == {"controller.N": f"{text} [controller.N]"}


@pytest.mark.parametrize("errors_m,zoomed", [([1e-5, 4e-5, 7e-5], True), ([0.1, -0.3, 0.6], False)])
def test_sweep_axes_fit_the_data(errors_m, zoomed):
    """Stop errors far inside the +-50 cm window: the axis zooms to them (not flat lines on a
    +-50 cm axis); errors reaching the window: window and data both in view. Legends sit
    outside both axes."""
    import matplotlib.pyplot as plt
    import pandas as pd

    from cosim.run.figures.sweep import draw_sweep

    frame = pd.DataFrame({"scenario": "s", "controller.N": [3, 4, 5], "stop_error_m": errors_m,
                          "command_switches": [10, 9, 8], "controller_executions": [30, 20, 10]})
    fig = draw_sweep(frame, ["controller.N"], {"controller.N": "prediction horizon [controller.N]"})
    fig.canvas.draw()
    ax1, ax2 = fig.axes[:2]
    assert ax2.get_xlabel() == "prediction horizon [controller.N]"
    assert ax1.get_title() == "Stop error and command switches vs prediction horizon"
    lo, hi = ax1.get_ylim()
    cm = [100 * e for e in errors_m]
    assert lo <= min(cm) and max(cm) <= hi
    if zoomed:
        assert hi - lo < 0.01 * 100  # far narrower than the 100-cm window
    else:
        assert lo <= -50 and hi >= 50
    assert ax1.yaxis.get_major_formatter().get_offset() == ""
    renderer = fig.canvas.get_renderer()
    for ax in (ax1, ax2):
        box = ax.get_legend().get_window_extent(renderer)
        assert not any(box.overlaps(other.get_window_extent(renderer)) for other in (ax1, ax2))
    plt.close(fig)


def test_perturbed_boxes_are_not_collapsed(monkeypatch, tmp_path):
    """Millimetre stop errors under plant mismatch: the box plot's axis is on the boxes, not on
    the +-50 cm window (where they would collapse to a line)."""
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from cosim.run.figures.perturb import plot_perturbed

    drawn = []
    real = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: (drawn.append(self),
                                                                  real(self, *a, **k)))
    errors = np.random.default_rng(1).normal(0.0, 0.002, 20)
    frame = pd.DataFrame({"scenario": "seed000_stop_rmpc", "controller.N": 10,
                          "stop_error_m": errors, "controller_executions": 100})
    plot_perturbed(frame, ["controller.N"], tmp_path / "perturb.png")
    lo, hi = drawn[0].axes[0].get_ylim()
    assert lo <= 100 * errors.min() and 100 * errors.max() <= hi and hi - lo < 5.0


def _beneath_in_grey(line, measured) -> bool:
    """Whether ``line`` is drawn as a reference: solid, mid grey (equal channels, neither
    black nor white), beneath every ``measured`` curve."""
    from matplotlib.colors import to_rgba

    r, g, b, _ = to_rgba(line.get_color())
    return (line.get_linestyle() == "-" and r == g == b and 0.25 <= r <= 0.75
            and all(line.get_zorder() < m.get_zorder() for m in measured))


def _stopping_frame(offset: float = 0.0):
    """A synthetic stopping run as seed000_stop_rsmpc records it (0.2 s output, the
    controller's v_ref and brake command held between its events)."""
    import numpy as np
    import pandas as pd

    t = np.arange(0.0, 40.0, 0.2)
    s = 400.0 - 0.25 * (40.0 - t) ** 2 + offset
    v = 0.5 * (40.0 - t)
    held = np.floor(t / 2.0) * 2.0  # an event every 2 s
    return pd.DataFrame({"time": t, "plant.s": s, "plant.v": v + 0.01 * np.sin(t),
                         "controller.v_ref": 0.5 * (40.0 - held),
                         "controller.brake_command": 10.0 + held})


def test_reproduce_figures_read_as_paper_figures(built_fmus):
    """A reproduce overlay and a panels figure: axes named from the declarations with units
    (or the entry's own label), no offset notation, the legend outside the axes and inside the
    figure with the runs' names and the reference's declared description (no raw variable
    names), each run's measured speed solid in its own colour and marker, the reference
    ([summary] reference_speed) once in the legend, its continuous curve solid, mid grey,
    thinner and beneath the measured curves, the held command as steps."""
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import to_rgba

    from cosim.run.figures import figure_of
    sc = load_scenario("seed000_stop_rsmpc")
    frames = {"RSMPC": _stopping_frame(), "RSMPC 2": _stopping_frame(1e4)}
    scenarios = {name: sc for name in frames}
    overlay = figure_of({"file": "f.png", "x": "plant.s", "y": ["plant.v", "controller.v_ref"],
                         "kind": "overlay"}, frames, scenarios)
    overlay.canvas.draw()
    renderer = overlay.canvas.get_renderer()
    ax = overlay.axes[0]
    described = variable_info(sc, "plant.s")
    assert ax.get_xlabel() == f"{described[0]} (km)"  # the runs span 10 km: drawn in km
    assert np.isclose(max(ln.get_xdata().max() for ln in ax.get_lines()),
                      frames["RSMPC 2"]["plant.s"].max() / 1000.0)
    assert ax.get_ylabel().endswith("(km/h)")  # m/s declared, shown in km/h
    legend = ax.get_legend()
    assert not legend.get_window_extent(renderer).overlaps(ax.get_window_extent(renderer))
    assert overlay.bbox.contains(*legend.get_window_extent(renderer).min)
    assert overlay.bbox.contains(*legend.get_window_extent(renderer).max)
    texts = [t.get_text().replace("\n", " ") for t in legend.get_texts()]  # wrapped
    ref_text = variable_info(sc, "controller.v_ref")[0]
    assert texts == ["RSMPC", "RSMPC 2", f"reference: {ref_text}"]
    lines = ax.get_lines()
    speed = [ln for ln in lines if "reference" not in ln.get_label()]
    reference = [ln for ln in lines if "reference" in ln.get_label()]
    assert len(speed) == 2 and len(reference) == 2
    assert all(ln.get_linestyle() == "-" for ln in speed + reference)
    assert all(_beneath_in_grey(ln, speed) for ln in reference)
    assert len({to_rgba(ln.get_color()) for ln in speed}) == 2
    assert len({ln.get_marker() for ln in speed}) == 2
    assert max(ln.get_linewidth() for ln in reference) < min(ln.get_linewidth() for ln in speed)
    assert all(ln.get_drawstyle() == "default" for ln in speed + reference)
    # the held v_ref column replaced by the declared stopping curve at the recorded positions
    s = frames["RSMPC"]["plant.s"].to_numpy()
    curve = 3.6 * np.sqrt(2 * 0.5 * np.maximum(sc.summary["stop_point"] - s, 0.0))
    assert np.allclose(reference[0].get_ydata(), curve)
    assert np.allclose(speed[0].get_ydata(), 3.6 * frames["RSMPC"]["plant.v"])
    for axis in (ax.xaxis, ax.yaxis):  # positions near 1e4 m: no "+1e4" offset
        assert axis.get_major_formatter().get_offset() == ""
    plt.close(overlay)

    panels = figure_of({"file": "c.png", "x": "time", "y": ["controller.brake_command"],
                        "kind": "panels", "ylabel": "brake command (%)"}, frames, scenarios)
    panels.canvas.draw()
    renderer = panels.canvas.get_renderer()
    assert len(panels.axes) == 2
    for ax in panels.axes:
        assert ax.get_ylabel() == "brake command (%)"
        assert [ln.get_drawstyle() for ln in ax.get_lines()] == ["steps-post"]
        assert ax.get_legend() is None  # one curve: named by the panel's title and y label
    assert panels.axes[-1].get_xlabel() == "time (s)"
    plt.close(panels)


def test_error_from_the_reference_is_the_curve_minus_the_measured_speed(built_fmus):
    """``error = "reference"``: under the tracking axes, each run's reference as drawn (the
    declared stopping curve at the recorded positions, not the held column) minus its
    measured speed, in the tracking axes' unit; a figure without a reference series is
    refused naming the figure and the run."""
    import matplotlib.pyplot as plt
    import numpy as np

    from cosim.run.figures import FigureError, figure_of
    sc = load_scenario("seed000_stop_rsmpc")
    frames = {"RSMPC": _stopping_frame(), "RSMPC 2": _stopping_frame(1e4)}
    scenarios = {name: sc for name in frames}
    fig = figure_of({"file": "f.png", "x": "plant.s", "y": ["plant.v", "controller.v_ref"],
                     "kind": "overlay", "error": "reference"}, frames, scenarios)
    main, error = fig.axes
    assert error.get_shared_x_axes().joined(main, error)
    assert error.get_ylabel() == "reference − measured (km/h)"
    runs = [ln for ln in error.get_lines() if ln.get_label() != "_nolegend_"
            and len(ln.get_xdata()) > 2]  # the zero line is an axhline of two points
    for line, name in zip(runs, frames, strict=True):
        frame = frames[name]
        s = frame["plant.s"].to_numpy()
        curve = np.sqrt(2 * 0.5 * np.maximum(sc.summary["stop_point"] - s, 0.0))
        assert np.allclose(line.get_ydata(), 3.6 * (curve - frame["plant.v"].to_numpy()))
    plt.close(fig)
    with pytest.raises(FigureError, match="figure g.png: error = 'reference' needs a "
                                          "reference and a measured series; run 'RSMPC' has "
                                          "no reference"):
        figure_of({"file": "g.png", "x": "plant.s", "y": ["plant.v"], "kind": "overlay",
                   "error": "reference"}, frames, scenarios)


def test_per_unit_panels_name_each_unit_and_keep_coinciding_curves_visible(built_fmus):
    """Seed 001's per-unit figures: every unit's curve labelled by its own declaration (not the
    train's mean speed, not a raw name), ``y_minus`` said in the label, curves of one panel
    solid in distinct colours and markers (units with equal speed stay visible), the limit
    band in the legend, a 270 km route drawn in km."""
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    from cosim.run.figures import figure_of
    sc = load_scenario("seed001_emu_ismpc")
    t = np.arange(0.0, 100.0)
    v = np.full_like(t, 80.0)
    frame = pd.DataFrame({"time": t, "plant.s": 2700.0 * t, "controller.v_ref": v + 0.1,
                          **{f"plant.v[{i}]": v for i in (1, 2, 3)}})
    units = [f"plant.v[{i}]" for i in (1, 2, 3)]
    texts = [variable_info(sc, u)[0] for u in units]
    assert len(set(texts)) == 3 and all(f"unit {i}" in x for i, x in zip((1, 2, 3), texts))
    fig = figure_of({"file": "e.png", "kind": "panels", "x": "plant.s", "y": units,
                     "y_minus": "controller.v_ref", "y_scale": 3.6, "limit_ref":
                     "controller.v_ref"}, {"ISMPC": frame}, {"ISMPC": sc})
    fig.canvas.draw()
    [ax] = fig.axes
    ref_text = variable_info(sc, "controller.v_ref")[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:3] == [f"{x} - {ref_text}" for x in texts]
    assert not any("plant." in x or "controller." in x for x in labels), labels
    units_drawn = ax.get_lines()[:3]
    assert {ln.get_linestyle() for ln in units_drawn} == {"-"}  # measured: solid
    assert len({ln.get_color() for ln in units_drawn}) == 3
    assert len({ln.get_marker() for ln in units_drawn}) == 3
    assert ax.get_xlabel().endswith("(km)") and np.isclose(ax.get_lines()[0].get_xdata()[-1],
                                                           2700.0 * 99 / 1000.0)
    plt.close(fig)


def test_ensemble_figure_draws_held_bands_as_steps(built_fmus, tmp_path):
    """The median and 5-95 % band over the members: a held signal's median and band as steps,
    its label from the declaration, the legend outside; in the svg the medians are vector
    paths and the bands one embedded raster image each (a band of a long run as a polygon is
    megabytes)."""
    import matplotlib.pyplot as plt
    import numpy as np

    from cosim.run.figures import ensemble_figure_of

    sc = load_scenario("seed000_stop_rsmpc")
    members = [_stopping_frame() for _ in range(3)]
    for i, frame in enumerate(members):
        frame["controller.brake_command"] += i
    fig = ensemble_figure_of({"file": "e.png", "x": "time", "y": "controller.brake_command"},
                             {"RSMPC": members}, {"RSMPC": sc})
    fig.canvas.draw()
    ax = fig.axes[0]
    [line] = ax.get_lines()
    assert line.get_drawstyle() == "steps-post"
    assert np.allclose(line.get_ydata(), members[1]["controller.brake_command"])
    band = ax.collections[0].get_paths()[0].vertices
    assert np.any(np.isclose(np.diff(band[:, 0]), 0.0))  # vertical risers: a stepped band
    assert ax.get_xlabel() == "time (s)" and "(%)" in ax.get_ylabel()
    renderer = fig.canvas.get_renderer()
    assert not ax.get_legend().get_window_extent(renderer).overlaps(
        ax.get_window_extent(renderer))
    assert ax.collections[0].get_rasterized() and not line.get_rasterized()
    fig.savefig(tmp_path / "e.svg")
    svg = (tmp_path / "e.svg").read_text()
    assert svg.count("<image") == 1 and "FillBetweenPolyCollection" not in svg
    assert svg.count('<g id="line2d_') >= 1
    plt.close(fig)
    # members spanning 10 km of position: the axis in km, as the single run's figure
    far = [_stopping_frame(1e4) for _ in range(3)]
    fig = ensemble_figure_of({"file": "e.png", "x": "plant.s", "y": "plant.v"},
                             {"RSMPC": far}, {"RSMPC": sc})
    ax = fig.axes[0]
    [line] = ax.get_lines()
    assert ax.get_xlabel() == f"{variable_info(sc, 'plant.s')[0]} (km)"
    assert np.allclose(line.get_xdata(), far[0]["plant.s"] / 1000.0)
    plt.close(fig)
    # a difference (y_minus) in a panel is named by its declarations, not by raw names
    fig = ensemble_figure_of({"file": "e.png", "x": "time", "y": "plant.v",
                              "y_minus": "controller.v_ref", "kind": "panels"},
                             {"RSMPC": far}, {"RSMPC": sc})
    [text] = [t.get_text().replace("\n", " ") for t in fig.axes[0].get_legend().get_texts()]
    assert text == (f"{variable_info(sc, 'plant.v')[0]} - "
                    f"{variable_info(sc, 'controller.v_ref')[0]} (median of 3)"), text
    plt.close(fig)


def _title_clear_of_axes(fig) -> None:
    """The figure's suptitle overlaps no axes (with its title and tick labels)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    title = fig._suptitle.get_window_extent(renderer)
    for ax in fig.axes:
        assert not title.overlaps(ax.get_tightbbox(renderer)), ax.get_title()


def test_tall_panel_figures_keep_the_title_above_the_first_panel():
    """Ten panels (a tall ensemble figure) and the most a run figure draws: the suptitle clears
    the first panel and its title."""
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    from cosim.run.figures import ensemble_figure_of, figure_of

    t = np.arange(0.0, 100.0, 0.2)
    from cosim.run.figures import MAX_PANELS

    frames = {f"run {i}": pd.DataFrame({"time": t, "e": np.sin(t)}) for i in range(10)}
    spec = {"file": "e.png", "x": "time", "y": ["e"], "kind": "panels", "ylabel": "e (km/h)",
            "title": "Speed error of each controller (Figs. 9-11, upper plots)"}
    most = dict(list(frames.items())[:MAX_PANELS])
    for fig in (figure_of(spec, most, {}),
                ensemble_figure_of(spec, {k: [v, v] for k, v in frames.items()}, {})):
        _title_clear_of_axes(fig)
        plt.close(fig)


def test_sweep_series_are_named_by_their_labels():
    """A sweep's legend names each scenario's series by the label given (an entry's
    ``labels``, else the scenario's description), wrapped; the raw name where none is given."""
    import matplotlib.pyplot as plt
    import pandas as pd

    from cosim.run.figures.sweep import draw_sweep

    frame = pd.DataFrame({"scenario": ["a_rmpc"] * 2 + ["a_rsmpc"] * 2, "controller.N": [3, 4] * 2,
                          "stop_error_m": [0.01, 0.02, 0.03, 0.01],
                          "command_switches": [10, 9, 8, 7], "controller_executions": [3, 2, 5, 4]})
    long = "robust self-triggered MPC, the command held for M samples between its events"
    fig = draw_sweep(frame, ["controller.N"], None, {"a_rsmpc": long})
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts[0] == "a_rmpc"
    assert texts[1].replace("\n", " ") == long and all(
        len(line) <= 40 for line in texts[1].splitlines())
    plt.close(fig)


def _tracking_frame(offset: float = 0.0):
    """A synthetic tracking run as seed 003 records it: speed, profile speed and acceleration
    and the controller's speed error v - v_ref (m/s)."""
    import numpy as np
    import pandas as pd

    t = np.arange(0.0, 200.0, 1.0)
    v_ref = 80.0 * (1.0 - np.exp(-t / 50.0))
    v = v_ref + 0.2 * np.sin(t / 7.0) + offset
    return pd.DataFrame({"time": t, "plant.s": np.cumsum(v), "plant.v": v,
                         "controller.v_ref": v_ref, "controller.speed_error": v - v_ref,
                         "plant.a": np.gradient(v, t), "controller.a_ref": np.gradient(v_ref, t)})


def test_error_panel_under_each_tracking_axes(built_fmus):
    """``error``: a panel under each tracking axes with the recorded error column, drawn with
    the tracking axes' factor (km/h) in each run's colour, labelled by its declaration in that
    unit, the zero error drawn as a reference (solid mid grey, beneath); an overlay is two
    axes, panels two per run; more than MAX_PANELS axes is an error naming the figure
    and the count."""
    import matplotlib.pyplot as plt
    import numpy as np

    from cosim.run.figures import MAX_PANELS, FigureError, figure_of, panel_count

    sc = load_scenario("seed003_crh3_lmimpc_eco")
    frames = {"GPC": _tracking_frame(), "LMI MPC": _tracking_frame(0.1)}
    scenarios = {name: sc for name in frames}
    spec = {"file": "f.png", "x": "time", "y": ["plant.v", "controller.v_ref"], "y_scale": 3.6,
            "ylabel": "speed (km/h)", "error": "controller.speed_error", "kind": "overlay"}
    fig = figure_of(spec, frames, scenarios)
    track, err = fig.axes
    assert track.get_ylabel() == "speed (km/h)" and err.get_ylabel() == "v - v_ref (km/h)"
    assert err.get_xlabel() == "time (s)" and track.get_xlabel() == ""
    drawn = [ln for ln in err.get_lines() if len(ln.get_xdata()) > 2]  # not the zero line
    assert len(drawn) == 2
    for line, name in zip(drawn, frames, strict=True):
        assert np.allclose(line.get_ydata(), 3.6 * frames[name]["controller.speed_error"])
        assert line.get_linestyle() == "-"
    colours = {name: ln.get_color() for ln in track.get_lines()
               for name in frames if ln.get_label() == name}
    assert [ln.get_color() for ln in drawn] == [colours[n] for n in frames]
    [zero] = [ln for ln in err.get_lines() if ln not in drawn]
    assert _beneath_in_grey(zero, drawn)
    assert err.get_position().height < track.get_position().height
    plt.close(fig)

    panels = figure_of({**spec, "kind": "panels"}, frames, scenarios)
    assert len(panels.axes) == panel_count({**spec, "kind": "panels"}, 2) == 4
    assert [ax.get_ylabel() for ax in panels.axes] == ["speed (km/h)", "v - v_ref (km/h)"] * 2
    plt.close(panels)
    three = {f"run {i}": _tracking_frame() for i in range(3)}
    assert panel_count({**spec, "kind": "panels"}, 3) == 6 > MAX_PANELS
    with pytest.raises(FigureError, match=r"figure f\.png: 6 panels \(3 runs"):
        figure_of({**spec, "kind": "panels"}, three, {n: sc for n in three})


def test_a_figures_reference_key_marks_a_series_the_summary_does_not(built_fmus):
    """Seed 003's scenarios declare no ``reference_accel``: ``controller.a_ref`` is a measured
    curve unless the figure's ``reference`` names it; then it is the reference (solid, mid
    grey, beneath the measured curve, named "reference: <its description>"). A reference not
    among y is an error naming the key and value."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgba

    from cosim.run.figures import FigureError, figure_of
    sc = load_scenario("seed003_crh3_lmimpc_eco")
    assert "reference_accel" not in sc.summary
    frames = {"Eco": _tracking_frame()}
    spec = {"file": "a.png", "x": "time", "y": ["plant.a", "controller.a_ref"]}
    plain = figure_of(spec, frames, {"Eco": sc})
    lines = plain.axes[0].get_lines()
    assert not any(_beneath_in_grey(ln, lines) for ln in lines)
    assert len({to_rgba(ln.get_color()) for ln in lines}) == 2  # two measured colours
    plt.close(plain)
    marked = figure_of({**spec, "reference": ["controller.a_ref"]}, frames, {"Eco": sc})
    ax = marked.axes[0]
    by_label = {ln.get_label(): ln for ln in ax.get_lines()}
    ref = by_label[f"reference: {variable_info(sc, 'controller.a_ref')[0]}"]
    assert _beneath_in_grey(ref, [by_label["Eco"]])
    assert by_label["Eco"].get_linestyle() == "-" and by_label["Eco"].get_marker() != "None"
    assert not _beneath_in_grey(by_label["Eco"], [])
    assert ax.get_ylabel().endswith("(m/s²)")
    plt.close(marked)
    with pytest.raises(FigureError, match=r"figure a\.png: reference = \['plant\.v'\] not among"):
        figure_of({**spec, "reference": ["plant.v"]}, frames, {"Eco": sc})


PAPER_FIGURES = [("seed000", "speed_position.png"), ("seed000", "stop_window.png"),
                 ("seed001", "fig6_unit_speed_tracking.png"),
                 ("seed003", "fig1_2_speed_distance.png"), ("seed003", "fig3_acceleration.png")]


@pytest.mark.parametrize("entry_name,file", PAPER_FIGURES)
def test_paper_figures_from_their_records_read_as_published(built_fmus, entry_name, file):
    """The shipped figures drawn from the shipped records: at most MAX_PANELS axes, the runs
    the paper compares overlaid (seed 003's figs. 1-3 on one tracking axes), every measured
    curve solid, a reference drawn in each tracking axes (solid, mid grey, beneath the measured
    curves), every axis label
    with a unit in parentheses, the legend inside the figure, its lines wrapped."""
    import re
    from pathlib import Path

    import matplotlib.pyplot as plt

    from cosim.reproduce.entry import load_entry
    from cosim.reproduce.record import load, series_name
    from cosim.reproduce.series import run_scenarios
    from cosim.run.figures import LEGEND_WIDTH, MAX_PANELS, figure_of, measured_line

    entry = load_entry(entry_name)
    figure = next(f for f in entry.figures if f.file == file)
    record = load(Path(__file__).parents[1] / "docs" / "papers" / entry_name)
    runs = figure.runs or [r.name for r in entry.runs]
    frames = {n: record.frame(series_name("run", n)) for n in runs}
    fig = figure_of(figure.spec(), frames, run_scenarios(entry))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    tracking = fig.axes[::2] if figure.error else fig.axes
    assert len(fig.axes) <= MAX_PANELS
    if entry_name == "seed003":
        assert len(tracking) == 1 and len([ln for ln in tracking[0].get_lines()
                                           if measured_line(ln)]) == len(runs)
    for ax in tracking:
        measured = [ln for ln in ax.get_lines() if measured_line(ln)]
        references = [ln for ln in ax.get_lines() if not measured_line(ln)]
        assert measured and all(ln.get_linestyle() == "-" for ln in measured)
        assert references and all(_beneath_in_grey(ln, measured) for ln in references)
    unit = re.compile(r"\(\S+\)$")
    for ax in fig.axes:
        assert unit.search(ax.get_ylabel()), ax.get_ylabel()
    assert unit.search(fig.axes[-1].get_xlabel()), fig.axes[-1].get_xlabel()
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == 1
    box = legends[0].get_window_extent(renderer)
    assert fig.bbox.contains(*box.min) and fig.bbox.contains(*box.max)
    assert box.height > 20  # readable entries, not a shrunk legend
    assert all(len(line) <= LEGEND_WIDTH for text in legends[0].get_texts()
               for line in text.get_text().splitlines())  # long descriptions wrap
    plt.close(fig)


def test_ensemble_figure_draws_the_reference_the_members_recorded(built_fmus):
    """The members' median and band of the measured speed in its colour, solid; the reference
    (the [summary]'s reference_speed) as its median, solid mid grey beneath the measured one,
    where the members recorded
    it, left out where they did not (a record made before the figure named it)."""
    import matplotlib.pyplot as plt

    from cosim.run.figures import ensemble_figure_of

    sc = load_scenario("seed003_crh3_lmimpc_eco")
    spec = {"file": "e.png", "x": "time", "y": ["plant.v", "controller.v_ref"]}
    members = [_tracking_frame(0.1 * i) for i in range(3)]
    fig = ensemble_figure_of(spec, {"Eco": members}, {"Eco": sc})
    speed, reference = fig.axes[0].get_lines()
    assert speed.get_linestyle() == "-" and not _beneath_in_grey(speed, [])
    assert _beneath_in_grey(reference, [speed])
    plt.close(fig)
    fig = ensemble_figure_of(spec, {"Eco": [m.drop(columns="controller.v_ref")
                                            for m in members]}, {"Eco": sc})
    [speed] = fig.axes[0].get_lines()
    assert speed.get_label().startswith("Eco: ")
    plt.close(fig)


@pytest.mark.parametrize("runs", [2, 18])
def test_an_overlay_of_many_runs_keeps_its_axes_beside_the_legend(runs, tmp_path):
    """However many runs a figure overlays, the legend right of the axes fits beside them:
    the figure grows to the legend's height (no "axes sizes collapsed" from the constrained
    layout) and the axes keep at least their designed height."""
    import warnings

    import matplotlib.pyplot as plt

    from cosim.run.figures import PANEL_HEIGHT, figure_of, save_figure

    frames = {f"run {i}, a label long enough to wrap in the legend's column": _stopping_frame(i)
              for i in range(runs)}
    fig = figure_of({"file": "f.png", "x": "time", "y": "plant.s"}, frames, {})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's collapse warning fails the test
        fig.canvas.draw()
        [ax] = fig.axes
        legend = ax.get_legend()
        renderer = fig.canvas.get_renderer()
        axes_in = ax.get_window_extent(renderer).height / fig.dpi
        assert axes_in >= PANEL_HEIGHT * 0.75, axes_in  # ticks and labels take the rest
        assert legend.get_window_extent(renderer).height <= fig.bbox.height
        save_figure(fig, tmp_path / "f.png")
    plt.close("all")
