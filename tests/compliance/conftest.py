"""Fixtures of the compliance suite: compliance results computed once per FMU and test run
(shared by the pytest-xdist workers), the broken FMU."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import pytest

from cosim.interop.compliance import Options, Problem, check_fmu

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="session")
def checked_once(tmp_path_factory, worker_id) -> Callable[[Path], list[Problem]]:
    """``check_fmu(path)`` computed once per FMU file in this test run: the first worker to
    ask computes it under a file lock and stores it in the run's temporary folder (shared by
    the pytest-xdist workers); the others read it. Keyed on the file's path, size and
    modification time."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if worker_id != "master" else base) / "compliance-results"
    folder.mkdir(exist_ok=True)
    memory: dict[str, list[Problem]] = {}

    def results(path: Path) -> list[Problem]:
        stat = path.stat()
        where = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:12]
        key = f"{path.name}-{stat.st_size}-{stat.st_mtime_ns}-{where}"
        if key in memory:
            return memory[key]
        with open(folder / f"{key}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            stored = folder / f"{key}.json"
            if stored.is_file():
                problems = [Problem(**p) for p in json.loads(stored.read_text())]
            else:
                problems = check_fmu(path)
                partial = stored.with_suffix(".part")
                partial.write_text(json.dumps([asdict(p) for p in problems]))
                os.replace(partial, stored)
        memory[key] = problems
        return problems

    return results


@pytest.fixture(scope="session")
def compliance_results(built_fmus, checked_once):
    """identifier -> problems, computed once per FMU and test run."""
    return lambda identifier: checked_once(built_fmus[identifier].path)


@pytest.fixture(scope="session")
def broken_fmu(tmp_path_factory) -> Path:
    """tests/compliance/broken_train.py built as an FMU (plain pythonfmu, planted faults)."""
    from pythonfmu.builder import FmuBuilder

    dest = tmp_path_factory.mktemp("broken") / "BrokenTrain.fmu"
    return Path(FmuBuilder.build_FMU(HERE / "broken_train.py", dest=dest))


@pytest.fixture(scope="session")
def broken_results(broken_fmu):
    # a short call limit: the planted (blocked) hang costs twice this much of a free core once
    return check_fmu(broken_fmu, Options(call_timeout=1.0))
