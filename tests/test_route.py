"""Route data: step profiles, length-share resistance, reference profiles, bundled lines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plants.route import (
    GRAVITY,
    KMH,
    ReferenceProfile,
    StepProfile,
    load_reference,
    load_route,
)


def test_mean_over_a_grade_change_is_the_length_share() -> None:
    grade = StepProfile.from_pairs([[0.0, 2.0], [1000.0, 12.0]])
    length = 25.0
    for inside in (0.0, 5.0, 12.5, 20.0, 25.0):  # metres of the vehicle past the change
        front = 1000.0 + inside
        expected = (inside * 12.0 + (length - inside) * 2.0) / length
        assert grade.mean_over(np.array([front]), length)[0] == pytest.approx(expected)
    # several vehicles at once, zero length falls back to the point value
    fronts = np.array([990.0, 1010.0, 1100.0])
    assert np.allclose(grade.mean_over(fronts, 20.0), [2.0, 7.0, 12.0])
    assert grade.mean_over(np.array([1000.5]), 0.0)[0] == 12.0


def test_intervals_and_sums() -> None:
    curves = StepProfile.from_intervals([[100.0, 200.0, 3.0], [200.0, 300.0, 5.0]], 0.0)
    assert [curves.at(x) for x in (-1e9, 50.0, 100.0, 199.9, 200.0, 300.0)] == \
        [0.0, 0.0, 3.0, 3.0, 5.0, 0.0]
    total = StepProfile.sum(curves, StepProfile.from_pairs([[150.0, 1.0]]))
    assert [total.at(x) for x in (0.0, 120.0, 160.0, 250.0, 400.0)] == [1.0, 4.0, 4.0, 6.0, 1.0]
    with pytest.raises(ValueError, match="overlaps"):
        StepProfile.from_intervals([[0.0, 200.0, 1.0], [100.0, 300.0, 1.0]])
    with pytest.raises(ValueError, match="end > start"):
        StepProfile.from_intervals([[10.0, 10.0, 1.0]])


def test_route_file_resistance_profiles(tmp_path) -> None:
    path = tmp_path / "line.toml"
    path.write_text(
        'name = "t"\nlength_m = 5000.0\ngrade = [[0.0, 0.0], [1000.0, 6.0]]\n'
        "curves = [[2000.0, 2600.0, 3000.0]]\ntunnels = [[3000.0, 4000.0]]\n"
        "neutral_sections = [[4200.0, 4400.0]]\n"
        'stations = [["A", 0.0], ["B", 5000.0]]\nspeed_limits = [[0.0, 50.0]]\n')
    route = load_route(path)
    assert route.curve_radius.at(100.0) == math.inf and route.curve_radius.at(2100.0) == 3000.0
    assert route.curve_resistance.at(2100.0) == pytest.approx(600.0 / 3000.0)
    assert route.tunnel.at(3500.0) == 1.0 and route.tunnel.at(100.0) == 0.0
    assert route.tunnel_resistance.at(3500.0) == pytest.approx(0.00013 * 1000.0)
    assert route.neutral.at(4300.0) == 1.0 and route.neutral.at(4500.0) == 0.0
    assert route.station_position("B") == 5000.0
    # a 20 m vehicle straddling the start of the curve: half its length on the curve
    w = route.additional_resistance(np.array([2010.0]), 20.0)[0]
    assert w == pytest.approx(6.0 + 0.5 * 0.2)
    assert route.additional_accel(np.array([2010.0]), 20.0)[0] == pytest.approx(GRAVITY * w / 1e3)
    with pytest.raises(ValueError, match="no station"):
        route.station_position("C")


def test_bad_route_files_name_the_problem(tmp_path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('length_m = 100.0\ngrade = [[0.0, 1.0]]\ncurves = [[0.0, 50.0, -5.0]]\n')
    with pytest.raises(ValueError, match="radius"):
        load_route(path)
    with pytest.raises(ValueError, match="not found"):
        load_route("no_such_route")


def test_distance_profile_has_constant_acceleration_between_points() -> None:
    """v^2 linear in s: a braking curve from 20 m/s at 0.5 m/s^2 is exact with two points."""
    ref = ReferenceProfile("distance", np.array([0.0, 400.0]), np.array([20.0, 0.0]))
    for s in (0.0, 100.0, 250.0, 399.0):
        assert ref.speed(s) == pytest.approx(math.sqrt(2 * 0.5 * (400.0 - s)))
        assert ref.accel(s) == pytest.approx(-0.5)
    assert ref.speed(500.0) == 0.0 and ref.accel(500.0) == 0.0
    assert ref.run_time() == pytest.approx(40.0)


def test_time_profile_and_file_formats(tmp_path) -> None:
    csv_path = tmp_path / "r.csv"
    csv_path.write_text("# comment\ntime_s,speed_kmh\n0,0\n100,180\n200,180\n")
    ref = load_reference(csv_path)
    assert ref.kind == "time"
    assert ref.speed(50.0) == pytest.approx(90.0 * KMH)
    assert ref.accel(50.0) == pytest.approx(0.5)
    assert ref.accel(150.0) == 0.0
    toml_path = tmp_path / "r.toml"
    toml_path.write_text('[reference]\nkind = "distance"\nspeed_unit = "km/h"\n'
                         "points = [[0.0, 0.0], [1000.0, 36.0]]\n")
    ref = load_reference(toml_path)
    assert ref.speed(1000.0) == pytest.approx(10.0)
    assert ref.accel(10.0) == pytest.approx(100.0 / 2000.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("position_m,speed_kmh\n0,10\n0,20\n")
    with pytest.raises(ValueError, match="increase"):
        load_reference(bad)
    bad.write_text("distance,speed\n0,10\n")
    with pytest.raises(ValueError, match="header"):
        load_reference(bad)


def test_bundled_jinan_xuzhou_east_line() -> None:
    route = load_route("jinan_xuzhou_east")
    assert route.length_m == pytest.approx(688.700e3 - 419.445e3)
    assert route.stations[0][0] == "Jinan West" and route.stations[-1][0] == "Xuzhou East"
    assert np.max(np.abs(route.grade.values)) <= 20.0
    ref = route.reference
    assert ref is not None and ref.kind == "distance"
    s = ref.x
    assert ref.v[0] == 0.0 and ref.v[-1] == 0.0 and s[-1] == route.length_m
    assert np.all(ref.v <= route.speed_limit.at_array(s) + 1e-9)
    assert ref.v.max() == pytest.approx(300.0 * KMH)
    accel = np.array([ref.accel(x) for x in s[:-1]])
    assert accel.max() <= 0.5 + 1e-9 and accel.min() >= -0.5 - 1e-3  # CSV rounding
    # coasting through every neutral section: no traction, so the reference does not rise
    starts, values = route.neutral.starts, route.neutral.values
    sections = [(starts[i], starts[i + 1]) for i in range(1, starts.size - 1) if values[i] > 0]
    assert len(sections) >= 8
    for a, b in sections:
        inside = (s[:-1] >= a) & (s[:-1] < b)
        assert np.all(accel[inside] <= 0.0)
    assert 3000.0 < ref.run_time() < 4000.0  # about 59 min at 300 km/h


@pytest.mark.parametrize("factor", [1.0, 0.5, 2.0])
def test_jinan_xuzhou_east_reference_keeps_a_traction_reserve(factor: float) -> None:
    """Each reference needs at most the traction envelope minus its reserve, on every 25 m
    segment: the force m a + resistance + line resistance at the segment's start speed. The
    main profile's reserve is 3 sigma of the slowly varying disturbance of the seed 001
    reproduction (its main rows); the variant rows' profiles are planned with half and twice it
    (``factor``), each named by its reserve, run by the four laws of its variant rows until
    after the profile's end and with the profile's run time as the planned arrival."""
    from cosim.reproduce.entry import load_entry
    from cosim.run.scenario import load_scenario
    from plants.emu import emu_config

    entry = load_entry("seed001")
    (main,) = [r for r in entry.runs if r.name == "FFDL-ISMPC"]
    reserve = factor * 3.0 * main.overrides["plant.disturbance_accel_std"]  # m/s^2: 0.09 main
    route = load_route("jinan_xuzhou_east")
    if factor == 1.0:
        ref, rows = route.reference, [main]
    else:
        name = f"jinan_xuzhou_east_reference_reserve_{reserve:g}".replace(".", "p")
        rows = [r for r in entry.runs if r.overrides.get("controller.reference") == name]
        assert sorted(r.name for r in rows) == sorted(
            f"{law}, traction reserve {reserve:g}"
            for law in ("FFDL-ISMPC", "FFDL-ISMC", "FFDL-MFAC", "GPC"))
        ref = load_reference(name)
    for row in rows:  # the run outlasts the profile; arrival is planned at its end (0.1 s CSV)
        scenario = load_scenario(row.scenario, row.overrides)
        assert scenario.simulation.stop_time >= ref.run_time()
        assert scenario.summary["planned_arrival_time"] == pytest.approx(ref.run_time(),
                                                                         abs=0.05)
    p = emu_config("crh380a_3unit")
    mass, length = sum(p.masses), sum(p.lengths)
    s, v = ref.x[:-1], ref.v[:-1]
    accel = np.array([ref.accel(x) for x in s])
    resist = sum(p.davis_a) + sum(p.davis_b) * v + sum(p.davis_c) * v * v
    line = mass * GRAVITY * route.additional_resistance(s, length) / 1000.0
    needed = (mass * accel + resist + line) / mass
    envelope = np.minimum(sum(p.max_traction_force),
                          sum(p.max_traction_power) / np.maximum(v, 1e-3)) / mass
    # 1e-3 m/s^2: the CSV's 1e-4 km/h rounding over 25 m (5e-5 m/s^2 at 300 km/h) and the
    # envelope's change over a segment (3e-5); 85 % of the envelope leaves 0.033 m/s^2 at
    # 300 km/h and fails the main reserve by 0.057 m/s^2
    assert np.max(needed - (envelope - reserve)) <= 1e-3
    # and it uses that envelope: somewhere the reserve is all that is left
    assert np.min(envelope - needed) == pytest.approx(reserve, abs=1e-3)


def test_seed004_reference_changes_at_200_and_600_s() -> None:
    ref = load_route("seed004_level").reference
    assert ref.kind == "time"
    assert ref.accel(199.0) == 0.0 and ref.accel(201.0) > 0.0
    assert ref.accel(599.0) == 0.0 and ref.accel(601.0) < 0.0
    assert ref.speed(800.0) == pytest.approx(30.0)


def test_scalar_mean_over_is_the_array_path_in_floats() -> None:
    """Same operations as np.interp (slope (x - x_j) + y_j): equal to the last bit, also
    before, after and exactly on the segment starts."""
    import numpy as np

    from plants.route import load_route

    profile = load_route("freight_20km").additional
    rng = np.random.default_rng(3)
    starts = profile.starts[1:]
    fronts = np.concatenate([rng.uniform(-2e3, 2.5e4, 200), starts, starts + 12.0,
                             [starts[0] - 1e8, starts[-1] + 1e8]])
    for length in (12.0, 1331.2):
        expected = profile.mean_over(fronts, length)
        got = [profile.mean_over_scalar(float(f), length) for f in fronts]
        assert got == expected.tolist()
