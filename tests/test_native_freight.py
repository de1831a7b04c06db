"""The native C FreightTrain FMU (cosim/fmu/native/plants/freight.c and freight_kernel.c behind the
FMI 2 front) against its Python core, plants.freight.FreightTrain with its compiled kernel (the path
the Python FMU runs).

Tolerance. The C files are compiled -std=c99 -ffp-contract=off (no fused multiply-add, no fast
math) and perform the core's IEEE double operations in the core's order: the train built from
the parameters, the sub-step grid, the command histories, the kernel's sub-steps (the numba
kernel's operations; its libm calls exp and pow are the glibc functions the C calls) and the
outputs. So every output is equal bit for bit but one: ``air_brake_force``, the total air-brake
force, which the core sums with numpy's dot product (BLAS: blocked, possibly fused
multiply-add, in an order of its own) and the C in index order. Its n = 109 terms
``(brake_scale_i p_i) phi_i`` are the same doubles and all >= 0, so each computed sum is within
gamma_n = n u / (1 - n u) of the exact sum S (u = 2^-53; Higham, Accuracy and Stability of
Numerical Algorithms, eq. 3.5, which covers any order and FMA), and the two differ by at most
2 gamma_n S <= 2 gamma_n / (1 - gamma_n) times either of them: 109 eps relative
(:func:`air_brake_bound`). Every other output, and every closed-loop quantity that does not
read air_brake_force (the controllers do not), is compared with ``==``.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmi_state_helpers import assert_replays_from_state
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from native_helpers import build_unzipped, initialising, open_native, variable_rows

from cosim.fmu.state import to_ticks
from cosim.run.scenario import scenario_files
from plants import kernels
from plants.freight import FreightTrain

ROOT = Path(__file__).resolve().parents[1]
U = 2.0**-53  # unit roundoff of IEEE double
AIR = "air_brake_force"


def air_brake_bound(n: int) -> float:
    """Largest relative difference of two sums of the same n non-negative products in any
    orders (with or without FMA): 2 gamma_n / (1 - gamma_n), gamma_n = n u / (1 - n u)."""
    gamma = n * U / (1.0 - n * U)
    return 2.0 * gamma / (1.0 - gamma)


pytestmark = pytest.mark.skipif(not kernels.KERNELS,
                                reason="numba absent: the Python core runs its numpy reference, "
                                "which the native FMU does not replicate operation by operation")


@pytest.fixture(scope="module")
def native(tmp_path_factory, native_builds):
    return build_unzipped("FreightTrain", tmp_path_factory, native_builds)


def core_of(params: dict) -> FreightTrain:
    values = {v.name: v.start for v in FreightTrain.declarations()
              if v.causality == "parameter"}
    values.update(params)
    core = FreightTrain.from_parameters(values, ROOT)
    assert core.kernel
    return core


def compare_run(native, params: dict, steps: list[tuple[float, float, float]]) -> dict:
    """Step core and FMU with ``(h, force_demand, pipe_reduction)``; every output after every
    step equal (air_brake_force within its bound). Returns the coverage seen."""
    core = core_of(params)
    fmu, vr = open_native(native, params)
    names = [v.name for v in native[1].modelVariables if v.causality == "output"]
    vrs = [vr[n] for n in names]
    bound = air_brake_bound(core.x.size)
    seen = {"held": False, "wave": False, "air": False, "moved": 0.0}
    t = 0.0
    for h, demand, reduction in steps:
        fmu.setReal([vr["force_demand"], vr["pipe_reduction"]], [demand, reduction])
        fmu.doStep(t, h)
        core.advance(to_ticks(t), to_ticks(h),
                     {"force_demand": demand, "pipe_reduction": reduction})
        t += h
        expected = core.outputs()
        got = dict(zip(names, fmu.getReal(vrs)))
        exact = {n: got[n] for n in names if n != AIR}
        assert exact == {n: expected[n] for n in names if n != AIR}, t
        assert abs(got[AIR] - expected[AIR]) <= bound * abs(expected[AIR]), (t, got[AIR])
        seen["held"] |= core.held
        seen["wave"] |= len(core.brake_history) > 1
        seen["air"] |= expected[AIR] > 0
        seen["moved"] = expected["s"]
    fmu.terminate()
    fmu.freeInstance()
    return seen


@pytest.fixture(scope="module")
def seed002_loop():
    """The closed loop of seed002_freight_pid with the Python FMUs."""
    from cosim.run.simulate import run_scenario

    return run_scenario("seed002_freight_pid", plot=False)


def test_native_equals_python_core_on_the_seed002_inputs(native, seed002_loop):
    """The force demands and pipe reductions the speed PID commands over the whole seed-002
    run, replayed into core and FMU: all 131 outputs after every 0.2-s step."""
    sc = seed002_loop.scenario
    frame = seed002_loop.frame
    h = sc.simulation.output_interval
    steps = [(h, d, r) for d, r in zip(frame["controller.force_demand"].tolist()[:-1],
                                       frame["controller.pipe_reduction"].tolist()[:-1])]
    seen = compare_run(native, dict(sc.components["plant"].parameters), steps)
    assert seen["air"] and seen["wave"] and seen["moved"] > 19000.0  # braked to the stop


def _random_steps(seed: int, n: int) -> list[tuple[float, float, float]]:
    """Irregular steps, traction, electric brake, staged applications and release."""
    rng = random.Random(seed)
    out, demand, reduction = [], 0.0, 0.0
    for k in range(n):
        if k % 9 == 0:
            demand = rng.choice([4e5, 7.6e5, 0.0, -3e5, rng.uniform(-5e5, 8e5)])
            reduction = rng.choice([0.0, 0.0, 40e3, 60e3, 100e3, 160e3, rng.uniform(0, 2e5)])
        out.append((rng.choice([0.2, 0.2, 0.05, 0.37, 1.3]), demand, reduction))
    return out


CASES = [
    ({"v0": 15.0, "s0": 3000.0}, 1),
    ({"traction_model": 1, "traction_delay": 0.33, "max_step": 0.02, "v0": 8.0}, 2),
    ({"coupler_slack": 0.05, "brake_apply_delay": 0.4, "brake_release_delay": 0.7,
      "brake_release_exponent": 1.3, "v0": 2.0}, 3),
    ({"route": "jinan_xuzhou_east", "v0": 20.0, "s0": 5000.0, "ed_fade_speed": 0.0}, 4),
]


@pytest.mark.parametrize("params,seed", CASES)
def test_native_equals_python_core_other_parameters(native, params, seed):
    """Other sub-step grids and delays, the ramp traction model, coupler slack, valve delays,
    a non-linear release curve, another route; braking to rest (static friction hold)."""
    seen = compare_run(native, params, _random_steps(seed, 250))
    assert seen["wave"] and seen["air"]
    if seed in (2, 3):
        assert seen["held"]  # the standstill hold ran


def test_state_get_set_and_serialize_replay_exactly(native):
    """FMU state mid brake wave (commands still travelling along the train): restored from
    the state and from its serialized bytes, the rest of the run repeats bit for bit."""
    fmu, vr = open_native(native, {"v0": 18.0})
    outs = [v.valueReference for v in native[1].modelVariables if v.causality == "output"]
    steps = _random_steps(5, 60)
    steps[29] = (0.2, 0.0, 120e3)  # an application that is travelling at the snapshot
    t = 0.0
    for h, d, r in steps[:30]:
        fmu.setReal([vr["force_demand"], vr["pipe_reduction"]], [d, r])
        fmu.doStep(t, h)
        t += h
    t_saved = t

    def rest():
        tt, rows = t_saved, []
        for h, d, r in steps[30:]:
            fmu.setReal([vr["force_demand"], vr["pipe_reduction"]], [d, r])
            fmu.doStep(tt, h)
            tt += h
            rows.append(fmu.getReal(outs))
        return rows

    assert_replays_from_state(fmu, rest)
    fmu.freeInstance()


def test_model_description_is_the_python_fmus(native, built_fmus):
    """Same variables, value references, units, ranges and starts as the Python FMU."""
    _, md, _ = native
    py = read_model_description(str(built_fmus["FreightTrain"].path))

    assert variable_rows(md) == variable_rows(py)
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def test_sources_and_route_data_inside(native):
    """sources/ compiles on its own (buildDescription's files); the route profiles are the
    bundled routes' (exact reprs of the Python arrays)."""
    import zipfile

    from plants.route import load_route

    path, md, unzipdir = native
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
    for f in ("sources/freight.c", "sources/freight_kernel.c", "sources/fmi2_front.c",
              "sources/FreightTrain_decl.h", "sources/buildDescription.xml",
              "binaries/linux64/FreightTrain.so"):
        assert f in names
    rows = np.loadtxt(Path(unzipdir) / "resources" / "routes" / "freight_20km.additional")
    xs, cum = load_route("freight_20km").additional._cumulative
    assert np.array_equal(rows[:, 0], xs) and np.array_equal(rows[:, 1], cum)


def test_native_resistance_spread_equals_python_core(native):
    """The vehicles' lognormal resistance factors (plants.freight.resistance_factors: numpy's
    seeded normal draws, then exp) drawn in C: every output equal after every step. The C
    takes libm's exp of each draw; numpy's exp over the array is checked to give the same
    doubles here first (a vectorised exp may differ in the last bit on other CPUs)."""
    import math

    from plants.freight import resistance_factors

    params = {"resistance_spread": 0.2, "disturbance_seed": 5, "v0": 15.0, "s0": 3000.0}
    n = core_of({}).x.size
    z = np.random.default_rng(5).standard_normal(n)
    libm = [math.exp(0.2 * zi - 0.5 * (0.2 * 0.2)) for zi in z.tolist()]
    if resistance_factors(n, 0.2, 5).tolist() != libm:
        pytest.skip("numpy's vectorised exp differs from libm's exp on this CPU")
    assert len(set(libm)) == n  # every vehicle its own factor
    seen = compare_run(native, params, _random_steps(5, 250))
    assert seen["wave"] and seen["air"]


def test_errors_reach_the_log_with_logging_off(native):
    messages: list[str] = []
    fmu, vr = initialising(native, messages, "bad")
    with pytest.raises(FMICallException):
        fmu.setInteger([vr["traction_model"]], [2])
    assert any("traction_model = 2 outside [0, 1]" in m for m in messages), messages
    fmu.setReal([vr["max_traction_force"]], [0.0])  # declared above 0 (exclusive)
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any("max_traction_force = 0: must be greater than 0" in m for m in messages)
    fmu.setReal([vr["max_traction_force"]], [760e3])
    fmu.setReal([vr["coupler_slack"]], [0.05])
    fmu.setReal([vr["max_step"]], [0.05])  # contact too stiff for this sub-step
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any("coupler_stiffness" in m and "max_step <=" in m for m in messages), messages
    fmu.setReal([vr["max_step"]], [0.01])
    fmu.setString([vr["route"]], ["/tmp/my_route.toml"])
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any("route = '/tmp/my_route.toml'" in m and "Python FMU" in m for m in messages)
    fmu.freeInstance()


def test_build_without_gcc_names_the_compiler(tmp_path):
    """`cosim build --native` on a machine without gcc stops with a message naming it."""
    bare = tmp_path / "bin"
    bare.mkdir()
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "build", "--native",
                           "FreightTrain"], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), PATH=str(bare)),
                          cwd=tmp_path)
    assert done.returncode != 0
    text = done.stdout + done.stderr
    assert "'gcc'" in text and "apt-get install gcc" in text, text


SEED002 = [n for n in scenario_files() if n.startswith("seed002_")]
TIMING_KEYS = ("wall_time", "real_time_factor", "fmu_wall", "solve_time")  # clock readings


def _timing(key: str) -> bool:
    return any(t in key for t in TIMING_KEYS)


def check_same_loop(python, c, n_vehicles: int) -> None:
    """Recorded series equal (air_brake_force within its bound); summaries equal but for
    clock readings."""
    assert list(c.frame.columns) == list(python.frame.columns)
    for col in python.frame.columns:
        a, b = c.frame[col].to_numpy(), python.frame[col].to_numpy()
        if col.endswith("." + AIR):
            assert np.all(np.abs(a - b) <= air_brake_bound(n_vehicles) * np.abs(b)), col
        else:
            assert np.array_equal(a, b), col
    assert ({k: v for k, v in c.summary.items() if not _timing(k)}
            == {k: v for k, v in python.summary.items() if not _timing(k)})


def test_closed_loop_with_the_native_plant_is_the_same(native, seed002_loop):
    """seed002_freight_pid with the native plant (``--set plant.fmu=<path>``)."""
    from cosim.run.simulate import run_scenario

    c = run_scenario("seed002_freight_pid", overrides={"plant.fmu": str(native[0])},
                     plot=False)
    check_same_loop(seed002_loop, c, 109)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", [s for s in SEED002 if s != "seed002_freight_pid"])
def test_closed_loops_of_all_seed002_scenarios_are_the_same(native, scenario):
    from cosim.run.simulate import run_scenario

    python = run_scenario(scenario, plot=False)
    c = run_scenario(scenario, overrides={"plant.fmu": str(native[0])}, plot=False)
    check_same_loop(python, c, 109)
