"""CRH3 high-speed train as a single mass with an energy account (seed 003, eqs. 1-9).

The paper treats the train as a point mass (sec. 1.1)::

    dv/dt = c f_c,   c = g / (1000 (1 + gamma))                              (eqs. 1-2)
    f_c = u - w0 - w_r - w_s - w_g          (N/kN: force per unit weight)    (eq. 3)
    w0 = 0.76 + 0.00636 v + 0.000115 v^2    (v in km/h, Table 1)             (eq. 4)
    w_r = 600 / R,  w_s = 0.00013 L_s,  w_g = g sin(atan(h_i / s_i))         (eqs. 5-7)

In SI, with ``M = mass`` and ``M (1 + gamma)`` the mass with the rotating parts::

    M (1 + gamma) dv/dt = F - W0(v) - M g (w_r + w_s + w_g) / 1000,   ds/dt = v

Readings (stated, not printed in the paper): eq. 2 is garbled in the text; ``c = g / (1000
(1 + gamma))`` is the standard Chinese traction-calculation constant (0.00981 / (1 + gamma))
and ``gamma`` = 0.06 (EMU value of the traction rules). Eq. 5 is printed ``600 g / R``; in N/kN
it is ``600 / R``. Eq. 7 ``g sin(atan(h_i/s_i))`` is the grade force per unit *mass*; per unit
weight in N/kN it is ``1000 sin(atan(i/1000)) ~ i`` (permille), which the route module uses
(the two differ by < 0.02 % at 20 permille). ``W0`` is the Table 1 formula for 980 t in newtons
(``plants.resistance.Davis.from_n_per_kn_kmh``). Additional resistances come from
:mod:`plants.route` (point mass, or averaged over ``length`` if > 0).

Traction / brake (not in the paper; CRH3 public figures, see :func:`Crh3Params`): the force
``F`` follows the command ``u`` (N, traction > 0, braking < 0; first clipped to the largest
forces) through a first-order lag (``traction_time_constant`` while the target is >= 0, else
``brake_time_constant``) and acts clipped to the envelope at the present speed: traction
``min(F_t, P_t / v)`` up to ``max_speed`` (none above), braking ``min(F_b, P_b / v)``.

Energy (eq. 9), each integral kept separately in joules::

    energy_traction = int(max(F, 0) v dt) / eta_M
    energy_regen    = eta_b int(max(-F, 0) v dt)
    energy_aux      = e0 (t - t0)
    energy_net      = energy_traction - energy_regen + energy_aux
    brake_work      = int(max(-F, 0) v dt)          (Table 2's positive braking energy)

The work integrals of resistance (basic + curve + tunnel) and grade are kept too, so the
mechanical balance ``W_traction = dKE + W_grade + W_resistance + W_brake`` can be checked
(``tests/test_crh3.py`` does, with the bound derived there).

Integration: sub-steps no longer than ``max_step`` on a grid anchored at absolute multiples of
``max_step`` (:func:`plants.dead_time.substep_ends`), so results do not depend on the
communication step; in each sub-step the lag is solved exactly and (v, s, work integrals) use
RK4. The train does not roll back: at rest it stays until the traction exceeds the grade and
the static resistance ``W0(0)``; the instant of stopping inside a sub-step is located (Newton on
the RK4 solution).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.fmu.declare import Checked, Declared, Var, build, group, param
from cosim.fmu.state import StatefulCore, to_seconds, to_ticks
from plants import dead_time
from plants.resistance import KMH, Davis
from plants.route import (
    GRAVITY,
    Route,
    StepProfile,
    initial_state_parameters,
    load_route,
    route_parameter,
    routes_dir_in,
)

MASS = 980e3  # kg, Table 1
# CRH3C (Velaro CN, 8 cars 4M4T, about 424 t loaded): 8,800 kW at the wheel, 283 kN starting
# effort (the figures of plants/emu.py). Table 1's 980 t train is given the CRH3C's power and
# effort per tonne: 20.34 MW and 654 kN; its balancing speed on level track with the Table 1
# resistance is then about 380 km/h, the paper's maximum speed.
CRH3C_MASS = 424e3
TRACTION_FORCE = 283e3 * MASS / CRH3C_MASS
TRACTION_POWER = 8.8e6 * MASS / CRH3C_MASS


def _rest(value: float) -> float:
    return value if value > 0.0 else 0.0


@dataclass(frozen=True)
class Crh3Params(Checked):
    """Train data in SI (defaults: seed 003 Table 1 and public CRH3 figures)."""

    mass: float = param(MASS, "kg", "train mass M (Table 1: 980 t)", min=1.0)
    rotating_mass_factor: float = param(0.06, "1", "gamma: M (1 + gamma) dv/dt (eq. 2)",
                                        min=0.0)
    davis: Davis = group(Davis.from_n_per_kn_kmh(0.76, 0.00636, 0.000115,
                                                 MASS * GRAVITY / 1e3), "davis_")
    max_traction_force: float = param(TRACTION_FORCE, "N", "F_t: traction force at low speed",
                                      min=0.0)
    max_traction_power: float = param(TRACTION_POWER, "W", "P_t: traction power at the wheel "
                                      "(traction limit min(F_t, P_t / v))", min=0.0)
    max_speed: float = param(380.0 * KMH, "m/s", "no traction above this speed (Table 1: "
                             "380 km/h)", min=0.0)
    max_brake_force: float = param(0.9 * MASS, "N", "F_b: brake force at low speed "
                                   "(0.9 m/s2 x M)", min=0.0)
    max_brake_power: float = param(0.7 * MASS * 300.0 * KMH, "W", "P_b: brake power (brake "
                                   "limit min(F_b, P_b / v); 0.7 m/s2 x M at 300 km/h)",
                                   min=0.0)
    traction_time_constant: float = param(0.5, "s", "first-order lag of the force while the "
                                          "target is traction", min=1e-6)
    brake_time_constant: float = param(0.5, "s", "first-order lag of the force while the "
                                       "target is braking", min=1e-6)
    motor_efficiency: float = param(0.9, "1", "eta_M of eq. 9", min=1e-6, max=1.0)
    regen_efficiency: float = param(0.8, "1", "eta_b of eq. 9 (share of the braking work "
                                    "fed back)", min=0.0, max=1.0)
    aux_power: float = param(4e5, "W", "e0 of eq. 9: auxiliary power", min=0.0)
    length: float = param(0.0, "m", "train length over which grade, curve and tunnel "
                          "resistance are averaged (0: point mass, as the paper)", min=0.0)
    max_step: float = param(0.1, "s", "longest internal integration sub-step", min=1e-6)

    @property
    def effective_mass(self) -> float:
        """M (1 + gamma) (kg)."""
        return self.mass * (1.0 + self.rotating_mass_factor)

    def traction_limit(self, v: float) -> float:
        """Largest traction force (N) at speed ``v`` (m/s): min(F_t, P_t/v), 0 above max."""
        v = abs(v)
        if v > self.max_speed:
            return 0.0
        return min(self.max_traction_force, self.max_traction_power / max(v, 1e-9))

    def brake_limit(self, v: float) -> float:
        """Largest brake force (N, >= 0) at speed ``v`` (m/s): min(F_b, P_b/v)."""
        return min(self.max_brake_force, self.max_brake_power / max(abs(v), 1e-9))


class _Lookup:
    """Fast scalar reads of a step profile (N/kN or permille): point value or length mean."""

    def __init__(self, profile: StepProfile, length: float) -> None:
        self.profile = profile
        self.length = length
        self.starts = profile.starts.tolist()
        self.values = profile.values.tolist()

    def __call__(self, s: float) -> float:
        if self.length > 0.0:
            return self.profile.mean_over_scalar(s, self.length)
        return self.values[bisect.bisect_right(self.starts, s) - 1]


class Crh3Train(StatefulCore, Declared):
    """Single-mass CRH3 with traction/brake lag, envelope and energy account (seed 003)."""

    state_fields = ("t_ticks", "v", "s", "force", "command", "held", "work_traction",
                    "work_brake", "work_resistance", "work_grade")
    params_class = Crh3Params
    setup_vars = (
        *initial_state_parameters(0.0),
        route_parameter("seed003_crh3", "grade, curves, tunnels, speed limits"),
    )
    input_vars = (
        Var.input("force", "N", "force demand (traction > 0, braking < 0)"),
    )
    output_vars = (
        Var.output("v", "m/s", "speed"),
        Var.output("s", "m", "position"),
        Var.output("a", "m/s2", "acceleration dv/dt"),
        Var.output("applied_force", "N", "force acting now, after lag and envelope "
                   "(traction > 0)"),
        Var.output("traction_limit", "N", "largest traction force at the present speed"),
        Var.output("brake_limit", "N", "largest brake force at the present speed (>= 0)"),
        Var.output("speed_limit", "m/s", "line speed limit at the train position"),
        Var.output("grade", "‰", "grade at the train position (uphill > 0)"),
        Var.output("power", "W", "electrical power of eq. 9: traction / eta_M - eta_b "
                   "braking + e0"),
        Var.output("energy_traction", "J", "int(F v dt) / eta_M since the start (eq. 9)"),
        Var.output("energy_regen", "J", "eta_b int(B v dt) since the start (eq. 9)"),
        Var.output("energy_aux", "J", "e0 (t - t0) (eq. 9)"),
        Var.output("energy_net", "J", "energy_traction - energy_regen + energy_aux (eq. 9)"),
        Var.output("brake_work", "J", "int(B v dt) since the start: the work of the brakes, "
                   "fed back and lost (the positive braking energy of seed 003's Table 2)"),
    )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path,
                        t0: float = 0.0) -> Crh3Train:
        route = load_route(values["route"], routes_dir_in(data_dir))
        return cls(build(Crh3Params, values), route, v0=values["v0"], s0=values["s0"], t0=t0)

    def __init__(self, params: Crh3Params, route: Route, v0: float = 0.0, s0: float = 0.0,
                 t0: float = 0.0) -> None:
        params.check()
        if not v0 >= 0:
            raise ValueError(f"v0 = {v0} must be >= 0")
        self.p = params
        self.route = route
        self.t0_ticks = self.t_ticks = to_ticks(t0)
        self.v = float(v0)
        self.s = float(s0)
        self.force = 0.0  # N, lagged force before the envelope
        self.command = 0.0  # N, last force demand
        self.held = self.v <= 0.0
        self.work_traction = 0.0  # J, int(max(F, 0) v dt)
        self.work_brake = 0.0  # J, int(max(-F, 0) v dt)
        self.work_resistance = 0.0  # J, basic + curve + tunnel
        self.work_grade = 0.0  # J, int(M g w_g / 1000 v dt)
        self._grid = to_ticks(params.max_step)
        self._m_eff = params.effective_mass
        self._mg = params.mass * GRAVITY / 1000.0  # N per (N/kN)
        self._grade = _Lookup(route.grade, params.length)
        self._other = _Lookup(StepProfile.sum(route.curve_resistance, route.tunnel_resistance),
                              params.length)
        self._speed_limit = _Lookup(route.speed_limit, 0.0)

    # -- physics ----------------------------------------------------------------------------
    def envelope(self, force: float, v: float) -> float:
        """``force`` (N) clipped to the envelope at speed ``v``."""
        p = self.p
        if force >= 0.0:
            return min(force, p.traction_limit(v))
        return max(force, -p.brake_limit(v))

    def height(self, s: float) -> float:
        """Elevation (m) of the train at ``s`` relative to the line origin: int i/1000 ds (of
        the length-mean grade when ``length`` > 0), exact for step grades."""
        xs, cum = self.route.grade._cumulative
        if self.p.length <= 0.0:
            return _interp(s, xs, cum) / 1000.0
        # mean over [s - l, s] of the height: d/ds = (H(s) - H(s - l)) / l = mean grade
        return _integral_of_interp(s, self.p.length, xs, cum) / 1000.0

    def _rates(self, force: float, v: float, s: float) -> tuple[float, ...]:
        """(dv/dt, ds/dt, traction power, brake power, resistance power, grade power)."""
        p = self.p
        vp = _rest(v)
        applied = self.envelope(force, vp)
        grade = self._mg * self._grade(s)
        other = self._mg * self._other(s)
        resist = p.davis.a + (p.davis.b + p.davis.c * vp) * vp + other
        acc = (applied - resist - grade) / self._m_eff
        if v <= 0.0 and acc < 0.0:
            acc = 0.0
        return (acc, vp, _rest(applied) * vp, _rest(-applied) * vp, resist * vp, grade * vp)

    def _lagged(self, target: float, dt: float) -> float:
        tau = (self.p.traction_time_constant if target >= 0.0
               else self.p.brake_time_constant)
        return target + (self.force - target) * math.exp(-dt / tau)

    def _rk4(self, target: float, h: float) -> tuple[float, ...]:
        """(v, s, dW_t, dW_b, dW_r, dW_g) after ``h`` from the present state."""
        v, s = self.v, self.s
        f0, fm, f1 = self.force, self._lagged(target, 0.5 * h), self._lagged(target, h)
        k1 = self._rates(f0, v, s)
        k2 = self._rates(fm, v + 0.5 * h * k1[0], s + 0.5 * h * k1[1])
        k3 = self._rates(fm, v + 0.5 * h * k2[0], s + 0.5 * h * k2[1])
        k4 = self._rates(f1, v + h * k3[0], s + h * k3[1])
        d = [h / 6.0 * (a + 2.0 * b + 2.0 * c + e) for a, b, c, e in zip(k1, k2, k3, k4)]
        return (v + d[0], s + d[1], d[2], d[3], d[4], d[5])

    def _can_start(self, force: float) -> bool:
        """At rest: does the traction overcome grade, curve/tunnel and static resistance?"""
        drive = self.envelope(force, 0.0) - self._mg * (self._grade(self.s) + self._other(self.s))
        return drive > self.p.davis.a

    def _substep(self, h: float, target: float) -> None:
        if self.held:
            if not self._can_start(self.force):
                self.force = self._lagged(target, h)
                return
            self.held = False
        v1, s1, wt, wb, wr, wg = self._rk4(target, h)
        dt = h
        if v1 < 0.0:  # stops inside the sub-step: find the instant (Newton on v(dt) = 0)
            dt = h * self.v / (self.v - v1)
            for _ in range(3):
                v1, *_rest_ = self._rk4(target, dt)
                acc = self._rates(self._lagged(target, dt), max(v1, 1e-12), s1)[0]
                if acc >= 0.0:
                    break
                dt = min(max(dt - v1 / acc, 0.0), h)
            v1, s1, wt, wb, wr, wg = self._rk4(target, dt)
            v1 = 0.0
            self.held = True
        self.v, self.s = v1, s1
        self.work_traction += wt
        self.work_brake += wb
        self.work_resistance += wr
        self.work_grade += wg
        self.force = self._lagged(target, h)  # the lag runs on through a stop

    # -- co-simulation step -----------------------------------------------------------------
    def advance(self, t_ticks: int, h_ticks: int, inputs: dict[str, float]) -> None:
        """Advance from ``t_ticks`` by ``h_ticks`` with ``inputs['force']`` (N) held."""
        if t_ticks != self.t_ticks:
            raise ValueError(f"doStep at t={to_seconds(t_ticks)} s but plant is at "
                             f"t={to_seconds(self.t_ticks)} s")
        p = self.p
        self.command = float(inputs["force"])
        target = min(max(self.command, -p.max_brake_force), p.max_traction_force)
        now = t_ticks
        for cut in dead_time.substep_ends(t_ticks, h_ticks, [self._grid]):
            self._substep(to_seconds(cut - now), target)
            now = cut
        self.t_ticks = now

    # -- outputs ----------------------------------------------------------------------------
    @property
    def applied_force(self) -> float:
        """Force acting now (N): the lagged force within the envelope (none while held)."""
        if self.held and not self._can_start(self.force):
            return 0.0 if self.force >= 0.0 else self.envelope(self.force, 0.0)
        return self.envelope(self.force, self.v)

    def kinetic_energy(self) -> float:
        """0.5 M (1 + gamma) v^2 (J)."""
        return 0.5 * self._m_eff * self.v * self.v

    def energies(self) -> dict[str, float]:
        """Eq. 9 terms (J) since the start."""
        p = self.p
        trac = self.work_traction / p.motor_efficiency
        regen = p.regen_efficiency * self.work_brake
        aux = p.aux_power * to_seconds(self.t_ticks - self.t0_ticks)
        return {"energy_traction": trac, "energy_regen": regen, "energy_aux": aux,
                "energy_net": trac - regen + aux, "brake_work": self.work_brake}

    def outputs(self) -> dict[str, float]:
        p = self.p
        applied = self.applied_force
        acc = 0.0 if self.held else self._rates(self.force, self.v, self.s)[0]
        v = self.v
        return {
            "v": v,
            "s": self.s,
            "a": acc,
            "applied_force": applied,
            "traction_limit": p.traction_limit(v),
            "brake_limit": p.brake_limit(v),
            "speed_limit": self._speed_limit(self.s),
            "grade": self._grade(self.s),
            "power": (_rest(applied) * v / p.motor_efficiency
                      - p.regen_efficiency * _rest(-applied) * v + p.aux_power),
            **self.energies(),
        }


def _interp(x: float, xs: Any, ys: Any) -> float:
    import numpy as np

    return float(np.interp(x, xs, ys))


def _integral_of_interp(s: float, length: float, xs: Any, cum: Any) -> float:
    """Mean over [s - length, s] of the piecewise-linear function (xs, cum)."""
    import numpy as np

    grid = np.concatenate(([s - length], xs[(xs > s - length) & (xs < s)], [s]))
    vals = np.interp(grid, xs, cum)
    return float(np.trapezoid(vals, grid) / length)
