"""Speed-tracking PID with reference-acceleration feedforward (baseline of seeds 001, 002, 004).

The loop works in acceleration units (m/s^2) so that one tuning fits any train; multiply by the
effective mass ``M (1 + gamma)`` (seed 002: ``M (1+gamma) a = F_t - F_b - F_r``) for a force::

    e       = v_ref - v                                          (m/s, > 0 when too slow)
    a_dem   = a_ref + a_res + kp e + ki int(e) dt - kd dv_f/dt   (m/s^2)
    F_dem   = m_eff a_dem                                        (N)

``a_ref`` is the reference acceleration (feedforward of the profile slope), ``a_res`` an optional
estimate of the running resistance per unit mass (resistance feedforward, 0 when unknown).
The derivative acts on the measured speed (no kick at reference steps), filtered by a first-order
lag ``derivative_filter`` (s; 0 = raw backward difference).

Saturation and anti-windup: ``a_dem`` is clamped to ``[a_lo, a_hi]`` where the caller may pass
the limits that hold *now* (e.g. the traction/brake envelope at the current speed divided by the
mass), else ``[accel_min, accel_max]``. The integral is updated by conditional integration: it
is frozen while the demand is saturated and the error would push it further out (the same rule
as :mod:`controllers.pid.stop_pid`).
``rate_limit`` (m/s^3, 0 = off) limits the change of the demand per
sample (jerk limit, ride comfort).

One call of :meth:`SpeedPid.update` per sample; the sample time is a parameter, so the integral
and derivative use the nominal ``T`` (the co-simulation master calls the controller on its grid).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.fmu.declare import Checked, Declared, Var, build, group, param, parameters, sample_time
from cosim.fmu.state import StatefulCore
from plants.route import load_reference, routes_dir_in


@dataclass(frozen=True)
class SpeedPidParams(Checked):
    """Gains in acceleration units; limits in m/s^2. Defaults suit a high-speed EMU at T = 0.2 s."""

    kp: float = param(0.6, "1/s", "m/s2 of demand per m/s of speed error", min=0.0)
    ki: float = param(0.05, "1/s2", "m/s2 of demand per m of integrated error", min=0.0)
    kd: float = param(0.0, "1", "m/s2 of demand per m/s2 of measured acceleration", min=0.0)
    derivative_filter: float = param(0.0, "s", "time constant of the derivative low-pass "
                                     "(0: none)", min=0.0)
    accel_min: float = param(-1.0, "m/s2", "most negative demand")
    accel_max: float = param(1.0, "m/s2", "largest demand")
    rate_limit: float = param(0.0, "m/s3", "largest change of the demand per second "
                              "(0: unlimited)", min=0.0)
    feedforward: bool = param(True, description="add the reference acceleration to the demand")
    sample_time: float = sample_time(0.2)

    def check_relations(self) -> None:
        if not self.accel_min < self.accel_max:
            raise ValueError(f"accel_min = {self.accel_min} must be < accel_max = "
                             f"{self.accel_max}")


class SpeedPid(StatefulCore):
    """Sampled speed PID; :meth:`update` returns the clamped acceleration demand (m/s^2)."""

    state_fields = ("integral", "prev_speed", "derivative", "demand", "error")

    def __init__(self, params: SpeedPidParams) -> None:
        params.check()
        self.p = params
        self.integral = 0.0  # m, integral of the speed error
        self.prev_speed: float | None = None  # m/s, measured speed at the previous sample
        self.derivative = 0.0  # m/s^2, filtered measured acceleration
        self.demand = 0.0  # m/s^2, last (clamped) demand
        self.error = 0.0  # m/s, last speed error v_ref - v

    def reset(self, demand: float = 0.0) -> None:
        """Forget the history; ``demand`` is the output held before the first sample."""
        self.integral = 0.0
        self.prev_speed = None
        self.derivative = 0.0
        self.demand = float(demand)
        self.error = 0.0

    def update(self, v: float, v_ref: float, a_ref: float = 0.0, a_res: float = 0.0,
               a_lo: float | None = None, a_hi: float | None = None) -> float:
        """One sample: speeds in m/s, accelerations in m/s^2. Returns the demand (m/s^2).

        ``a_lo``/``a_hi`` narrow ``[accel_min, accel_max]`` to what the actuators can give now.
        """
        p = self.p
        T = p.sample_time
        lo = p.accel_min if a_lo is None else max(p.accel_min, a_lo)
        hi = p.accel_max if a_hi is None else min(p.accel_max, a_hi)
        lo = min(lo, hi)  # inconsistent limits: the upper one wins
        if p.rate_limit > 0:  # jerk limit, but never outside the actuator limits
            step = p.rate_limit * T
            lo, hi = (min(max(lo, self.demand - step), hi),
                      max(min(hi, self.demand + step), lo))
        error = v_ref - v
        if self.prev_speed is not None:
            raw = (v - self.prev_speed) / T
            if p.derivative_filter > 0:
                alpha = T / (p.derivative_filter + T)
                self.derivative += alpha * (raw - self.derivative)
            else:
                self.derivative = raw
        self.prev_speed = v
        integral = self.integral + error * T
        ff = (a_ref if p.feedforward else 0.0) + a_res
        unclamped = ff + p.kp * error + p.ki * integral - p.kd * self.derivative
        demand = min(max(unclamped, lo), hi)
        pushing_out = (unclamped > hi and error > 0) or (unclamped < lo and error < 0)
        if not pushing_out:
            self.integral = integral
        self.demand = demand
        self.error = error
        return demand


@dataclass(frozen=True)
class DistributedSpeedPidParams(Checked):
    """Speed PID for a multi-unit EMU (seeds 001, 004): one PID, force shared by the units."""

    pid: SpeedPidParams = group(SpeedPidParams(), "")
    units: int = 1  # number of power units / cars that receive a force (the FMU's size)
    mass: float = param(479.5e3, "kg", "effective train mass M (1 + gamma)", min=1.0)
    hold_accel: float = param(-0.5, "m/s2", "brake demand holding the train at the final stop",
                              max=0.0)
    stop_speed: float = param(0.3, "m/s", "below this speed with a zero reference the holding "
                              "brake is applied", min=0.0)

    def check_relations(self) -> None:
        self.pid.check_relations()
        if self.units < 1:
            raise ValueError(f"units = {self.units} must be >= 1")


class DistributedSpeedPid(StatefulCore, Declared):
    """Tracks a reference profile and distributes the force demand over the units.

    Inputs: ``v`` (m/s) and ``s`` (m, head position) of the train, and per unit the force the
    plant can give now, ``traction_limit[i]`` and ``brake_limit[i]`` (N, both >= 0). The
    reference ``profile`` (:class:`plants.route.ReferenceProfile`) is looked up by ``s`` for a
    speed-distance profile and by time for a speed-time one. The total demand
    ``F = M a_dem`` is shared in proportion to each unit's available force: traction only on
    units that can pull (so trailers never brake while the train pulls, seed 004's delta),
    braking on all. The summed limits bound the PID (anti-windup against the real envelope).
    At the end of the profile (zero reference, speed below ``stop_speed``) it holds the brake.
    """

    state_fields = ("forces", "v_ref", "a_ref", "pid")
    setup_vars = (Var("reference", "parameter", "jinan_xuzhou_east_reference", description=
                      "bundled reference profile name or path of a CSV/TOML profile"),)
    output_vars = (
        Var.output("force_demand", "N", "total force demand M a_dem"),
        Var.output("accel_demand", "m/s2", "acceleration demand a_dem"),
        Var.output("v_ref", "m/s", "reference speed"),
        Var.output("a_ref", "m/s2", "reference acceleration"),
        Var.output("speed_error", "m/s", "v - v_ref"),
    )

    @classmethod
    def declarations(cls, units: int = 1) -> tuple[Var, ...]:
        """Parameters, inputs and outputs for ``units`` units (indexed ``force[i]``...)."""
        indices = range(1, units + 1)
        return (
            *parameters(DistributedSpeedPidParams()),
            *cls.setup_vars,
            Var.input("v", "m/s", "measured train speed"),
            Var.input("s", "m", "measured head position"),
            *[Var.input(f"traction_limit[{i}]", "N", f"traction force unit {i} can give now")
              for i in indices],
            *[Var.input(f"brake_limit[{i}]", "N", f"brake force unit {i} can give now")
              for i in indices],
            *[Var.output(f"force[{i}]", "N", f"force command of unit {i}") for i in indices],
            *cls.output_vars,
        )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path, t0: float = 0.0,
                        units: int = 1) -> DistributedSpeedPid:
        params = build(DistributedSpeedPidParams(units=units), values)
        profile = load_reference(values["reference"], routes_dir=routes_dir_in(data_dir))
        return cls(params, profile)

    def __init__(self, params: DistributedSpeedPidParams, profile) -> None:
        params.check()
        self.p = params
        self.profile = profile
        self.pid = SpeedPid(params.pid)
        self.forces = [0.0] * params.units
        self.v_ref = 0.0
        self.a_ref = 0.0

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        p = self.p
        n = p.units
        x = inputs["s"] if self.profile.kind == "distance" else t
        self.v_ref = v_ref = self.profile.speed(x)
        self.a_ref = a_ref = self.profile.accel(x)
        v = inputs["v"]
        trac = [max(float(inputs[f"traction_limit[{i + 1}]"]), 0.0) for i in range(n)]
        brake = [max(float(inputs[f"brake_limit[{i + 1}]"]), 0.0) for i in range(n)]
        total_trac, total_brake = sum(trac), sum(brake)
        demand = self.pid.update(v, v_ref, a_ref, a_lo=-total_brake / p.mass,
                                 a_hi=total_trac / p.mass)
        if v_ref <= 0.0 and a_ref <= 0.0 and v < p.stop_speed:
            demand = max(p.hold_accel, -total_brake / p.mass)  # hold at the stop
            self.pid.demand = demand
        force = p.mass * demand
        if force >= 0.0:
            share = trac if total_trac > 0 else [0.0] * n
            total = total_trac
        else:
            share = brake
            total = total_brake
        self.forces = [force * si / total if total > 0 else 0.0 for si in share]
        return self.outputs(), 1

    def outputs(self) -> dict[str, float]:
        out = {f"force[{i + 1}]": f for i, f in enumerate(self.forces)}
        demand = self.pid.demand
        out.update({"force_demand": self.p.mass * demand, "accel_demand": demand,
                    "v_ref": self.v_ref, "a_ref": self.a_ref, "speed_error": -self.pid.error})
        return out
