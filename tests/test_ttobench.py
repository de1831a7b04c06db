"""TTOBench JSON (cosim.optimal.ttobench): tracks, trains and journeys written here in the
format of its READMEs, converted to SI; the real instances shipped in cosim_data/ttobench
(or ``$TTOBENCH_DIR``); ``cosim optimal`` on a small line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cosim.cli import app
from cosim.optimal import ttobench as tb
from cosim.optimal.model import Section
from cosim.optimal.pontryagin import Grid, SectionSolver

META = {"id": "x", "library version": "TTOBench v1.5"}


def _write(path: Path, data: dict) -> Path:
    path.write_text(json.dumps(data))
    return path


def _track(tmp_path: Path) -> Path:
    return _write(tmp_path / "track.json", {
        "metadata": META,
        "stops": {"unit": "m", "values": [0.0, 1500.0, 3000.0]},
        "speed limits": {"units": {"position": "m", "velocity": "km/h"},
                         "values": [[0.0, 72], [2000.0, 54]]},
        "gradients": {"units": {"position": "m", "slope": "permil"},
                      "values": [[0.0, 0.0], [1000.0, 8.0], [1800.0, -5.0]]},
        "curvatures": {"units": {"position": "m", "radius at start": "m",
                                 "radius at end": "m"},
                       "values": [[0.0, "infinity", "infinity"], [500.0, 600.0, 600.0],
                                  [700.0, -1200.0, "infinity"], [900.0, "infinity",
                                                                  "infinity"]]},
        "tunnels": {"units": {"position": "m", "length": "m", "cross section": "m^2"},
                    "values": [[2200.0, 300.0, 40.0]]}})


def _train(tmp_path: Path) -> Path:
    def q(unit: str, value: float) -> dict:
        return {"unit": unit, "value": value}

    return _write(tmp_path / "train.json", {
        "metadata": META, "mass": q("kg", 200000.0), "rho": q("%", 8),
        "max traction power": q("kW", 2500.0), "max reg braking power": q("kW", 3000.0),
        "max traction force": q("kN", 200.0), "max reg braking force": q("kN", 150.0),
        "max pn braking force": q("kN", 100.0), "max acceleration": q("m/s^2", 1.0),
        "max deceleration": q("m/s^2", 0.9), "max speed": q("km/h", 100),
        "rolling resistance r0": q("kN", 3.0), "rolling resistance r1": q("kN/(km/h)", 0.02),
        "rolling resistance r2": q("kN/(km/h)^2", 0.0008),
        "efficiency traction": q("%", 85.0), "efficiency reg brake": q("%", 75.0)})


def _journey(tmp_path: Path) -> Path:
    return _write(tmp_path / "journey.json", {
        "metadata": {**META, "associated track": "x"},
        "timing points": {"units": {"position": "m", "lower time constraint": "s",
                                    "upper time constraint": "s",
                                    "lower speed constraint": "km/h",
                                    "upper speed constraint": "km/h"},
                          "values": [[0, 0, 0, 0, 0], [800, 40, 90, 10, None],
                                     [1500, 100, 130, 0, 0], [1500, 160, 170, 0, 0],
                                     [3000, 260, 300, 0, 0]]}})


def test_a_track_in_si_with_curves_as_equivalent_grade(tmp_path: Path) -> None:
    t = tb.load_track(_track(tmp_path))
    r = t.route
    assert t.stops == (0.0, 1500.0, 3000.0) and r.length_m == 3000.0
    assert r.speed_limit.at(100.0) == pytest.approx(20.0) and r.speed_limit.at(2500.0) == 15.0
    assert r.grade.at(1500.0) == 8.0 and r.grade.at(2500.0) == -5.0
    # constant curve 600 m: 600 / R N/kN; a clothoid 1200 m -> straight: the mean curvature
    assert r.curve_resistance.at(600.0) == pytest.approx(1.0)
    assert r.curve_resistance.at(800.0) == pytest.approx(600.0 * 0.5 / 1200.0)
    assert r.curve_resistance.at(950.0) == 0.0
    assert r.additional.at(600.0) == pytest.approx(1.0)  # level there: curve alone
    assert t.tunnels == ((2200.0, 300.0, 40.0),)
    sec = t.section(1, 2)
    assert (sec.start, sec.end) == (1500.0, 3000.0)


def test_a_train_in_si(tmp_path: Path) -> None:
    tr = tb.load_train(_train(tmp_path))
    assert tr.mass == 200000.0 and tr.rotating_mass_factor == pytest.approx(0.08)
    assert tr.max_traction_power == 2.5e6 and tr.max_regen_force == 150e3
    assert tr.max_friction_force == 100e3 and tr.max_speed == pytest.approx(100 / 3.6)
    assert tr.traction_efficiency == pytest.approx(0.85)
    assert tr.regen_efficiency == pytest.approx(0.75)
    v = 20.0  # m/s = 72 km/h: r0 + r1 72 + r2 72^2 kN
    assert tr.davis.force(v) == pytest.approx((3.0 + 0.02 * 72 + 0.0008 * 72**2) * 1e3)
    assert tr.traction_limit(np.array([v]))[0] * tr.effective_mass == pytest.approx(125e3)


def test_unknown_units_and_bad_documents_are_errors(tmp_path: Path) -> None:
    data = json.loads(_train(tmp_path).read_text())
    data["mass"]["unit"] = "lb"
    with pytest.raises(ValueError, match="unit 'lb'"):
        tb.load_train(_write(tmp_path / "bad.json", data))
    with pytest.raises(ValueError, match="not a TTOBench"):
        tb.load_track(_write(tmp_path / "none.json", {"stops": []}))


def test_a_journey_in_sections_with_windows_and_passing_points(tmp_path: Path) -> None:
    j = tb.load_journey(_journey(tmp_path))
    assert len(j.sections) == 2
    a, b = j.sections
    assert (a.departure.position, a.arrival.position) == (0.0, 1500.0)
    assert a.running_time() == 130.0 and a.window() == (100.0, 130.0)
    assert b.running_time() == 300.0 - 160.0 and len(a.passing) == 1
    p = a.passing[0]
    assert p.lowest_speed == pytest.approx(10 / 3.6) and p.highest_speed is None
    s = np.array([0.0, 1500.0])
    assert a.missed(s, np.array([0.0, 130.0]), np.array([0.0, 0.0]))  # 0 m/s < 10 km/h
    assert not a.missed(s, np.array([0.0, 130.0]), np.array([5.0, 5.0]))


def test_the_optimum_of_a_journey_section_meets_its_window(tmp_path: Path) -> None:
    track = tb.load_track(_track(tmp_path))
    train = tb.load_train(_train(tmp_path))
    sec = tb.load_journey(_journey(tmp_path)).sections[0]
    solver = SectionSolver(Section(track.route, sec.departure.position,
                                   sec.arrival.position), train, Grid(50.0, 300))
    run = solver.for_time(sec.running_time())
    lo, hi = sec.window()
    assert lo <= run.running_time <= hi
    assert run.v.max() <= 20.0 + 1e-9  # the 72 km/h limit
    assert math.isfinite(run.energy) and run.energy > 0


def test_cosim_optimal_writes_the_profile_and_figure(tmp_path: Path) -> None:
    from plants.route import load_reference

    res = CliRunner().invoke(app, [
        "optimal", str(_track(tmp_path)), "--train", str(_train(tmp_path)), "--journey",
        str(_journey(tmp_path)), "--out", str(tmp_path / "out"), "--ds", "100",
        "--speeds", "200"])
    assert res.exit_code == 0, res.output
    for name in ("section0.csv", "section0.png", "section1.csv", "section1.png"):
        assert (tmp_path / "out" / name).is_file()
    ref = load_reference(tmp_path / "out" / "section1.csv")  # a speed-distance reference
    assert ref.kind == "distance" and ref.x[0] == 1500.0 and ref.x[-1] == 3000.0
    assert ref.v[0] == 0.0 and ref.v[-1] == 0.0
    # on time: the plan's own times (written to 0.1 ms, so within half of that); the reference
    # re-integrated from the written speeds lacks the integration's split steps
    times = pd.read_csv(tmp_path / "out" / "section1.csv", comment="#")["time_s"]
    assert times.iloc[-1] <= 140.0 + 0.5e-4


def test_every_real_instance_loads() -> None:
    tracks = sorted((tb.DATA / "tracks").glob("*.json"))
    trains = sorted((tb.DATA / "trains").glob("*.json"))
    journeys = sorted((tb.DATA / "journeys").glob("*.json"))
    assert len(tracks) >= 3 and len(trains) >= 3 and journeys
    assert (tb.DATA / "LICENSE").read_text().startswith("BSD 2-Clause License")
    for path in tracks:
        t = tb.load_track(path)
        assert t.route.length_m == t.stops[-1] > 0
    for path in trains:
        tr = tb.load_train(path)
        assert tr.mass > 0 and tr.davis.force(20.0) > 0
    for path in journeys:
        j = tb.load_journey(path)
        assert all(s.running_time() > 0 for s in j.sections)


def test_an_unknown_instance_names_those_there_are() -> None:
    assert tb.instance("tracks", "00_reference").is_file()
    with pytest.raises(FileNotFoundError, match="00_reference"):
        tb.instance("tracks", "no_such_line")
    with pytest.raises(ValueError, match="kind"):
        tb.instance("track", "00_reference")


def test_the_reference_track_with_a_real_train() -> None:
    track = tb.load_track(tb.instance("tracks", "00_reference"))
    train = tb.load_train(tb.instance("trains", "CH_Stadler_FLIRT_TPF"))
    solver = SectionSolver(track.section(0, 1), train, Grid(100.0, 300))
    fastest = solver.fastest()
    run = solver.for_time(1.1 * fastest.running_time)
    assert run.running_time <= 1.1 * fastest.running_time
    assert run.energy < fastest.energy
