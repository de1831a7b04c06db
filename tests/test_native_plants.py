"""The native C plant FMUs Crh3Train, Emu3 and Emu8 (cosim/fmu/native/plants/crh3.c, emu.c) against
their Python cores (plants.crh3.Crh3Train; plants.emu.Emu with the compiled kernels of
plants.kernels), on the inputs of the shipped scenarios.

Tolerances, from the numerics (compiled -std=c99 -ffp-contract=off: no fused multiply-add):

* Crh3Train: the same IEEE operations in the same order, the one libm call (exp) is glibc's in
  both, so every output is equal bit for bit, and so are the closed loops with it.
* Emu3 / Emu8, outputs: the same operations as the kernel's emu_outputs, so at the same state
  every output is equal bit for bit; the seeded disturbance is numpy's default_rng draw
  reproduced in C, so it is equal too (it enters the accelerations).
* Emu3 / Emu8, dynamics: the coupler step X+ = phi X + gamma f uses the matrix exponential of
  the 3n x 3n block [[A h, B h], [0, 0]]; the core takes scipy.linalg.expm (LAPACK / BLAS),
  the C model a Pade(13) scaling-and-squaring exponential with s = ceil(log2(|M|_1 / 5.37))
  squarings. Each is the exponential to within (s + 7) (3n) u of its scale (six matrix
  products and one LU solve for the Pade step, then s squarings, each product of 3n-term sums
  with relative error <= 3n u of the sum of absolute terms), so one sub-step differs by at
  most EPS = 2 (s + 7) (3n) u times |phi| |X| + |gamma| |f| (both sides err). The chain is
  neutrally stable (spectral radius 1, the rigid-body block integrates speed into position),
  so over K sub-steps of h the state differs by at most K (1 + K h / 1 s) EPS of its scale;
  the closed loops' summaries are asserted within that relative bound of their values or of
  the position scale (for the stop error, a difference of positions). A loop that amplifies
  rounding-level differences exponentially over the run cannot meet any
  bound of this kind with any other rounding; for it the Python core's own numpy reference
  path (ATO_COSIM_NO_KERNELS: the same equations, other summation orders) must leave the
  bound as well, so that the native plant is shown not to be the cause.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
from fmi_state_helpers import assert_replays_from_state
from native_helpers import build_unzipped, open_native
from scenario_groups import one_per_fmu_pair

from cosim.fmu.state import to_seconds, to_ticks
from cosim.run.scenario import scenario_files
from plants.crh3 import Crh3Train
from plants.emu import Emu

ROOT = Path(__file__).resolve().parents[1]
U = 2.0 ** -53  # unit roundoff of IEEE double
TIMING_KEYS = ("wall_time", "real_time_factor", "fmu_wall", "solve_time", "cpu_time")  # clocks


@pytest.fixture(scope="module")
def natives(tmp_path_factory, native_builds):
    return {ident: build_unzipped(ident, tmp_path_factory, native_builds)
            for ident in ("Crh3Train", "Emu3", "Emu8")}


class Native:
    """One instance of a native FMU through fmpy, parameters set by declared type."""

    def __init__(self, native, params: dict) -> None:
        md = self.md = native[1]
        self.fmu, self.vr = open_native(native, params)
        self.outputs = [v.name for v in md.modelVariables if v.causality == "output"]

    def step(self, t: float, h: float, inputs: dict[str, float]) -> None:
        self.fmu.setReal([self.vr[n] for n in inputs], list(inputs.values()))
        self.fmu.doStep(t, h)

    def read(self) -> dict[str, float]:
        return dict(zip(self.outputs, self.fmu.getReal([self.vr[n] for n in self.outputs])))

    def core_state(self, n: int) -> dict:
        """The Emu core's state fields from the native FMU's serialized state (layout of
        plant_backend.c: front mode, magic, variables, strings, flags, start, executions,
        core)."""
        state = self.fmu.getFMUstate()
        data = bytes(self.fmu.serializeFMUstate(state))
        self.fmu.freeFMUstate(state)
        at = data.index(b"\0", 4) + 1  # after the front's mode and the magic
        at += 8 * len(self.md.modelVariables)
        for v in self.md.modelVariables:
            if v.type == "String":
                (length,) = struct.unpack_from("<Q", data, at)
                at += 8 + length
        at += 8 + 8 + 8  # flags, start, executions
        (t,) = struct.unpack_from("<q", data, at)
        x = struct.unpack_from(f"<{n}d", data, at + 8)
        v = struct.unpack_from(f"<{n}d", data, at + 8 + 8 * n)
        (held,) = struct.unpack_from("<i", data, at + 8 + 16 * n)
        te, re = struct.unpack_from("<2d", data, at + 12 + 16 * n)
        command = struct.unpack_from(f"<{n}d", data, at + 28 + 16 * n)
        return {"t_ticks": t, "x": np.array(x), "v": np.array(v), "held": bool(held),
                "traction_energy": te, "regenerated_energy": re, "command": np.array(command)}


def scenario_run(name: str, stop: float | None = None, plant: Path | None = None):
    from cosim.run.simulate import run_scenario

    over: dict = {}
    if stop is not None:
        over["simulation.stop_time"] = stop
    if plant is not None:
        over["plant.fmu"] = str(plant)
    return run_scenario(name, overrides=over or None, plot=False)


def plant_parameters(name: str) -> dict:
    from cosim.run.scenario import find_scenario, load_scenario

    return dict(load_scenario(find_scenario(name)).components["plant"]
                .parameters)


def core_of(cls, params: dict, **options):
    values = {v.name: v.start for v in cls.declarations(**options)
              if v.causality == "parameter"}
    values.update(params)
    return cls.from_parameters(values, ROOT, **options)


# -- Crh3Train ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def seed003_inputs():
    """(time, force demand) of the shipped seed-003 eco run with the Python plant (first
    400 s: start from rest, traction up to the power envelope)."""
    run = scenario_run("seed003_crh3_gpc_eco", stop=400.0)
    return list(zip(run.frame["time"].tolist(), run.frame["controller.force"].tolist()))


@pytest.mark.parametrize("params", [{}, {"length": 200.0, "max_step": 0.03},
                                    {"s0": 19000.0, "v0": 40.0, "brake_time_constant": 0.8}])
def test_crh3_equals_python_core_bit_for_bit(natives, seed003_inputs, params):
    """Every output after every step, the demands of the seed-003 run, in its 1-s steps and
    in irregular ones (0.37 s, 0.2 s: sub-steps split off the max_step grid)."""
    params = {**plant_parameters("seed003_crh3_gpc_eco"), **params}
    native = Native(natives["Crh3Train"], params)
    core = core_of(Crh3Train, params)
    t = 0.0
    steps = [(1.0, u) for _, u in seed003_inputs[:250]] + \
        [(h, u) for (_, u), h in zip(seed003_inputs[250:], [0.37, 0.2, 1.0, 0.43] * 60)]
    for h, u in steps:
        native.step(t, h, {"force": u})
        core.advance(to_ticks(t), to_ticks(h), {"force": u})
        t += h
        expected = core.outputs()
        assert native.read() == expected, t
    assert core.v > 0.0


def test_crh3_stop_and_state_replay(natives):
    """Braking to a stop (the located stopping instant, the hold) and a state restored from
    its serialized bytes replays the same outputs."""
    native = Native(natives["Crh3Train"], {"v0": 30.0})
    core = core_of(Crh3Train, {"v0": 30.0})
    t = 0.0
    for _ in range(120):
        native.step(t, 0.5, {"force": -8e5})
        core.advance(to_ticks(t), to_ticks(0.5), {"force": -8e5})
        t += 0.5
        assert native.read() == core.outputs()
    assert core.held and core.v == 0.0

    def rest() -> list[dict[str, float]]:
        rows = []
        for k in range(10):
            native.step(t + k, 1.0, {"force": 4e5})
            rows.append(native.read())
        return rows

    assert assert_replays_from_state(native.fmu, rest)[-1]["v"] > 0.0


# -- Emu3 / Emu8 -----------------------------------------------------------------------------

def expm_bound(core: Emu, h: float) -> float:
    """EPS of the module docstring for sub-steps of h: 2 (s + 7) (3n) u."""
    n = core.n
    big = np.zeros((3 * n, 3 * n))
    big[:2 * n, :2 * n] = core._A * h
    big[:2 * n, 2 * n:] = core._B * h
    norm = np.abs(big).sum(axis=0).max()
    s = max(0, math.ceil(math.log2(norm / 5.371920351148152)))
    return 2.0 * (s + 7) * (3 * n) * U


@pytest.fixture(scope="module")
def seed001_inputs():
    """(time, unit forces) of the shipped seed-001 PID run with the Python plant (first 120 s:
    start from rest, traction up to the power envelope), white-noise disturbance on."""
    run = scenario_run("seed001_emu_pid", stop=120.0)
    cols = [f"plant.applied_force[{i}]" for i in (1, 2, 3)]
    return list(zip(run.frame["time"].tolist(), run.frame[cols].to_numpy().tolist()))


def emu_case(units: int):
    params = plant_parameters("seed001_emu_pid")
    if units == 8:  # the 8-car CRH3 on the seed-001 line with the same disturbance
        params = {k: v for k, v in params.items() if k != "configuration"}
    return params


def unit_forces(forces: list[float], units: int) -> dict[str, float]:
    if units == 3:
        return {f"force[{i + 1}]": f for i, f in enumerate(forces)}
    share = sum(forces) / units * (424e3 / 479.5e3)  # the 8-car train's mass share
    return {f"force[{i + 1}]": share for i in range(units)}


def set_core_state(core: Emu, state: dict) -> None:
    for name, value in state.items():
        setattr(core, name, value)


MISMATCH = {"mass_factor": 1.07, "davis_a_factor": 0.8, "davis_b_factor": 1.25,
            "davis_c_factor": 0.9}  # a plant-mismatch sample: scaled masses and Davis terms


@pytest.mark.parametrize(("units", "mismatch"), [(3, {}), (8, {}), (3, MISMATCH)])
def test_emu_outputs_and_disturbance_equal_the_core_at_the_same_state(natives, seed001_inputs,
                                                                        units, mismatch):
    """The core put in the native model's state (from its serialized FMU state) computes the
    native outputs bit for bit: envelopes, neutral sections, route forces, coupler forces,
    powers, and the accelerations with numpy's seeded disturbance draw of each interval, also
    with the masses and Davis terms scaled."""
    params = {**emu_case(units), **mismatch}
    native = Native(natives[f"Emu{units}"], params)
    core = core_of(Emu, params, units=units)
    assert core.kernel  # compared with the compiled kernels (numba), as the Python FMU runs
    t = 0.0
    for k, (_, forces) in enumerate(seed001_inputs):
        native.step(t, 0.2, unit_forces(forces, units))
        t += 0.2
        if k % 10 == 9:
            set_core_state(core, native.core_state(units))
            assert native.read() == core.outputs(), t


COLOURED = {"disturbance_accel_std": 0.03, "disturbance_correlation_time": 10.0}


def coloured_noise_bound(core: Emu, t: float, smooth: bool) -> np.ndarray:
    """Per unit, how far the native coloured disturbance force (N) may be from the core's at
    the interval start ``t``: m sigma sqrt(2/K) sum_k (d |omega_k| t + 4 u (|omega_k| t +
    |phi_k|) + 2 u) + the pairwise sums' 2 gamma_6 K. d = 4 u where omega comes from ndtri
    (scipy's and the C's each within 2 u of the exact inverse), 0 for the Lorentzian (libm's
    tan on both sides); 4 u (|omega t| + |phi|): the rounding of each argument on each side;
    2 u: cos within 1 ulp on each side (numpy's cos need not be libm's)."""
    from plants.emu import COLOURED_COMPONENTS, _coloured_spectrum

    p = core.p
    omega, phase = _coloured_spectrum(int(p.disturbance_seed), core.n,
                                      float(p.disturbance_correlation_time), smooth)
    d = 4 * U if smooth else 0.0
    terms = d * np.abs(omega) * t + 4 * U * (np.abs(omega) * t + np.abs(phase)) + 2 * U
    gamma6 = 6 * U / (1 - 6 * U)
    unit = math.sqrt(2.0 / COLOURED_COMPONENTS) * (terms.sum(axis=1)
                                                   + 2 * gamma6 * COLOURED_COMPONENTS)
    return core.m * p.disturbance_accel_std * unit


@pytest.mark.parametrize("smooth", [True, False], ids=["gaussian", "lorentzian"])
def test_emu_coloured_disturbance_within_the_spectrum_bound(natives, seed001_inputs, smooth):
    """Seed 001's coloured disturbance (plants.emu.coloured_noise) in the native Emu3: the
    core put in the native model's state computes every output the native model does, bit
    for bit, except the accelerations, which carry the disturbance force: those within
    :func:`coloured_noise_bound` over the unit's effective mass (plus the rounding of the sum
    it enters); the disturbance is not zero."""
    params = {**emu_case(3), **COLOURED, "disturbance_smooth": smooth}
    native = Native(natives["Emu3"], params)
    core = core_of(Emu, params, units=3)
    accels = {"a", "a[1]", "a[2]", "a[3]"}
    t, moved = 0.0, 0.0
    for k, (_, forces) in enumerate(seed001_inputs):
        native.step(t, 0.2, unit_forces(forces, 3))
        t += 0.2
        if k % 10 != 9:
            continue
        set_core_state(core, native.core_state(3))
        got, want = native.read(), core.outputs()
        assert {n: v for n, v in got.items() if n not in accels} == {
            n: v for n, v in want.items() if n not in accels}, t
        noise = core._noise(core.t_ticks)
        start = to_seconds(core.t_ticks // core._noise_ticks * core._noise_ticks)
        a_i = np.array([want[f"a[{i}]"] for i in (1, 2, 3)])
        tol_i = (coloured_noise_bound(core, start, smooth) / core.m_eff
                 + 4 * U * (np.abs(a_i) + np.abs(noise) / core.m_eff))
        for i in (1, 2, 3):
            assert abs(got[f"a[{i}]"] - want[f"a[{i}]"]) <= tol_i[i - 1], (t, i)
        tol = float(core.m_eff @ tol_i) / float(np.sum(core.m_eff)) + 8 * U * np.max(np.abs(a_i))
        assert abs(got["a"] - want["a"]) <= tol, t
        moved = max(moved, float(np.max(np.abs(noise))))
    assert moved > 0.0


def step_bound(core: Emu, eps: float, h: float, u: dict[str, float]) -> np.ndarray:
    """EPS (|phi| |X| + |gamma| |f|) of one sub-step of h from the core's state, with |f|
    bounded by |u| + |route force| + Davis resistance + |disturbance| per unit."""
    prop = core._propagator(to_ticks(h))
    state = np.concatenate((core.x, core.v))
    f = np.abs(np.array(list(u.values()))) + np.abs(core._route_force(core.x)) + core.da + \
        core.db * np.abs(core.v) + core.dc * core.v ** 2 + np.abs(core._noise(core.t_ticks))
    return eps * (np.abs(prop.phi) @ np.abs(state) + np.abs(prop.gamma) @ f)


@pytest.mark.parametrize("units", [3, 8])
def test_emu_dynamics_within_the_expm_bound(natives, seed001_inputs, units):
    """One sub-step from the same state differs by at most EPS (|phi| |X| + |gamma| |f|);
    the open-loop run over the seed-001 inputs after K sub-steps by K (1 + K h) times the
    largest one-step bound so far."""
    params = emu_case(units)
    native = Native(natives[f"Emu{units}"], params)
    core = core_of(Emu, params, units=units)
    h = params["max_step"]
    eps = expm_bound(core, h)
    n = units
    t, k_sub, worst, largest = 0.0, 0, 0.0, 0.0
    for k, (_, forces) in enumerate(seed001_inputs):
        u = unit_forces(forces, units)
        if k % 40 == 20:  # one sub-step from the native state, both sides
            set_core_state(core, native.core_state(n))
            bound = step_bound(core, eps, h, u)
            native.step(t, h, u)
            core.advance(to_ticks(t), to_ticks(h), u)
            got = native.core_state(n)
            diff = np.abs(np.concatenate((got["x"] - core.x, got["v"] - core.v)))
            assert np.all(diff <= bound), (t, diff, bound)
            native.step(t + h, 0.2 - h, u)
            core.advance(to_ticks(t + h), to_ticks(0.2 - h), u)
            t = to_seconds(to_ticks(t + 0.2))
            set_core_state(core, native.core_state(n))  # the open-loop run restarts here
            k_sub, largest = 0, 0.0
            continue
        largest = max(largest, float(np.max(step_bound(core, eps, h, u))))
        native.step(t, 0.2, u)
        core.advance(to_ticks(t), to_ticks(0.2), u)
        t = to_seconds(to_ticks(t + 0.2))
        k_sub += round(0.2 / h)
        got = native.core_state(n)
        diff = np.abs(np.concatenate((got["x"] - core.x, got["v"] - core.v)))
        worst = max(worst, float(np.max(diff)) / (k_sub * (1.0 + k_sub * h) * largest))
    assert worst <= 1.0, worst
    assert float(np.max(core.v)) > 5.0  # the run left the start


def test_emu_state_replay_and_bad_parameters(natives):
    """A serialized state replays bit for bit (the disturbance is a function of seed and
    time); a configuration of another unit count, a negative correlation time and a route file
    path are refused at initialisation with a message naming the parameter."""
    from fmpy.fmi1 import FMICallException

    params = {"disturbance_accel_std": 0.05, "disturbance_seed": 3, "v0": 20.0}
    native = Native(natives["Emu3"], params)
    fmu = native.fmu
    for k in range(20):
        native.step(k * 0.2, 0.2, unit_forces([5e4, 5e4, 5e4], 3))

    def rest() -> list[dict[str, float]]:
        rows = []
        for k in range(20, 40):
            native.step(k * 0.2, 0.2, unit_forces([-2e5, -2e5, -2e5], 3))
            rows.append(native.read())
        return rows

    assert_replays_from_state(fmu, rest)
    for bad, word in (({"configuration": "crh3_8car"}, "units"),
                      ({"disturbance_correlation_time": -5.0, "disturbance_accel_std": 0.1},
                       "disturbance_correlation_time"),
                      ({"route": "/tmp/x.toml"}, "route")):
        messages: list[str] = []
        with pytest.raises(FMICallException):
            open_native(natives["Emu3"], bad, messages, "bad")
        assert any(word in m for m in messages), messages


# -- closed loops ------------------------------------------------------------------------------

def _timing(key: str) -> bool:
    return any(t in key for t in TIMING_KEYS)


def summaries_outside(python: dict, native: dict, relative: float,
                      position_scale: float) -> list[str]:
    """Summary keys whose values differ by more than ``relative`` of their value (the stop
    error and the distance short, differences of positions: of the position scale); clock
    readings left out, the others must be equal."""
    outside = []
    for key, value in python.items():
        other = native[key]
        if _timing(key):
            continue
        if isinstance(value, float) and isinstance(other, float):
            positional = key.startswith(("stop_error", "distance_short"))
            scale = max(abs(value), position_scale if positional else 0.0)
            if not abs(other - value) <= relative * scale:
                outside.append(key)
        elif other != value:
            outside.append(key)
    return outside


def assert_same_summaries(python, native, relative: float, position_scale: float) -> None:
    outside = summaries_outside(python.summary, native.summary, relative, position_scale)
    assert not outside, [(k, python.summary[k], native.summary[k]) for k in outside]


def reference_summary(scenario: str) -> dict:
    """The summary of ``scenario`` with the Python plant on its numpy reference path
    (ATO_COSIM_NO_KERNELS: the same equations as the compiled kernels, other summation
    orders), in a fresh process."""
    import json
    import os
    import subprocess
    import sys

    code = ("import json, sys; from cosim.run.simulate import run_scenario; "
            f"r = run_scenario({scenario!r}, plot=False); "
            "print(json.dumps(r.summary, default=str))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=3600, env=dict(os.environ, PYTHONPATH=str(ROOT),
                                                 ATO_COSIM_NO_KERNELS="1"))
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def emu_loop_bound(scenario: str, stop: float) -> float:
    """K (1 + K h) EPS of an Emu scenario run to ``stop``."""
    params = plant_parameters(scenario)
    units = 8 if params.get("configuration") == "crh3_8car" else 3
    core = core_of(Emu, params, units=units)
    h = params["max_step"]
    k = stop / h
    return k * (1.0 + k * h) * expm_bound(core, h)


SEED003 = [n for n in scenario_files() if n.startswith("seed003_")]
EMU_LOOPS = [n for n in scenario_files() if n.startswith(("seed001_", "seed004_"))]


def test_crh3_closed_loop_is_the_same(natives):
    """The seed-003 eco loop (first 300 s) with the native plant: recorded series and
    summary equal (the plant is equal bit for bit, so the loop is)."""
    python = scenario_run("seed003_crh3_gpc_eco", stop=300.0)
    native = scenario_run("seed003_crh3_gpc_eco", stop=300.0, plant=natives["Crh3Train"][0])
    assert native.frame.equals(python.frame)
    assert_same_summaries(python, native, 0.0, 0.0)


@pytest.mark.parametrize("scenario", ["seed001_emu_pid", "seed004_crh3_pid"])
def test_emu_closed_loop_summaries_within_the_bound(natives, scenario):
    """The first 120 s of a seed-001 and a seed-004 loop with the native Emu3: every summary
    within K (1 + K h) EPS of its value (the stop error of the position scale)."""
    stop = 120.0
    python = scenario_run(scenario, stop=stop)
    native = scenario_run(scenario, stop=stop, plant=natives["Emu3"][0])
    relative = emu_loop_bound(scenario, stop)
    positions = float(np.max(np.abs(python.frame["plant.s"])))
    assert_same_summaries(python, native, relative, positions)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", one_per_fmu_pair(SEED003))
def test_crh3_whole_closed_loops_are_the_same(natives, scenario):
    python = scenario_run(scenario)
    native = scenario_run(scenario, plant=natives["Crh3Train"][0])
    assert native.frame.equals(python.frame)
    assert_same_summaries(python, native, 0.0, 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", one_per_fmu_pair(EMU_LOOPS))
def test_emu_whole_closed_loops_within_the_bound(natives, scenario):
    """A whole shipped seed-001 / seed-004 loop with the native Emu3: every summary within
    K (1 + K h) EPS. A loop that amplifies rounding-level differences beyond any such bound
    (a positive growth rate of deviations, e.g. an adaptive law) cannot meet it with any other
    rounding; then the Python core's own numpy reference path (the same equations, other
    summation orders) must leave the bound as well: the native plant is not the cause."""
    python = scenario_run(scenario)
    native = scenario_run(scenario, plant=natives["Emu3"][0])
    relative = emu_loop_bound(scenario, float(python.frame["time"].iloc[-1]))
    positions = float(np.max(np.abs(python.frame["plant.s"])))
    outside = summaries_outside(python.summary, native.summary, relative, positions)
    if not outside:
        return
    reference = reference_summary(scenario)
    print(f"{scenario}: the loop amplifies rounding; outside the bound: native {outside}, "
          f"numpy reference {summaries_outside(python.summary, reference, relative, positions)}")
    assert summaries_outside(python.summary, reference, relative, positions), (
        f"native plant outside the bound in {outside}; the numpy reference path within it")


