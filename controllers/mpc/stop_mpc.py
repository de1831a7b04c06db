"""Predictive accurate-stopping controllers of seed 000: ideal MPC, tube RMPC, RSMPC (sec. 2-3).

All three share the design model of eq. (9) (:mod:`controllers.common.design_model`) and
the horizon QP builder (:mod:`controllers.common.qp`). At an event at sample k the controller

1. predicts ``x_{0|k} = x(k+l)`` from the measured ``[a_c, v, s]`` and the ``l`` commands already
   issued but not yet acting (eq. 10: the dead time is handled by prediction);
2. builds the time-indexed reference ``x_s`` (the stopping curve followed at ``a0`` from the
   position of the first event; ``x_s(k+1) = A x_s(k)`` in the paper) for stages ``l+i``;
3. solves the QP of eq. (11) (ideal), (11)+(14) (RMPC) or (25)+(26)/(29) (RSMPC) and applies
   ``u(k) = u(k-1) + du_{0|k}``.

Choices where the paper is silent (all parameters of :class:`StopMpcParams`):

* Cost ``Q = diag(0, 0, q_speed, q_position)`` on the tracking error, ``R = r_du`` on du;
  terminal weight ``P`` and tube feedback ``K`` from the DARE of (A, b, Q, R), so
  ``Q + K'RK + A_cl'P A_cl - P = 0`` (eq. 19 with equality) and A_cl is Schur stable.
* The reference's a_c and u components (seen only by ``P``) are those of steady tracking at
  ``a0``: ``a_c,s = a_r,ff - a0``, ``u_s = -a_c,s / c``; zero once the reference rests.
* Ideal MPC feeds the resistance forward (Davis + grade from the route, evaluated along the
  previous plan), with the untightened constraints and no terminal set.
* Tube RMPC / RSMPC (``nominal_resistance = true``, default): the nominal model carries the same
  known resistance as the ideal MPC, and W bounds only what the controller does not know, the
  spread ``a_r,true - a_r,nominal`` for mass within ``1 -+ mass_uncertainty``, Davis force
  within ``1 -+ davis_uncertainty`` and grades within ``1 -+ grade_uncertainty`` of nominal
  (:func:`spread_bounds`; seed 000 defaults 0.1 / 0.2 / 0.2: ``W = [-0.0630, 0.0648] m/s^2``).
  With ``nominal_resistance = false`` the whole resistance is the disturbance (the paper's
  reading: ``W = [-0.0500, 0.3103] m/s^2``, :func:`disturbance_bounds`) and the nominal
  prediction uses ``a_r = 0``. Constraints are tightened by support functions of ``R_i``
  (eq. 14) or ``R_i^M`` (eq. 26). Constraint set X: ``u in [u_min, u_max]``, ``v <= v_max``,
  ``|v - v_s| <= speed_error_max``, ``|s - s_s| <= position_error_max``; du bounded by
  ``du_max``.
* Offset-free option (``disturbance_observer``): a one-state observer estimates the resistance
  error from the measured speed (:meth:`_StopMpcBase.observe`), clipped to the spread, and
  adds it to the fed-forward resistance. Estimate and true error both lie in the spread S, so
  the tube uses ``W = S (-) S`` (twice as wide); with the default spread its terminal set is
  empty (construction fails with a clear error), with ``grade_uncertainty = 0.1`` it is not.
* Terminal set (eq. 16-18): the maximal robust positively invariant set of the tracking error
  under the tube law ``du = K e`` inside X (speed and position error, ``|K e| <= du_max`` and,
  with nominal resistance, the command bounds for the steady-tracking command of the route),
  computed by :func:`controllers.mpc.terminal.robust_invariant_set`; the terminal constraint
  of a QP is that set tightened by ``R_H`` (or ``R_H^M``).
* RSMPC (eq. 25-29): the held-input problem for hold M predicts ``M + N - 1`` stages (the
  paper writes ``M + N``) so that M = 1 is exactly RMPC with horizon N; it has ``N`` free moves
  (``du_0`` and stages ``M .. M+N-2``); the first M stage costs are scaled by ``1/beta``.
  M is the largest in ``[1, N-1]`` whose problem is feasible with ``J^M <= J^1``; the M = 1
  problem is solved first and a longer hold is only taken when feasible.
* Infeasible tightened QP (RSMPC: its M = 1 problem): the fallback (:meth:`fallback`) tracks the
  same reference with only the command bounds (always feasible), so the command stays
  admissible and the train keeps braking along the stopping curve; counted in
  ``qp_infeasible``; nothing raises. Only an exactly solved QP counts as feasible (DAQP exit 1,
  OSQP "solved"; never "solved inaccurate").
* Standstill: once the measured speed is at most ``standstill_speed`` after the reference has
  come to rest or within ``standstill_window`` m of the stop point, the brake is held at
  ``max(u, standstill_command)`` (a train at a platform does not creep); RSMPC then holds
  its longest hold (``N - 1``) samples. The QP is still solved there and its infeasibility
  counted in ``qp_infeasible_after_stop``; events are counted as ``events_moving`` and
  ``events_standstill``.
* ``design_model = "euler"``: the paper's printed rows for v and s (eq. 9) instead of the exact
  ZOH ones (the plant is not that model: a design-model mismatch the ideal MPC then has).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.common.design_model import (
    A_C,
    U_PREV,
    DesignModel,
    S,
    V,
    brake_delay_model,
    dare,
)
from controllers.common.qp import QP_SOLVERS, HorizonQP, QPResult, support_of_sum
from controllers.common.stopping import (
    MEASURED_SPEED_POSITION,
    davis_group,
    mass_param,
    route_param,
    u_max_param,
    u_min_param,
)
from controllers.mpc.terminal import robust_invariant_set
from cosim.fmu.c_text import ShippedValues, c_array
from cosim.fmu.declare import Checked, Declared, Var, build, param, sample_time
from cosim.fmu.diagnostics import SolveTimes
from cosim.fmu.profiles import StoppingCurve, ref_decel_param, stop_point_param
from cosim.fmu.state import StatefulCore
from plants.resistance import Davis
from plants.route import GRAVITY, Route, load_route, routes_dir_in

DESIGN_MODELS = ("zoh", "euler")
NO_BOUND = 1e30  # "no lower bound" on a terminal row (DAQP's infinity)


@dataclass(frozen=True)
class StopMpcParams(Checked):
    """Parameters, SI units (defaults: seed 000 Table 1 plant, tuned weights)."""

    horizon: int = param(10, description="prediction (and control) horizon N", min=2, max=60,
                         integer=True, name="N")
    q_speed: float = param(10.0, "s2/m2", "q1: weight on the speed error", min=0.0)
    q_position: float = param(10.0, "1/m2", "q2: weight on the position error (the stop is a "
                              "position target: without it the tube feedback does not "
                              "stabilise)", min=1e-9)
    r_du: float = param(0.01, "1", "R: weight on the command increment (per %^2)", min=1e-12)
    beta: float = param(2.0, "1", "beta >= 1: suboptimality traded for fewer executions "
                        "(eq. 22, 25)", min=1.0)  # RSMPC only
    sample_time: float = sample_time(0.2)
    brake_gain: float = param(1.07 / 100.0, "m/s2/%", "c: deceleration per % of command",
                              min=1e-9)
    brake_time_constant: float = param(0.4, "s", "tau: brake lag of the design model", min=1e-6)
    brake_delay: float = param(1.0, "s", "Td: brake dead time of the design model (whole "
                               "samples)", min=0.0)
    ref_decel: float = ref_decel_param()
    stop_point: float = stop_point_param()
    u_min: float = u_min_param()
    u_max: float = u_max_param()
    du_max: float = param(100.0, "%", "largest command change per sample", min=1e-9)
    v_max: float = param(20.0, "m/s", "speed limit", min=0.0)
    speed_error_max: float = param(2.0, "m/s", "bound of |v - v_s| in the constraint set X",
                                   min=1e-9)
    position_error_max: float = param(20.0, "m", "bound of |s - s_s| in the constraint set X",
                                      min=1e-9)
    mass: float = mass_param()
    davis: Davis = davis_group()
    route: str = route_param()
    davis_uncertainty: float = param(0.2, "1", "relative Davis uncertainty in the disturbance "
                                     "bound W", min=0.0)
    nominal_resistance: bool = param(True, description="tube controllers: the nominal model "
                                     "carries the known Davis resistance and the route grade "
                                     "ahead, W bounds only their spread (false: the whole "
                                     "resistance is W)")
    mass_uncertainty: float = param(0.1, "1", "relative mass spread designed for (in W)",
                                    min=0.0, max=0.9)
    grade_uncertainty: float = param(0.2, "1", "relative grade spread designed for (in W)",
                                     min=0.0)
    disturbance_observer: bool = param(False, description="offset-free: estimate the "
                                       "resistance error from the measured speed (one-state "
                                       "observer) and feed it forward")
    observer_gain: float = param(0.3, "1", "L: share of the speed innovation taken into the "
                                 "resistance estimate per event", min=0.0, max=1.0)
    design_model: str = param("zoh", description='design rows for v and s: "zoh" (exact) or '
                              '"euler" (the paper\'s eq. 9)', choices=DESIGN_MODELS)
    initial_command: float = param(0.0, "%", "command held before the first event", min=0.0,
                                   max=100.0)
    standstill_speed: float = param(0.02, "m/s", "speed below which a train near the stop "
                                    "point is held", min=0.0)
    standstill_window: float = param(2.0, "m", "distance before the stop point where "
                                     "standstill holding may start", min=0.0)
    standstill_command: float = param(30.0, "%", "least brake command while held at "
                                      "standstill", min=0.0, max=100.0)
    eps: float = 1e-7  # OSQP tolerance
    qp_solver: str = param("daqp", description='QP solver: "daqp" (exact active set, default) '
                           'or "osqp" (ADMM)', choices=QP_SOLVERS)

    def check_relations(self) -> None:
        if not self.u_min < self.u_max:
            raise ValueError(f"u_min = {self.u_min} must be < u_max = {self.u_max}")


def nominal_resistance_range(p: StopMpcParams, route: Route) -> tuple[float, float]:
    """Range of the known resistance a_r = Davis(v)/m + g i/1000 over the route and [0, v_max]."""
    a_g = GRAVITY * np.asarray(route.grade.values, float) / 1000.0
    return (float(a_g.min() + p.davis.force(0.0) / p.mass),
            float(a_g.max() + p.davis.force(p.v_max) / p.mass))


def spread_bounds(p: StopMpcParams, route: Route) -> tuple[float, float]:
    """W with nominal resistance: the interval of ``a_r,true - a_r,nominal`` (m/s^2).

    Davis force within ``1 -+ davis_uncertainty`` of nominal, mass within ``1 -+
    mass_uncertainty`` (so ``Davis/m`` within ``(1 - d)/(1 + m)`` .. ``(1 + d)/(1 - m)`` of
    nominal, the largest at ``v_max``), grades within ``1 -+ grade_uncertainty`` of the route's
    (the largest |grade| of the route). Seed 000 defaults (0.1, 0.2, 0.2):
    ``W = [-0.0630, 0.0648] m/s^2`` against ``[-0.0500, 0.3103]`` for the whole resistance.
    """
    a_w = p.davis.force(p.v_max) / p.mass
    d, m = p.davis_uncertainty, p.mass_uncertainty
    grades = np.abs(np.asarray(route.grade.values, float))
    a_g = p.grade_uncertainty * GRAVITY * float(grades.max()) / 1000.0
    return (a_w * ((1.0 - d) / (1.0 + m) - 1.0) - a_g, a_w * ((1.0 + d) / (1.0 - m) - 1.0) + a_g)


def disturbance_bounds(p: StopMpcParams, route: Route) -> tuple[float, float]:
    """W as an interval of resistance acceleration a_r (m/s^2): grade range + Davis range
    (the whole resistance as disturbance, ``nominal_resistance = false``)."""
    grades = route.grade.values
    a_g = GRAVITY * np.asarray(grades, float) / 1000.0
    a_w_lo = p.davis.force(0.0) / p.mass * (1.0 - p.davis_uncertainty)
    a_w_hi = p.davis.force(p.v_max) / p.mass * (1.0 + p.davis_uncertainty)
    return float(a_g.min() + a_w_lo), float(a_g.max() + a_w_hi)


_DESIGN_FIELDS = ("model", "curve", "route", "N", "Q", "P", "K", "A_cl", "known_resistance",
                  "observer", "spread", "w_bounds", "w_vertices", "F", "ref_mask", "x_lo",
                  "x_hi", "F_term", "h_term")
_DESIGNS: dict[tuple, dict[str, Any]] = {}  # (class, params, routes_dir) -> shared design
_DESIGN_CACHE_SIZE = 64


class _StopMpcBase(StatefulCore, Declared):
    """Shared event logic; subclasses choose the QP(s)."""

    params_class = StopMpcParams
    params_exclude: ClassVar[tuple[str, ...]] = ("beta",)  # only the self-triggered one has it
    input_vars = (
        *MEASURED_SPEED_POSITION,
        Var.input("a_c", "m/s2", "measured brake acceleration a_c (<= 0 when braking)"),
    )
    output_vars = (
        Var.output("brake_command", "%", "brake command u"),
        Var.output("v_ref", "m/s", "stopping-curve speed at the measured position"),
        Var.output("qp_solves", "1", "QPs solved so far", start=0),
        Var.output("qp_infeasible", "1", "events with an infeasible QP (fallback law used)",
                   start=0),
        Var.output("hold_steps", "1", "samples the current command is held (RSMPC: M)",
                   start=1),
        Var.output("qp_infeasible_after_stop", "1", "events at standstill with an infeasible "
                   "QP (the brake is held regardless)", start=0),
        Var.output("events_moving", "1", "controller events while moving", start=0),
        Var.output("events_standstill", "1", "controller events at standstill (brake held)",
                   start=0),
        Var.output("resistance_estimate", "m/s2", "disturbance observer: estimated resistance "
                   "error added to the nominal resistance (0 without observer)"),
    )

    #: the catalog FMUs of the tube cores: the terminal sets of their shipped designs go to
    #: the native law (:meth:`native_data`)
    TUBE_FMUS: ClassVar[tuple[str, ...]] = ("StopRmpc", "StopRsmpc")

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`; one law file
        for the three seed 000 controllers): ``sources/ato_stop_mpc_sets.h``, the terminal sets
        of the tube controllers (the maximal robust positively invariant sets of
        :func:`controllers.mpc.terminal.robust_invariant_set`, computed by
        :class:`TubeStopMpc` itself) for the declared defaults and each design the shipped
        scenarios and reproduction runs give :data:`TUBE_FMUS`, each with the data it is
        computed from: A_cl, the rows ``C e <= h`` of :meth:`terminal_constraints` and the
        vertices of W. The native law builds its own design from its parameters and takes the
        set whose data match (one set per distinct data)."""
        lines = ["/* generated by cosim/build/native.py from controllers.mpc.stop_mpc (the "
                 "terminal sets of the seed 000 designs); do not edit */",
                 "#ifndef ATO_STOP_MPC_SETS_H", "#define ATO_STOP_MPC_SETS_H"]
        rows, seen = [], set()
        for values in shipped(cls.TUBE_FMUS):
            core = TubeStopMpc(build(StopMpcParams, values))
            C, h = core.terminal_constraints()
            data = (core.A_cl, C, h, core.w_vertices, core.F_term, core.h_term)
            key = b"".join(np.ascontiguousarray(x, dtype=float).tobytes() for x in data)
            if key in seen:
                continue
            seen.add(key)
            k = len(rows)
            lines += [c_array(f"SM_ACL_{k}", core.A_cl), c_array(f"SM_C_{k}", C),
                      c_array(f"SM_H_{k}", h), c_array(f"SM_W_{k}", core.w_vertices),
                      c_array(f"SM_ROWS_{k}", core.F_term),
                      c_array(f"SM_RHS_{k}", core.h_term)]
            rows.append(f"    {{{C.shape[0]}, {core.F_term.shape[0]}, SM_ACL_{k}, SM_C_{k}, "
                        f"SM_H_{k}, SM_W_{k}, SM_ROWS_{k}, SM_RHS_{k}}},")
        lines += ["typedef struct { int n_c, n_rows; const double *a_cl, *c, *h, *w, *rows, "
                  "*rhs; } sm_set;", f"#define SM_N_SETS {len(rows)}",
                  "static const sm_set SM_SETS[SM_N_SETS] = {", *rows, "};", "#endif"]
        return {"sources/ato_stop_mpc_sets.h": "\n".join(lines) + "\n"}

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path,
                        t0: float = 0.0) -> _StopMpcBase:
        return cls(build(StopMpcParams, values), routes_dir_in(data_dir))

    state_fields: ClassVar[tuple[str, ...]] = (
        "history", "command", "last_t", "anchor", "warm", "plan", "hold", "qp_solves",
        "qp_infeasible", "standstill", "last_v_ref", "qp_infeasible_after_stop",
        "events_moving", "events_standstill", "d_hat", "obs_x", "obs_inputs")
        # timing (wall clock): not state, reported through the FMI log at termination
    feedforward: ClassVar[bool] = False
    tube: ClassVar[bool] = True
    self_triggered: ClassVar[bool] = False

    def __init__(self, params: StopMpcParams, routes_dir: Path | None = None) -> None:
        params.check()
        self.p = params
        # the design (DARE, tube sets, QP matrices) is a function of the parameters only:
        # computed once per process and shared (read-only) by further cores, e.g. further FMU
        # instances; each core gets its own solver workspaces (HorizonQP.clone)
        key = (type(self), params, None if routes_dir is None else str(routes_dir))
        design = _DESIGNS.get(key)
        if design is None:
            self._design(params, routes_dir)
            design = {name: getattr(self, name) for name in _DESIGN_FIELDS}
            design["qp_templates"] = {}
            if len(_DESIGNS) >= _DESIGN_CACHE_SIZE:
                _DESIGNS.pop(next(iter(_DESIGNS)))
            _DESIGNS[key] = design
        else:
            self.__dict__.update({name: design[name] for name in _DESIGN_FIELDS})
        self._qp_templates: dict[int, HorizonQP] = design["qp_templates"]
        self._qps: dict[int, HorizonQP] = {}
        self.max_hold = 1  # longest hold M (RSMPC: N - 1)
        # state
        m = self.model
        self.history: list[float] = [params.initial_command] * (m.delay_steps + 1)
        self.command = float(params.initial_command)
        self.last_t: float | None = None
        self.anchor: list[float] | None = None  # [t0, s0] of the time-indexed reference
        self.warm: dict[int, list[np.ndarray]] = {}
        self.plan: list[float] = []
        self.hold = 1
        self.qp_solves = 0
        self.qp_infeasible = 0
        # wall-clock diagnostics: bounded, outside the (deterministic, serialized) state and
        # the outputs; logged at fmi2Terminate (cosim.fmu.diagnostics)
        self.timing = SolveTimes()
        self.standstill = False
        self.last_v_ref = 0.0
        self.qp_infeasible_after_stop = 0
        self.events_moving = 0
        self.events_standstill = 0
        self.d_hat = 0.0  # observer: estimated a_r,true - a_r,nominal (m/s^2)
        self.obs_x: list[float] | None = None  # design state measured at the last event
        self.obs_inputs: list[float] = []  # plant inputs from the last event on
        self._fallback_qp: HorizonQP | None = None

    def _design(self, params: StopMpcParams, routes_dir: Path | None) -> None:
        """Everything derived from the parameters (the attributes in ``_DESIGN_FIELDS``)."""
        self.model: DesignModel = brake_delay_model(
            params.brake_gain, params.brake_time_constant, params.brake_delay, params.sample_time,
            euler=params.design_model == "euler")
        self.curve = StoppingCurve(params.ref_decel, params.stop_point)
        self.route = load_route(params.route, routes_dir)
        self.N = int(params.horizon)
        m = self.model
        Q = np.diag([0.0, 0.0, params.q_speed, params.q_position])
        self.Q = Q
        self.P = dare(m.A, m.b[:, None], Q, np.array([[params.r_du]]))
        bPb = float(m.b @ self.P @ m.b)
        self.K = -(m.b @ self.P @ m.A) / (params.r_du + bPb)  # du = K e
        self.A_cl = m.A + np.outer(m.b, self.K)
        if not np.max(np.abs(np.linalg.eigvals(self.A_cl))) < 1.0:
            raise ValueError("the LQR feedback of (A, b, Q, R) does not stabilise the design "
                             "model: check q_speed, q_position, r_du")
        # nominal resistance fed forward (ideal MPC always; tube controllers by default)
        self.known_resistance = self.feedforward or (self.tube and params.nominal_resistance)
        self.observer = bool(params.disturbance_observer) and self.known_resistance
        self.spread = spread_bounds(params, self.route)
        if not self.tube:
            self.w_bounds = (0.0, 0.0)
        elif not params.nominal_resistance:
            self.w_bounds = disturbance_bounds(params, self.route)
        elif self.observer:  # estimate and true error both in the spread: W = spread - spread
            width = self.spread[1] - self.spread[0]
            self.w_bounds = (-width, width)
        else:
            self.w_bounds = self.spread
        self.w_vertices = np.array([m.g * self.w_bounds[0], m.g * self.w_bounds[1]])
        # constraint rows on x: u_prev (abs), v (abs upper), speed / position error
        self.F = np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 0], [0, 0, 0, 1]], float)
        self.ref_mask = np.array([0.0, 0.0, 1.0, 1.0])
        self.x_lo = np.array([params.u_min, -math.inf, -params.speed_error_max,
                              -params.position_error_max])
        self.x_hi = np.array([params.u_max, params.v_max, params.speed_error_max,
                              params.position_error_max])
        if self.tube:
            self.F_term, self.h_term = self._terminal_set()
        else:
            self.F_term, self.h_term = None, None

    # -- tube sets ---------------------------------------------------------------------------
    def reach_mats(self, i: int, hold: int = 1) -> list[np.ndarray]:
        """Matrices whose images of W sum to R_i^M (eq. 26); hold = 1 gives R_i (eq. 14)."""
        A, Acl = self.model.A, self.A_cl
        if i <= hold:
            return [np.linalg.matrix_power(A, j) for j in range(i)]
        head = np.linalg.matrix_power(Acl, i - hold)
        return ([head @ np.linalg.matrix_power(A, j) for j in range(hold)]
                + [np.linalg.matrix_power(Acl, j) for j in range(i - hold)])

    def tightening(self, i: int, rows: np.ndarray, hold: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(h_R(-f), h_R(f)) per row f: lower bounds rise by the first, upper fall by the second."""
        if not self.tube or i == 0:
            z = np.zeros(np.atleast_2d(rows).shape[0])
            return z, z
        mats = self.reach_mats(i, hold)
        return (support_of_sum(mats, self.w_vertices, -rows),
                support_of_sum(mats, self.w_vertices, rows))

    def mrpi_box(self, rows: np.ndarray, terms: int = 400) -> np.ndarray:
        """Support of Z = R_inf (eq. 15) in -rows then +rows; series cut after ``terms``."""
        mats = [np.linalg.matrix_power(self.A_cl, j) for j in range(terms)]
        return np.concatenate([support_of_sum(mats, self.w_vertices, -rows),
                               support_of_sum(mats, self.w_vertices, rows)])

    def terminal_constraints(self) -> tuple[np.ndarray, np.ndarray]:
        """``(C, h)``: the constraint set X (and du bounds under the tube law) on the tracking
        error ``e = x - x_s``, as ``C e <= h``. The command rows use the range of the
        steady-tracking command ``u_s = (a0 - a_r)/c`` over the known resistance; without
        nominal resistance ``u_s`` is not known (the reference's ``a0/c`` is not what the plant
        needs), so the command bounds are left to the stage constraints."""
        p = self.p
        e = np.eye(4)
        C = np.vstack([e[V], -e[V], e[S], -e[S], self.K, -self.K])
        h = np.array([p.speed_error_max, p.speed_error_max, p.position_error_max,
                      p.position_error_max, p.du_max, p.du_max])
        if self.known_resistance:
            a_lo, a_hi = nominal_resistance_range(p, self.route)
            u_s_lo = (p.ref_decel - a_hi) / p.brake_gain
            u_s_hi = (p.ref_decel - a_lo) / p.brake_gain
            C = np.vstack([C, e[U_PREV], -e[U_PREV]])
            h = np.concatenate([h, [p.u_max - u_s_hi, u_s_lo - p.u_min]])
        return C, h

    def _terminal_set(self) -> tuple[np.ndarray, np.ndarray]:
        """Sigma (eq. 16-18): the maximal robust positively invariant set of the error under
        the tube law, ``A_cl Sigma (+) W subset Sigma`` inside X (:mod:`controllers.mpc.terminal`).
        The terminal constraint of a QP is ``Sigma (-) R_H`` (rows tightened by ``R_H``)."""
        C, h = self.terminal_constraints()
        try:
            return robust_invariant_set(self.A_cl, C, h, self.w_vertices)
        except ValueError as err:
            raise ValueError(f"{err}: W = {self.w_bounds} m/s2 (check mass_uncertainty, "
                             f"davis_uncertainty, grade_uncertainty, the error bounds of X)"
                             ) from err

    def make_qp(self, hold: int) -> HorizonQP:
        """QP for hold length M (eq. 25-26); M = 1 is RMPC (eq. 11, 14) with horizon N."""
        p, N = self.p, self.N
        H = hold + N - 1
        free = [0] + list(range(hold, H))
        beta = p.beta if self.self_triggered else 1.0
        scale = [1.0 / beta if i < hold else 1.0 for i in range(H)]
        lo = np.zeros((H + 1, 4))
        hi = np.zeros((H + 1, 4))
        for i in range(H + 1):
            dlo, dhi = self.tightening(i, self.F, hold)
            lo[i] = self.x_lo + dlo
            hi[i] = self.x_hi - dhi
        lo_term = hi_term = None
        if self.F_term is not None:
            _, thi = self.tightening(H, self.F_term, hold)
            hi_term = self.h_term - thi
            lo_term = np.full(len(hi_term), -NO_BOUND)
        return HorizonQP(self.model.A, self.model.b, self.model.g, H, free, self.Q, p.r_du,
                         self.P, stage_scale=scale, F=self.F, ref_mask=self.ref_mask, lo=lo,
                         hi=hi, F_term=self.F_term, lo_term=lo_term,
                         hi_term=hi_term, du_min=-p.du_max, du_max=p.du_max, eps=p.eps,
                         solver=p.qp_solver)

    def fallback_qp(self) -> HorizonQP:
        """The fallback problem: horizon N, the command bounds only (no state, terminal or
        tightened constraints), so ``du = 0`` is always feasible."""
        if self._fallback_qp is None:
            p, N = self.p, self.N
            F = np.array([[0.0, 1.0, 0.0, 0.0]])
            lo = np.full((N + 1, 1), p.u_min)
            hi = np.full((N + 1, 1), p.u_max)
            self._fallback_qp = HorizonQP(
                self.model.A, self.model.b, self.model.g, N, list(range(N)), self.Q, p.r_du,
                self.P, F=F, ref_mask=np.zeros(1), lo=lo, hi=hi, du_min=-p.du_max,
                du_max=p.du_max, eps=p.eps, solver=p.qp_solver)
        return self._fallback_qp

    def qp(self, hold: int) -> HorizonQP:
        """This core's QP for hold M: a clone of the process-wide template (own solver)."""
        qp = self._qps.get(hold)
        if qp is None:
            template = self._qp_templates.get(hold)
            if template is None:
                template = self._qp_templates[hold] = self.make_qp(hold)
            qp = self._qps[hold] = template.clone()
        return qp

    # -- prediction and reference --------------------------------------------------------------
    def resistance(self, v: float, s: float) -> float:
        """Known resistance a_r (m/s^2) fed forward: Davis + route grade (+ the observer's
        estimate)."""
        return (self.p.davis.force(max(v, 0.0)) / self.p.mass + self.route.grade_accel(s)
                + self.d_hat)

    def delay_prediction(self, a_c: float, v: float, s: float) -> np.ndarray:
        """x_{0|k} = x(k+l) from the measurement and the commands still in the dead time."""
        m = self.model
        x = np.array([a_c, self.history[0], v, s])
        for u in self.history[1:]:
            a_r = self.resistance(x[V], x[S]) if self.known_resistance else 0.0
            x = m.step_command(x, u, a_r)
        return x

    def reference(self, t: float, stages: int, a_r: np.ndarray | None = None) -> np.ndarray:
        """x_s for stages 0..stages (times t + (l + i) T), shape (stages + 1, 4)."""
        m, p = self.model, self.p
        t0, s0 = self.anchor
        elapsed = t - t0 + (m.delay_steps + np.arange(stages + 1)) * m.sample_time
        v_s, s_s = self.curve.along_time(s0, elapsed, rest=False)
        a_r = np.zeros(stages + 1) if a_r is None else a_r
        a_cs = a_r - p.ref_decel
        ref = np.zeros((stages + 1, 4))
        ref[:, A_C] = a_cs
        ref[:, U_PREV] = -a_cs / m.brake_gain
        ref[:, V] = v_s
        ref[:, S] = s_s
        return ref

    def feedforward_profile(self, x0: np.ndarray, H: int) -> np.ndarray:
        """Known a_r along the previous plan (shifted); zeros without nominal resistance."""
        if not self.known_resistance:
            return np.zeros(H)
        m = self.model
        plan = list(self.plan[1:]) + [0.0] * H
        x = x0.copy()
        out = np.zeros(H)
        for i in range(H):
            out[i] = self.resistance(x[V], x[S])
            x = m.step(x, plan[i] if i < len(plan) else 0.0, out[i])
        return out

    # -- one QP --------------------------------------------------------------------------------
    def solve(self, hold: int, x0: np.ndarray, t: float) -> tuple[QPResult, np.ndarray]:
        qp = self.qp(hold) if hold > 0 else self.fallback_qp()
        d = self.feedforward_profile(x0, qp.H)
        a_r_ref = np.concatenate([d, d[-1:]]) if self.known_resistance else None
        ref = self.reference(t, qp.H, a_r_ref)
        warm = self.warm.get(hold)
        res = qp.solve(x0, ref, d if self.known_resistance else None,
                       warm_x=None if warm is None else warm[0],
                       warm_y=None if warm is None else warm[1])
        self.qp_solves += 1
        if res.feasible:  # the QP's own arrays (fresh per solve): primal and dual warm start
            self.warm[hold] = [res.U, res.dual]
        return res, ref

    def fallback(self, x0: np.ndarray, t: float) -> tuple[float, list[float], float]:
        """Infeasible tightened problem: what a stopping controller in service does is keep
        braking along the stopping curve within what the brake can do. Solve the same tracking
        problem with the command bounds only (always feasible: ``du = 0`` is admissible); if
        even that fails, the tube law ``du = K (x - x_s)`` clipped. Either way the command
        stays in ``[u_min, u_max]`` and moves by at most ``du_max``, and the next event
        retries the tightened problem. Returns (du_0, plan, solve time)."""
        res, _ = self.solve(0, x0, t)
        if res.feasible:
            return float(res.du[0]), res.du.tolist(), res.solve_time
        ref = self.reference(t, 0)[0]
        du = float(self.K @ (x0 - ref))
        return float(np.clip(du, -self.p.du_max, self.p.du_max)), [], res.solve_time

    # -- event ---------------------------------------------------------------------------------
    def choose(self, x0: np.ndarray, t: float) -> tuple[float, int, list[float], float]:
        """Return (du_0, hold M, planned du sequence, solve time): one QP, M = 1."""
        res, _ = self.solve(1, x0, t)
        if not res.feasible:
            self.qp_infeasible += 1
            du, plan, elapsed = self.fallback(x0, t)
            return du, 1, plan, res.solve_time + elapsed
        return float(res.du[0]), 1, res.du.tolist(), res.solve_time

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        p, m = self.p, self.model
        v, s, a_c = float(inputs["v"]), float(inputs["s"]), float(inputs["a_c"])
        if self.last_t is not None:  # the held command acted for the samples since last event
            elapsed = int(round((t - self.last_t) / m.sample_time))
            self.history = (self.history + [self.command] * elapsed)[-(m.delay_steps + 1):]
            if self.observer:
                self.observe(v, elapsed)
        else:
            self.anchor = [t, s]
        self.last_t = t
        ref_now = self.reference(t - m.delay_steps * m.sample_time, 0)[0]
        rest = ref_now[V] <= 0.0 or p.stop_point - s <= p.standstill_window
        if self.standstill or (v <= p.standstill_speed and rest):
            self.standstill = True
            self.events_standstill += 1
            # the QP is still solved, to count what the hold hides; its answer is not used
            res, _ = self.solve(1, self.delay_prediction(a_c, v, s), t)
            if not res.feasible:
                self.qp_infeasible_after_stop += 1
            u = max(self.command, p.standstill_command)
            hold = self.max_hold
            self.plan = []
            elapsed_s = res.solve_time
        else:
            self.events_moving += 1
            x0 = self.delay_prediction(a_c, v, s)
            du, hold, plan, elapsed_s = self.choose(x0, t)
            u = float(np.clip(x0[U_PREV] + du, p.u_min, p.u_max))
            self.plan = plan
        self.timing.add(elapsed_s)
        if self.observer:  # what the next event compares its measured speed with
            self.obs_x = [a_c, self.history[0], v, s]
            self.obs_inputs = self.history[1:] + [u]
        self.command = u
        self.hold = int(hold)
        self.last_v_ref = self.curve.speed(s)
        return self.outputs(), self.hold

    def observe(self, v: float, elapsed: int) -> None:
        """One-state disturbance observer (offset-free option): predict the speed from the
        last event's measurement with the nominal resistance plus ``d_hat`` and the plant inputs
        since, then ``d_hat += L (v - v_pred) / (dv_pred/dd_hat)``, clipped to the spread
        W. Frozen near standstill (the plant then is not the linear model: it cannot roll)."""
        if self.obs_x is None or elapsed <= 0 or v <= self.p.standstill_speed:
            return
        m = self.model
        x = np.array(self.obs_x, float)
        sens = np.zeros(4)  # response of the state to a unit step of d_hat
        inputs = (self.obs_inputs + [self.obs_inputs[-1]] * elapsed)[:elapsed]
        for u in inputs:
            x = m.step_command(x, u, self.resistance(x[V], x[S]))
            sens = m.A @ sens + m.g
        if x[V] <= self.p.standstill_speed or abs(sens[V]) < 1e-12:
            return
        d = self.d_hat + self.p.observer_gain * (v - x[V]) / sens[V]
        self.d_hat = float(np.clip(d, *self.spread))

    def diagnostics(self) -> dict[str, float]:
        """QP solve times of the events computed by this instance (run-dependent)."""
        return self.timing.diagnostics()

    def outputs(self) -> dict[str, Any]:
        return {
            "brake_command": self.command,
            "v_ref": self.last_v_ref,
            "qp_solves": self.qp_solves,
            "qp_infeasible": self.qp_infeasible,
            "hold_steps": self.hold,
            "qp_infeasible_after_stop": self.qp_infeasible_after_stop,
            "events_moving": self.events_moving,
            "events_standstill": self.events_standstill,
            "resistance_estimate": self.d_hat,
        }


class IdealStopMpc(_StopMpcBase):
    """MPC with the resistance known and fed forward (paper sec. 4, the 5.95 cm case)."""

    feedforward = True
    tube = False


class TubeStopMpc(_StopMpcBase):
    """Tube-based robust MPC (RMPC, eq. 13-20): tightened constraints, no feedforward."""


class SelfTriggeredStopMpc(_StopMpcBase):
    """Robust self-triggered MPC (RSMPC, eq. 25-29): largest hold M with J^M <= J^1."""

    self_triggered = True
    params_exclude = ()

    def __init__(self, params: StopMpcParams, routes_dir: Path | None = None,
                 max_hold: int | None = None) -> None:
        super().__init__(params, routes_dir)
        self.max_hold = self.N - 1 if max_hold is None else max(1, min(max_hold, self.N - 1))

    def choose(self, x0: np.ndarray, t: float) -> tuple[float, int, list[float], float]:
        first, _ = self.solve(1, x0, t)
        elapsed = first.solve_time
        if not first.feasible:  # no hold is tried: M = 1 with the fallback, retried next sample
            self.qp_infeasible += 1
            du, plan, more = self.fallback(x0, t)
            return du, 1, plan, elapsed + more
        for hold in range(self.max_hold, 1, -1):
            res, _ = self.solve(hold, x0, t)
            elapsed += res.solve_time
            if res.feasible and res.cost <= first.cost:
                return float(res.du[0]), hold, res.du.tolist(), elapsed
        return float(first.du[0]), 1, first.du.tolist(), elapsed
