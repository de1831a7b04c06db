"""The freight sub-step kernel: numba vs the same kernel in C vs the numpy reference.

Issue 10 item 1 asks to measure a numba kernel and a C kernel built with gcc on the freight
plant, choose one and say why. ``cosim/fmu/native/plants/freight_kernel.c`` is
:func:`plants.kernels.freight_steps` line by line in C (same operations in the same order,
``-O2 -ffp-contract=off``, no fast-math); it is compiled here into a temporary folder and called
through ctypes on the arguments the plant passes to the numba kernel in one communication
step (captured from :meth:`plants.freight.FreightTrain.advance`). Both run from the same
state on the same inputs; the figure is the time per 0.01 s sub-step (median over repeated
calls, each 20 sub-steps from the same state), and the results of the two are compared (max
relative difference of x, v, pressures and scalars; same operations, so 0 is expected).

Cases: ``cruise`` (brakes released, one pipe command: the common case of the closed loop) and
``brake wave`` (brake-pipe commands still travelling along the train, per-vehicle arrivals).

Numba is the Python plant's production path. On identical inputs the two kernels perform the
same IEEE operations in the same order with the same libm ``pow``/``exp``, so they give
identical results (tests/test_kernels.py); their speed ratio is what this benchmark measures
(docs/benchmarks.md). What decides between them:

* build step: numba needs none (compiled on first use, kept in an on-disk cache keyed by the
  kernel's content, so an FMU extracted to a fresh folder loads it); C needs gcc at
  ``cosim build`` and a binary per platform inside every plant FMU;
* portability: numba ships wheels for Linux, macOS and Windows on x86-64 and arm64 and
  compiles for the host CPU; a C kernel must be built (or cross-built) for each target;
* FMU without Python: the C kernel is a self-contained function. The C
  file, tested equal to the numba kernel (``tests/test_kernels.py``), is the kernel of the
  native FreightTrain FMU (``cosim/fmu/native/plants/freight.c``, ``docs/native_fmus.md``), where
  that port is done.

    python benchmarks/bench_kernels.py [--repeat 2000]
"""

from __future__ import annotations

import argparse
import ctypes
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from cosim.build.native import native_file  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from plants import kernels  # noqa: E402
from plants.freight import FreightParams, FreightTrain  # noqa: E402
from plants.route import load_route  # noqa: E402

C_SOURCE = native_file("freight_kernel.c")  # cosim/fmu/native/plants/
COMM = 0.2  # s, one communication step = 20 sub-steps of 0.01 s
GCC_FLAGS = ["-O2", "-fPIC", "-shared", "-ffp-contract=off"]


def build_c(out_dir: Path) -> ctypes.CDLL:
    """Compile the C kernel with gcc into ``out_dir`` and load it."""
    lib = out_dir / "freight_kernel.so"
    subprocess.run(["gcc", *GCC_FLAGS, "-o", str(lib), str(C_SOURCE), "-lm"], check=True)
    dll = ctypes.CDLL(str(lib))
    dll.freight_steps.restype = None
    return dll


def case_state(train: FreightTrain, case: str, seed: int = 0) -> dict:
    """A moving train mid-route; ``brake wave``: pipe commands still travelling."""
    rng = np.random.default_rng(seed)
    n = train.x.size
    state = train.get_state()
    t0 = 300.0
    state["t_ticks"] = to_ticks(t0)
    state["v"] = rng.uniform(12.0, 20.0) + rng.uniform(-0.05, 0.05, n)
    state["x"] = state["x"] + 8000.0 + rng.uniform(-0.01, 0.01, n)
    state["traction_force"] = 2e5
    state["traction_history"] = [[-(2**62), 2e5]]
    if case == "brake wave":
        state["pressure"] = rng.uniform(0.0, train.p.max_cylinder_pressure, n)
        state["brake_history"] = [[t0 - 30.0, 0.0], [t0 - 4.0, 120e3], [t0 - 1.0, 20e3]]
    return state


def captured_args(case: str) -> tuple[FreightTrain, tuple]:
    """The numba kernel's arguments for one communication step of ``case`` (copies)."""
    train = FreightTrain(FreightParams(), load_route("freight_20km"), kernel=True)
    train.set_state(case_state(train, case))
    seen: list[tuple] = []
    real = kernels.freight_steps
    kernels.freight_steps = lambda *args: seen.append(tuple(np.copy(a) for a in args))
    try:
        train.advance(train.t_ticks, to_ticks(COMM), {"force_demand": 3e5, "pipe_reduction":
                                                      train.brake_history[-1][1]})
    finally:
        kernels.freight_steps = real
    return train, seen[0]


def c_call(dll: ctypes.CDLL, args: tuple):
    """A call of the C kernel on numba-kernel arguments (arrays updated in place), with the
    ctypes arguments converted once (as a C-FMU or a cached wrapper would)."""
    x, hs, values, xs = args[0], args[4], args[9], args[17]
    targets = np.empty(values.size)
    i64 = ctypes.c_int64
    converted = (i64(x.size), i64(hs.size), i64(values.size), i64(xs.size),
                 *(a.ctypes.data_as(ctypes.c_void_p) for a in (*args, targets)))
    return lambda: dll.freight_steps(*converted)


def _timed(prepare, fresh, repeat: int) -> float:
    """Median seconds of the call ``prepare(args)`` returns, on fresh arguments each time."""
    times = []
    for _ in range(repeat):
        call = prepare(fresh())
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def compare(case: str, repeat: int, dll: ctypes.CDLL) -> dict:
    """Figures and the agreement of numba and C on one case."""
    train, args = captured_args(case)
    n_sub = args[4].size

    def fresh() -> tuple:
        return tuple(np.copy(a) for a in args)

    numba_args, c_args = fresh(), fresh()
    kernels.freight_steps(*numba_args)
    c_call(dll, c_args)()
    diff = 0.0
    for a, b in zip(numba_args[:4], c_args[:4]):
        scale = np.maximum(np.abs(a), np.finfo(float).tiny)
        diff = max(diff, float(np.max(np.abs(a - b) / scale)))
    numba_s = _timed(lambda a: lambda: kernels.freight_steps(*a), fresh, repeat)
    c_s = _timed(lambda a: c_call(dll, a), fresh, repeat)
    # the numpy reference from the same state over the same communication step
    ref = FreightTrain(FreightParams(), load_route("freight_20km"), kernel=False)
    state = case_state(ref, case)
    numpy_times = []
    with threadpool_limits(1):  # one BLAS thread: the 109 x 109 matvec gains nothing from two
        for _ in range(max(3, repeat // 200)):
            ref.set_state(state)
            inputs = {"force_demand": 3e5, "pipe_reduction": ref.brake_history[-1][1]}
            t0 = time.perf_counter()
            ref.advance(ref.t_ticks, to_ticks(COMM), inputs)
            numpy_times.append(time.perf_counter() - t0)
    return {"case": case, "vehicles": int(args[0].size), "substeps": int(n_sub),
            "numba_us_per_substep": numba_s / n_sub * 1e6,
            "c_us_per_substep": c_s / n_sub * 1e6,
            "numpy_us_per_substep": statistics.median(numpy_times) / n_sub * 1e6,
            "c_over_numba": c_s / numba_s,
            "max_rel_diff_numba_c": diff}


def run(repeat: int = 2000) -> list[dict]:
    """Both cases; gcc and numba are needed (returns [] without them)."""
    if not kernels.KERNELS or shutil.which("gcc") is None:
        return []
    with tempfile.TemporaryDirectory() as tmp:
        dll = build_c(Path(tmp))
        return [compare(case, repeat, dll) for case in ("cruise", "brake wave")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2000)
    args = parser.parse_args()
    for row in run(args.repeat):
        print(f"{row['case']:>10}: numba {row['numba_us_per_substep']:6.2f} us/sub-step, "
              f"C (gcc {' '.join(GCC_FLAGS[:1])}) {row['c_us_per_substep']:6.2f}, "
              f"numpy reference {row['numpy_us_per_substep']:6.1f}; C / numba "
              f"{row['c_over_numba']:.2f}; max rel. diff numba-C "
              f"{row['max_rel_diff_numba_c']:.1e}")


if __name__ == "__main__":
    main()
