"""Plots a person reads: the command axis in a physical unit (kN, %, m/s²), never a variable
name and raw N; the stop error in cm under 1 m, otherwise in m; a partial run marked
incomplete; a zoom on the last 20 m of a stop; many couplers as one envelope."""

from __future__ import annotations

import pytest

from cosim.run.results import display_unit, format_stop_error, variable_unit
from cosim.run.scenario import load_scenario


@pytest.mark.parametrize("error,text", [(0.149, "+14.9 cm"), (-0.004, "-0.4 cm"),
                                        (3.4, "+3.40 m"), (-340.2, "-340.20 m")])
def test_stop_error_in_cm_under_a_metre_else_in_m(error, text):
    assert format_stop_error(error) == text


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

    from cosim.run.results import plot_run

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
    assert len(inset) == 1 and inset[0].get_xlim()[0] == pytest.approx(380.0)


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
