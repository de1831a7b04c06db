"""Mismatch studies (``cosim sweep --perturb``): parsing, seeded draws, nominal values from the
scenario or the FMU, per-run rows and the per-point table, and the command limits under
perturbed plants (issue 11)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cosim.run.perturb import run_perturbed, summarize
from cosim.run.perturbation import Perturbation, draw_samples, nominal_values, parse_perturb
from tests.cli_inproc import cosim_inproc

STUDY = ["plant.mass=+-10%", "plant.brake_time_constant=0.3..0.6", "plant.brake_delay=0.8..1.2",
         "plant.davis_a=+-30%", "plant.davis_b=+-30%", "plant.davis_c=+-30%",
         "plant.grade_scale=0.7..1.3"]


def test_parse_forms_and_errors():
    perts = parse_perturb(["plant.mass=+-10%", "plant.v0=+-0.5", "plant.brake_delay=0.8..1.2"])
    assert perts == [Perturbation("plant.mass", "relative", 0.1),
                     Perturbation("plant.v0", "absolute", 0.5),
                     Perturbation("plant.brake_delay", "range", 0.8, 1.2)]
    assert perts[0].interval(490e3) == pytest.approx((441e3, 539e3))
    assert perts[1].interval(20.0) == (19.5, 20.5)
    for bad, match in [("plant.mass", "expected"), ("mass=+-10%", "expected"),
                       ("plant.mass=10%", "SPEC"), ("plant.mass=0.6..0.3", "empty range"),
                       ("plant.mass=+-x%", "SPEC"), ("plant.mass=+--5%", "half-width")]:
        with pytest.raises(ValueError, match=match):
            parse_perturb([bad])
    with pytest.raises(ValueError, match="twice"):
        parse_perturb(["plant.mass=+-1%", "plant.mass=+-2%"])


def test_draws_are_seeded_and_inside_their_intervals():
    perts = parse_perturb(["plant.mass=+-10%", "plant.brake_delay=0.8..1.2"])
    nominal = {"plant.mass": 490e3}
    a, b = draw_samples(perts, nominal, 200, 1), draw_samples(perts, nominal, 200, 1)
    assert a == b and a != draw_samples(perts, nominal, 200, 2)
    mass = np.array([d["plant.mass"] for d in a])
    delay = np.array([d["plant.brake_delay"] for d in a])
    assert mass.min() >= 441e3 and mass.max() <= 539e3
    assert delay.min() >= 0.8 and delay.max() <= 1.2
    # 200 uniform draws: each end tenth of the interval is hit (miss probability 0.9^200)
    assert mass.min() < 451e3 and mass.max() > 529e3
    with pytest.raises(ValueError, match="nominal"):
        draw_samples(perts, {}, 1, 1)
    with pytest.raises(ValueError, match="samples"):
        draw_samples(perts, nominal, 0, 1)


def test_nominal_values_from_scenario_then_fmu(built_fmus):
    nominal = nominal_values("seed000_stop_rmpc", ["plant.mass", "plant.davis_a",
                                                   "plant.grade_scale"])
    assert nominal == {"plant.mass": 490000.0, "plant.davis_a": pytest.approx(5400.0),
                       "plant.grade_scale": 1.0}
    with pytest.raises(ValueError, match="no variable 'massa'"):
        nominal_values("seed000_stop_rmpc", ["plant.massa"])
    with pytest.raises(ValueError, match="no FMU named 'train'"):
        nominal_values("seed000_stop_rmpc", ["train.mass"])


def test_nominal_values_come_from_the_fmu_the_job_runs(built_fmus, monkeypatch):
    """A job's ``NAME.fmu`` / ``NAME.build`` choose the FMU whose start value is the nominal;
    its other overrides are not the nominal plant."""
    from cosim.run import perturbation

    read: list[str] = []
    real = perturbation.read_fmu
    monkeypatch.setattr(perturbation, "read_fmu",
                        lambda sc, name, path: read.append(str(path)) or real(sc, name, path))
    other = str(built_fmus["StopRmpc"].path)  # an FMU with no plant.grade_scale
    job = {"plant.fmu": other, "plant.mass": 1.0}
    with pytest.raises(ValueError, match="has no variable 'grade_scale'"):
        nominal_values("seed000_stop_rmpc", ["plant.grade_scale"], job)
    assert read == [other]
    assert nominal_values("seed000_stop_rmpc", ["plant.mass"], job) == {"plant.mass": 490000.0}


def test_nominal_values_read_the_fmu_within_the_archive_limits(built_fmus, monkeypatch):
    """A start value is read from the FMU only after its archive passed the limits (here a
    modelDescription limit of about 1 KiB, which every real modelDescription exceeds)."""
    monkeypatch.setenv("COSIM_MAX_MODEL_DESCRIPTION_MB", "0.001")
    assert nominal_values("seed000_stop_rmpc", ["plant.mass"]) == {"plant.mass": 490000.0}
    with pytest.raises(ValueError, match=r"\[fmus\.plant\] fmu = .*modelDescription\.xml is "
                                         r".* more than the limit of 1\.02 KiB"):
        nominal_values("seed000_stop_rmpc", ["plant.grade_scale"])


def test_summarize_counts_the_window_and_infeasible():
    frame = pd.DataFrame({"scenario": ["a"] * 3, "controller.N": [5] * 3,
                          "stop_error_m": [0.1, -0.6, 0.2], "controller_executions": [10, 20, 30],
                          "qp_infeasible": [0, 2, 1], "command_min": [0.0, 1.0, 2.0],
                          "command_max": [90.0, 100.0, 80.0]})
    row = summarize(frame, ["controller.N"]).iloc[0]
    assert row["runs"] == 3 and row["inside_window"] == 2
    assert row["max_abs_stop_error_m"] == 0.6 and row["stop_error_median_m"] == 0.1
    assert row["qp_infeasible_total"] == 3 and row["qp_infeasible_max"] == 2
    assert row["command_min"] == 0.0 and row["command_max"] == 100.0


def test_perturbed_runs_keep_the_command_inside_its_limits(built_fmus, tmp_path):
    """Two plants of the study per controller: the command stays in [u_min, u_max] =
    [0, 100] %, every run completes, the drawn values reach the plant (they differ per run)."""
    frame, table = run_perturbed(["seed000_stop_rmpc", "seed000_stop_rsmpc"],
                                 {"controller.N": [5]}, parse_perturb(STUDY), 2, 1, tmp_path,
                                 workers=2)
    assert len(frame) == 4 and frame["completed"].all()
    assert (frame["command_min"] >= 0.0).all() and (frame["command_max"] <= 100.0).all()
    assert frame.groupby("scenario")["stop_error_m"].nunique().min() == 2
    # the same plants for both controllers (common random numbers)
    rm, rs = (frame[frame.scenario == s].sort_values("sample") for s in
              ("seed000_stop_rmpc", "seed000_stop_rsmpc"))
    np.testing.assert_array_equal(rm["plant.mass"], rs["plant.mass"])
    assert len(table) == 2 and set(table["runs"]) == {2}
    for name in ("perturb.csv", "perturb_summary.csv"):
        assert len(pd.read_csv(tmp_path / name)) == len(frame if name == "perturb.csv" else table)
    assert (tmp_path / "perturb.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_mismatch_study_at_n5_and_n10_stays_in_the_window(built_fmus, tmp_path):
    """The issue's study: 50 plants, RMPC and RSMPC at N = 5 and 10 inside +-0.5 m."""
    frame, _ = run_perturbed(["seed000_stop_rmpc", "seed000_stop_rsmpc"],
                             {"controller.N": [5, 10]}, parse_perturb(STUDY), 50, 1, None,
                             workers=2)
    assert (frame["stop_error_m"].abs() <= 0.5).all()
    assert (frame["command_min"] >= 0.0).all() and (frame["command_max"] <= 100.0).all()


def test_cli_perturb_errors_name_the_item(built_fmus, tmp_path):
    bad = cosim_inproc("sweep", "seed000_stop_rmpc", "--set", "controller.N=5",
                       "--perturb", "plant.mass=10%", "--out", str(tmp_path / "x"))
    assert bad.exit_code == 2 and "plant.mass=10%" in bad.stderr


def test_an_interrupted_study_keeps_its_finished_runs_and_resume_runs_the_rest(built_fmus,
                                                                             tmp_path,
                                                                             monkeypatch):
    from cosim.run import interrupt, sweep

    grid = {"simulation.stop_time": [20.0]}  # short runs
    perts = parse_perturb(["plant.mass=+-5%"])
    add = sweep.RowWriter.add

    def add_then_interrupt(self, row):  # a SIGINT (the flag its handler sets) after a row
        add(self, row)
        interrupt._requested.append("SIGINT")

    monkeypatch.setattr(sweep.RowWriter, "add", add_then_interrupt)
    try:
        with pytest.raises(interrupt.Interrupted, match="the mismatch study interrupted"):
            run_perturbed("seed000_stop_pid", grid, perts, 4, 1, tmp_path, workers=1,
                          plot=False)
    finally:
        interrupt._requested.clear()
    monkeypatch.setattr(sweep.RowWriter, "add", add)
    kept = pd.read_csv(tmp_path / "perturb.csv", dtype={"inputs_digest": str})
    assert 1 <= len(kept) < 4 and kept["inputs_digest"].str.len().eq(16).all()
    frame, table = run_perturbed("seed000_stop_pid", grid, perts, 4, 1, tmp_path, workers=1,
                                 plot=False, resume=True)
    assert list(frame["sample"]) == [0, 1, 2, 3] and int(table["runs"].iloc[0]) == 4
    again = pd.read_csv(tmp_path / "perturb.csv", dtype={"inputs_digest": str})
    for _, row in kept.iterrows():  # kept as they were: not run again (same wall time)
        assert again[again["sample"] == row["sample"]].iloc[0].equals(row)
