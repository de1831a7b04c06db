"""The bare C loop of benchmarks/bench_c_limit.py runs the closed loop the master runs."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.mark.skipif(shutil.which("gcc") is None, reason="the C loop and native FMUs need gcc")
def test_the_bare_c_loop_ends_where_the_master_ends_on_the_same_native_fmus(
        tmp_path: Path) -> None:
    """Same FMU binaries, start values, connection order and steps: the same floating-point
    operations, so the final position agrees to the last bit (printed with 17 digits)."""
    sys.path.insert(0, str(BENCHMARKS))
    import bench_c_limit

    sc = bench_c_limit.native_scenario("seed000_stop_pid")
    c = bench_c_limit.c_run(*bench_c_limit.prepare_c_loop(sc, tmp_path))
    master = bench_c_limit.master_run(sc)
    assert c["final"] == master["final"]
