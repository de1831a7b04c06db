"""Shared fixtures of the suite, for ``tests/`` and each paper's ``papers/NAME/tests/`` (the
rootdir's conftest, so a run of either folder alone sees them too): FMUs are built once per
session (only those missing or out of date), the native FMUs once per test run. The shared test
helpers are modules of ``tests/`` (``from tests.claim_rows import claim_row``)."""

from __future__ import annotations

import fcntl
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from cosim.build.python import build_stale, catalog


@pytest.fixture(scope="session")
def built_fmus() -> dict:
    """Every catalog FMU, built and up to date: identifier -> FmuSpec (``.path``)."""
    build_stale()
    return catalog()


@pytest.fixture(scope="session")
def built_fmus_fmi3(built_fmus) -> dict:
    """Every catalog FMU's FMI 3.0 build, up to date: identifier -> FmuSpec (``.path_fmi3``)."""
    build_stale(fmi_version=3)
    return built_fmus



@pytest.fixture(scope="session")
def native_builds(tmp_path_factory, worker_id) -> Callable[[str], dict[int, Path]]:
    """identifier -> {FMI version: path} of its native FMUs (Linux binaries, both FMI
    versions), built once per test run: the first pytest-xdist worker to ask builds them under
    a file lock in the run's temporary folder, the others find them there. Skips where gcc is
    absent."""
    from cosim.build.native import FMI_VERSIONS, build_natives, native_path

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    base = tmp_path_factory.getbasetemp()
    dest = (base.parent if worker_id != "master" else base) / "native-builds"
    dest.mkdir(exist_ok=True)

    def get(identifier: str) -> dict[int, Path]:
        done = dest / f"{identifier}.done"
        with open(dest / f"{identifier}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not done.is_file():
                build_natives(identifier, FMI_VERSIONS, dest, windows=False)
                done.touch()
        return {version: native_path(identifier, version, dest) for version in FMI_VERSIONS}

    return get
