"""Multi-model LMI robust MPC ("LMI MPC"; not seed 000's tube RMPC) of seed 003 (section
3.2-3.3, eqs. 14-28) for the CRH3.

:class:`Crh3LmiMpc` is a seed-003 tracker (:class:`controllers.eco.tracking.EcoTracker`: same
inputs, outputs and profile parameters as the GPC baseline); its law, per sample (T = 1 s):

1. measures ``y(k)`` = speed (km/h) and updates the switching index of the ARX set with the
   one-step mismatch of every model (eqs. 27-28): the active model ``s``;
2. estimates the disturbance ``xi`` of eq. 13 as the filtered one-step residual of model ``s``
   (the paper's D xi term of eq. 14, handled by feed-forward instead of eq. 24's D column);
3. feeds forward ``u_ff = (y_r(k+1) - a_s y_r(k) - c_s - xi_hat) / b_s`` (the input that keeps
   model ``s`` on the reference ``y_r``) and regulates ``x = [y - y_r (km/h), z (m)]``, ``z``
   the position error (the tracker: the integral of the speed error against its references,
   which already carry the position correction), whose model at vertex ``j`` is
   ``x+ = [[a_j, 0], [T/3.6, 1]] x + [b_j; 0] du``;
4. solves the Kothare LMI problem (eqs. 22-26, :class:`controllers.common.lmi.KothareLmi`)
   over the polytope Omega of eq. 16 (:meth:`RobustMpcLaw.polytope`): the four corners of the
   box ``[a_lo, a_hi] x [b_lo, b_hi]`` that holds the models chosen by ``vertices``
   (``"neighbours"``, our reading of the paper's switching: the active model and its two
   neighbours in speed order; ``"all"``: the six; ``"nominal"``: the active model) with their
   pole ``1 - a`` scaled by ``1 -+ resistance_uncertainty`` and gain ``b`` by ``1 / (1 -+
   mass_uncertainty)``. The printed models share one ``b``, so without the box the polytope
   would hold no gain (mass) uncertainty. With ``"nominal"`` and both uncertainties 0 the
   problem has the active model as its one vertex (the nominal-model LMI controller);
5. applies ``u = u_ff + F x`` (``F = Y Qv^-1``) clipped to the tracker's input box (envelope
   and comfort bound). An LMI problem the solver (Clarabel) leaves unsolved is re-solved by
   the fallback solver (SCS, counted in ``lmi_fallbacks``); one neither solves keeps the
   previous gain (counted in ``qp_infeasible``).

Units of the law: ``y`` km/h, ``u`` daN/kN (per cent of the train's weight, the unit that
reconciles the paper's a_i and b = 0.318, see :mod:`controllers.robust.multimodel`); the tracker
converts from and to m/s and m/s^2 (``u_unit = 100 (1 + gamma) u / g``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.common.lmi import LMI_SOLVERS, KothareLmi
from controllers.common.speed_profiles import PHASE_BRAKE, SpeedProfile
from controllers.eco.tracking import EcoTracker, EcoTrackingParams
from controllers.robust.multimodel import ArxSet, SwitchingIndex
from cosim.fmu.declare import Checked, Var, group, param
from cosim.fmu.diagnostics import SolveTimes
from cosim.fmu.state import StatefulCore
from plants.route import GRAVITY

G = GRAVITY
STANDSTILL_KMH = 0.01  # below this, now and one sample before, the train is at rest
VERTEX_SETS = ("neighbours", "all", "nominal")
MODEL_SETS = ("identified", "paper")
DATA_DIR = Path(__file__).resolve().parent / "data"
IDENTIFIED_FILE = "crh3_arx.toml"


@dataclass(frozen=True)
class RmpcParams(Checked):
    """The law's settings; section 4 of the paper: Q = diag(1, 1, 1) (here: speed and position
    error), R = 1."""

    q_speed: float = param(1.0, "1", "Q: weight on the speed error (km/h)^-2", min=0.0)
    q_position: float = param(1.0, "1", "Q: weight on the position error m^-2", min=0.0)
    r_input: float = param(1.0, "1", "R: weight on the input correction (daN/kN)^-2",
                           min=1e-9, name="R")
    u_max: float = param(3.0, "1", "bound on the LMI input correction |F z| over the "
                         "invariant ellipsoid (eq. 25), daN/kN", min=1e-6)
    vertices: str = param("neighbours", description='models the polytope of the LMI spans: '
                          '"neighbours" (active model and its neighbours), "all" or "nominal" '
                          '(the active model)', choices=VERTEX_SETS)
    mass_uncertainty: float = param(0.1, "1", "relative train-mass uncertainty the polytope "
                                    "covers: b of every model between b / (1 + this) and "
                                    "b / (1 - this)", min=0.0, max=0.9)
    resistance_uncertainty: float = param(0.3, "1", "relative running-resistance uncertainty "
                                          "the polytope covers: 1 - a of every model scaled "
                                          "by 1 -+ this", min=0.0, max=0.9)
    model_set: str = param("identified", description='ARX set: "identified" (fitted to our '
                           'CRH3 plant, controllers/robust/data) or "paper" (section 2)',
                           choices=MODEL_SETS)
    switch_alpha: float = param(1.0, "1", "a: weight of the current mismatch (eq. 27)",
                                min=1e-9)
    switch_beta: float = param(1.0, "1", "b: weight of the past mismatches (eq. 27)", min=1e-9)
    switch_rho: float = param(0.8, "1", "forgetting factor rho (eq. 27)", min=1e-6,
                              max=0.999999)
    switch_horizon: int = param(10, "1", "past horizon l (eq. 27, samples)", min=0, max=1000,
                                integer=True)
    disturbance_gain: float = param(0.3, "1", "filter gain of the disturbance estimate",
                                    min=0.0, max=1.0)
    error_clip_speed: float = param(30.0, "m/s", "speed error fed to the LMI clipped to "
                                    "+- this (conditioning)", min=0.0)
    error_clip_position: float = param(200.0, "m", "position error fed to the LMI clipped "
                                       "to +- this", min=0.0)
    lmi_floor: float = param(1.0, "1", "errors smaller than this (km/h, m) are scaled up to "
                             "it in the LMI problem (conditioning)", min=1e-6)
    solver: str = param("clarabel", description=f"SDP solver, one of {LMI_SOLVERS}",
                        choices=LMI_SOLVERS)
    fallback_solver: str = param("scs", description="SDP solver that re-solves an event the "
                                 "first leaves unsolved (Clarabel may stop short of its "
                                 'tolerance, "optimal_inaccurate"), "none": no second try',
                                 choices=("none", *LMI_SOLVERS))


def models_dir_in(data_dir: Path) -> Path:
    """The bundled model-set folder under an FMU's data folder (or the project tree)."""
    return Path(data_dir) / "controllers" / "robust" / "data"


def load_model_set(name: str, data_dir: Path | None = None) -> ArxSet:
    """The ARX set ``name`` ("paper" or "identified": the bundled file)."""
    if name == "paper":
        return ArxSet.paper()
    if name != "identified":
        raise ValueError(f"model_set = {name!r} must be one of {MODEL_SETS}")
    import tomllib

    path = (data_dir or DATA_DIR) / IDENTIFIED_FILE
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"model_set = 'identified': cannot read {path}: {exc}") from exc
    return ArxSet.from_toml(data, str(path))


class RobustMpcLaw(StatefulCore):
    """The per-event law of the module docstring in ARX units (km/h, daN/kN)."""

    state_fields: ClassVar[tuple[str, ...]] = (
        "switch", "xi_hat", "y_prev", "u_prev", "gain", "active", "gamma", "lmi_solves",
        "lmi_failures", "lmi_fallbacks", "last_status")

    def __init__(self, params: RmpcParams, models: ArxSet, sample_time: float = 1.0) -> None:
        params.check()
        self.p, self.models, self.T = params, models, float(sample_time)
        if abs(models.sample_time - self.T) > 1e-9:
            raise ValueError(f"model set sampled at {models.sample_time} s, controller at "
                             f"sample_time = {self.T} s")
        self.lmi = KothareLmi(2, 1, 1 if self.nominal else 4,
                              np.diag([params.q_speed, params.q_position]),
                              np.array([[params.r_input]]), u_max=[params.u_max],
                              solver=params.solver,
                              fallback=None if params.fallback_solver == "none"
                              else params.fallback_solver)
        self.switch = SwitchingIndex(models, params.switch_alpha, params.switch_beta,
                                     params.switch_rho, int(params.switch_horizon))
        self.xi_hat = 0.0
        self.y_prev: float | None = None
        self.u_prev = 0.0
        self.gain = [0.0, 0.0]
        self.active = 0
        self.gamma = 0.0
        self.lmi_solves = 0
        # run-dependent solve times: bounded, outside the state and the outputs,
        # reported once at fmi2Terminate (cosim.fmu.diagnostics)
        self.timing = SolveTimes()
        self.lmi_failures = 0
        self.lmi_fallbacks = 0
        self.last_status = ""

    def vertex_indices(self, s: int) -> list[int]:
        """Models spanning the polytope at active model ``s`` (``vertices``)."""
        n = self.models.size
        if self.p.vertices == "all":
            return list(range(n))
        if self.p.vertices == "nominal":
            return [s]
        lo = min(max(s - 1, 0), max(n - 3, 0))
        return list(range(lo, lo + min(3, n)))

    @property
    def nominal(self) -> bool:
        """The LMI sees one model: the active one, without uncertainty (the nominal-model
        controller)."""
        p = self.p
        return (p.vertices == "nominal" and p.mass_uncertainty == 0.0
                and p.resistance_uncertainty == 0.0)

    def vertex(self, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
        """``(A, B)`` of the regulated state ``[y - y_r, z]`` for the model ``(a, b)``."""
        return (np.array([[a, 0.0], [self.T / 3.6, 1.0]]), np.array([[b], [0.0]]))

    def polytope(self, s: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """Vertices of Omega (eq. 16) at active model ``s``: the corners of the box
        ``[a_lo, a_hi] x [b_lo, b_hi]`` that holds every model of :meth:`vertex_indices` with
        its pole ``1 - a`` scaled by ``1 -+ resistance_uncertainty`` and its gain ``b`` by
        ``1 / (1 +- mass_uncertainty)`` (the law scales force by the nominal mass, so a
        heavier train has a smaller gain). ``A`` and ``B`` are affine in ``(a, b)``: the box's
        corners span every such model. One vertex for the nominal-model controller."""
        m, p = self.models, self.p
        idx = self.vertex_indices(s)
        if self.nominal:
            return [self.vertex(m.a[s], m.b[s])]
        dr, dm = p.resistance_uncertainty, p.mass_uncertainty
        a_lo = min(1.0 - (1.0 - m.a[j]) * (1.0 + dr) for j in idx)
        a_hi = max(1.0 - (1.0 - m.a[j]) * (1.0 - dr) for j in idx)
        b_lo = min(m.b[j] for j in idx) / (1.0 + dm)
        b_hi = max(m.b[j] for j in idx) / (1.0 - dm)
        return [self.vertex(a, b) for a in (a_lo, a_hi) for b in (b_lo, b_hi)]

    def control(self, y: float, y_ref: float, y_ref_next: float, position_error: float,
                lo: float, hi: float) -> float:
        """One event: speed ``y`` (km/h), reference now and one sample ahead (km/h), position
        error (m), input box (daN/kN); returns ``u`` (daN/kN)."""
        p, m = self.p, self.models
        # at standstill (now and before) the ARX models say nothing: no switching, no update
        if self.y_prev is not None and max(y, self.y_prev) > STANDSTILL_KMH:
            self.active = self.switch.update(y, self.y_prev, self.u_prev)
            i = self.active
            resid = y - (m.a[i] * self.y_prev + m.b[i] * self.u_prev + m.c[i])
            self.xi_hat += p.disturbance_gain * (resid - self.xi_hat)
        i = self.active
        u_ff = (y_ref_next - m.a[i] * y_ref - m.c[i] - self.xi_hat) / m.b[i]
        clip_v = 3.6 * p.error_clip_speed
        x = np.array([min(max(y - y_ref, -clip_v), clip_v),
                      min(max(position_error, -p.error_clip_position), p.error_clip_position)])
        # an error smaller than the LMI floor (|x| in km/h and m) is scaled up to it: the gain
        # F is applied to the true x; this keeps gamma ~ |x|^2 away from the solver's zero
        size = float(np.max(np.abs(x)))
        if size >= p.lmi_floor:
            x_lmi = x
        else:
            x_lmi = x * (p.lmi_floor / size) if size > 0 else np.array([p.lmi_floor, 0.0])
        sol = self.lmi.solve(x_lmi, self.polytope(i))
        self.lmi_solves += 1
        self.timing.add(sol.solve_time, sol.cpu_time)
        self.last_status = sol.status
        self.lmi_fallbacks += sol.fallback
        if sol.ok:
            self.gain = [float(sol.F[0, 0]), float(sol.F[0, 1])]
            self.gamma = sol.gamma
        else:
            self.lmi_failures += 1
        u = u_ff + self.gain[0] * x[0] + self.gain[1] * x[1]
        return min(max(u, lo), hi)

    def applied(self, y: float, u: float) -> None:
        """What acted after the event: speed ``y`` (km/h) and input ``u`` (daN/kN)."""
        self.y_prev, self.u_prev = y, u

    def status_outputs(self) -> dict[str, Any]:
        """The law's deterministic outputs (counts and the last solution)."""
        return {
            "active_model": self.active + 1,
            "lmi_gamma": self.gamma,
            "qp_infeasible": self.lmi_failures,
            "lmi_fallbacks": self.lmi_fallbacks,
            "qp_solves": self.lmi_solves,
            "disturbance_estimate": self.xi_hat,
        }

    def diagnostics(self) -> dict[str, float]:
        """LMI solve times of the events computed by this instance (run-dependent): wall
        and CPU medians per event and totals."""
        return self.timing.diagnostics()


@dataclass(frozen=True)
class Crh3LmiMpcParams(Checked):
    """Interface part (:class:`EcoTrackingParams`) and the robust MPC's settings."""

    track: EcoTrackingParams = group(EcoTrackingParams(), "")
    rmpc: RmpcParams = group(RmpcParams(), "")


class Crh3LmiMpc(EcoTracker):
    """LMI robust MPC tracker of the seed-003 profiles (multi-model, switching)."""

    params_class = Crh3LmiMpcParams
    state_fields = (*EcoTracker.tracker_state, "law", "z", "ref_now")
    output_vars = (
        *EcoTracker.output_vars,
        Var.output("active_model", "1", "active ARX model s of eq. 28 (1-based)", start=1.0),
        Var.output("lmi_gamma", "1", "gamma of the last solved LMI problem (eq. 23)"),
        Var.output("disturbance_estimate", "1", "xi_hat: filtered one-step residual of the "
                   "active model (km/h)"),
        Var.output("qp_solves", "1", "LMI (SDP) problems solved so far", start=0),
        Var.output("qp_infeasible", "1", "events whose LMI problem has no solution (previous "
                   "gain kept)", start=0),
        Var.output("lmi_fallbacks", "1", "events whose LMI problem the first solver leaves "
                   "unsolved, handed to the fallback solver", start=0),
    )

    @classmethod
    def build_core(cls, params: Crh3LmiMpcParams, profile: SpeedProfile, t0: float,
                   data_dir: Path) -> Crh3LmiMpc:
        models = load_model_set(params.rmpc.model_set, models_dir_in(data_dir))
        return cls(params, profile, t0, models)

    def __init__(self, params: Crh3LmiMpcParams, profile: SpeedProfile, t0: float = 0.0,
                 models: ArxSet | None = None) -> None:
        super().__init__(params, profile, t0)
        if models is None:
            models = load_model_set(params.rmpc.model_set)
        self.law = RobustMpcLaw(params.rmpc, models, params.track.sample_time)
        # u (m/s^2) -> daN/kN: F = M (1 + gamma) u = u_unit M g / 100
        self.to_unit = 100.0 * (1.0 + params.track.rotating_mass_factor) / G
        self.z = 0.0  # position error (m): integral of the speed error against the references
        self.ref_now: float | None = None  # r(k) (m/s): the previous event's refs[0]

    def law_control(self, y: float, refs: np.ndarray, lo: float, hi: float) -> float:
        T, tr = self.track.sample_time, self.track
        if y < tr.stop_speed and float(refs[0]) < tr.stop_speed and self.phase == PHASE_BRAKE:
            # the last centimetres of the distance-indexed braking (v_ref < stop_speed: at most
            # stop_speed^2 / (2 brake_decel) = 9 cm to go): stop and hold instead of creeping
            u = min(max(tr.hold_accel, lo), hi)
            self.law_hold(y, u)
            return u
        r_now = y if self.ref_now is None else self.ref_now
        u_unit = self.law.control(3.6 * y, 3.6 * r_now, 3.6 * float(refs[0]), self.z,
                                  lo * self.to_unit, hi * self.to_unit)
        self.law.applied(3.6 * y, u_unit)
        self.z += T * (y - r_now)
        self.ref_now = float(refs[0])
        return u_unit / self.to_unit

    def law_hold(self, y: float, u: float) -> None:
        self.law.applied(3.6 * y, u * self.to_unit)
        self.z, self.ref_now = 0.0, None

    def outputs(self) -> dict[str, float]:
        out = super().outputs()
        out.update(self.law.status_outputs())
        return out

    def diagnostics(self) -> dict[str, float]:
        """LMI solve times (wall and CPU), logged once at fmi2Terminate."""
        return self.law.diagnostics()
