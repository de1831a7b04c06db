"""Point-mass train and line for optimal train control, in SI and per unit effective mass.

Motion along the line (position ``s``, speed ``v``, kinetic energy per unit effective mass
``E = v^2 / 2``)::

    dE/ds = (F - R(v) - m g w(s) / 1000) / m_eff,        m_eff = m (1 + rho)

with ``R(v) = a + b v + c v^2`` the Davis resistance (:class:`plants.resistance.Davis`),
``w(s)`` the additional specific resistance in N/kN of :class:`plants.route.Route` (grade in
permille, uphill > 0, plus curves ``600 / R`` and tunnels as an equivalent grade) and ``F`` the
force at the wheel: traction ``0 <= F <= min(F_t, P_t / v)`` (none above the train's top
speed), braking ``-F = B_r + B_f`` with regenerative ``0 <= B_r <= min(F_r, P_r / v)`` and
friction ``0 <= B_f <= F_f``; optional comfort limits ``-d_max <= dv/dt <= a_max``.

Energy (the accounting of seed 003's eq. 9 without its auxiliary term, which the schedule
fixes): ``J = int F_+ ds / eta_t - eta_r int B_r ds`` (traction work over the traction
efficiency, less the regenerated share of the regenerative braking work).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numba
import numpy as np

from plants.crh3 import Crh3Params
from plants.resistance import Davis
from plants.route import GRAVITY, Route, StepProfile

# controls of the force laws (:func:`control_force`)
POWER, HOLD, COAST, BRAKE, REGEN = 0, 1, 2, 3, 4


# The laws of the model, once: per unit effective mass (m/s2) at speed ``v`` (m/s) for the
# train's vector ``p`` (:attr:`Train.vector`: m_eff, Davis a, b, c, F_t, P_t, F_r, P_r, F_f,
# v_top, a_max, d_max). Compiled (numba) for the switching points' integration; the train's
# numpy methods apply them element by element.
@numba.njit(cache=True)
def resistance_at(v: float, p: np.ndarray) -> float:
    """Davis resistance ``(a + b v + c v^2) / m_eff``."""
    return (p[1] + (p[2] + p[3] * v) * v) / p[0]


@numba.njit(cache=True)
def traction_at(v: float, p: np.ndarray) -> float:
    """Largest traction ``min(F_t, P_t / v) / m_eff``, none from the top speed on."""
    return min(p[4], p[5] / max(v, 1e-9)) / p[0] if v < p[9] else 0.0


@numba.njit(cache=True)
def regen_at(v: float, p: np.ndarray) -> float:
    """Largest regenerative brake force ``min(F_r, P_r / v) / m_eff``."""
    return min(p[6], p[7] / max(v, 1e-9)) / p[0]


@numba.njit(cache=True)
def brake_at(v: float, p: np.ndarray) -> float:
    """Largest brake force, regenerative and friction: ``regen_at + F_f / m_eff``."""
    return regen_at(v, p) + p[8] / p[0]


@numba.njit(cache=True)
def control_force(control: int, v: float, g: float, p: np.ndarray) -> float:
    """The force of a control of the maximum principle at ``v`` on additional resistance ``g``
    (m/s2): maximum traction (within the comfort acceleration), holding the speed (partial
    traction or braking within the envelopes), coasting, maximum braking and maximum
    regenerative braking alone (both within the comfort deceleration, never a traction)."""
    r = resistance_at(v, p)
    if control == POWER:
        return min(traction_at(v, p), p[10] + r + g)
    if control == HOLD:
        return min(max(r + g, -brake_at(v, p)), traction_at(v, p))
    if control == COAST:
        return 0.0
    if control == BRAKE:
        return min(max(-brake_at(v, p), r + g - p[11]), 0.0)
    return min(max(-regen_at(v, p), r + g - p[11]), 0.0)


@numba.njit(cache=True)
def _law_each(law: int, v: np.ndarray, p: np.ndarray) -> np.ndarray:
    out = np.empty(v.size)
    for i in range(v.size):
        if law == 0:
            out[i] = resistance_at(v[i], p)
        elif law == 1:
            out[i] = traction_at(v[i], p)
        elif law == 2:
            out[i] = regen_at(v[i], p)
        else:
            out[i] = brake_at(v[i], p)
    return out


def _law(law: int, v: np.ndarray | float, p: np.ndarray) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    out = _law_each(law, np.ascontiguousarray(a.ravel()), p).reshape(a.shape)
    return out[()] if out.ndim == 0 else out  # a scalar for a scalar, as numpy gives


@dataclass(frozen=True)
class Train:
    """A train for optimal control (SI). Forces in N, powers in W, speeds in m/s."""

    name: str
    mass: float  # kg, m
    rotating_mass_factor: float  # rho: m_eff = m (1 + rho)
    davis: Davis
    max_traction_force: float  # F_t
    max_traction_power: float  # P_t (at the wheel)
    max_regen_force: float  # F_r
    max_regen_power: float  # P_r
    max_friction_force: float = 0.0  # F_f (pneumatic / friction brake, no energy back)
    max_speed: float = math.inf  # no traction above, and the speed never exceeds it
    max_accel: float = math.inf  # m/s2, comfort limit on dv/dt
    max_decel: float = math.inf  # m/s2, comfort limit on -dv/dt
    traction_efficiency: float = 1.0  # eta_t
    regen_efficiency: float = 0.0  # eta_r
    length: float = 0.0  # m (information; the model is a point mass)

    def __post_init__(self) -> None:
        for name in ("mass", "max_traction_force", "max_traction_power"):
            if not getattr(self, name) > 0:
                raise ValueError(f"train {self.name!r}: {name} must be > 0")
        if not 0 < self.traction_efficiency <= 1 or not 0 <= self.regen_efficiency <= 1:
            raise ValueError(f"train {self.name!r}: efficiencies must be in (0, 1] and [0, 1]")
        if self.max_regen_force + self.max_friction_force <= 0 and self.max_decel > 0:
            raise ValueError(f"train {self.name!r} has no brake")

    @property
    def effective_mass(self) -> float:
        """m (1 + rho) (kg)."""
        return self.mass * (1.0 + self.rotating_mass_factor)

    @classmethod
    def from_crh3(cls, params: Crh3Params | None = None, traction_share: float = 1.0,
                  max_accel: float = math.inf, max_decel: float = math.inf) -> Train:
        """The CRH3 of seed 003 (:class:`plants.crh3.Crh3Params`): all its braking is
        regenerative (eq. 9 feeds back eta_b of the whole braking work), its brake envelope
        ``min(F_b, P_b / v)``; ``traction_share`` scales the traction envelope (the planning
        margin of :mod:`controllers.common.speed_profiles`)."""
        p = params or Crh3Params()
        return cls(name="CRH3 (seed 003)", mass=p.mass,
                   rotating_mass_factor=p.rotating_mass_factor, davis=p.davis,
                   max_traction_force=traction_share * p.max_traction_force,
                   max_traction_power=traction_share * p.max_traction_power,
                   max_regen_force=p.max_brake_force, max_regen_power=p.max_brake_power,
                   max_speed=p.max_speed, max_accel=max_accel, max_decel=max_decel,
                   traction_efficiency=p.motor_efficiency,
                   regen_efficiency=p.regen_efficiency, length=p.length)

    def with_limits(self, **changes: float) -> Train:
        return replace(self, **changes)

    @functools.cached_property
    def vector(self) -> np.ndarray:
        """The train as the compiled laws take it: m_eff, Davis a, b, c, F_t, P_t, F_r, P_r,
        F_f, top speed, a_max, d_max (SI)."""
        d = self.davis
        return np.array([self.effective_mass, d.a, d.b, d.c, self.max_traction_force,
                         self.max_traction_power, self.max_regen_force, self.max_regen_power,
                         self.max_friction_force, self.max_speed, self.max_accel,
                         self.max_decel], dtype=float)

    # -- per unit effective mass (m/s2), element by element over v -------------------------
    def resistance(self, v: np.ndarray) -> np.ndarray:
        """Davis resistance per unit effective mass (m/s2) (:func:`resistance_at`)."""
        return _law(0, v, self.vector)

    def resistance_slope(self, v: np.ndarray | float) -> np.ndarray | float:
        """d/dv of :meth:`resistance` (1/s)."""
        return (self.davis.b + 2.0 * self.davis.c * v) / self.effective_mass

    def traction_limit(self, v: np.ndarray) -> np.ndarray:
        """Largest traction force per unit effective mass (m/s2): min(F_t, P_t / v)
        (:func:`traction_at`)."""
        return _law(1, v, self.vector)

    def regen_limit(self, v: np.ndarray) -> np.ndarray:
        """Largest regenerative brake force per unit effective mass (m/s2)
        (:func:`regen_at`)."""
        return _law(2, v, self.vector)

    def brake_limit(self, v: np.ndarray) -> np.ndarray:
        """Largest brake force (regenerative + friction) per unit effective mass (m/s2)
        (:func:`brake_at`)."""
        return _law(3, v, self.vector)

    def grade_accel(self, w_nkn: np.ndarray | float) -> np.ndarray | float:
        """Force of an additional specific resistance ``w`` (N/kN) per unit effective mass."""
        return GRAVITY * np.asarray(w_nkn) / 1000.0 * self.mass / self.effective_mass

    def psi(self, v: float) -> float:
        """psi(v) = v^2 R'(v) per unit effective mass (m^2/s^3): the Pontryagin holding-speed
        function (Howlett & Pudney 1995; Albrecht et al. 2016)."""
        return v * v * float(self.resistance_slope(v))


@dataclass(frozen=True)
class Section:
    """One run from a stop to the next: the line between ``start`` and ``end`` (m, line
    positions) with the additional resistance ``w`` (N/kN) and the speed limit (m/s)."""

    route: Route
    start: float
    end: float

    def __post_init__(self) -> None:
        if not self.end > self.start:
            raise ValueError(f"section end {self.end} must be beyond its start {self.start}")

    @property
    def length(self) -> float:
        return self.end - self.start

    def breakpoints(self) -> np.ndarray:
        """Positions (m, from the section start) where w or the speed limit changes."""
        pts = [self.route.additional.starts[1:], self.route.speed_limit.starts[1:]]
        x = np.concatenate(pts) - self.start
        return np.unique(x[(x > 0) & (x < self.length)])

    def grid(self, ds: float) -> np.ndarray:
        """Positions (m from the section start): every breakpoint and a uniform grid of at most
        ``ds`` between them."""
        knots = np.concatenate(([0.0], self.breakpoints(), [self.length]))
        out = [np.array([0.0])]
        for a, b in zip(knots[:-1], knots[1:]):
            n = max(int(math.ceil((b - a) / ds - 1e-9)), 1)
            out.append(np.linspace(a, b, n + 1)[1:])
        return np.concatenate(out)

    def w_on(self, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
        """Mean additional resistance (N/kN) over each step ``[x0, x1]`` (m from the start)."""
        prof: StepProfile = self.route.additional
        xs, cum = prof._cumulative  # exact integral of the step profile
        a = np.interp(x0 + self.start, xs, cum)
        b = np.interp(x1 + self.start, xs, cum)
        return (b - a) / (x1 - x0)

    def limit_on(self, x0: np.ndarray, x1: np.ndarray, train: Train) -> np.ndarray:
        """Speed limit (m/s) on each step (the grid has the limit's changes as nodes)."""
        mid = 0.5 * (x0 + x1) + self.start
        return np.minimum(self.route.speed_limit.at_array(mid), train.max_speed)
