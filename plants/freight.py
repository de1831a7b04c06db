"""Heavy freight train: one mass per vehicle, draft-gear couplers, traction lag, air-brake wave.

Seed 002 (Li et al. 2022): HXD1 locomotive + 108 loaded C80 wagons (Table 1: 200 t / 35.2 m,
20 t tare + 77 t load / 12 m; 10,676 t, 1,331.2 m). Vehicle ``i`` (1 = locomotive at the head)
has its front at ``x_i`` (m along the line) and speed ``v_i`` (m/s)::

    m_i (1 + gamma_i) dv_i/dt = F_t [i = 1] - F_b,i - F_r,i + f_{i-1} - f_i     (eqs. 1, 7)
    f_j = k d_j + c (v_j - v_{j+1}),   d_j = x_j - l_j - x_{j+1}

``f_j`` is the force of coupler ``j`` (between vehicles ``j`` and ``j+1``), positive in draft
(tension), negative in buff. Couplers are linear spring-dampers without slack: the default
stiffness is the secant stiffness of two MT-2 friction draft gears in series (public MT-2
figures: 83 mm travel, 2.27 MN at full travel, so 2.27 MN / 0.166 m = 1.37e7 N/m per coupling);
the damping ``c`` = 1.5e6 N s/m is an equivalent viscous damping of friction draft gears
(friction forces of some hundred kN at relative speeds of a few tenths of m/s). Even so the
slowest whole-train mode (period 18.7 s, omega = 0.34 /s) is lightly damped: its damping ratio
is c omega / (2 k) = 0.02 (it decays as exp(-t / 160 s); measured in
``tests/test_freight_reference.py``), against 0.004 with a smaller value (e.g. 20 % of critical
for the two-wagon mode, 3e5): these are the head-to-tail stretch oscillations the seed-002 notes
measure. Slack is optional (``coupler_slack``, the
total free play of a coupling, default 0): the paper's eq. (1) has none and speed tracking
hardly depends on it, but run-in/run-out peaks do. With slack the draft gear (spring and
damper) acts only beyond +-slack/2; engagement is decided at each sub-step start (contact is
found at most one sub-step late, so peaks are resolved to ``max_step``; the contact stiffness
must satisfy ``k max_step^2 / (m/2) <= 0.5``, checked, or the late contact pumps energy in).

Resistance per vehicle (N/kN of its weight ``m g / 1000`` kN, v in km/h; eqs. 2-6):

* basic: locomotive ``1.40 + 0.038 v + 0.000300 v^2`` (eq. 3), loaded wagon
  ``0.92 + 0.0048 v + 0.000125 v^2`` — the paper prints ``1.25e-5`` for the ``v^2`` term; we use
  the Chinese traction-rules value 0.000125 (TB/T 1407) as SPEC says;
* additional (grade ``i``, curve ``600/R``, tunnel): by the share of the vehicle's length on each
  segment, :meth:`plants.route.Route.additional` (eq. 5).

Basic resistance and brake forces oppose motion; near standstill they are regularised
(``stiction_speed``) so that they never push a train backwards. As in the EMU, static friction
is explicit: once the mean speed is within ``stiction_speed`` of zero and the brake shoes (at
their standstill friction coefficient) plus the constant resistance terms can hold the train
against traction and grade, it is held at rest (all speeds zero) until they no longer can.

Traction / electric brake (locomotive only): the demand ``force_demand`` (N, > 0 traction,
< 0 electric braking) is delayed by ``traction_delay`` (tau of eq. 15), clamped to the HXD1
envelope at the current speed (traction 760 kN up to 9,600 kW; electric brake 461 kN up to
9,600 kW, fading linearly to 0 below ``ed_fade_speed``) and then lags: eq. (15)
``t_vb dF/dt + F = F_dem(t - tau)`` (``traction_model = 0``) or the ramp of eq. (8), the force
moving at ``0.8 F_M / (t3 - t2)`` towards the demand (``traction_model = 1``, ``F_M`` the
traction maximum, ``t3 - t2 = traction_ramp_time``). Loading and removal share one lag (paper).

Air brake on every vehicle (eqs. 9-13): the brake-pipe reduction ``r`` (Pa) set at the driver's
brake valve in the locomotive cab (train front) reaches vehicle ``i`` after
``t_d,i = brake_apply_delay + D_i / brake_propagation_speed`` (application) or
``brake_release_delay + D_i / brake_release_propagation_speed`` (release), ``D_i`` the distance
from the train front to the vehicle's centre. The public figure used for the service-brake
wave of Chinese freight trains (120/120-1 valves) is about 250 m/s; the release wave is slower
(200 m/s here, a chosen value). The cylinder pressure then moves towards the target
``p(r) = p_max min(r / r_full, 1)`` for ``r >= r_min`` (0 below: the valve does not apply),
with ``p_max`` the cylinder pressure at a full service reduction ``r_full`` (500 kPa pipe:
140 kPa -> about 360 kPa, 50 kPa minimum reduction). Rising follows eq. (9),
``p = p_max ((t - t_d) / t_max)^lambda`` (``t_max = brake_fill_time``, full service ~20 s for
a long freight train), stopping at the target; falling mirrors it,
``p = p_max (1 - ((t - t_jd) / t_rel)^lambda_r)``. A vehicle's pressure is its own state: a
further reduction continues up the same curve from the current pressure (equivalent-time form),
a partial increase of pipe pressure lowers the target (graduated release; real 120 valves release
directly, which is how the blending controller uses them: apply in stages, release fully).
Brake force ``F_b,i = theta_i phi(v_i) (p_i / p_max) m_i g`` with the converted braking ratio
``theta`` at ``p_max`` and the converted friction coefficient of high-friction composite shoes
``phi = 0.322 (v + 150) / (2 v + 150)`` (v km/h; TB/T 1407 form).

Integration on sub-steps no longer than ``max_step`` on an absolute grid (split where a delayed
traction change acts, so dead times are exact): the stiff linear coupler forces are integrated
by the trapezoidal rule (A-stable, second order, exact momentum balance: the tridiagonal system
is solved with a cached inverse; with slack it changes with the engagement and is solved as a
banded system), the other forces once per sub-step (speed terms at the start, positions at the
predicted mid-point, traction and brake pressures averaged over
the sub-step from their exact lag solutions). Brake-pipe arrivals inside a sub-step are split
exactly per vehicle. Outputs: see :meth:`FreightTrain.outputs`.

Speed: a communication step runs in one call of the compiled kernel
:func:`plants.kernels.freight_steps` (numba) when numba is available; ``_substep`` here is the
numpy reference it is tested against (``kernel=False`` selects it).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded

from cosim.fmu.declare import Checked, Declared, Var, build, param, parameters
from cosim.fmu.state import TICKS_PER_SECOND, StatefulCore, to_seconds, to_ticks
from plants import dead_time, kernels
from plants.kernels import shoe_friction as _shoe_friction  # the plain-Python definition
from plants.route import (
    GRAVITY,
    KMH,
    Route,
    initial_state_parameters,
    load_route,
    route_parameter,
    routes_dir_in,
)

LOCO_RESISTANCE = (1.40, 0.038, 0.000300)  # N/kN, v in km/h (eq. 3)
LOADED_WAGON_RESISTANCE = (0.92, 0.0048, 0.000125)  # N/kN, v in km/h (eq. 4, rules v^2 term)


@dataclass(frozen=True)
class FreightParams(Checked):
    """Parameters in SI (defaults: seed 002 Table 1, HXD1 + 108 loaded C80; see module doc)."""

    n_wagons: int = 108
    loco_mass: float = param(200e3, "kg", "locomotive mass (HXD1: 200 t)", min=1.0)
    loco_length: float = param(35.2, "m", "locomotive length (35.2 m)", min=0.1)
    wagon_mass: float = param(97e3, "kg", "loaded wagon mass (C80: 20 t + 77 t)", min=1.0)
    wagon_length: float = param(12.0, "m", "wagon length (12 m)", min=0.1)
    loco_rotating_mass_factor: float = param(0.06, "1", "gamma of the locomotive", min=0.0)
    wagon_rotating_mass_factor: float = param(0.06, "1", "gamma of a wagon", min=0.0)
    loco_resistance: tuple[float, float, float] = LOCO_RESISTANCE  # N/kN, km/h
    wagon_resistance: tuple[float, float, float] = LOADED_WAGON_RESISTANCE  # N/kN, km/h
    coupler_stiffness: float = param(1.37e7, "N/m", "draft-gear stiffness per coupling", min=1.0)
    coupler_damping: float = param(1.5e6, "N.s/m", "draft-gear damping per coupling", min=0.0)
    coupler_slack: float = param(0.0, "m", "total free play per coupling (0: none)", min=0.0)
    max_traction_force: float = param(760e3, "N", "largest tractive effort (760 kN)", above=0.0)
    max_traction_power: float = param(9.6e6, "W", "traction power at the wheel (9600 kW)", min=1.0)
    max_ed_force: float = param(461e3, "N", "largest electric brake force (461 kN)", min=0.0)
    max_ed_power: float = param(9.6e6, "W", "electric brake power (9600 kW)", min=1.0)
    ed_fade_speed: float = param(
        5.0 * KMH, "m/s", "electric brake fades linearly to 0 below this speed", min=0.0)
    traction_model: int = param(
        0, "1", "0: first-order lag with dead time (eq. 15); 1: ramp (eq. 8)",
                                min=0, max=1, integer=True)
    traction_delay: float = param(
        0.5, "s", "tau of eq. (15): dead time of traction/electric brake", min=0.0)
    traction_time_constant: float = param(
        1.5, "s", "t_vb of eq. (15): traction/electric brake lag", min=1e-6)
    traction_ramp_time: float = param(3.0, "s", "t3 - t2 of eq. (8) (traction_model = 1)", min=1e-6)
    brake_propagation_speed: float = param(
        250.0, "m/s", "brake-pipe application wave speed (~250 m/s)", min=1e-3)
    brake_release_propagation_speed: float = param(
        200.0, "m/s", "brake-pipe release wave speed", min=1e-3)  # m/s, release wave
    brake_apply_delay: float = param(
        0.0, "s", "valve delay added to the application propagation delay", min=0.0)
    brake_release_delay: float = param(
        0.0, "s", "valve delay added to the release propagation delay", min=0.0)  # s
    brake_fill_time: float = param(20.0, "s", "t_max of eq. (9): cylinder 0 -> p_max", min=1e-6)
    brake_fill_exponent: float = param(0.7, "1", "lambda of eq. (9)", min=1e-6)
    brake_release_time: float = param(25.0, "s", "cylinder p_max -> 0", min=1e-6)
    brake_release_exponent: float = param(1.0, "1", "exponent of the release curve", min=1e-6)
    max_cylinder_pressure: float = param(
        360e3, "Pa", "p_max: cylinder pressure at a full service reduction", min=1.0)
    full_service_reduction: float = param(
        140e3, "Pa", "brake-pipe reduction of a full service application", min=1.0)  # Pa, r_full
    min_reduction: float = param(50e3, "Pa", "smallest reduction that applies the brakes", min=0.0)
    loco_braking_ratio: float = param(
        0.20, "1", "converted braking ratio of the locomotive at p_max", min=0.0)  # theta at p_max
    wagon_braking_ratio: float = param(
        0.20, "1", "converted braking ratio of a wagon at p_max", min=0.0)  # theta at p_max
    stiction_speed: float = param(
        0.01, "m/s", "regularisation of friction forces at standstill", min=1e-6)
    max_step: float = param(0.01, "s", "longest internal integration sub-step", min=1e-6)
    resistance_spread: float = param(
        0.0, "1", "standard deviation of the log of each vehicle's basic-resistance factor "
        "(lognormal, mean 1; 0: every vehicle has the printed coefficients)", min=0.0, max=1.0)
    disturbance_seed: int = param(0, description="seed of the vehicles' resistance factors")

    def check_relations(self) -> None:
        if self.coupler_slack > 0:
            # engagement is found one sub-step late: the spring then starts with up to
            # |dv| h of penetration; keep k h^2 / m_rel small so no energy is pumped in
            stiffness = self.coupler_stiffness * self.max_step**2 / (
                0.5 * min(self.loco_mass, self.wagon_mass))
            if stiffness > 0.5:
                raise ValueError(f"coupler_stiffness = {self.coupler_stiffness} with slack needs "
                                 f"max_step <= {math.sqrt(0.5 / stiffness) * self.max_step:.2g}"
                                 " s (contact too stiff for the sub-step)")
        if self.n_wagons < 0:
            raise ValueError(f"n_wagons = {self.n_wagons} must be >= 0")

    @property
    def n_vehicles(self) -> int:
        return self.n_wagons + 1


def resistance_factors(n: int, spread: float, seed: int) -> np.ndarray:
    """Each vehicle's factor on its basic-resistance coefficients (eqs. 3-4): lognormal with
    mean 1 and log standard deviation ``spread`` (bearing, wheel and load state differ from
    vehicle to vehicle and are not known to a controller), drawn from ``seed``; all ones for
    ``spread = 0``."""
    if spread == 0.0:
        return np.ones(n)
    z = np.random.default_rng(seed).standard_normal(n)
    return np.exp(spread * z - 0.5 * spread**2)


def friction_coefficient(v: np.ndarray) -> np.ndarray:
    """Converted friction coefficient of high-friction composite shoes, v in m/s (TB/T 1407)."""
    return _shoe_friction(np.abs(v) / KMH)


def friction_coefficient_at(v: float) -> float:
    """:func:`friction_coefficient` of one speed (m/s) in plain floats (the same operations)."""
    return _shoe_friction(abs(v) / KMH)


PRESSURE_VEHICLES = (1, 28, 55, 82, 109)  # vehicles whose cylinder pressure is an output
_RESISTANCE = (("loco_resistance", "locomotive"), ("wagon_resistance", "loaded wagon"))
_RESISTANCE_TERMS = (("a", "N/kN"), ("b", "N/kN per km/h"), ("c", "N/kN per (km/h)^2"))


def _resistance_parameters(p: FreightParams) -> tuple[Var, ...]:
    """The (a, b, c) tuples of eq. (3)-(4) as scalars ``loco_resistance_a``..."""
    return tuple(Var(f"{name}_{term}", "parameter", float(value), "1",
                     f"basic resistance of a {who}: {what} (v in km/h)", min=0.0)
                 for name, who in _RESISTANCE
                 for (term, what), value in zip(_RESISTANCE_TERMS, getattr(p, name)))


class FreightTrain(StatefulCore, Declared):
    """Multi-mass freight train core (see module docstring)."""

    state_fields = ("t_ticks", "x", "v", "traction_force", "pressure", "traction_history",
                    "brake_history", "energy", "peak_draft", "peak_buff", "accel", "held")
    setup_vars = (*initial_state_parameters(0.0, " of every vehicle"),
                  route_parameter("freight_20km"))
    input_vars = (
        Var.input("force_demand", "N",
                  "locomotive force demand: > 0 traction, < 0 electric brake"),
        Var.input("pipe_reduction", "Pa",
                  "brake-pipe pressure reduction at the driver's brake valve (0 = released)",
                  min=0.0),
    )
    output_vars = (
        Var.output("v", "m/s", "head (locomotive) speed"),
        Var.output("s", "m", "head position (train front)"),
        Var.output("v_tail", "m/s", "tail (last wagon) speed"),
        Var.output("s_tail", "m", "tail position (rear of the last wagon)"),
        Var.output("a", "m/s2", "train acceleration (mass-weighted, last sub-step)"),
        Var.output("traction_force", "N",
                   "achieved locomotive force (> 0 traction, < 0 electric brake)"),
        Var.output("traction_power", "W", "traction power at the wheel (< 0 regen)"),
        Var.output("traction_energy", "J", "traction minus regenerated energy"),
        Var.output("applied_demand", "N", "force demand acting now: F_dem(t - tau)"),
        Var.output("draft_force_max", "N", "largest coupler draft force now"),
        Var.output("buff_force_max", "N", "largest coupler buff force now (> 0)"),
        Var.output("draft_force_peak", "N",
                   "largest draft force over the last communication step"),
        Var.output("buff_force_peak", "N",
                   "largest buff force (> 0) over the last communication step"),
        Var.output("air_brake_force", "N", "total air-brake force"),
        Var.output("grade", "‰", "grade at the head (uphill > 0)"),
        Var.output("speed_limit", "m/s", "line speed limit at the head"),
        Var.output("brake_pipe_reduction", "Pa", "brake-pipe reduction commanded"),
    )

    @classmethod
    def declarations(cls) -> tuple[Var, ...]:
        """The FMU interface is fixed: 1 locomotive + 108 wagons (the default train)."""
        p = FreightParams()
        return (*parameters(p), *_resistance_parameters(p), *cls.setup_vars, *cls.input_vars,
                *cls.output_vars,
                *(Var.output(f"p_cyl[{i}]", "Pa", f"brake-cylinder pressure of vehicle {i}")
                  for i in PRESSURE_VEHICLES),
                *(Var.output(f"v[{i}]", "m/s", f"speed of vehicle {i} (1 = locomotive)")
                  for i in range(1, p.n_vehicles + 1)))

    @classmethod
    def from_parameters(cls, values: dict, data_dir, t0: float = 0.0) -> FreightTrain:
        tuples = {name: tuple(values[f"{name}_{term}"] for term, _ in _RESISTANCE_TERMS)
                  for name, _ in _RESISTANCE}
        params = dataclasses.replace(build(FreightParams, values), **tuples)
        route = load_route(values["route"], routes_dir_in(data_dir))
        return cls(params, route, v0=values["v0"], s0=values["s0"], t0=t0)

    def __init__(self, params: FreightParams, route: Route, v0: float = 0.0, s0: float = 0.0,
                 t0: float = 0.0, kernel: bool | None = None) -> None:
        """``kernel``: compiled sub-steps (default: when numba is there) or the numpy path."""
        params.check()
        p = self.p = params
        self.route = route
        n = p.n_vehicles
        self.mass = np.full(n, p.wagon_mass)
        self.mass[0] = p.loco_mass
        self.length = np.full(n, p.wagon_length)
        self.length[0] = p.loco_length
        gamma = np.full(n, p.wagon_rotating_mass_factor)
        gamma[0] = p.loco_rotating_mass_factor
        self.m_eff = self.mass * (1.0 + gamma)
        weight = self.mass * GRAVITY  # N
        coeffs = np.tile(np.asarray(p.wagon_resistance, dtype=float), (n, 1))
        coeffs[0] = p.loco_resistance
        coeffs *= resistance_factors(n, p.resistance_spread, p.disturbance_seed)[:, None]
        # basic resistance in N with v in m/s: N/kN * kN, v_kmh = v / KMH
        self.res_a = coeffs[:, 0] * weight / 1e3
        self.res_b = coeffs[:, 1] * weight / 1e3 / KMH
        self.res_c = coeffs[:, 2] * weight / 1e3 / KMH**2
        self.weight_per_kn = weight / 1e3  # N per (N/kN) of specific resistance
        theta = np.full(n, p.wagon_braking_ratio)
        theta[0] = p.loco_braking_ratio
        self.brake_scale = theta * weight / p.max_cylinder_pressure  # N per (Pa * phi)
        fronts = -np.concatenate(([0.0], np.cumsum(self.length[:-1])))  # relative to the head
        centre_distance = -fronts + 0.5 * self.length
        self.apply_delay = p.brake_apply_delay + centre_distance / p.brake_propagation_speed
        self.release_delay = (p.brake_release_delay
                              + centre_distance / p.brake_release_propagation_speed)
        self.train_length = float(self.length.sum())
        self._additional = route.additional
        # state
        self.t_ticks = to_ticks(t0)
        self.x = s0 + fronts  # m, front of each vehicle
        self.v = np.full(n, float(v0))
        if v0 < 0:
            raise ValueError(f"v0 = {v0} must be >= 0")
        self.traction_force = 0.0  # N, achieved (traction > 0, electric brake < 0)
        self.pressure = np.zeros(n)  # Pa, brake-cylinder pressures
        self.traction_history = dead_time.new_history(0.0)  # [tick, demand N]
        self.brake_history: list[list[float]] = [[-1e18, 0.0]]  # [t s, reduction Pa]
        self.energy = 0.0  # J, traction minus regenerated energy at the wheel
        self.peak_draft = 0.0  # N, largest draft force over the last communication step
        self.peak_buff = 0.0  # N, largest buff force (positive) over the last step
        self.accel = 0.0  # m/s^2, train (mass-weighted) acceleration over the last sub-step
        self.held = False  # at rest, held by the brakes and static resistance (see _holds)
        self._grid = to_ticks(p.max_step)
        self._delay_ticks = to_ticks(p.traction_delay)
        self._inverse: dict[int, np.ndarray] = {}
        self._names_v = [f"v[{i + 1}]" for i in range(n)]
        self._pressure_index = sorted({0, n // 4, n // 2, (3 * n) // 4, n - 1})
        self.kernel = (kernel is None or bool(kernel)) and kernels.compile_kernels()
        if self.kernel:
            xs, cum = self._additional._cumulative
            self._route_arrays = (xs, cum, np.diff(cum) / np.diff(xs))
            self._hints = (np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64))
            self._work = np.zeros((kernels.N_WORK, n))
            self._no_arrivals = np.zeros((1, n))
            self._constants = np.array([
                p.stiction_speed, p.coupler_stiffness, p.coupler_damping, p.coupler_slack,
                float(p.traction_model), p.traction_time_constant,
                0.8 * p.max_traction_force / p.traction_ramp_time, p.max_traction_force,
                p.max_traction_power, p.max_ed_force, p.max_ed_power, p.ed_fade_speed,
                p.max_cylinder_pressure, p.brake_fill_time, p.brake_fill_exponent,
                p.brake_release_time, p.brake_release_exponent, p.full_service_reduction,
                p.min_reduction])

    # -- traction ----------------------------------------------------------------------------
    def traction_limits(self, v: float) -> tuple[float, float]:
        """(largest traction force, largest electric brake force) in N at speed ``v`` (m/s)."""
        p = self.p
        speed = abs(v)
        trac = min(p.max_traction_force, p.max_traction_power / speed) if speed > 0 else \
            p.max_traction_force
        ed = min(p.max_ed_force, p.max_ed_power / speed) if speed > 0 else p.max_ed_force
        if p.ed_fade_speed > 0 and speed < p.ed_fade_speed:
            ed *= speed / p.ed_fade_speed
        return trac, ed

    def delayed_demand(self, tick: int) -> float:
        """Force demand acting at the lag input at ``tick``: F_dem(t - tau)."""
        return dead_time.delayed(self.traction_history, tick, self._delay_ticks)

    def _traction_step(self, demand: float, h: float) -> tuple[float, float]:
        """Achieved force at the end of the sub-step and its mean over it (N)."""
        trac, ed = self.traction_limits(self.v[0])
        target = min(max(demand, -ed), trac)
        f0 = self.traction_force
        p = self.p
        if p.traction_model == 0:
            tau = p.traction_time_constant
            decay = math.exp(-h / tau)
            f1 = target + (f0 - target) * decay
            mean = target + (f0 - target) * tau / h * (1.0 - decay)
            return f1, mean
        rate = 0.8 * p.max_traction_force / p.traction_ramp_time
        gap = target - f0
        step = rate * h
        if abs(gap) <= step:  # reaches the target inside the sub-step
            t_reach = abs(gap) / rate
            return target, target - gap * t_reach / (2.0 * h)
        f1 = f0 + math.copysign(step, gap)
        return f1, 0.5 * (f0 + f1)

    # -- air brake ---------------------------------------------------------------------------
    def target_pressure(self, reduction: np.ndarray | float) -> np.ndarray:
        """Cylinder pressure (Pa) a held pipe reduction (Pa) leads to."""
        p = self.p
        r = np.asarray(reduction, dtype=float)
        level = p.max_cylinder_pressure * np.minimum(r / p.full_service_reduction, 1.0)
        return np.where(r >= max(p.min_reduction, 1e-9), level, 0.0)

    def evolve_pressure(self, pres: np.ndarray, target: np.ndarray,
                         dt: np.ndarray | float) -> np.ndarray:
        """Move pressures towards ``target`` for ``dt`` s along eq. (9) / its release mirror."""
        p = self.p
        pmax = p.max_cylinder_pressure
        frac = np.minimum(pres / pmax, 1.0)
        t_up = p.brake_fill_time * frac ** (1.0 / p.brake_fill_exponent)
        up = pmax * np.minimum((t_up + dt) / p.brake_fill_time, 1.0) ** p.brake_fill_exponent
        t_down = p.brake_release_time * (1.0 - frac) ** (1.0 / p.brake_release_exponent)
        down = pmax * (1.0 - np.minimum((t_down + dt) / p.brake_release_time, 1.0)
                       ** p.brake_release_exponent)
        return np.where(pres < target, np.minimum(up, target),
                        np.where(pres > target, np.maximum(down, target), pres))

    def _arrivals(self) -> tuple[np.ndarray, np.ndarray]:
        """Arrival time (s) of each brake-pipe change at each vehicle, and the reductions."""
        hist = np.asarray(self.brake_history)
        times, values = hist[:, 0], hist[:, 1]
        rising = np.concatenate(([True], values[1:] >= values[:-1]))
        delay = np.where(rising[:, None], self.apply_delay[None, :], self.release_delay[None, :])
        return times[:, None] + delay, values

    def commands_seen(self, arrivals: np.ndarray, t: float) -> np.ndarray:
        """Index of the latest command (by command time) that has reached each vehicle at t."""
        k = np.arange(arrivals.shape[0])[:, None]
        return np.max(np.where(arrivals <= t, k, 0), axis=0)

    def _brake_step(self, t0: float, t1: float) -> np.ndarray:
        """Advance cylinder pressures over [t0, t1]; returns the mean pressure over it."""
        start = self.pressure
        if len(self.brake_history) == 1:
            target = self.target_pressure(self.brake_history[0][1])
            if np.all(start == target):
                return start
            end = self.evolve_pressure(start, np.broadcast_to(target, start.shape), t1 - t0)
        else:
            arrivals, values = self._arrivals()
            idx0, idx1 = self.commands_seen(arrivals, t0), self.commands_seen(arrivals, t1)
            cols = np.arange(start.size)
            target0 = self.target_pressure(values[idx0])
            target1 = self.target_pressure(values[idx1])
            switch = np.clip(arrivals[idx1, cols], t0, t1)  # where idx0 == idx1: harmless
            mid = self.evolve_pressure(start, target0, switch - t0)
            end = self.evolve_pressure(mid, target1, t1 - switch)
            # forget commands every vehicle has already passed
            newest_everywhere = int(np.min(idx1))
            if newest_everywhere > 0:
                del self.brake_history[:newest_everywhere]
        self.pressure = end
        return 0.5 * (start + end)

    def step_brakes(self, t0: float, t1: float, reduction: float) -> np.ndarray:
        """Brake pipe only: set ``reduction`` (Pa) at ``t0`` and advance the cylinder pressures
        to ``t1`` (s); returns them (Pa). For controllers that model the brake wave."""
        if reduction != self.brake_history[-1][1]:
            self.brake_history.append([t0, float(reduction)])
        self._brake_step(t0, t1)
        return self.pressure

    # -- mechanics ---------------------------------------------------------------------------
    def _system_inverse(self, h_ticks: int) -> np.ndarray:
        inv = self._inverse.get(h_ticks)
        if inv is None:
            h = to_seconds(h_ticks)
            p = self.p
            n = self.m_eff.size
            lap = np.zeros((n, n))
            idx = np.arange(n - 1)
            lap[idx, idx] += 1.0
            lap[idx + 1, idx + 1] += 1.0
            lap[idx, idx + 1] -= 1.0
            lap[idx + 1, idx] -= 1.0
            system = np.diag(self.m_eff) + (0.25 * h * h * p.coupler_stiffness
                                            + 0.5 * h * p.coupler_damping) * lap
            inv = np.linalg.inv(system)
            if len(self._inverse) > 16:
                self._inverse.clear()
            self._inverse[h_ticks] = inv
        return inv

    def _engagement(self, gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per coupler: 1 where the slack is taken up (else 0) and the free play to subtract
        (m, signed): the draft gear works on ``gap - offset`` only beyond +-slack/2."""
        half = 0.5 * self.p.coupler_slack
        draft, buff = gap > half, gap < -half
        return (draft | buff).astype(float), np.where(draft, half, np.where(buff, -half, 0.0))

    def coupler_forces(self, x: np.ndarray | None = None,
                       v: np.ndarray | None = None) -> np.ndarray:
        """Coupler forces (N, draft > 0) between vehicles j and j+1."""
        x = self.x if x is None else x
        v = self.v if v is None else v
        p = self.p
        gap = x[:-1] - self.length[:-1] - x[1:]
        if p.coupler_slack > 0:
            on, offset = self._engagement(gap)
            return on * (p.coupler_stiffness * (gap - offset)
                         + p.coupler_damping * (v[:-1] - v[1:]))
        return p.coupler_stiffness * gap + p.coupler_damping * (v[:-1] - v[1:])

    def _solve_with_slack(self, h: float, gap: np.ndarray, dv: np.ndarray,
                          force: np.ndarray, v0: np.ndarray) -> np.ndarray:
        """Trapezoidal step with the couplers engaged at the sub-step start (tridiagonal)."""
        p = self.p
        on, offset = self._engagement(gap)
        k, c = p.coupler_stiffness * on, p.coupler_damping * on
        y = k * (gap - offset) + (0.25 * h * k + 0.5 * c) * dv
        force[:-1] -= y
        force[1:] += y
        w = 0.25 * h * h * k + 0.5 * h * c
        banded = np.zeros((2, v0.size))
        banded[0, 1:] = -w
        banded[1] = self.m_eff
        banded[1, :-1] += w
        banded[1, 1:] += w
        return solveh_banded(banded, self.m_eff * v0 + h * force, check_finite=False)

    def _holds(self, traction: float, pres: np.ndarray | None) -> bool:
        """Static friction, as the EMU's explicit hold: can the brake shoes (at their
        standstill friction coefficient) and the constant resistance terms hold the train at
        rest against traction and the grade/curve forces?"""
        if pres is None or not pres.any():
            return False
        grade = -float(self.weight_per_kn @ self._additional.mean_over(self.x, self.length))
        capacity = (float(self.brake_scale @ (pres * friction_coefficient(np.zeros(1))[0]))
                    + float(self.res_a.sum()))
        return abs(traction + grade) <= capacity

    def _substep(self, t_ticks: int, h_ticks: int) -> None:
        p = self.p
        h = to_seconds(h_ticks)
        x0, v0 = self.x, self.v
        f1, f_mean = self._traction_step(self.delayed_demand(t_ticks), h)
        pres = self._brake_step(to_seconds(t_ticks), to_seconds(t_ticks + h_ticks))
        if self.held:
            if self._holds(f_mean, pres):
                self.traction_force = f1
                self.accel = 0.0
                return
            self.held = False
        speed = np.abs(v0)
        dissipative = self.res_a + (self.res_b + self.res_c * speed) * speed
        if pres is not None and pres.any():
            dissipative = dissipative + self.brake_scale * pres * friction_coefficient(v0)
        direction = np.maximum(np.minimum(v0 / p.stiction_speed, 1.0), -1.0)
        force = -dissipative * direction
        force -= self.weight_per_kn * self._additional.mean_over(x0 + 0.5 * h * v0, self.length)
        force[0] += f_mean
        dv = v0[:-1] - v0[1:]
        gap = x0[:-1] - self.length[:-1] - x0[1:]
        if p.coupler_slack > 0:
            v1 = self._solve_with_slack(h, gap, dv, force, v0)
        else:
            k, c = p.coupler_stiffness, p.coupler_damping
            y = k * gap + (0.25 * h * k + 0.5 * c) * dv
            force[:-1] -= y
            force[1:] += y
            v1 = self._system_inverse(h_ticks) @ (self.m_eff * v0 + h * force)
        x1 = x0 + 0.5 * h * (v0 + v1)
        self.energy += f_mean * 0.5 * (v0[0] + v1[0]) * h
        self.accel = float(np.dot(self.m_eff, v1 - v0) / (h * self.m_eff.sum()))
        self.traction_force = f1
        v_mean = float(np.dot(self.m_eff, v1)) / float(self.m_eff.sum())
        if abs(v_mean) <= p.stiction_speed and self._holds(f1, pres):
            v1 = np.zeros_like(v1)  # the regularised friction alone would let it creep
            self.held = True
        self.x, self.v = x1, v1
        fc = self.coupler_forces(x1, v1)
        self.peak_draft = max(self.peak_draft, float(fc.max()))
        self.peak_buff = max(self.peak_buff, -float(fc.min()))

    # -- co-simulation step --------------------------------------------------------------------
    def advance(self, t_ticks: int, h_ticks: int, inputs: dict[str, float]) -> None:
        """Advance by ``h_ticks`` with ``force_demand`` (N) and ``pipe_reduction`` (Pa) held."""
        if t_ticks != self.t_ticks:
            raise ValueError(f"doStep at t={to_seconds(t_ticks)} s but plant is at "
                             f"t={to_seconds(self.t_ticks)} s")
        demand = float(inputs.get("force_demand", 0.0))
        reduction = float(inputs.get("pipe_reduction", 0.0))
        dead_time.record(self.traction_history, t_ticks, demand)
        if reduction != self.brake_history[-1][1]:
            self.brake_history.append([to_seconds(t_ticks), reduction])
        end = t_ticks + h_ticks
        cuts = dead_time.substep_ends(t_ticks, h_ticks, [self._grid], self.traction_history,
                                      self._delay_ticks)
        self.peak_draft = 0.0
        self.peak_buff = 0.0
        if self.kernel:
            self._advance_compiled(t_ticks, cuts)
        else:
            now = t_ticks
            for cut in cuts:
                self._substep(now, cut - now)
                now = cut
        self.t_ticks = end
        dead_time.prune(self.traction_history, end, self._delay_ticks)

    def _advance_compiled(self, t_ticks: int, cuts: list[int]) -> None:
        """The sub-steps ending at ``cuts`` in one kernel call (same grid and inputs as the
        reference loop: delayed demand per sub-step start, brake commands with arrivals)."""
        ends = np.array(cuts, dtype=np.int64)
        starts = np.empty_like(ends)
        starts[0] = t_ticks
        starts[1:] = ends[:-1]
        # int64 ns -> s: exact conversion, one rounded division, as to_seconds
        t0s = starts / TICKS_PER_SECOND
        t1s = ends / TICKS_PER_SECOND
        hs = (ends - starts) / TICKS_PER_SECOND
        history = self.traction_history
        if len(history) == 1:
            demands = np.full(ends.size, history[0][1])
        else:  # dead_time.delayed at every sub-step start
            ticks = np.array([h[0] for h in history], dtype=np.int64)
            index = np.searchsorted(ticks, starts - self._delay_ticks, side="right") - 1
            demands = np.array([h[1] for h in history])[np.maximum(index, 0)]
        if len(self.brake_history) == 1:
            arrivals = self._no_arrivals
            values = np.array([self.brake_history[0][1]])
        else:
            arrivals, values = self._arrivals()
            arrivals, values = np.ascontiguousarray(arrivals), np.ascontiguousarray(values)
        scalars = np.array([self.traction_force, self.energy, 0.0, 0.0, self.accel, 0.0,
                            float(self.held)])
        x, v, pressure = self.x.copy(), self.v.copy(), self.pressure.copy()
        kernels.freight_steps(x, v, pressure, scalars, hs, t0s, t1s, demands,
                              arrivals, values, self.m_eff, self.length,
                              self.res_a, self.res_b, self.res_c, self.weight_per_kn,
                              self.brake_scale, *self._route_arrays, *self._hints,
                              self._constants, self._work)
        self.x, self.v, self.pressure = x, v, pressure
        traction, energy, draft, buff, accel, first, held = scalars.tolist()
        self.traction_force, self.energy = traction, energy
        self.peak_draft, self.peak_buff, self.accel = draft, buff, accel
        if first:
            del self.brake_history[:int(first)]
        self.held = bool(held)

    def outputs(self) -> dict[str, float]:
        x, v = self.x, self.v
        fc = self.coupler_forces()
        # released brakes (most of a run): the force is an exact 0 without the dot product
        air = (float(np.dot(self.brake_scale * self.pressure, friction_coefficient(v)))
               if self.pressure.any() else 0.0)
        out = {
            "v": float(v[0]),
            "s": float(x[0]),
            "v_tail": float(v[-1]),
            "s_tail": float(x[-1] - self.length[-1]),
            "a": self.accel,
            "traction_force": self.traction_force,
            "traction_power": self.traction_force * float(v[0]),
            "traction_energy": self.energy,
            "applied_demand": self.delayed_demand(self.t_ticks),
            "draft_force_max": max(float(fc.max()), 0.0) if fc.size else 0.0,
            "buff_force_max": max(-float(fc.min()), 0.0) if fc.size else 0.0,
            "draft_force_peak": self.peak_draft,
            "buff_force_peak": self.peak_buff,
            "air_brake_force": air,
            "grade": self.route.grade.at(float(x[0])),
            "speed_limit": float(self.route.speed_limit.at(float(x[0]))),
            "brake_pipe_reduction": self.brake_history[-1][1],
        }
        out.update(zip(self._names_v, v.tolist()))
        for i in self._pressure_index:
            out[f"p_cyl[{i + 1}]"] = float(self.pressure[i])
        return out
