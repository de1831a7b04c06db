"""Compiled plant kernels (plants/kernels.py, numba) against the numpy reference paths.

Both paths integrate the same equations on the same sub-step grid; they differ only in rounding:
the coupler system is solved by the Thomas algorithm instead of a product with the cached dense
inverse, sums run in another order, and numpy may use its own SIMD ``pow``. Per sub-step the
speeds then differ by at most the matvec rounding bound ``(n + 8) eps |v|_max`` (``n``
vehicles: a length-``n`` dot product, plus a few roundings of the Thomas sweep), the
pressures by a few ulps of ``p_max`` (two ``pow`` per update), and the dynamics are stable
(trapezoidal couplers, dissipative resistance), so these add up over the sub-steps:
``tol_v = n_sub (n + 8) eps |v|_max``; positions take their own ulps plus the integral of the
speed error, ``tol_x = n_sub 2 eps |x|_max + T tol_v``. States are drawn away from the
non-smooth points (standstill regularisation, electric-brake fade), where a rounding-level
difference could be amplified by ``1 / stiction_speed``.
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cosim.fmu.state import to_ticks
from plants import kernels
from plants.freight import FreightParams, FreightTrain
from plants.route import load_route

pytestmark = pytest.mark.skipif(not kernels.KERNELS, reason="numba not installed")
EPS = np.finfo(float).eps
COMM = 0.2


def random_state(train: FreightTrain, rng: np.random.Generator) -> dict:
    """A moving train in the middle of the route with brake-pipe commands still travelling."""
    n = train.x.size
    state = train.get_state()
    t0 = 300.0
    state["t_ticks"] = to_ticks(t0)
    state["v"] = rng.uniform(8.0, 22.0) + rng.uniform(-0.05, 0.05, n)
    state["x"] = state["x"] + rng.uniform(3000.0, 15000.0) + rng.uniform(-0.01, 0.01, n)
    state["pressure"] = rng.uniform(0.0, train.p.max_cylinder_pressure, n)
    state["traction_force"] = rng.uniform(-3e5, 5e5)
    state["traction_history"] = [[-(2**62), 0.0], [to_ticks(t0 - 0.3), rng.uniform(-4e5, 6e5)]]
    state["brake_history"] = [[t0 - 30.0, 0.0], [t0 - 4.0, rng.uniform(60e3, 150e3)],
                              [t0 - 1.0, rng.uniform(0.0, 40e3)]]
    return state


@pytest.mark.parametrize("slack", [0.0, 0.05])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_freight_kernel_matches_the_numpy_reference(seed: int, slack: float) -> None:
    params = FreightParams(coupler_slack=slack)
    route = load_route("freight_20km")
    fast = FreightTrain(params, route, kernel=True)
    ref = FreightTrain(params, route, kernel=False)
    assert fast.kernel and not ref.kernel
    rng = np.random.default_rng(seed)
    state = random_state(ref, rng)
    fast.set_state(state)
    ref.set_state(state)
    steps = 12
    t = state["t_ticks"]
    peaks = []
    for _ in range(steps):
        inputs = {"force_demand": float(rng.uniform(-4e5, 6e5)),
                  "pipe_reduction": float(rng.choice([0.0, 30e3, 80e3, 140e3]))}
        for train in (fast, ref):
            train.advance(t, to_ticks(COMM), inputs)
        peaks.append((fast.peak_draft - ref.peak_draft, fast.peak_buff - ref.peak_buff))
        t += to_ticks(COMM)
    n, n_sub, duration = ref.x.size, steps * round(COMM / params.max_step), steps * COMM
    tol_v = n_sub * (n + 8) * EPS * np.max(np.abs(ref.v))
    tol_x = n_sub * 2 * EPS * np.max(np.abs(ref.x)) + duration * tol_v
    tol_p = n_sub * 4 * EPS * params.max_cylinder_pressure
    np.testing.assert_allclose(fast.v, ref.v, rtol=0, atol=tol_v)
    np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=tol_x)
    np.testing.assert_allclose(fast.pressure, ref.pressure, rtol=0, atol=tol_p)
    # forces from the state: couplers k gap + c dv, traction (power limit P / v^2 per m/s)
    tol_f = params.coupler_stiffness * 2 * tol_x + params.coupler_damping * 2 * tol_v
    assert np.max(np.abs(peaks)) <= tol_f
    v_min = np.min(np.abs(ref.v))
    tol_trac = n_sub * 4 * EPS * params.max_traction_force \
        + params.max_traction_power / v_min**2 * tol_v
    assert abs(fast.traction_force - ref.traction_force) <= tol_trac
    assert abs(fast.energy - ref.energy) <= (n_sub * 4 * EPS * abs(ref.energy)
                                             + params.max_traction_force * duration * tol_v
                                             + tol_trac * duration * np.max(np.abs(ref.v)))
    assert abs(fast.accel - ref.accel) <= 2 * tol_v / params.max_step
    assert fast.brake_history == ref.brake_history
    assert fast.outputs().keys() == ref.outputs().keys()
    # the reference does something: the trains moved and braked
    assert np.max(np.abs(ref.x - state["x"])) > 10.0
    assert np.ptp(ref.pressure) > 1e3


@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
@pytest.mark.parametrize("case", ["cruise", "brake wave"])
def test_c_kernel_matches_numba(case: str, tmp_path) -> None:
    """The C version of the freight kernel (cosim/fmu/native/plants/freight_kernel.c, the kernel of
    the native FreightTrain FMU, measured against numba in
    benchmarks/bench_kernels.py) stays the same kernel: same operations in the same order, so
    they differ at most by libm's pow/exp roundings, bounded as against the numpy path."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        import bench_kernels
    finally:
        sys.path.pop(0)
    dll = bench_kernels.build_c(tmp_path)
    _, args = bench_kernels.captured_args(case)
    ours, theirs = (tuple(np.copy(a) for a in args) for _ in range(2))
    kernels.freight_steps(*ours)
    bench_kernels.c_call(dll, theirs)()
    x, v, pres, sc = ours[:4]
    n, n_sub = x.size, args[4].size
    tol_v = n_sub * (n + 8) * EPS * np.max(np.abs(v))
    np.testing.assert_allclose(theirs[1], v, rtol=0, atol=tol_v)
    np.testing.assert_allclose(theirs[0], x, rtol=0, atol=n_sub * 2 * EPS * np.max(np.abs(x))
                               + n_sub * 0.01 * tol_v)
    np.testing.assert_allclose(theirs[2], pres, rtol=0, atol=n_sub * 4 * EPS * 360e3)
    assert theirs[3][kernels.S_FIRST] == sc[kernels.S_FIRST]
    assert np.max(np.abs(v - args[1])) > 1e-3  # the step did something
    if case == "brake wave":
        assert np.max(np.abs(pres - args[2])) > 1e3


def test_cache_locator_is_by_content(tmp_path, monkeypatch) -> None:
    """Compiled code is found by the digest of kernels.py, wherever the file was extracted."""
    assert kernels.compile_kernels()
    monkeypatch.setenv("ATO_COSIM_NUMBA_CACHE", str(tmp_path))
    assert kernels.cache_dir() == tmp_path
    locator = kernels._ContentCacheLocator.from_function(kernels.freight_steps.py_func,
                                                         kernels.__file__)
    assert locator is not None
    assert locator.get_cache_path() == str(tmp_path / kernels._DIGEST)
    assert locator.get_source_stamp() == kernels._DIGEST
    other = kernels._ContentCacheLocator.from_function(len, str(tmp_path / "elsewhere.py"))
    assert other is None  # other files keep numba's own locators


def test_importing_the_plants_does_not_import_numba() -> None:
    """numba (about a second) is imported when a plant is built, not by the catalog."""
    import subprocess
    import sys

    code = ("import sys, plants.freight, plants.emu, controllers.pid.freight_pid; "
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(kernels.__file__).resolve().parents[1])
    assert out.stdout.strip() == "False"


def test_prune_cache_removes_only_stale_digest_folders(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("ATO_COSIM_NUMBA_CACHE", str(tmp_path))
    old = time.time() - 30 * 86400.0

    def folder(name: str, files: tuple[str, ...], mtime: float) -> Path:
        path = tmp_path / name
        path.mkdir()
        for f in files:
            (path / f).write_bytes(b"")
            os.utime(path / f, (mtime, mtime))
        os.utime(path, (mtime, mtime))
        return path

    cache_files = ("kernels.freight_steps-1.py311.nbi", "kernels.freight_steps-1.py311.1.nbc")
    stale = folder("0123456789abcdef0123", cache_files, old)
    recent = folder("fedcba9876543210fedc", cache_files, time.time())
    current = folder(kernels._DIGEST, cache_files, old)
    foreign = folder("00000000000000000000", ("notes.txt",), old)
    other_name = folder("my-numba-stuff", cache_files, old)
    assert kernels.prune_cache(keep_days=7.0) == [stale]
    assert not stale.exists()
    assert recent.exists() and current.exists() and foreign.exists() and other_name.exists()


def emu_pair(config: str, seed: int):
    from plants.emu import Emu, emu_config

    params = emu_config(config, disturbance_accel_std=0.05, disturbance_interval=0.2,
                        disturbance_seed=seed)
    route = load_route("jinan_xuzhou_east")
    rng = np.random.default_rng(seed)
    v0, s0 = rng.uniform(20.0, 80.0), rng.uniform(5e3, 2e5)
    fast, ref = (Emu(params, route, v0=v0, s0=s0, kernel=k) for k in (True, False))
    state = ref.get_state()
    state["x"] = state["x"] + rng.uniform(-0.01, 0.01, params.n)
    state["v"] = state["v"] + rng.uniform(-0.05, 0.05, params.n)
    fast.set_state(state)
    ref.set_state(state)
    return params, fast, ref, rng


@pytest.mark.parametrize("config", ["crh380a_3unit", "crh3_8car"])
@pytest.mark.parametrize("seed", [0, 1])
def test_emu_kernel_matches_the_numpy_reference(config: str, seed: int) -> None:
    """Tolerance: both paths round the exact-propagator products ``phi s + gamma f`` (length
    ``3n`` sums) within ``3n eps (|phi| |s| + |gamma| |f|)`` per sub-step (the coupler rows of
    ``phi`` are big, ``k h / m``, and act on absolute positions); these add up over the
    sub-steps. ``|f|`` is bounded by the envelope, resistance, 5 % grade and 6 sigma noise."""
    params, fast, ref, rng = emu_pair(config, seed)
    assert fast.kernel and not ref.kernel
    n, steps = params.n, 25
    x_start = ref.x.copy()
    t = ref.t_ticks
    for _ in range(steps):
        level = rng.uniform(-1.5e5, 2.5e5)
        inputs = {f"force[{i + 1}]": level * (1 + 0.1 * rng.standard_normal()) for i in range(n)}
        for train in (fast, ref):
            train.advance(t, to_ticks(COMM), inputs)
        t += to_ticks(COMM)
    n_sub = steps * round(COMM / params.max_step)
    prop = ref._propagator(to_ticks(params.max_step))
    v_max = float(np.max(np.abs(ref.v))) + 1.0
    f_max = (np.maximum(ref.ft, ref.fb) + ref.da + ref.db * v_max + ref.dc * v_max**2
             + ref.m * 9.81 * (0.05 + 6 * 0.05))
    s_max = np.concatenate([np.full(n, np.max(np.abs(ref.x)) + 1e3), np.full(n, v_max)])
    per_step = 3 * n * EPS * (np.abs(prop.phi) @ s_max + np.abs(prop.gamma) @ f_max)
    tol = 2 * n_sub * per_step
    tol_x, tol_v = tol[:n], tol[n:]
    np.testing.assert_allclose(fast.x, ref.x, rtol=0, atol=np.max(tol_x))
    np.testing.assert_allclose(fast.v, ref.v, rtol=0, atol=np.max(tol_v))
    assert fast.held == ref.held
    duration = steps * COMM
    for name in ("traction_energy", "regenerated_energy"):
        energy_tol = (n_sub * 2 * n * EPS * abs(getattr(ref, name))
                      + np.sum(f_max) * duration * np.max(tol_v))
        assert abs(getattr(fast, name) - getattr(ref, name)) <= energy_tol
    out_fast, out_ref = fast.outputs(), ref.outputs()
    assert out_fast.keys() == out_ref.keys()
    tol_fz = params.coupler_stiffness * 2 * np.max(tol_x) + params.coupler_damping * 2 * np.max(
        tol_v)
    for j in range(n - 1):
        name = f"coupler_force[{j + 1}]"
        assert abs(out_fast[name] - out_ref[name]) <= tol_fz
    tol_a = 2 * tol_fz / np.min(ref.m_eff) + 1e-9  # + forces' own dependence (Lipschitz, tiny)
    for i in range(n):
        assert abs(out_fast[f"a[{i + 1}]"] - out_ref[f"a[{i + 1}]"]) <= tol_a + 2 * np.max(
            tol_v) * np.max((ref.db + 2 * ref.dc * v_max) / ref.m_eff)
        # limits P / v: d/dv = -P / v^2
        tol_limit = np.max(np.maximum(ref.pt, ref.pb)) / np.min(np.abs(ref.v))**2 * tol_v[i]
        for name, bound in (("v", tol_v[i]), ("s", tol_x[i]), ("applied_force", tol_limit),
                            ("traction_limit", tol_limit), ("brake_limit", tol_limit)):
            key = f"{name}[{i + 1}]"
            assert abs(out_fast[key] - out_ref[key]) <= bound, key
    assert np.max(np.abs(ref.x - x_start)) > 50.0  # it moved


def _planted(folder, kind: str) -> None:
    """Poison every numba cache file in ``folder``: truncated, garbage or '<dynamic>'."""
    for entry in sorted(folder.iterdir()):
        data = entry.read_bytes()
        if kind == "truncated" and entry.suffix == ".nbc":
            entry.write_bytes(data[:50])
        elif kind == "garbage" and entry.suffix == ".nbi":
            entry.write_bytes(b"garbage\n")
        elif kind == "dynamic" and entry.suffix == ".nbi":
            entry.write_bytes(data + b"<dynamic>")


def test_unloadable_cache_entries_are_found_and_discarded(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("ATO_COSIM_NUMBA_CACHE", str(tmp_path))
    folder = tmp_path / kernels._DIGEST
    folder.mkdir()
    (folder / "kernels._affine-x.py311.nbi").write_bytes(b"\x80\x04 index")
    (folder / "kernels._affine-x.py311.1.nbc").write_bytes(b"\x80\x04 data")
    (folder / "notes.txt").write_text("not numba's")
    assert kernels._cache_entries_valid()
    _planted(folder, "dynamic")
    assert not kernels._cache_entries_valid()
    (folder / "kernels._affine-x.py311.nbi").write_bytes(b"")
    assert not kernels._cache_entries_valid()
    kernels._discard_cache()
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    assert kernels._cache_entries_valid()


# kernels.py loaded from its file as plants.kernels, then no longer importable by that name
# (an FMU's bundle leaves sys.path): the kernels must compile or load, whatever the cache holds
_OUTSIDE = """
import importlib.util, math, sys
spec = importlib.util.spec_from_file_location("plants.kernels", sys.argv[1])
mod = importlib.util.module_from_spec(spec)
sys.modules["plants.kernels"] = mod
spec.loader.exec_module(mod)
del sys.modules["plants.kernels"]
assert "plants" not in sys.modules
assert mod.compile_kernels() is True
assert hasattr(mod._pow, "py_func")  # compiled, not the Python function
assert abs(mod._pow(2.0, 0.5) - math.sqrt(2.0)) < 1e-15
print("ok")
"""


@pytest.mark.slow
@pytest.mark.skipif(not kernels.KERNELS, reason="numba not installed")
def test_a_poisoned_cache_never_fails_the_kernels(tmp_path) -> None:
    """A truncated, garbled or '<dynamic>' cache (what a host without the package importable
    once wrote) is discarded and rebuilt; the next process loads the rebuilt one. The
    processes run without this repository on sys.path (numba installed, package not)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["ATO_COSIM_NUMBA_CACHE"] = str(tmp_path)
    script = tmp_path / "outside.py"
    script.write_text(_OUTSIDE)

    def run() -> None:
        done = subprocess.run([sys.executable, str(script), kernels.__file__], env=env,
                              cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]

    run()  # compiles into the empty cache
    folder = tmp_path / kernels._DIGEST
    assert any(p.suffix == ".nbc" for p in folder.iterdir())
    for kind in ("truncated", "garbage", "dynamic"):
        _planted(folder, kind)
        run()
        assert kernels._cache_entries_valid()


def test_shoe_friction_is_one_law_written_once():
    """TB/T 1407's phi = 0.322 (v + 150) / (2 v + 150): its values, and one definition that
    the plant's numpy path, the blending and the compiled kernels all call."""
    from pathlib import Path

    from plants.freight import KMH, friction_coefficient, friction_coefficient_at
    from plants.kernels import shoe_friction

    assert shoe_friction(0.0) == 0.322
    assert shoe_friction(150.0) == pytest.approx(0.322 * 300.0 / 450.0, rel=1e-15)
    assert friction_coefficient_at(-150.0 * KMH) == shoe_friction(150.0 * KMH / KMH)
    assert friction_coefficient(np.array([150.0 * KMH]))[0] == friction_coefficient_at(150 * KMH)
    root = Path(__file__).resolve().parent.parent
    writers = [p.relative_to(root).as_posix() for part in ("plants", "controllers")
               for p in (root / part).rglob("*.py") if "0.322 *" in p.read_text()]
    assert writers == ["plants/kernels.py"]
