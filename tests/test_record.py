"""The record of a reproduction's simulations (cosim.reproduce.record): summaries read back bit for
bit, series at the record's digits, the same record the same bytes, a record that cannot
serve an entry named as such, and a save cut at any step leaving one complete record."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cosim.reproduce.record as record_module
from cosim.reproduce.record import (
    SERIES_DIGITS,
    Job,
    Record,
    RecordError,
    build_of,
    check_jobs,
    load,
    save,
    simulation_of,
)

# floats a decimal writer could round: thirds, subnormals, extremes, a NaN
AWKWARD = [1.0 / 3.0, 2.0 / 3.0 * 1e-310, 1.7976931348623157e308, -0.1 - 0.2, math.nan,
           np.nextafter(1.0, 2.0)]


def _record() -> Record:
    rec = Record("seedX", "ab" * 32, 2, True)
    summary = {"stop_error_m": AWKWARD[0], "ok": True, "executions": {"plant": 301},
               "warnings": ["w"], "missing": math.nan}
    rec.add(Job("run", ("PID", 0), "s_pid", {"controller.kp": 30.0}), summary)
    rec.add(Job("member", ("PID", "disturbance", 1, 1), "s_pid",
                {"plant.disturbance_seed": 2}, {"ATO_COSIM_NO_KERNELS": "1"}), None)
    rec.add(Job("sweep", ("fig11",), ["a", "b"], {"controller.N": "3..5"}),
            {"columns": ["scenario", "x"], "rows": [["a", 1.5], ["b", None]]})
    rec.series["run/PID"] = pd.DataFrame({"time": np.linspace(0.0, 1.0, 6),
                                          "plant.v": AWKWARD})
    return rec


def test_a_record_reads_back_and_rewrites_the_same_bytes(tmp_path: Path) -> None:
    rec = _record()
    folder = save(rec, tmp_path)
    back = load(tmp_path)
    assert (back.entry, back.simulation, back.seeds, back.rounding) == (
        "seedX", "ab" * 32, 2, True)
    assert back.jobs == rec.jobs
    got = back.result("run", "PID", 0)
    assert got["stop_error_m"] == AWKWARD[0] and math.isnan(got["missing"])
    assert got["executions"] == {"plant": 301} and got["ok"] is True
    assert back.result("member", "PID", "disturbance", 1, 1) is None
    frame = back.frame("run/PID")
    want = np.array([float(f"{v:.{SERIES_DIGITS}g}") for v in AWKWARD])
    assert frame["plant.v"].to_numpy().tobytes() == want.tobytes()
    assert simulation_of(tmp_path) == ("ab" * 32, 2)
    assert back.build == "python" and build_of(tmp_path) == "python"
    first = {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    save(back, tmp_path / "again")
    again = tmp_path / "again" / "record"
    assert {p.relative_to(again): p.read_bytes() for p in again.rglob("*")
            if p.is_file()} == first


def test_a_record_that_cannot_serve_names_the_job_and_why(tmp_path: Path) -> None:
    rec = _record()
    check_jobs(rec, list(rec.jobs.values()))
    with pytest.raises(RecordError, match=r"no run \['MPC', 0\]"):
        check_jobs(rec, [Job("run", ("MPC", 0), "s_mpc", {})])
    with pytest.raises(RecordError, match=r"run \['PID', 0\] ran as .*30\.0.*now asks for.*50"):
        check_jobs(rec, [Job("run", ("PID", 0), "s_pid", {"controller.kp": 50.0})])
    with pytest.raises(RecordError, match="no series 'run/MPC'|no recorded series 'run/MPC'"):
        rec.frame("run/MPC")
    with pytest.raises(RecordError, match="no record"):
        load(tmp_path / "nothing")
    (tmp_path / "record").mkdir()
    (tmp_path / "record" / "record.json.gz").write_bytes(b"not gzip")
    with pytest.raises(RecordError, match="unreadable record"):
        load(tmp_path)


def test_a_series_keeps_what_its_figures_draw_reduced_and_thinned(tmp_path: Path) -> None:
    """A train-mean figure (y_reduce over plant.v[*]) records one column holding the mean, not
    every vehicle's; a member's series is thinned evenly to max_rows with its last row; the
    figure drawn from the record is the figure of the full run at the kept rows."""
    from cosim.reproduce.entry import Figure
    from cosim.reproduce.series import record_series
    from cosim.run.figures import figure_series

    t = np.arange(10.0)
    full = pd.DataFrame({"time": t, "plant.v[1]": t, "plant.v[2]": 2 * t, "plant.v[3]": 4 * t,
                         "plant.s": t * t, "controller.v_ref": t / 2})
    (tmp_path / "run").mkdir()
    full.to_csv(tmp_path / "run" / "results.csv", index=False)
    spec = {"file": "f.png", "x": "time", "y": ["plant.v[*]"], "y_reduce": "mean",
            "y_minus": "controller.v_ref"}
    rec = Record("seedX", "0" * 64, 1, False)
    figure = Figure(**spec)
    record_series(rec, "member/A/0", tmp_path / "run", [figure], None, scalars=False,
                  max_rows=4)
    got = rec.series["member/A/0"]
    assert sorted(got.columns) == ["controller.v_ref", "plant.v[*]", "time"]
    assert list(got["time"]) == [0.0, 3.0, 6.0, 9.0]
    rows = got["time"].to_numpy(dtype=int)
    assert figure_series(got, spec, "plant.v[*]", "A").tolist() == pytest.approx(
        figure_series(full, spec, "plant.v[*]", "A")[rows].tolist(), rel=1e-15)
    record_series(rec, "run/A", tmp_path / "run", [figure], None)  # a table run: scalars too
    assert "plant.s" in rec.series["run/A"] and len(rec.series["run/A"]) == 10


def test_a_record_of_one_rerun_flag_reads_as_paths(tmp_path: Path) -> None:
    """A record written when a member's key ended in a rerun flag (false / true) reads as
    path 0 / 1, so its jobs serve the same jobs of the path numbering."""
    import gzip
    import json

    rec = _record()
    save(rec, tmp_path)
    path = tmp_path / "record" / "record.json.gz"
    body = json.loads(gzip.decompress(path.read_bytes()))
    for item in body["jobs"]:
        if item["kind"] == "member":
            item["key"][3] = True
    path.write_bytes(gzip.compress(json.dumps(body).encode()))
    back = load(tmp_path)
    [key] = [k for k in back.jobs if k[0] == "member"]
    assert key == ("member", "PID", "disturbance", 1, 1) and type(key[4]) is int


@pytest.mark.parametrize("cut", ["writing", "between the renames", "removing the old"])
def test_a_save_stopped_anywhere_leaves_one_complete_record(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, cut: str) -> None:
    """A checkpoint cut by a kill keeps every member recorded: the old record until the new
    one is complete, the new one after (here the cut is an exception at each step of save)."""
    first = _record()
    save(first, tmp_path)
    second = _record()
    second.add(Job("run", ("PID", 1), "stop", {"seed": 7}), {"stop_error_m": 0.25})

    class Cut(Exception):
        pass

    def stop(*args: object, **kwargs: object) -> None:
        raise Cut

    if cut == "writing":
        monkeypatch.setattr(record_module, "_gzip", stop)
    elif cut == "between the renames":
        renames = []
        real = Path.replace

        def replace(self: Path, target: Path) -> Path:
            renames.append(self.name)
            if len(renames) == 2:  # the staged record onto the record's place
                raise Cut
            return real(self, target)

        monkeypatch.setattr(Path, "replace", replace)
    else:
        real_rmtree = record_module.shutil.rmtree

        def rmtree(path: Path, **kwargs: object) -> None:
            if Path(path).name == ".record.old":
                raise Cut
            real_rmtree(path, **kwargs)

        monkeypatch.setattr(record_module.shutil, "rmtree", rmtree)
    with pytest.raises(Cut):
        save(second, tmp_path)
    monkeypatch.undo()
    back = load(tmp_path)
    want = first if cut == "writing" else second
    assert back.jobs == want.jobs and back.results.keys() == want.results.keys()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["record"] + ([".record.tmp"] if cut == "writing" else []))
    save(second, tmp_path)  # and the next save goes through
    assert load(tmp_path).jobs == second.jobs
