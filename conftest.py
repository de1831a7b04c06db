"""Shared fixtures of the suite, for ``tests/`` and each paper's ``papers/NAME/tests/`` (the
rootdir's conftest, so a run of either folder alone sees them too): FMUs are built once per
session (only those missing or out of date), the native FMUs and the C hosts once per test run.
The shared test helpers are modules of ``tests/`` (``from tests.claim_rows import claim_row``)."""

from __future__ import annotations

import contextlib
import fcntl
import shutil
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from cosim.build.python import build_stale, catalog


@pytest.fixture(scope="session")
def built_fmus(tmp_path_factory, worker_id) -> dict:
    """Every catalog FMU, built and up to date: identifier -> FmuSpec (``.path``). The
    pytest-xdist workers build in turn, under a file lock of the run: the first builds what is
    stale, the next finds it current (instead of every worker building the same FMUs at once
    in a fresh clone)."""
    with _run_lock(tmp_path_factory, worker_id, "build-stale"):
        build_stale()
    return catalog()


@pytest.fixture(scope="session")
def built_fmus_fmi3(built_fmus, tmp_path_factory, worker_id) -> dict:
    """Every catalog FMU's FMI 3.0 build, up to date: identifier -> FmuSpec (``.path_fmi3``),
    built in turn by the workers as :func:`built_fmus`."""
    with _run_lock(tmp_path_factory, worker_id, "build-stale-fmi3"):
        build_stale(fmi_version=3)
    return built_fmus


def _run_lock(tmp_path_factory, worker_id: str,
              name: str) -> contextlib.AbstractContextManager[None]:
    """An exclusive file lock ``name`` held across the pytest-xdist workers of this run."""
    return _locked(_run_folder(tmp_path_factory, worker_id, "locks"), name)


@contextlib.contextmanager
def _locked(folder: Path, name: str) -> Iterator[None]:
    """Hold the exclusive file lock ``folder/name.lock`` (across processes)."""
    with open(folder / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _run_folder(tmp_path_factory, worker_id: str, name: str) -> Path:
    """A folder ``name`` shared by every pytest-xdist worker of this test run."""
    base = tmp_path_factory.getbasetemp()
    dest = (base.parent if worker_id != "master" else base) / name
    dest.mkdir(exist_ok=True)
    return dest


# the C hosts of tests/c_host: executable -> (source, libraries); fmu_host needs no libm
C_HOSTS = {"fmu_host": ("fmu_host.c", ["-ldl"]), "fmu3_host": ("fmu3_host.c", ["-ldl", "-lm"])}


@pytest.fixture(scope="session")
def c_hosts(tmp_path_factory, worker_id) -> Callable[[str], Path]:
    """executable name -> path of a C host of tests/c_host (``fmu_host``: FMI 2,
    ``fmu3_host``: FMI 3) for Linux, compiled against fmpy's FMI headers with ``gcc -std=c99
    -D_DEFAULT_SOURCE -Wall -Wextra -Werror -O1`` once per test run: the first pytest-xdist
    worker to ask compiles it under a file lock in the run's temporary folder, the others
    find it there. Skips where gcc is absent."""
    import fmpy

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    dest = _run_folder(tmp_path_factory, worker_id, "c-hosts")
    headers = Path(fmpy.__file__).parent / "c-code"
    sources = Path(__file__).resolve().parent / "tests" / "c_host"

    def get(exe: str) -> Path:
        source, libraries = C_HOSTS[exe]
        with _locked(dest, exe):
            if not (dest / f"{exe}.done").is_file():
                done = subprocess.run(
                    ["gcc", "-std=c99", "-D_DEFAULT_SOURCE", "-Wall", "-Wextra", "-Werror",
                     "-O1", f"-I{headers}", "-o", str(dest / exe), str(sources / source),
                     *libraries], capture_output=True, text=True)
                assert done.returncode == 0, f"gcc {source}:\n{done.stderr}"
                (dest / f"{exe}.done").touch()
        return dest / exe

    return get


@pytest.fixture(scope="session")
def native_builds(tmp_path_factory, worker_id) -> Callable[[str], dict[int, Path]]:
    """identifier -> {FMI version: path} of its native FMUs (Linux binaries, both FMI
    versions), built once per test run: the first pytest-xdist worker to ask builds them under
    a file lock in the run's temporary folder, the others find them there. Skips where gcc is
    absent."""
    from cosim.build.native import FMI_VERSIONS, build_natives, native_path

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    dest = _run_folder(tmp_path_factory, worker_id, "native-builds")

    def get(identifier: str) -> dict[int, Path]:
        done = dest / f"{identifier}.done"
        with _locked(dest, identifier):
            if not done.is_file():
                build_natives(identifier, FMI_VERSIONS, dest, windows=False)
                done.touch()
        return {version: native_path(identifier, version, dest) for version in FMI_VERSIONS}

    return get
