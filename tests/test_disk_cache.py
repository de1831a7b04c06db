"""The on-disk design cache (cosim.fmu.disk_cache) and the bytecode bundled into FMUs."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.fmu import disk_cache
from cosim.fmu.disk_cache import cached_arrays

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "designs"


def counting(result):
    calls = []

    def compute():
        calls.append(1)
        return result
    return compute, calls


def test_second_call_loads_the_same_floats(cache):
    rng = np.random.default_rng(3)
    a = rng.standard_normal((4, 4))
    out = (a @ a.T, np.linspace(0.0, 1.0, 7) / 3.0)
    compute, calls = counting(out)
    first = cached_arrays("t", "v1", [a, 0.2], compute)
    again = cached_arrays("t", "v1", [a, 0.2], compute)
    assert len(calls) == 1
    for x, y, z in zip(out, first, again, strict=True):
        assert x.tobytes() == y.tobytes() == z.tobytes()  # exact round trip, same dtype
    assert len(list(cache.glob("t-*.npz"))) == 1


@pytest.mark.parametrize("change", ["input", "scalar", "version", "kind"])
def test_any_change_of_the_key_computes_again(cache, change):
    a = np.eye(3)
    compute, calls = counting((np.ones(2),))
    cached_arrays("t", "v1", [a, 0.2], compute)
    b = a.copy()
    b[1, 2] = np.nextafter(0.0, 1.0)  # one ulp away
    args = {"input": ("t", "v1", [b, 0.2]), "scalar": ("t", "v1", [a, 0.2 + 2**-52]),
            "version": ("t", "v2", [a, 0.2]), "kind": ("u", "v1", [a, 0.2])}[change]
    cached_arrays(*args, compute)
    assert len(calls) == 2


def test_off_and_unwritable_and_damaged(tmp_path, monkeypatch):
    compute, calls = counting((np.arange(3.0),))
    monkeypatch.setenv("ATO_COSIM_CACHE", "off")
    cached_arrays("t", "v", [1.0], compute)
    cached_arrays("t", "v", [1.0], compute)
    assert len(calls) == 2
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("ATO_COSIM_CACHE", str(blocker))  # mkdir fails: computed, no error
    assert cached_arrays("t", "v", [1.0], compute)[0].tolist() == [0.0, 1.0, 2.0]
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path / "c"))
    cached_arrays("t", "v", [1.0], compute)
    (damaged,) = (tmp_path / "c" / "designs").glob("*.npz")
    damaged.write_bytes(b"garbage")
    assert cached_arrays("t", "v", [1.0], compute)[0].tolist() == [0.0, 1.0, 2.0]
    assert len(calls) == 5
    assert not list((tmp_path / "c" / "designs").glob("*.tmp"))


def test_failures_are_not_stored(cache):
    def fails():
        raise ValueError("empty set")
    for _ in range(2):
        with pytest.raises(ValueError, match="empty set"):
            cached_arrays("t", "v", [1.0], fails)
    assert not cache.exists() or not list(cache.iterdir())


def test_pruning_keeps_the_most_recent(cache, monkeypatch):
    monkeypatch.setattr(disk_cache, "MAX_FILES", 3)
    for i in range(5):
        cached_arrays("t", "v", [float(i)], lambda: (np.zeros(1),))
        newest = max(cache.glob("*.npz"), key=os.path.getmtime)
        os.utime(newest, (1e9 + i, 1e9 + i))  # distinct, increasing use times
    assert len(list(cache.glob("*.npz"))) == 3


def test_key_rejects_objects():
    with pytest.raises(TypeError, match="cannot key"):
        disk_cache._digest("t", "v", [object()])


def test_tube_mpc_design_warm_equals_cold_without_scipy(tmp_path):
    """A fresh process builds the RMPC core twice with the cache at tmp_path: the first
    computes (scipy imported), the second loads the same DARE solution, ZOH model and terminal
    set without importing scipy at all."""
    code = (
        "import sys, hashlib\n"
        "from controllers.mpc.stop_mpc import StopMpcParams, TubeStopMpc\n"
        "core = TubeStopMpc(StopMpcParams())\n"
        "h = hashlib.sha256()\n"
        "for a in (core.model.A, core.model.b, core.P, core.K, core.F_term, core.h_term):\n"
        "    h.update(a.tobytes())\n"
        "print(h.hexdigest(), any(m == 'scipy' or m.startswith('scipy.') for m in sys.modules))\n"
    )
    env = {**os.environ, "ATO_COSIM_CACHE": str(tmp_path),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    runs = [subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True,
                           text=True, check=True).stdout.split() for _ in range(2)]
    (cold_hash, cold_scipy), (warm_hash, warm_scipy) = runs
    assert cold_hash == warm_hash
    assert cold_scipy == "True" and warm_scipy == "False"


def test_fmu_carries_checked_hash_bytecode():
    """Every bundled module has a pyc for this interpreter whose PEP 552 header says
    'checked hash' and whose hash is the bundled source's."""
    from cosim.build.python import build_stale, catalog

    spec = catalog()["StopRmpc"]
    build_stale([spec])
    with zipfile.ZipFile(spec.path) as z:
        names = set(z.namelist())
        sources = [n for n in names if n.startswith("resources/atocosim_bundle/")
                   and n.endswith(".py")]
        assert sources
        tag = sys.implementation.cache_tag
        for src in sources:
            folder, _, file = src.rpartition("/")
            pyc = f"{folder}/__pycache__/{file[:-3]}.{tag}.pyc"
            assert pyc in names, pyc
            header = z.read(pyc)[:16]
            assert header[:4] == importlib.util.MAGIC_NUMBER
            assert int.from_bytes(header[4:8], "little") == 0b11  # hash-based, checked
            assert header[8:16] == importlib.util.source_hash(z.read(src))


def test_a_build_found_current_is_checked_again_once_it_or_a_project_file_changes(
        tmp_path, monkeypatch):
    """A campaign asks for the same FMU once per run: a build found current is not checked
    again (stale_unless_known) until the archive or the newest project file changes; then the
    check runs and says stale where a file it bundles is newer."""
    from cosim.build import python as build

    spec = build.catalog()["StopRmpc"]
    source = tmp_path / "core.py"
    source.write_text("x = 1\n")
    monkeypatch.setattr(build, "FMU_DIR", tmp_path)
    monkeypatch.setattr(build, "bundled_files", lambda module: [source])
    monkeypatch.setattr(build, "_builder_files", lambda fmi_version: [])
    monkeypatch.setattr(build, "newest_project_file", lambda: source.stat().st_mtime)
    checks = []
    exact = build._is_stale
    monkeypatch.setattr(build, "_is_stale", lambda *a: checks.append(a) or exact(*a))
    fmu = tmp_path / "StopRmpc.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
    os.utime(source, (100, 100))
    os.utime(fmu, (200, 200))
    assert not build.is_stale(spec) and not build.is_stale(spec)
    assert len(checks) == 1  # the second answer was remembered
    os.utime(source, (300, 300))  # a project file newer than the build
    assert build.is_stale(spec) and len(checks) == 2
    os.utime(fmu, (400, 400))  # rebuilt: checked again, current
    assert not build.is_stale(spec) and len(checks) == 3
    fmu.unlink()
    assert build.is_stale(spec)


def test_is_stale_shortcut_agrees_with_the_exact_scan(tmp_path, monkeypatch):
    """The mtime shortcut (no project file newer than the FMU) never hides a stale FMU: the
    project's newest file is at least as new as any bundled one, and when it is newer than
    the FMU the exact import scan decides."""
    from cosim.build import python as build

    spec = build.catalog()["StopRmpc"]
    monkeypatch.setattr(build, "FMU_DIR", tmp_path)
    fmu = tmp_path / "StopRmpc.fmu"
    assert build.is_stale(spec)  # missing
    with zipfile.ZipFile(fmu, "w") as z:  # an intact archive: only the times decide
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
    bundled = max(f.stat().st_mtime for f in [*build.bundled_files(spec.module),
                                              Path(build.__file__)])
    newest = build.newest_project_file()
    assert newest >= bundled
    os.utime(fmu, (newest + 10, newest + 10))
    assert not build.is_stale(spec)  # shortcut
    os.utime(fmu, (bundled - 10, bundled - 10))
    assert build.is_stale(spec)
    # an unrelated file newer than the FMU: the exact scan says fresh
    monkeypatch.setattr(build, "newest_project_file", lambda: bundled + 100)
    os.utime(fmu, (bundled + 10, bundled + 10))
    assert not build.is_stale(spec)
