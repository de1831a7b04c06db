"""The native C FMUs of the seed-001 data-driven controllers EmuMfac3, EmuIsmc3, EmuIsmpc3 and
EmuGpc3 (cosim/fmu/native/controllers/ffdl_mfac.c, ffdl_ismc.c, ffdl_ismpc.c, emu_gpc.c over
datadriven.c, ffdl.c, sliding.c, linalg.c; ISMPC's QP by DAQP compiled from
its source distribution) against the Python FMUs of their cores
(controllers.datadriven.emu_control), on the inputs of the shipped seed-001 scenarios.

What is compared, and why so. The cores' scalar operations (scaling, input box, reference,
holding brake, estimator and RLS updates, sliding surface, sums, clips) are written in C in
the cores' order, compiled -std=c99 -ffp-contract=off, and equal bit for bit; the matrix
products (numpy: BLAS, other summation orders, fused multiply-adds), the SVD of Phi_2
(numpy: LAPACK's dgesdd; C: cyclic Jacobi on Phi_2'Phi_2, linalg.h) and the linear solves
(LAPACK's dgesv; C: Gaussian elimination with the same pivoting) are not the same operations,
so a sample's outputs differ by rounding. Those differences are not compared over a run: the
laws feed their own inputs back into their estimators (u -> du -> Phi or theta -> u), and on
the seed-001 runs that internal loop amplifies a rounding-level change to percent within
minutes even with the same recorded plant outputs fed to both (open loop), as the closed
loops are known to. So the comparison is one sample at a time from the same state: the
Python FMU is run open loop on the recorded plant outputs of the shipped scenario (the
closed loop with the Python controller and the native plant), and before every sample the
native FMU's law state is set to the Python core's (its FMU state image with the law's
doubles replaced, in the order datadriven.h, ffdl.h and emu_gpc.c document); then
both compute the sample and every output and every state value after it are compared.

Bound of one sample. Each implementation computes the exact sample of a state whose blocks
(Phi, the histories, u, E, F, s, theta, P, ...) are perturbed by at most EPS times their norm
(backward error): a dot product of L terms errs by gamma_L, Jacobi on a 3 x 3 by at most
(sweeps) 6 u of |A| per sweep, the LU solves by gamma_3n rho |L||U| with rho <= 2^(n-1); the
longest chain of a sample (estimator update, gain, inverse, products, or RLS update,
prediction matrices, 6 x 6 solve) stays below 512 roundings, so EPS = 512 u. A value then
differs by at most 2 EPS sum_B |d value / d B| |B| (first order, both sides err): the
sensitivities are measured on the Python core by finite differences along random unit
directions of each block (a random direction carries at least about 1 / sqrt(dim) of the
largest gain, hence the factor sqrt(dim B)), plus 2 EPS of the value itself; and for the
laws that solve a linear system (MFAC's delta I + Phi_2'Phi_2, GPC's G'G + w I) the forward
error of a backward-stable solve, 2 EPS cond(A) |x|, on the entries that hold the move (an
ill-conditioned A, GPC's under a large covariance, is not reached by perturbing the blocks).

ISMPC's MPC solves the same kind of system: its unconstrained minimiser (eq. 72) inverts
Theta'Theta + theta I on the kept directions (eigenvalues lambda_tt sv^2 + theta), its QP
factorises H = 2 (I (x) Phi_2'Phi_2) + 2 theta (D'D (x) I) on the active set (DAQP: LDL' of
the free block, exact up to rounding for a given active set); the move's bound is 2 EPS
max(cond) |plan|, and the duals kept for the next warm start (the plan's, shifted) err by
the residual of that solve, 2 EPS (cond(H) + 1) (|H| |z| + |q|). The warm-start duals of the
state before a sample only choose DAQP's starting active set, not its answer, so they are not
perturbed. DAQP's tolerances are thresholds like the cutoff: it accepts a bound violated by
less than its primal_tol (1e-6) as met, so a sample where an inactive bound of the Python
plan is violated within the solve's error of primal_tol may end on another active set in C,
and is not compared either.

Near a threshold the two may take different branches: the truncated inverse keeps the
singular directions with sigma_j >= cutoff sigma_1, and a sigma_j within the SVDs' error
(EPS |Phi_2|) of cutoff sigma_1 may be kept by one and dropped by the other, which changes
K by the whole direction (a force jump, not a rounding). Such samples are detected on the
Python side and not compared (the state is synchronised again after them); the same holds for
the anti-windup's BOUND_TOL, the clip to the input box and the estimator's reset threshold,
whose finite-difference sensitivities show a crossing as a large (conservative) bound.

The C hosts without Python, fmpy, libcosim, the compliance suite (FMI 2.0 and 3.0) and the
Windows binaries under Wine run over every native FMU, these included, in
tests/test_native_hosts.py.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import random
import shutil
import subprocess
import tempfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from native_helpers import set_by_type

from cosim.build.python import catalog

UNIT = 2.0**-53
EPS = 512 * UNIT  # backward error of a sample's blocks (module docstring)
H = 2.0**-20  # finite-difference step, relative to a block's norm
DIRECTIONS = 3  # random directions per block
SCENARIOS = {"EmuMfac3": "seed001_emu_mfac", "EmuIsmc3": "seed001_emu_ismc",
             "EmuIsmpc3": "seed001_emu_ismpc", "EmuGpc3": "seed001_emu_gpc"}
SLIDING = ("EmuIsmc3", "EmuIsmpc3")  # the laws on the integral sliding surface
DAQP_PRIMAL_TOL = 1e-6  # DAQP's default primal_tol (csrc/include/constants.h), both sides
INPUTS = ("v[1]", "v[2]", "v[3]", "s", "traction_limit[1]", "traction_limit[2]",
          "traction_limit[3]", "brake_limit[1]", "brake_limit[2]", "brake_limit[3]")
SHORT_S = 150.0  # s of each scenario in the default suite (start, acceleration, power limit)

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None,
                               reason="gcc not installed: native FMUs cannot be built")


@pytest.fixture(scope="module")
def natives(tmp_path_factory, native_builds):
    out = {}
    for ident in SCENARIOS:
        path = native_builds(ident)[2]
        md = read_model_description(str(path), validate=True)
        out[ident] = (path, md, extract(str(path), unzipdir=str(tmp_path_factory.mktemp(ident))))
    return out


@functools.cache
def recorded_inputs(scenario: str, stop_time: float) -> tuple[np.ndarray, np.ndarray]:
    """(times, inputs (samples, 10)): the controller's inputs at its samples in the shipped
    closed loop (Python controller, native plant: equal to the Python plant bit for bit,
    tests/test_native_plants.py)."""
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import run_scenario

    sc = load_scenario(scenario, [f"simulation.stop_time={stop_time}", "plant.build=native"])
    sc = dataclasses.replace(sc, record=[*(sc.record or []), *(f"plant.{n}" for n in INPUTS)])
    frame = run_scenario(sc, plot=False).frame
    return (frame["time"].to_numpy(),
            np.column_stack([frame[f"plant.{n}"].to_numpy() for n in INPUTS]))


def law_state(ident: str, state: dict) -> np.ndarray:
    """The Python core's state as the native law's doubles (their documented order)."""
    law = state["law"]
    parts: list = [state["forces"], [state["v_ref"], state["a_ref"], state["speed_error"],
                                     float(state["holding"])]]
    if ident == "EmuGpc3":
        g = law["gpc"]
        parts += [g["theta"], g["P"], g["y_prev"], g["dy_hist"], g["du_hist"], g["u_prev"],
                  [float(g["started"]), float(g["updates"])], law["u"]]
    else:
        e = law["est"]
        parts += [e["phi"], e["y_prev"], e["dy_hist"], e["du_hist"], e["u_prev"], e["dH_prev"],
                  e["dd_hat"], e["dd_hat_prev"], [float(e["resets"]), float(e["started"])],
                  law["u"]]
        if ident in SLIDING:
            parts += [law["E"], law["F"], law["s"]]
        if ident == "EmuIsmpc3":
            parts += [law["warm_dual"], [float(law["qp_solves"]), float(law["qp_failures"])]]
    return np.concatenate([np.asarray(p, float).ravel() for p in parts])


def blocks(ident: str, state: dict) -> list[tuple[str, ...]]:
    """The paths of the law state's array blocks that carry rounding (module docstring)."""
    if ident == "EmuGpc3":
        return [("law", "gpc", k) for k in ("theta", "P", "y_prev", "dy_hist", "du_hist",
                                             "u_prev")] + [("law", "u")]
    out = [("law", "est", k) for k in ("phi", "y_prev", "dy_hist", "du_hist", "u_prev",
                                       "dH_prev", "dd_hat", "dd_hat_prev")] + [("law", "u")]
    if ident in SLIDING:  # not ISMPC's warm_dual (module docstring)
        out += [("law", k) for k in ("E", "F", "s")]
    return out


def _at(state: dict, path: tuple[str, ...]):
    for key in path[:-1]:
        state = state[key]
    return state, path[-1]


def one_sample_bound(core, ident: str, state: dict, t: float, inputs: dict,
                     rng: np.random.Generator) -> np.ndarray:
    """Per value of the law state after the sample: 2 EPS sum_B sqrt(dim B) |dvalue/dB| |B|
    + 2 EPS |value| (module docstring), the sensitivities by finite differences on the core."""
    def run(s: dict) -> np.ndarray:
        core.set_state(s)
        core.compute(t, inputs)
        return law_state(ident, core.get_state())

    base = run(state)
    total = np.zeros_like(base)
    for path in blocks(ident, state):
        parent, key = _at(state, path)
        block = np.asarray(parent[key], float)
        norm = float(np.linalg.norm(block))
        if norm == 0.0 or not math.isfinite(norm):
            continue
        worst = np.zeros_like(base)
        for _ in range(DIRECTIONS):
            d = rng.standard_normal(block.shape)
            d /= np.linalg.norm(d)
            moved = copy.deepcopy(state)
            p, k = _at(moved, path)
            p[k] = block + H * norm * d
            worst = np.maximum(worst, np.abs(run(moved) - base) / H)
        total += math.sqrt(block.size) * worst
    bound = 2 * EPS * (total + np.abs(base))
    if ident == "EmuIsmpc3":
        move, dual = mpc_error(core, state, t, inputs)
        if dual > 0.0:  # the warm-start duals of the next sample, after the qp counters
            bound[-2 - dual_size(core):-2] += dual
    else:
        move = solve_error(core, ident, state, t, inputs)
    if move > 0.0:  # the move's entries: u, u_prev, du(t) in du_hist and dH; the forces (m u)
        marks = input_marks(ident, core.get_state())
        bound += move * marks
        bound[:3] += move * core.unit_mass / core.drive.input_scale
    return bound


def dual_size(core) -> int:
    return core.law.warm_dual.size


def _recording(law) -> list:
    """The calls of ``law.mpc_moves`` and ``law.qp.solve`` (the probe's instance; its class
    untouched), each as (name, arguments, result), recorded from now on."""
    if not hasattr(law, "_calls"):
        law._calls = []
        for owner, name in ((law, "mpc_moves"), (law.qp, "solve")):
            inner = getattr(owner, name)

            def wrapped(*args, _inner=inner, _name=name, **kwargs):
                result = _inner(*args, **kwargs)
                law._calls.append((_name, args, result))
                return result
            setattr(owner, name, wrapped)
    law._calls.clear()
    return law._calls


def mpc_error(core, state: dict, t: float, inputs: dict) -> tuple[float, float]:
    """ISMPC's (move bound, dual bound) of the sample (module docstring): 2 EPS cond |plan|
    with cond the larger of the unconstrained system's on the kept directions and the QP's
    cond(H); the duals' 2 EPS (cond(H) + 1) (|H| |z| + |q|) when the QP was solved; inf when
    an inactive bound of the QP's plan is violated within its error of DAQP's primal_tol (a
    threshold crossing; compare_samples skips the sample). (0, 0) at a holding sample."""
    law = core.law
    calls = _recording(law)
    core.set_state(state)
    core.compute(t, inputs)
    moves = [c for c in calls if c[0] == "mpc_moves"]
    if not moves:
        return 0.0, 0.0
    plan = float(np.linalg.norm(moves[0][2]))
    gain = law._gain
    lam = np.outer(law._tt_eig, gain.sv * gain.sv) + law.p.theta
    cond = float(lam.max() / lam.min()) if lam.size else 1.0
    solves = [c for c in calls if c[0] == "solve"]
    if not solves:
        return 2 * EPS * cond * plan, 0.0
    (H, q, lo, hi, _), (z, dual, _) = solves[0][1], solves[0][2]
    cond_h = float(np.linalg.cond(H))
    cond = max(cond, cond_h)
    z_norm = float(np.linalg.norm(z))
    move = 2 * EPS * cond * max(plan, z_norm)
    hi_eff = np.maximum(hi, lo)
    violation = np.maximum(lo - z, z - hi_eff)
    margin = 2 * EPS * cond_h * (z_norm + float(np.abs(np.concatenate([lo, hi_eff])).max()))
    inactive = dual == 0.0
    if np.any(inactive & (np.abs(violation - DAQP_PRIMAL_TOL) <= margin)):
        return math.inf, math.inf
    residual = float(np.linalg.norm(H, 2)) * z_norm + float(np.linalg.norm(q))
    return move, 2 * EPS * (cond_h + 1) * residual


def solve_error(core, ident: str, state: dict, t: float, inputs: dict) -> float:
    """2 EPS cond(A) |x|: the forward error of a backward-stable solve A x = b (LAPACK's and
    the C elimination, EPS of A), which a perturbation of the state blocks need not reach
    when A is ill-conditioned (GPC's G'G + w I under a large covariance); for MFAC the move
    rho x of (delta I + Phi_2'Phi_2) x = Phi_2' target, for GPC the first moves of dU. 0 at a
    holding sample (no solve)."""
    if ident in SLIDING:
        return 0.0
    core.set_state(state)
    d, n = core.drive, core.n
    v = np.array([inputs[f"v[{i}]"] for i in range(1, n + 1)])
    x = inputs["s"] if core.profile.kind == "distance" else t
    v_ref, a_ref = core.profile.speed(x), core.profile.accel(x)
    if v_ref <= 0.0 and a_ref <= 0.0 and float(v.sum()) < d.stop_speed * n:
        return 0.0
    c = d.output_scale
    y, y_r = c * v, c * v_ref
    y_r_next = c * core.next_reference(x, v, v_ref, a_ref)
    law = core.law
    if ident == "EmuGpc3":
        gpc = law.gpc
        gpc.observe(y)
        j = np.arange(1, gpc.p.Ny + 1)[:, None]
        refs = np.maximum(y_r + j * (y_r_next - y_r), 0.0) * np.ones((1, n))
        f, G = gpc.prediction_matrices()
        A = G.T @ G + gpc.p.control_weight * np.eye(G.shape[1])
        sol = np.linalg.solve(A, G.T @ (refs.ravel() - f))
        scale = 1.0
    else:
        est = law.est
        est.observe(y)
        M = est.input_block
        A = law.p.delta * np.eye(n) + M.T @ M
        sol = np.linalg.solve(A, M.T @ (y_r_next - y - est.free_response()))
        scale = law.p.rho
    return 2 * EPS * float(np.linalg.cond(A)) * scale * float(np.linalg.norm(sol))


def input_marks(ident: str, state: dict) -> np.ndarray:
    """1 at the law state's entries that hold this sample's input move, 0 elsewhere."""
    marked = copy.deepcopy(state)

    def zero(tree):
        for key, value in tree.items():
            if isinstance(value, dict):
                zero(value)
            elif isinstance(value, np.ndarray):
                tree[key] = np.zeros_like(value, dtype=float)
            elif isinstance(value, list):
                tree[key] = [0.0] * len(value)
            else:
                tree[key] = 0.0
    zero(marked)
    law = marked["law"]
    inner = law["gpc"] if ident == "EmuGpc3" else law["est"]
    n = law["u"].size
    law["u"][:] = 1.0
    inner["u_prev"][:] = 1.0
    inner["du_hist"][0] = 1.0
    if ident != "EmuGpc3":
        k = inner["dy_hist"].size
        inner["dH_prev"][k:k + n] = 1.0
    return law_state(ident, marked)


def near_cutoff(core, ident: str) -> bool:
    """True when a singular value of the law's Phi_2 (GPC with sharing: B_1) lies within the
    SVDs' error of the truncation threshold cutoff sigma_1 (the kept set may differ)."""
    law = core.law
    if ident == "EmuGpc3":
        if law.p.share_gain <= 0:
            return False
        from controllers.datadriven.laws import SHARE_INVERSE
        M, cutoff = law.gpc.input_gain(), SHARE_INVERSE.pinv_cutoff
    else:
        M, cutoff = law.est.input_block, law.est.p.pinv_cutoff
    sv = np.linalg.svd(M, compute_uv=False)
    margin = 4 * EPS * float(sv[0]) * (1 + cutoff)
    return bool(np.any(np.abs(sv[1:] - cutoff * sv[0]) <= margin))


class Twins:
    """The native FMU and the Python FMU of one controller, initialised with ``params``."""

    def __init__(self, natives, ident: str, params: dict | None = None) -> None:
        _, md, unzipdir = natives[ident]
        self.ident = ident
        self.vars = {v.name: v for v in md.modelVariables}
        self.native = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                                modelIdentifier=md.coSimulation.modelIdentifier)
        self.native.instantiate()
        self.py = catalog()[ident].load()(instance_name="python", resources=tempfile.mkdtemp())
        self.native.setupExperiment(startTime=0.0)
        self.py.setup_experiment(0.0)
        self.native.enterInitializationMode()
        self.py.enter_initialization_mode()
        for name, value in (params or {}).items():
            vr = [self.vars[name].valueReference]
            kind = self.vars[name].type
            if kind == "Integer":
                self.native.setInteger(vr, [value])
                self.py.set_integer(vr, [value])
            elif kind == "Boolean":
                self.native.setBoolean(vr, [value])
                self.py.set_boolean(vr, [value])
            elif kind == "String":
                self.native.setString(vr, [value])
                self.py.set_string(vr, [value])
            else:
                self.native.setReal(vr, [value])
                self.py.set_real(vr, [value])
        self.native.exitInitializationMode()
        self.py.exit_initialization_mode()
        self.in_vrs = [self.vars[n].valueReference for n in INPUTS]
        self.out_names = [v.name for v in md.modelVariables
                          if v.causality == "output" and v.type == "Real"]
        self.out_vrs = [self.vars[n].valueReference for n in self.out_names]

    def native_law_state(self, size: int) -> tuple[bytes, np.ndarray]:
        """The native FMU state image and its law state (the image's last ``size`` doubles,
        controller_backend.c)."""
        image = bytes(self.native.serializeFMUstate(self.native.getFMUstate()))
        return image, np.frombuffer(image[len(image) - 8 * size:], float)

    def sync_native(self) -> None:
        """Set the native law state to the Python core's."""
        want = law_state(self.ident, self.py.core.get_state())
        image, _ = self.native_law_state(want.size)
        image = image[:len(image) - 8 * want.size] + want.tobytes()
        self.native.setFMUstate(self.native.deSerializeFMUstate(image))

    def set_inputs(self, values) -> None:
        values = [float(x) for x in values]
        self.native.setReal(self.in_vrs, values)
        self.py.set_real(self.in_vrs, values)

    def outputs(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.array(self.native.getReal(self.out_vrs)),
                np.array(self.py.get_real(self.out_vrs)))

    def step(self, t: float, h: float) -> None:
        self.native.doStep(t, h)
        self.py.do_step(t, h)


def compare_samples(natives, ident: str, stop_time: float, stride: int = 1
                    ) -> tuple[int, int, list[tuple[float, float]]]:
    """Every ``stride``-th sample of the shipped scenario up to ``stop_time`` from the same
    state (module docstring; both twins step and synchronise at every sample); returns
    (compared, skipped near the cutoff, (t, the largest force bound) of each compared sample
    in order)."""
    times, values = recorded_inputs(SCENARIOS[ident], stop_time)
    twins = Twins(natives, ident)
    rng = np.random.default_rng(29)
    probe = None
    compared = skipped = 0
    force_bounds: list[tuple[float, float]] = []
    for k in range(len(times) - 1):
        t, h = float(times[k]), float(times[k + 1] - times[k])
        inputs = dict(zip(INPUTS, (float(x) for x in values[k])))
        core = twins.py.core
        if core is not None and k % stride:  # not compared: both twins step from one state
            twins.sync_native()
            twins.set_inputs(values[k])
            twins.step(t, h)
            continue
        if core is not None:
            twins.sync_native()
            probe = probe or copy.deepcopy(core)
            before = core.get_state()
            skip = near_cutoff(core, ident)
            bound = None if skip else one_sample_bound(probe, ident, before, t, inputs, rng)
            if bound is not None and not np.all(np.isfinite(bound)):  # a DAQP threshold
                skip, bound = True, None
        twins.set_inputs(values[k])
        native, py = twins.outputs()
        twins.step(t, h)
        if core is None:  # the first sample: no state to synchronise yet; the same start
            assert np.array_equal(native, py), f"{ident} at t = {t}"
            continue
        if skip:
            skipped += 1
            continue
        after = law_state(ident, twins.py.core.get_state())
        _, got = twins.native_law_state(after.size)
        bad = np.flatnonzero(~(np.abs(got - after) <= bound))
        assert bad.size == 0, (f"{ident} at t = {t}: state values {bad[:5].tolist()} native "
                               f"{got[bad[:5]].tolist()}, Python {after[bad[:5]].tolist()}, "
                               f"bound {bound[bad[:5]].tolist()}")
        forces = bound[:3]
        force_bounds.append((t, float(forces.max())))
        for name, a, b in zip(twins.out_names, native, py):
            if name.startswith("force["):
                tol = forces[int(name[6]) - 1]
            elif name == "force_demand":  # the forces' sum, 3 terms
                tol = float(forces.sum()) + 2 * 3 * UNIT * float(np.abs(after[:3]).sum())
            else:  # v_ref, a_ref, speed_error, next_event_time: the same scalar operations
                tol = 0.0
            assert abs(a - b) <= tol, f"{ident} at t = {t}: {name} native {a!r}, Python {b!r}"
        compared += 1
    return compared, skipped, force_bounds


class ShortComparisons:
    """:func:`compare_samples` over the first SHORT_S seconds of each model, kept once made
    in this process, and the sum of force bounds the loop test reads from it."""

    def __init__(self, natives) -> None:
        self.natives = natives
        self.made: dict[str, tuple[int, int, list[tuple[float, float]]]] = {}

    def __call__(self, ident: str) -> tuple[int, int, list[tuple[float, float]]]:
        if ident not in self.made:
            self.made[ident] = compare_samples(self.natives, ident, SHORT_S)
        return self.made[ident]

    def force_bound_sum(self, ident: str, until: float) -> float:
        """The sum, over the compared samples before ``until`` (s), of their largest force
        bound, added in sample order: read from the comparison over SHORT_S where this
        process made it, else from ``compare_samples(..., until)``. Both give the same
        number: the inputs recorded over ``until`` are the first ones recorded over SHORT_S,
        so the samples before ``until`` see the same inputs, states and random draws
        (``default_rng(29)``, drawn per compared sample in order), and each comparison has
        asserted every such sample within its bound."""
        bounds = (self.made[ident] if ident in self.made
                  else compare_samples(self.natives, ident, until))[2]
        total = 0.0
        for t, bound in bounds:
            if t < until:
                total += bound
        return total


@pytest.fixture(scope="module")
def short_comparisons(natives) -> ShortComparisons:
    return ShortComparisons(natives)


@needs_gcc
@pytest.mark.parametrize("ident", list(SCENARIOS))
def test_native_sample_equals_python_within_rounding(short_comparisons, ident):
    compared, skipped, _ = short_comparisons(ident)
    assert compared >= 0.9 * SHORT_S, (compared, skipped)


WHOLE_RUN_STRIDE = 5  # every 5th sample of a whole run is compared


@pytest.mark.slow
@needs_gcc
@pytest.mark.parametrize("ident", list(SCENARIOS))
def test_native_sample_equals_python_over_the_whole_run(natives, ident):
    """Every WHOLE_RUN_STRIDE-th sample of the whole run (the short test above compares every
    sample of the first SHORT_S seconds): the one-sample bound's probe steps the law several
    times per sample and is most of the cost, while the states a whole run visits (the stop,
    the limits, the adaptive laws' late estimates) are reached with any stride."""
    from cosim.run.scenario import load_scenario

    stop = load_scenario(SCENARIOS[ident]).simulation.stop_time
    compared, skipped, _ = compare_samples(natives, ident, stop, WHOLE_RUN_STRIDE)
    assert compared >= 0.9 * stop / WHOLE_RUN_STRIDE, (compared, skipped)


SHORT_LOOP_S = 30.0  # s of closed loop compared (module docstring of the loop test)


@needs_gcc
@pytest.mark.parametrize("ident", list(SCENARIOS))
def test_shipped_closed_loop_with_native_controller_over_a_short_horizon(short_comparisons,
                                                                          ident):
    """The shipped closed loop (native plant) with the native controller against the Python
    one over the first SHORT_LOOP_S seconds. The loop amplifies a rounding-level change
    (module docstring), so no bound holds over the whole run; over a short horizon the
    samples' differences are taken to add up without amplification: every recorded value
    and summary figure within rtol = (sum over the samples of the largest one-sample force
    bound) / (mean |force_demand|) of its scale (a relative change of the forces moves the
    train's speeds, positions and powers by the same relative order). The horizon is the
    start from rest at Jinan West and the first power-limited acceleration; after it the
    loop's amplification is no longer negligible, which is the known property, not a
    difference of the native law."""
    import fnmatch

    from cosim.run.simulate import run_scenario

    force_bounds = short_comparisons.force_bound_sum(ident, SHORT_LOOP_S)
    base = [f"simulation.stop_time={SHORT_LOOP_S}", "plant.build=native"]
    py = run_scenario(SCENARIOS[ident], base, plot=False)
    nat = run_scenario(SCENARIOS[ident], [*base, "controller.build=native"], plot=False)
    rtol = force_bounds / float(py.frame["controller.force_demand"].abs().mean())
    assert rtol < 1e-6  # the bound is far below any figure a summary reports
    timing = ("*wall_time*", "*real_time*", "*solve_time*", "*cpu_time*")
    for col in py.frame.columns:
        if any(fnmatch.fnmatch(col, p) for p in timing):
            continue
        a, b = py.frame[col].to_numpy(), nat.frame[col].to_numpy()
        scale = float(np.abs(a).max())
        assert np.all(np.abs(a - b) <= rtol * scale), f"{ident}: {col}"

    def flat(d: dict, prefix: str = "") -> dict:
        out = {}
        for key, value in d.items():
            if isinstance(value, dict):
                out.update(flat(value, f"{prefix}{key}."))
            elif not any(fnmatch.fnmatch(f"{prefix}{key}", p) for p in timing):
                out[f"{prefix}{key}"] = value
        return out

    s_py, s_nat = flat(py.summary), flat(nat.summary)
    assert s_py.keys() == s_nat.keys()
    for key, value in s_py.items():
        other = s_nat[key]
        if isinstance(value, float) and not isinstance(value, bool):
            assert (math.isnan(value) and math.isnan(other)) or math.isclose(
                other, value, rel_tol=rtol, abs_tol=rtol), (key, value, other)
        else:
            assert other == value, key


@pytest.fixture(scope="module")
def linalg(tmp_path_factory):
    """cosim/fmu/native/numerics/linalg.c compiled alone (the build's flags), through ctypes."""
    import ctypes

    from cosim.build.native import CC_FLAGS, native_file

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    lib = tmp_path_factory.mktemp("linalg") / "linalg.so"
    subprocess.run(["gcc", "-shared", "-fPIC", *CC_FLAGS, "-o", str(lib),
                    str(native_file("linalg.c")), "-lm"], check=True)
    return ctypes.CDLL(str(lib))


def c_truncated_gain(lib, M: np.ndarray, eps: float, cutoff: float):
    import ctypes

    n = M.shape[0]
    ptr = ctypes.POINTER(ctypes.c_double)
    m = np.ascontiguousarray(M, float)
    mr, k = np.zeros((n, n)), np.zeros((n, n))
    kept = ctypes.c_int()
    lib.ato_truncated_gain(m.ctypes.data_as(ptr), n, ctypes.c_double(eps),
                           ctypes.c_double(cutoff), mr.ctypes.data_as(ptr),
                           k.ctypes.data_as(ptr), ctypes.byref(kept))
    return mr, k, kept.value


JACOBI_EPS = 64 * UNIT  # backward error of M'M and its Jacobi eigen-decomposition, of |M|^2


def test_truncated_gain_equals_numpy_within_its_conditioning(linalg):
    """ato_truncated_gain against controllers.common.ffdl.truncated_gain (numpy's SVD) on
    random 3 x 3 blocks, near rank one as the coupled train's Phi_2 and general ones.

    Bound: Jacobi on M'M (3-term products, then rotations until the off-diagonal is below
    the diagonal's rounding: at most 64 u |M|^2 of backward error in M'M) moves a singular
    value s by at most JACOBI_EPS |M|^2 / s (s^2 moves by that) and LAPACK's SVD by less; the
    spectral function K = V g(S) U', g(s) = s / (s^2 + eps) on the kept s (M_r: g(s) = s),
    then moves by at most |E| (max |g'| + max g / s_min + max g / gap) with |E| the
    equivalent perturbation of M and gap the distance between kept and dropped singular
    values (divided differences of g; a dropped direction rotates into a kept one by |E| /
    gap); twice that for the two sides and sqrt(2) for the Frobenius-to-2-norm steps. Blocks
    with a singular value within 1e-6 of the threshold are not compared: there the kept set
    may differ (a jump of K by the whole direction)."""
    from controllers.common.ffdl import truncated_gain

    rng = np.random.default_rng(3)
    compared = 0
    for _ in range(400):
        M = rng.standard_normal((3, 3)) * float(rng.choice([1e-2, 1.0, 1e2]))
        if rng.random() < 0.5:  # near rank one, as the stiffly coupled train's Phi_2
            M = np.outer(rng.standard_normal(3), rng.standard_normal(3)) + 1e-2 * M
        eps, cutoff = float(rng.choice([0.0, 1e-2])), float(rng.choice([0.0, 0.5]))
        sv = np.linalg.svd(M, compute_uv=False)
        keep = sv >= cutoff * sv[0]
        if np.any(np.abs(sv - cutoff * sv[0]) <= 1e-6 * sv[0]):
            continue
        gain = truncated_gain(M, eps, cutoff)
        mr, k, kept = c_truncated_gain(linalg, M, eps, cutoff)
        assert kept == int(keep.sum())
        s_min, norm = float(sv[keep].min()), float(sv[0])
        E = JACOBI_EPS * norm * norm / s_min
        gap = float(np.abs(sv[keep][:, None] - sv[~keep][None, :]).min()) if (~keep).any() \
            else math.inf
        for got, want, g, dg in (
                (mr, gain.M, sv[keep], np.ones(keep.sum())),
                (k, gain.K, sv[keep] / (sv[keep] ** 2 + eps),
                 np.abs(eps - sv[keep] ** 2) / (sv[keep] ** 2 + eps) ** 2)):
            tol = 2 * math.sqrt(2) * E * (float(dg.max()) + float(g.max()) / s_min
                                          + float(g.max()) / gap)
            assert np.abs(got - want).max() <= tol, (M.tolist(), eps, cutoff)
        compared += 1
    assert compared > 300


def test_jacobi_eigen_reconstructs_the_matrix(linalg):
    """V diag(w) V' = A and V'V = I within the backward error of the rotations, largest
    eigenvalue first; a non-finite matrix is reported (-1), not looped on."""
    import ctypes

    ptr = ctypes.POINTER(ctypes.c_double)
    rng = np.random.default_rng(4)
    for n in (1, 2, 3, 6):
        for _ in range(50):
            B = rng.standard_normal((n, n))
            A = B @ B.T if rng.random() < 0.5 else B + B.T
            a, w, v = A.copy(), np.zeros(n), np.zeros((n, n))
            sweeps = linalg.ato_sym_eigen(a.ctypes.data_as(ptr), n, w.ctypes.data_as(ptr),
                                          v.ctypes.data_as(ptr))
            assert 0 < sweeps < 100
            assert np.all(np.diff(w) <= 0)
            scale = float(np.abs(A).max())
            assert np.abs(v @ np.diag(w) @ v.T - A).max() <= 2 * sweeps * n * n * UNIT * scale
            assert np.abs(v.T @ v - np.eye(n)).max() <= 2 * sweeps * n * n * UNIT
    a = np.array([[1.0, math.nan], [math.nan, 1.0]])
    assert linalg.ato_sym_eigen(a.ctypes.data_as(ptr), 2, np.zeros(2).ctypes.data_as(ptr),
                                np.zeros((2, 2)).ctypes.data_as(ptr)) == -1


@needs_gcc
@pytest.mark.parametrize("ident", list(SCENARIOS))
def test_native_datadriven_state_round_trip(natives, ident):
    """Get the state mid-run (an event instant with a tentative event shown), run on,
    restore it and a serialized copy in a fresh instance: the same outputs again."""
    times, values = recorded_inputs(SCENARIOS[ident], SHORT_S)
    twins = Twins(natives, ident)
    fmu = twins.native
    for k in range(40):
        twins.set_inputs(values[k])
        twins.step(float(times[k]), 1.0)
    later = range(40, 80)
    twins.set_inputs(values[40])
    fmu.getReal([twins.vars["next_event_time"].valueReference])  # a tentative event shown
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)
    rng = random.Random(5)
    steps = [rng.choice([1.0, 0.5, 2.5]) for _ in later]

    def run(slave) -> list:
        out, t = [], float(times[40])
        for k, h in zip(later, steps):
            slave.setReal(twins.in_vrs, [float(x) for x in values[k]])
            out.append(slave.getReal(twins.out_vrs))
            slave.doStep(t, h)
            t += h
        return out

    first = run(fmu)
    fmu.setFMUstate(state)
    assert run(fmu) == first
    _, md, unzipdir = natives[ident]
    other = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="other",
                      modelIdentifier=md.coSimulation.modelIdentifier)
    other.instantiate()
    other.setFMUstate(other.deSerializeFMUstate(blob))
    assert run(other) == first
    fmu.freeFMUstate(state)


@needs_gcc
@pytest.mark.parametrize(("ident", "params"), [
    ("EmuMfac3", {"L_y": 2, "L_u": 3, "share_gain": 0.0, "output_scale": 3.6}),
    ("EmuIsmc3", {"L_y": 2, "L_u": 2, "alpha": 0.5, "common_integral": 0.0,
                  "innovation_dd_hat": True, "anti_windup": False}),
    ("EmuIsmc3", {"disturbance_estimate": False, "input_scale": 2.0,
                  "reference_at_next_position": False}),
    ("EmuGpc3", {"na": 2, "nb": 2, "Ny": 5, "Nu": 3, "share_gain": 0.3, "p_max": 1e4}),
    ("EmuIsmpc3", {"constraints": "clip", "error_prediction": "eq72", "N": 4}),
    ("EmuIsmpc3", {"error_prediction": "off", "N": 25, "theta": 3.0, "output_scale": 3.6,
                   "input_scale": 2.0}),
])
def test_other_parameters_agree_at_the_first_samples(natives, ident, params):
    """Other orders and options of the same laws: from the same start, on the recorded
    inputs, the first samples (before the internal loop can amplify anything) within the
    one-sample bound accumulated over them (each sample's bound applied to its outputs)."""
    times, values = recorded_inputs(SCENARIOS[ident], SHORT_S)
    twins = Twins(natives, ident, params)
    rng = np.random.default_rng(1)
    probe = None
    for k in range(60):
        t = float(times[k])
        core = twins.py.core
        bound = None
        if core is not None:
            twins.sync_native()
            probe = probe or copy.deepcopy(core)
            if near_cutoff(core, ident):
                twins.set_inputs(values[k])
                twins.step(t, 1.0)
                continue
            inputs = dict(zip(INPUTS, (float(x) for x in values[k])))
            bound = one_sample_bound(probe, ident, core.get_state(), t, inputs, rng)
            if not np.all(np.isfinite(bound)):  # a DAQP threshold (module docstring)
                twins.set_inputs(values[k])
                twins.step(t, 1.0)
                continue
        twins.set_inputs(values[k])
        native, py = twins.outputs()
        twins.step(t, 1.0)
        if bound is None:
            assert np.array_equal(native, py)
            continue
        after = law_state(ident, twins.py.core.get_state())
        _, got = twins.native_law_state(after.size)
        assert np.all(np.abs(got - after) <= bound), (ident, params, t)


@needs_gcc
@pytest.mark.parametrize(("ident", "params", "message"), [
    ("EmuGpc3", {"Nu": 4, "Ny": 3}, "Nu = 4 must be <= Ny = 3"),
    ("EmuMfac3", {"reference": "no_such_profile"}, "no_such_profile"),
    ("EmuIsmpc3", {"constraints": "box"}, "constraints = 'box': must be one of 'qp', 'clip'"),
    ("EmuIsmpc3", {"error_prediction": "eq73"}, "must be one of 'eq78', 'eq72', 'off'"),
])
def test_bad_parameters_are_refused(natives, ident, params, message):
    _, md, unzipdir = natives[ident]
    logged: list[str] = []
    from fmpy.fmi2 import defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(lambda c, i, s, cat, text: logged.append(text.decode()))
    cb.allocateMemory = defaultCallbacks.allocateMemory
    cb.freeMemory = defaultCallbacks.freeMemory
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="native",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate(callbacks=cb)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    set_by_type(fmu, md, params)
    with pytest.raises(FMICallException):
        fmu.exitInitializationMode()
    assert any(message in text for text in logged), logged
