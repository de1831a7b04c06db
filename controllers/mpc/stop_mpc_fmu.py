"""FMU wrapper of :class:`controllers.mpc.stop_mpc.IdealStopMpc`, and the variables shared by the
seed 000 predictive controllers (RMPC and RSMPC wrappers import :class:`StopMpcSlave`)."""

from __future__ import annotations

from typing import Any, ClassVar

from controllers.mpc.stop_mpc import IdealStopMpc, StopMpcParams
from cosim.fmu.slave import CONTROLLER_TIMING_VARS, SampledControllerSlave, Var
from plants.resistance import Davis

_D = StopMpcParams()

MPC_VARS: tuple[Var, ...] = (
    Var("N", "parameter", _D.horizon, description="prediction (and control) horizon N", min=2,
        max=60),
    Var("q_speed", "parameter", _D.q_speed, "s2/m2", "q1: weight on the speed error", min=0.0),
    Var("q_position", "parameter", _D.q_position, "1/m2", "q2: weight on the position error",
        min=1e-9),
    Var("r_du", "parameter", _D.r_du, "1", "R: weight on the command increment (per %^2)",
        min=1e-12),
    Var("sample_time", "parameter", _D.sample_time, "s", "sample time T", min=1e-6),
    Var("brake_gain", "parameter", _D.brake_gain, "m/s2/%", "c: deceleration per % of command",
        min=1e-9),
    Var("brake_time_constant", "parameter", _D.brake_time_constant, "s",
        "tau: brake lag of the design model", min=1e-6),
    Var("brake_delay", "parameter", _D.brake_delay, "s",
        "Td: brake dead time of the design model (whole samples)", min=0.0),
    Var("ref_decel", "parameter", _D.ref_decel, "m/s2", "a0: reference deceleration", min=1e-6),
    Var("stop_point", "parameter", _D.stop_point, "m", "stop position"),
    Var("u_min", "parameter", _D.u_min, "%", "lowest brake command"),
    Var("u_max", "parameter", _D.u_max, "%", "highest brake command"),
    Var("du_max", "parameter", _D.du_max, "%", "largest command change per sample", min=1e-9),
    Var("v_max", "parameter", _D.v_max, "m/s", "speed limit", min=0.0),
    Var("speed_error_max", "parameter", _D.speed_error_max, "m/s",
        "bound of |v - v_s| in the constraint set X", min=1e-9),
    Var("position_error_max", "parameter", _D.position_error_max, "m",
        "bound of |s - s_s| in the constraint set X", min=1e-9),
    Var("terminal_set_scale", "parameter", _D.terminal_set_scale, "1",
        "terminal box = scale x box hull of the mRPI set Z", min=1.0),
    Var("mass", "parameter", _D.mass, "kg", "train mass (resistance model)", min=1.0),
    Var("davis_a", "parameter", _D.davis.a, "N", "Davis constant term a", min=0.0),
    Var("davis_b", "parameter", _D.davis.b, "N.s/m", "Davis linear term b", min=0.0),
    Var("davis_c", "parameter", _D.davis.c, "N.s2/m2", "Davis quadratic term c", min=0.0),
    Var("davis_uncertainty", "parameter", _D.davis_uncertainty, "1",
        "relative Davis uncertainty in the disturbance bound W", min=0.0),
    Var("route", "parameter", _D.route, description="route (grade profile): bundled name or path"),
    Var("initial_command", "parameter", _D.initial_command, "%",
        "command held before the first event", min=0.0, max=100.0),
    Var("standstill_speed", "parameter", _D.standstill_speed, "m/s",
        "speed below which a train near the stop point is held", min=0.0),
    Var("standstill_window", "parameter", _D.standstill_window, "m",
        "distance before the stop point where standstill holding may start", min=0.0),
    Var("standstill_command", "parameter", _D.standstill_command, "%",
        "least brake command while held at standstill", min=0.0, max=100.0),
    Var("qp_solver", "parameter", _D.qp_solver,
        description='QP solver: "daqp" (exact active set, default) or "osqp" (ADMM)'),
    Var("v", "input", 0.0, "m/s", "measured speed"),
    Var("s", "input", 0.0, "m", "measured position"),
    Var("a_c", "input", 0.0, "m/s2", "measured brake acceleration a_c (<= 0 when braking)"),
    Var("brake_command", "output", 0.0, "%", "brake command u"),
    Var("v_ref", "output", 0.0, "m/s", "stopping-curve speed at the measured position"),
    Var("qp_solves", "output", 0, "1", "QPs solved so far"),
    Var("qp_infeasible", "output", 0, "1", "events whose QP was infeasible (fallback law used)"),
    Var("qp_solve_time_median", "output", 0.0, "s", "median QP time per event so far"),
    Var("hold_steps", "output", 1, "1", "samples the current command is held (RSMPC: M)"),
    *CONTROLLER_TIMING_VARS,
)


class StopMpcSlave(SampledControllerSlave):
    """Shared wrapper of the seed 000 predictive cores (not an FMU by itself)."""

    core_class: ClassVar[type] = IdealStopMpc
    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2

    def params(self) -> StopMpcParams:
        val = self.values
        names = [n for n in StopMpcParams.__dataclass_fields__ if n not in ("horizon", "davis")]
        kwargs: dict[str, Any] = {k: val[k] for k in names if k in val}
        return StopMpcParams(horizon=int(val["N"]),
                             davis=Davis(val["davis_a"], val["davis_b"], val["davis_c"]),
                             **kwargs)

    def make_core(self):
        return self.core_class(self.params(), self.resource_path("plants", "routes"))


class StopMpcFmu(StopMpcSlave):
    """Ideal MPC for accurate stopping: resistance known and fed forward (seed 000, sec. 2.1)."""

    core_class = IdealStopMpc
    variables = MPC_VARS
