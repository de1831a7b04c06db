"""High-speed train with first-order-lag plus dead-time brakes (seed 000, eqs. 1-7).

    da_c/dt = -a_c / tau + (1 / tau) a_t(t - Td),   a_t = -c u       (eqs. 2-4)
    dv/dt   = a_c - a_r(v, s) - a_d(t),   ds/dt = v,   a_r = a_w(v) + a_g(s)   (eqs. 5-7)

``u`` is the brake command in percent of full service braking (0..100); ``c`` maps 100 % to the
maximum brake deceleration (1.07 m/s^2 in Table 1), so a_c <= 0 while braking (the paper's sign
convention: a = a_c - a_r). ``a_w`` is Davis resistance per unit mass, ``a_g = g i(s)/1000``;
``a_d`` an unknown bounded resistance disturbance (wind, rail condition; ours, the paper's
"uncertain disturbance from the external environment"), piecewise constant, seeded
(:meth:`BrakeDelayTrain.disturbance_at`; zero by default).

Integration: sub-steps no longer than ``max_step`` on a grid anchored at t = 0 and split at
every instant where the delayed command changes, so the result does not depend on the
communication step. Over each sub-step the delayed command is constant and the lag is solved
exactly (ZOH); speed and position use RK4 with the exact a_c(t) at the stage times.
The dead time is exact for any step: commands are kept with their time stamps (ticks).
A stopped train does not roll back: v >= 0, and it stays at rest while the net force is braking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.fmu.declare import Checked, Declared, Var, build, group, param
from cosim.fmu.state import StatefulCore, to_seconds, to_ticks
from plants import dead_time
from plants.resistance import Davis
from plants.route import (
    Route,
    initial_state_parameters,
    load_route,
    route_parameter,
    routes_dir_in,
)


@dataclass(frozen=True)
class BrakeDelayParams(Checked):
    """Parameters in SI (defaults: seed 000 Table 1)."""

    mass: float = param(490e3, "kg", "train mass", min=1.0)
    davis: Davis = group(Davis.from_kn_kmh(5.4, 0.0098, 0.00163), "davis_")
    brake_gain: float = param(1.07 / 100.0, "m/s2/%",
                              "c: brake deceleration per % of command (100 % -> 1.07 m/s2)",
                              above=0.0)
    brake_time_constant: float = param(0.4, "s", "tau: first-order brake lag", min=1e-6)
    brake_delay: float = param(1.0, "s", "Td: brake dead time", min=0.0)
    max_step: float = param(0.01, "s", "longest internal integration sub-step", min=1e-6)
    grade_scale: float = param(1.0, "1", "factor on the route's grades (model mismatch "
                               "studies)", min=0.0)
    disturbance_amplitude: float = param(0.0, "m/s2", "bound A of the unknown resistance "
                                         "disturbance a_d, uniform in [-A, A] (0: none)",
                                         min=0.0)
    disturbance_interval: float = param(1.0, "s", "a_d is held for this long, then drawn "
                                        "anew", min=1e-3)
    disturbance_seed: int = param(0, description="seed of the disturbance a_d")


class BrakeDelayTrain(StatefulCore, Declared):
    """Single-mass train, brake command -> lag + dead time -> deceleration."""

    state_fields = ("t_ticks", "a_c", "v", "s", "history", "a_d")
    params_class = BrakeDelayParams
    setup_vars = (
        *initial_state_parameters(20.0),
        Var("initial_command", "parameter", 0.0, "%",
            "brake command held before the start (brake in equilibrium with it)", min=0.0,
            max=100.0),
        route_parameter("seed000_stop", "grade profile"),
    )
    input_vars = (
        Var.input("brake_command", "%", "brake command u (0..100 %)", min=0.0, max=100.0),
    )
    output_vars = (
        Var.output("v", "m/s", "speed"),
        Var.output("s", "m", "position"),
        Var.output("a", "m/s2", "acceleration dv/dt"),
        Var.output("a_c", "m/s2", "acceleration produced by the brakes (<= 0)"),
        Var.output("applied_command", "%", "command acting now: u(t - Td)"),
        Var.output("grade", "‰", "grade at the train position (uphill > 0)"),
    )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path,
                        t0: float = 0.0) -> BrakeDelayTrain:
        route = load_route(values["route"], routes_dir_in(data_dir))
        return cls(build(BrakeDelayParams, values), route, v0=values["v0"], s0=values["s0"],
                   initial_command=values["initial_command"], t0=t0)

    def __init__(self, params: BrakeDelayParams, route: Route, v0: float, s0: float = 0.0,
                 initial_command: float = 0.0, t0: float = 0.0) -> None:
        params.check()
        if v0 < 0:
            raise ValueError(f"v0 = {v0} must be >= 0")
        self.p = params
        self.route = route
        self.t_ticks = to_ticks(t0)
        self.v = float(v0)
        self.s = float(s0)
        # brake acceleration in equilibrium with the command held before t0
        self.a_c = -params.brake_gain * initial_command
        # [tick from which the command acts at the plant input, command %]; sorted by tick
        self.history = dead_time.new_history(initial_command)
        self._delay_ticks = to_ticks(params.brake_delay)
        self._grid_ticks = to_ticks(params.max_step)
        self.a_d = 0.0  # m/s^2, the disturbance acting over the current communication step
        self._draw: tuple[int, float] = (-1, 0.0)  # (interval index, its a_d)

    # -- physics -------------------------------------------------------------------------------
    def resistance_accel(self, v: float, s: float) -> float:
        """a_r = a_w(v) + a_g(s) (m/s^2)."""
        return self.p.davis.force(v) / self.p.mass + self.grade_accel(s)

    def grade_accel(self, s: float) -> float:
        """g i(s)/1000 (m/s^2), the route's grade times ``grade_scale``."""
        return self.p.grade_scale * self.route.grade_accel(s)

    def disturbance_at(self, t: float) -> float:
        """a_d (m/s^2, > 0 decelerates) of the interval containing ``t``: uniform in
        ``[-A, A]``, drawn from ``(disturbance_seed, interval index)`` (a function of the time
        alone); the plant holds it over each communication step from the step's start."""
        p = self.p
        if p.disturbance_amplitude == 0.0:
            return 0.0
        k = int(math.floor(t / p.disturbance_interval + 1e-9))
        if self._draw[0] != k:
            rng = np.random.default_rng([p.disturbance_seed, k])
            self._draw = (k, float(rng.uniform(-p.disturbance_amplitude,
                                               p.disturbance_amplitude)))
        return self._draw[1]

    def _accel(self, a_c: float, v: float, grade_accel: float) -> float:
        a = a_c - self.p.davis.force(max(v, 0.0)) / self.p.mass - grade_accel
        if v <= 0.0 and a <= 0.0:
            return 0.0  # at rest and held: brakes and resistance cannot push it backwards
        return a

    def delayed_command(self, tick: int) -> float:
        """u(t - Td) at plant time ``tick``."""
        return dead_time.delayed(self.history, tick, self._delay_ticks)

    def _lag(self, a_c0: float, a_t: float, dt: float) -> float:
        return a_t + (a_c0 - a_t) * math.exp(-dt / self.p.brake_time_constant)

    def _rk4(self, a_t: float, g: float, h: float) -> tuple[float, float]:
        """RK4 for (v, s) over ``h`` from the current state, exact a_c(t), grade accel ``g``."""
        a_c0, v, s = self.a_c, self.v, self.s
        a_mid = self._lag(a_c0, a_t, 0.5 * h)
        a_end = self._lag(a_c0, a_t, h)
        k1v = self._accel(a_c0, v, g)
        k2v = self._accel(a_mid, v + 0.5 * h * k1v, g)
        k3v = self._accel(a_mid, v + 0.5 * h * k2v, g)
        k4v = self._accel(a_end, v + h * k3v, g)
        k1s, k2s, k3s, k4s = v, v + 0.5 * h * k1v, v + 0.5 * h * k2v, v + h * k3v
        return (v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v),
                s + h / 6.0 * (k1s + 2 * k2s + 2 * k3s + k4s))

    def _next_grade_change(self) -> float:
        starts = self.route.grade.starts
        i = int(np.searchsorted(starts, self.s, side="right"))
        return float(starts[i]) if i < len(starts) else math.inf

    def _substep(self, h: float, a_t: float) -> None:
        """Advance ``h`` seconds with the delayed command constant. Grade changes and the
        instant of stopping are located (Newton on the RK4 solution) and stepped to exactly,
        so the result does not depend on where sub-steps fall."""
        remaining = h
        while remaining > 0.0:
            g = self.grade_accel(self.s) + self.a_d
            boundary = self._next_grade_change()
            dt = remaining
            v1, s1 = self._rk4(a_t, g, dt)
            if s1 > boundary and self.v >= 0.0:
                dt = remaining * (boundary - self.s) / (s1 - self.s)
                for _ in range(4):
                    v1, s1 = self._rk4(a_t, g, dt)
                    dt = min(max(dt - (s1 - boundary) / max(v1, 1e-9), 0.0), remaining)
                v1, _ = self._rk4(a_t, g, dt)
                s1 = boundary
            if v1 < 0.0:
                dt = dt * self.v / (self.v - v1)
                for _ in range(4):
                    v1, s1 = self._rk4(a_t, g, dt)
                    a1 = self._accel(self._lag(self.a_c, a_t, dt), max(v1, 1e-12), g)
                    if a1 >= 0.0:
                        break
                    dt = min(max(dt - v1 / a1, 0.0), remaining)
                _, s1 = self._rk4(a_t, g, dt)
                v1 = 0.0
                if dt <= 0.0:  # already at rest: hold for the rest of the sub-step
                    dt = remaining
            self.a_c = self._lag(self.a_c, a_t, dt)
            self.v, self.s = v1, s1
            remaining -= dt

    # -- co-simulation step ----------------------------------------------------------------------
    def advance(self, t_ticks: int, h_ticks: int, inputs: dict[str, float]) -> None:
        """Advance from ``t_ticks`` by ``h_ticks`` with ``inputs['brake_command']`` (%) held."""
        if t_ticks != self.t_ticks:
            raise ValueError(f"doStep at t={to_seconds(t_ticks)} s but plant is at "
                             f"t={to_seconds(self.t_ticks)} s")
        dead_time.record(self.history, t_ticks, float(inputs["brake_command"]))
        self.a_d = self.disturbance_at(to_seconds(t_ticks))
        now = t_ticks
        for cut in dead_time.substep_ends(t_ticks, h_ticks, [self._grid_ticks], self.history,
                                          self._delay_ticks):
            a_t = -self.p.brake_gain * self.delayed_command(now)
            self._substep(to_seconds(cut - now), a_t)
            now = cut
        self.t_ticks = now
        dead_time.prune(self.history, now, self._delay_ticks)

    def outputs(self) -> dict[str, float]:
        t = self.t_ticks
        return {
            "v": self.v,
            "s": self.s,
            "a": self._accel(self.a_c, self.v, self.grade_accel(self.s) + self.a_d),
            "a_c": self.a_c,
            "applied_command": self.delayed_command(t),
            "grade": self.p.grade_scale * self.route.grade.at(self.s),
        }
