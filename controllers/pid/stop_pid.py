"""PID tracking of the reference stopping curve (seed 000 baseline, sec. 4.1).

Error ``e = v - v_ref(s)`` (m/s, positive when too fast); brake command (%)::

    u = u_ff + kp e + ki int(e) + kd de/dt,   u_ff = a0 / c   (reference deceleration)

or, with ``resistance_feedforward`` (the information the MPCs have), ``u_ff = (a0 - a_r) / c``
with the known resistance ``a_r`` (Davis force / mass + the route's grade).

clamped to ``[u_min, u_max]``. Anti-windup by conditional integration: the integral is frozen
while the command is saturated in the direction the error would push it. The derivative acts on
the error, by backward difference over the sample time. The feedforward stops at the stop point.

``hold_at_stop_point`` (default true, not in the paper): once at or past the stop point, or at
rest after the curve has ended, the feedforward becomes ``u_max`` (full brake), which is what
stops the train near the point with the default gains. The plain PID (false) is the paper's
baseline; it needs its own gains to stop inside the window (see the seed 000 scenario
``seed000_stop_pid_plain`` and ``papers/seed000/entry.toml``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from controllers.common.stopping import (
    MEASURED_SPEED_POSITION,
    davis_group,
    mass_param,
    route_param,
    u_max_param,
    u_min_param,
)
from cosim.fmu.declare import Checked, Declared, Var, build, param, sample_time
from cosim.fmu.profiles import StoppingCurve, ref_decel_param, stop_point_param
from cosim.fmu.state import StatefulCore
from plants.resistance import Davis
from plants.route import Route, load_route, routes_dir_in


@dataclass(frozen=True)
class StopPidParams(Checked):
    kp: float = param(60.0, "%.s/m", "proportional gain on v - v_ref")
    ki: float = param(10.0, "%/m", "integral gain")
    kd: float = param(0.0, "%/(m/s2)", "derivative gain")
    ref_decel: float = ref_decel_param()
    stop_point: float = stop_point_param()
    brake_gain: float = param(1.07 / 100.0, "m/s2/%",
                              "c: deceleration per % of command, for the feedforward a0 / c",
                              min=1e-9)
    feedforward: bool = param(True, description="add the reference-deceleration feedforward "
                              "a0 / c")
    u_min: float = u_min_param()
    u_max: float = u_max_param()
    sample_time: float = sample_time(0.2)
    hold_at_stop_point: bool = param(True, description="full brake (u_max) once at or past "
                                     "the stop point, or once stopped after the curve ended "
                                     "(not in the paper; false: the plain PID)")
    resistance_feedforward: bool = param(False, description="feed the known resistance "
                                         "forward as the MPCs do, u_ff = (a0 - a_r(v, s)) / c "
                                         "with a_r the Davis force / mass + the route's grade "
                                         "(false: a0 / c, the paper's PID)")
    mass: float = mass_param()
    davis: Davis = davis_group()
    route: str = route_param()

    def check_relations(self) -> None:
        if not self.u_min < self.u_max:
            raise ValueError(f"u_min = {self.u_min} must be < u_max = {self.u_max}")


class StopPid(StatefulCore, Declared):
    """Sampled PID with feedforward and anti-windup; one call of :meth:`compute` per sample."""

    state_fields = ("integral", "prev_error", "command")
    params_class = StopPidParams
    input_vars = MEASURED_SPEED_POSITION
    output_vars = (
        Var.output("brake_command", "%", "brake command u"),
        Var.output("v_ref", "m/s", "reference speed at the measured position"),
        Var.output("speed_error", "m/s", "v - v_ref"),
    )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path, t0: float = 0.0) -> StopPid:
        params = build(StopPidParams, values)
        route = (load_route(params.route, routes_dir_in(data_dir))
                 if params.resistance_feedforward else None)
        return cls(params, route)

    def __init__(self, params: StopPidParams, route: Route | None = None) -> None:
        """``route``: the grades of the resistance feedforward (loaded by name if needed)."""
        params.check()
        self.p = params
        if params.resistance_feedforward and route is None:
            route = load_route(params.route)
        self.route = route
        self.curve = StoppingCurve(params.ref_decel, params.stop_point)
        self.integral = 0.0
        self.prev_error: float | None = None
        self.command = 0.0

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        p = self.p
        v, s = inputs["v"], inputs["s"]
        v_ref = self.curve.speed(s)
        error = v - v_ref
        u_ff = 0.0
        if p.feedforward and s < p.stop_point:
            a_r = self.resistance(v, s) if p.resistance_feedforward else 0.0
            u_ff = (p.ref_decel - a_r) / p.brake_gain
        if p.hold_at_stop_point and (s >= p.stop_point or (v_ref == 0.0 and v <= 0.0)):
            u_ff = p.u_max  # at or past the stop point: hold the train
        derivative = 0.0 if self.prev_error is None else (error - self.prev_error) / p.sample_time
        self.prev_error = error
        integral = self.integral + error * p.sample_time
        unclamped = u_ff + p.kp * error + p.ki * integral + p.kd * derivative
        u = min(max(unclamped, p.u_min), p.u_max)
        saturated_high = unclamped > p.u_max and error > 0
        saturated_low = unclamped < p.u_min and error < 0
        if not (saturated_high or saturated_low):
            self.integral = integral
        self.command = u
        return {"brake_command": u, "v_ref": v_ref, "speed_error": error}, 1

    def resistance(self, v: float, s: float) -> float:
        """The known resistance a_r (m/s^2): Davis force / mass + the route's grade, as the
        MPCs feed forward (:meth:`controllers.mpc.stop_mpc._StopMpcBase.resistance`)."""
        assert self.route is not None
        return self.p.davis.force(max(v, 0.0)) / self.p.mass + self.route.grade_accel(s)

    def outputs(self) -> dict[str, float]:
        return {"brake_command": self.command, "v_ref": 0.0, "speed_error": 0.0}
