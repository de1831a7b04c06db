"""``cosim optimal --closed-loop`` (cosim/optimal/closed_loop.py): the route written for the
plant against TTOBench's JSON read here on its own, the brake envelope mapping, the closed loop
of the speed PID on the optimal run within seed 003's windows, and the error paths."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cosim.cli import app
from cosim.optimal import closed_loop as loop
from cosim.optimal.ttobench import instance, load_train
from plants.crh3 import Crh3Params
from plants.route import Route, load_route

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

FLIRT = instance("trains", "CH_Stadler_FLIRT_TPF")
REFERENCE = instance("tracks", "00_reference")


@pytest.mark.slow  # the optimum over 8.5 km and its closed loop: about 30 s of CPU
def test_the_closed_loop_follows_the_optimum_on_ttobench_reference_track(tmp_path: Path) -> None:
    """The FLIRT from stop 0 to stop 1 of the reference track (8.5 km, level, 140 km/h) in
    330 s on a coarse grid: the written route is the JSON's line, the plant carries the JSON's
    train, and the PID arrives within Delta T_max = 5 s of the schedule and stops within
    Delta l_max = 0.5 m (seed 003 sec. 4)."""
    result = CliRunner().invoke(app, [
        "optimal", str(REFERENCE), "--out", str(tmp_path), "--train", str(FLIRT),
        "--stops", "0:1", "--time", "330", "--ds", "100", "--speeds", "200",
        "--closed-loop", "pid"])
    assert result.exit_code == 0, result.output
    # the line, against the JSON read here (km/h and permille, positions in m)
    track = json.loads(REFERENCE.read_text())
    route = tomllib.loads((tmp_path / "route.toml").read_text())
    assert route["grade"] == [[float(x), float(g)] for x, g in track["gradients"]["values"]]
    limits = np.array(track["speed limits"]["values"], dtype=float)
    assert np.allclose(route["speed_limits"], limits * [1.0, 1 / 3.6], rtol=1e-15, atol=0)
    assert [x for _, x in route["stations"]] == track["stops"]["values"]
    assert "curves" not in route and "tunnels" not in route
    # the plant's data, against the JSON (kN, kW, km/h, %)
    train = json.loads(FLIRT.read_text())
    value = lambda key: train[key]["value"]  # noqa: E731
    scenario = tomllib.loads((tmp_path / "run_pid.toml").read_text())
    plant = scenario["fmus"]["plant"]["parameters"]
    assert plant["mass"] == value("mass")
    assert plant["rotating_mass_factor"] == pytest.approx(value("rho") / 100, rel=1e-15)
    assert plant["max_brake_force"] == pytest.approx(
        1e3 * (value("max reg braking force") + value("max pn braking force")), rel=1e-15)
    assert plant["max_brake_power"] == pytest.approx(
        1e3 * value("max reg braking power")
        + 1e3 * value("max pn braking force") * value("max speed") / 3.6, rel=1e-15)
    assert plant["davis_c"] == pytest.approx(1e3 * value("rolling resistance r2") * 3.6**2,
                                             rel=1e-14)
    assert plant["s0"] == 0.0 and scenario["summary"]["stop_point"] == 8500.0
    # the closed loop against the plan
    with open(tmp_path / "closed_loop.csv") as f:
        (row,) = list(csv.DictReader(f))
    assert float(row["schedule_s"]) == 330.0
    assert abs(float(row["arrival_error_s"])) <= loop.TIME_WINDOW_S, row
    assert abs(float(row["stop_error_m"])) <= loop.STOP_WINDOW_M, row
    assert row["verdict"] == "within the windows"
    # the recorded quadrature of the braking work against the plant's exact integral: the
    # trapezoidal rule on a function monotone between samples errs by at most h / 2 times the
    # function's variation (h the output interval)
    frame = np.genfromtxt(tmp_path / "run_pid" / "results.csv", delimiter=",", names=True)
    power = np.maximum(-frame["plantapplied_force"], 0.0) * frame["plantv"]
    bound = 0.5 * loop.SAMPLE_TIME * float(np.sum(np.abs(np.diff(power))))
    assert abs(float(row["brake_work_records_J"]) - float(row["brake_work_plant_J"])) <= bound
    # regenerated work is a part of the braking work, so the plant's eq. 9 (all braking fed
    # back) is at most the plan's accounting
    assert float(row["regen_work_J"]) <= float(row["brake_work_records_J"])
    eta_r = value("efficiency reg brake") / 100
    assert float(row["plant_energy_J"]) <= float(row["energy_J"]) + eta_r * bound


def test_the_plant_brake_covers_the_trains_two_brakes_and_meets_them_at_the_ends() -> None:
    """``min(F_b, P_b / v)`` against ``min(F_r, P_r / v) + F_f``: never below up to the top
    speed, equal at the top speed and at low speed."""
    train = load_train(FLIRT)
    p = loop.plant_parameters(train, Route.flat())
    plant = Crh3Params(max_brake_force=p["max_brake_force"],
                       max_brake_power=p["max_brake_power"])
    v = np.linspace(0.1, train.max_speed, 2000)
    own = train.brake_limit(v) * train.effective_mass
    mapped = np.array([plant.brake_limit(x) for x in v])
    assert np.all(mapped >= own * (1 - 1e-12))
    assert mapped[0] == pytest.approx(own[0], rel=1e-12)
    assert mapped[-1] == pytest.approx(own[-1], rel=1e-12)


def test_a_project_route_round_trips_through_the_written_route(tmp_path: Path) -> None:
    """Grade, curves, tunnels, speed limits, neutral sections and stations of a bundled line
    come back from the written TOML as :func:`plants.route.load_route` reads them."""
    src = load_route("jinan_xuzhou_east")
    back = load_route(loop.write_route(src, tmp_path / "line.toml"))
    x = np.linspace(0.0, src.length_m, 100_001)
    for name in ("additional", "grade", "curve_resistance", "tunnel_resistance", "neutral",
                 "speed_limit"):
        a, b = getattr(src, name).at_array(x), getattr(back, name).at_array(x)
        assert np.array_equal(a, b), name
    assert back.stations == src.stations and back.length_m == src.length_m


def test_errors_name_what_is_wrong(tmp_path: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(app, ["optimal", str(REFERENCE), "--out", str(tmp_path),
                                 "--time", "300", "--closed-loop", "gmpc"])
    assert result.exit_code == 2
    assert "'gmpc'" in result.output and "pid" in result.output
    assert not any(tmp_path.iterdir())  # refused before planning
    train = load_train(FLIRT).with_limits(max_speed=math.inf)
    with pytest.raises(ValueError, match="no top speed"):
        loop.plant_parameters(train, Route.flat())
    with pytest.raises(ValueError, match="no TOML literal"):
        loop.toml_text({"x": math.inf})
