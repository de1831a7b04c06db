"""Target speed profiles of seed 003 (sec. 3.1): conventional and energy-saving ("eco").

Both are computed on a nominal single-mass model of the train (:class:`plants.crh3.Crh3Params`:
mass, rotating-mass factor, Table 1 resistance, traction envelope) over the route's grade, curve
and tunnel resistance, on a distance grid of ``ds`` metres with constant acceleration over each
step (``v^2`` linear in ``s``). Limits of the paper: ``-1 <= a <= 1`` m/s^2, cruising speed
``V_act`` (330 km/h) and line limit ``V_lim`` (350 km/h).

* **Conventional** (Fig. 1: depart, accelerate, cruise, brake, stop): traction at
  ``traction_share`` of the envelope (and at most ``accel_max``) up to ``V_act``; cruise at
  ``V_act`` (where ``traction_share`` of the envelope cannot hold it uphill the speed sags and
  recovers with that traction); brake at the constant ``brake_decel`` onto the stop point
  (``v_b(s) = sqrt(2 a_b (L - s))``). It is the timetable's shortest run, ``T_conv``.
* **Eco** (Fig. 2: accelerate, coast, re-accelerate, ..., brake): the same start; then the
  *switching rule*: coast (no force) from ``V_act`` until the speed has fallen to ``V_low``,
  re-accelerate (as in the start) to ``V_act``, coast again, ...; on a down grade a coasting
  train that reaches ``V_lim`` is held there; wherever the run meets the braking curve ``v_b``
  it brakes to the stop. ``V_low`` is the one free number: the lower it is, the longer the run
  (monotone up to the jump when a cycle drops out before the braking curve), and it is found by
  bisection so that the arrival time equals the scheduled running time ``T_s`` (the route's
  ``scheduled_time_s``: ``T_conv`` plus the running-time supplement) to within
  ``time_tolerance``. If ``T_s <= T_conv`` there is no margin and the eco profile is the
  conventional one. Because the last run time found is within ``time_tolerance`` (default
  0.5 s) of ``T_s`` and the paper allows an arrival error of ``Delta T_max = 5`` s, the eco
  profile keeps the arrival within the margin; ``tests/test_speed_profiles.py`` checks it.

* **Cruise** (ours, the same-schedule conventional baseline): the conventional shape
  (accelerate, cruise, brake) at the one constant cruising speed ``V_c <= V_act`` whose run
  time equals ``T_s``, found by Brent's root finder (``scipy.optimize.brentq``) on the run time
  as a function of ``V_c`` (continuous and decreasing) to within ``time_tolerance``. It
  compares a strategy with the conventional one at equal arrival time; ``low_speed`` holds
  ``V_c``. If ``T_s <= T_conv`` it is the conventional profile.

* **Fixed family** (``fixed_family``; ours, beyond the paper): the best member of a fixed
  family of control sequences of optimal train control (Howlett, Pudney and Albrecht): maximum
  traction
  (the planning envelope, ``traction_share``, at most ``accel_max``) up to a holding speed
  ``V_h``; speed holding (full traction where a grade pulls the speed below ``V_h``; on a
  down grade the train is held at ``V_h`` by braking); coasting from a point ``s_c`` (held at
  the line limit if a down grade reaches it); braking at ``brake_decel`` (the service rate of
  every profile here, so that the trackers can follow it; the theory's maximum braking
  would be the plant's full brake) onto the stop point. The two switching parameters are
  found for the schedule: for each ``V_h`` the coasting point whose run time is ``T_s``
  (``brentq``), and ``V_h`` minimising the nominal eq. 9 energy (:func:`net_energy`:
  traction / eta_M minus the regenerated eta_b x braking work; the auxiliary energy is fixed
  by the schedule), with ``scipy.optimize.minimize_scalar``. On level track this family
  contains the optimum; on grades the exact optimum may add short power/coast phases around
  steep sections, and holding by braking is not a regime of the optimum when regeneration is
  below 100 %, so on grades it is not the optimum (a test compares it with a dynamic
  programme on a short level route). The cruise profile is the member with no coasting, so
  the fixed-family one never needs more.

* **Optimum** (:func:`read_optimum`): the true energy optimum (all regimes of the maximum
  principle, exact switching points) computed offline by ``cosim optimal``
  (:mod:`cosim.optimal`, which no FMU core imports) and read from its CSV: position, speed and
  time of its nodes (constant acceleration between nodes, the nodes' own times) and the
  regime of each step (:data:`OPTIMUM_REGIMES`).

The eco, cruise and fixed-family searches cost seconds per process; their results (``V_low``; the
cruise speed; ``V_h`` and ``s_c``) are kept on disk by
:func:`cosim.fmu.disk_cache.cached_arrays`, keyed by the route's profiles, the schedule, the
train, the settings and this module's code, and the profile is rebuilt from them (the same
floats as a fresh search).

:func:`traction_work` is the mechanical traction work of any profile on the nominal model.

Phases (Table 2, used by the energy-per-phase metrics): ``accelerate`` from the start until the
profile first reaches ``V_act`` (the optimum: until its first step that is not maximum
traction); ``brake`` from the start of the final braking; ``run`` between.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.optimize

from cosim.fmu.disk_cache import cached_arrays, source_digest
from plants.crh3 import Crh3Params
from plants.resistance import KMH
from plants.route import GRAVITY, Route, StepProfile

# mode of each profile step
TRACTION, CRUISE, COAST, REACCELERATE, HOLD_LIMIT, BRAKE = 1, 2, 3, 4, 5, 6
# Table 2 phases
PHASE_ACCELERATE, PHASE_RUN, PHASE_BRAKE = 1, 2, 3
PROFILE_KINDS = ("conventional", "eco", "cruise", "fixed_family")  # generated here
# regimes of the optimum's CSV (``cosim optimal``'s ``regime`` column) as profile modes
OPTIMUM_REGIMES = {"maximum traction": TRACTION, "cruise (partial traction)": CRUISE,
                   "coasting": COAST, "cruise (partial braking)": HOLD_LIMIT,
                   "maximum braking": BRAKE, "maximum regenerative braking": BRAKE}
OPTIMUM_COLUMNS = ("position_m", "speed_mps", "time_s")  # its first three columns (SI)
# code version of the cached profile searches: this module and the train model
_CODE_VERSION = source_digest(__file__, Path(__file__).resolve().parents[2] / "plants" / "crh3.py")


@dataclass(frozen=True)
class ProfileSettings:
    """Limits and rates of the profile generator (SI)."""

    cruise_speed: float = 330.0 * KMH  # V_act
    limit_speed: float = 350.0 * KMH  # V_lim
    accel_max: float = 1.0  # m/s^2
    brake_decel: float = 0.5  # m/s^2, constant service braking to the stop (<= 1)
    traction_share: float = 0.9  # share of the traction envelope the profile plans with
    ds: float = 10.0  # m, distance grid
    time_tolerance: float = 0.5  # s, eco arrival within this of the scheduled time
    min_low_speed: float = 150.0 * KMH  # lowest V_low the bisection considers

    def check(self) -> None:
        if not 0 < self.cruise_speed <= self.limit_speed:
            raise ValueError(f"need 0 < V_act = {self.cruise_speed} <= V_lim = "
                             f"{self.limit_speed} (m/s)")
        if not (0 < self.accel_max <= 1.0 and 0 < self.brake_decel <= 1.0):
            raise ValueError(f"accel_max = {self.accel_max} and brake_decel = "
                             f"{self.brake_decel} must be in (0, 1] m/s2 (seed 003)")
        if not 0 < self.traction_share <= 1 or not self.ds > 0:
            raise ValueError(f"traction_share = {self.traction_share} must be in (0, 1] and "
                             f"ds = {self.ds} > 0")


@dataclass(frozen=True)
class SpeedProfile:
    """A target profile on a distance grid: positions ``s`` (m), speeds ``v`` (m/s), times
    ``t`` (s, from departure), ``mode`` of the step starting at each point (last: BRAKE)."""

    kind: str
    s: np.ndarray
    v: np.ndarray
    t: np.ndarray
    mode: np.ndarray
    low_speed: float  # V_low of the eco rule (V_act for the conventional profile)
    scheduled_time: float  # s, T_s

    @property
    def arrival_time(self) -> float:
        """Planned running time (s)."""
        return float(self.t[-1])

    @property
    def stop_point(self) -> float:
        return float(self.s[-1])

    @functools.cached_property
    def accel(self) -> np.ndarray:
        """Acceleration (m/s^2) of the step starting at each point (0 at the end)."""
        a = np.diff(self.v**2) / (2.0 * np.diff(self.s))
        return np.append(a, 0.0)

    @functools.cached_property
    def accelerate_end_index(self) -> int:
        """First point at which the first traction phase has ended (V_act reached)."""
        idx = np.nonzero(self.mode != TRACTION)[0]
        return int(idx[0]) if idx.size else len(self.s) - 1

    @functools.cached_property
    def brake_start_index(self) -> int:
        """First point of the final braking."""
        idx = np.nonzero(self.mode != BRAKE)[0]
        return int(idx[-1]) + 1 if idx.size else 0

    @property
    def accelerate_end_time(self) -> float:
        return float(self.t[self.accelerate_end_index])

    @property
    def brake_start_position(self) -> float:
        return float(self.s[self.brake_start_index])

    @property
    def brake_start_time(self) -> float:
        return float(self.t[self.brake_start_index])

    def _segment_by_time(self, t: float) -> int:
        return int(min(max(np.searchsorted(self.t, t, side="right") - 1, 0), len(self.t) - 2))

    def at_time(self, t: float) -> tuple[float, float, float]:
        """(s_ref (m), v_ref (m/s), a_ref (m/s^2)) at time ``t`` after departure (constant
        acceleration in each step; before 0 and after arrival: at the ends, at rest)."""
        if t <= 0.0:
            return float(self.s[0]), float(self.v[0]), float(self.accel[0]) if t == 0 else 0.0
        if t >= self.t[-1]:
            return float(self.s[-1]), 0.0, 0.0
        i = self._segment_by_time(t)
        a = float(self.accel[i])
        tau = t - float(self.t[i])
        v = max(float(self.v[i]) + a * tau, 0.0)
        s = float(self.s[i]) + float(self.v[i]) * tau + 0.5 * a * tau * tau
        return min(s, float(self.s[i + 1])), v, a

    def at_position(self, s: float) -> tuple[float, float]:
        """(v_ref (m/s), a_ref (m/s^2)) at position ``s`` (``v^2`` linear in each step)."""
        if s >= self.s[-1]:
            return 0.0, 0.0
        if s <= self.s[0]:
            return float(self.v[0]), float(self.accel[0])
        i = int(np.searchsorted(self.s, s, side="right") - 1)
        a = float(self.accel[i])
        return math.sqrt(max(float(self.v[i]) ** 2 + 2.0 * a * (s - float(self.s[i])), 0.0)), a

    def phase_at_time(self, t: float) -> int:
        """Table 2 phase at time ``t`` (PHASE_ACCELERATE / PHASE_RUN / PHASE_BRAKE)."""
        if t < self.accelerate_end_time:
            return PHASE_ACCELERATE
        if t < self.brake_start_time:
            return PHASE_RUN
        return PHASE_BRAKE


class _Model:
    """Nominal single-mass model the profiles are planned on."""

    def __init__(self, train: Crh3Params, route: Route, settings: ProfileSettings) -> None:
        self.train, self.settings = train, settings
        self.m_eff = train.effective_mass
        self.mg = train.mass * GRAVITY / 1000.0
        additional = StepProfile.sum(route.grade, route.curve_resistance,
                                     route.tunnel_resistance)
        self.add_starts = additional.starts.tolist()
        self.add_values = additional.values.tolist()
        self.limit_starts = route.speed_limit.starts.tolist()
        self.limit_values = route.speed_limit.values.tolist()

    def drag(self, v: float, s: float) -> float:
        """Resistance + grade + curve + tunnel as a deceleration (m/s^2)."""
        import bisect

        d = self.train.davis
        w = self.add_values[bisect.bisect_right(self.add_starts, s) - 1]
        return (d.a + (d.b + d.c * v) * v + self.mg * w) / self.m_eff

    def traction_accel(self, v: float, s: float) -> float:
        st = self.settings
        return min(st.accel_max, st.traction_share * self.train.traction_limit(v) / self.m_eff
                   - self.drag(v, s))

    def ceiling(self, s: float) -> float:
        import bisect

        line = self.limit_values[bisect.bisect_right(self.limit_starts, s) - 1]
        return min(self.settings.limit_speed, line)


def _run(model: _Model, length: float, kind: str, low: float,
         coast_from: float = math.inf) -> tuple[np.ndarray, ...]:
    """One forward pass: (s, v, mode) on the grid; ``low`` = V_low (eco); from ``coast_from``
    (m) on, a cruising train coasts to the braking curve (fixed family)."""
    st = model.settings
    n = max(int(math.ceil(length / st.ds)), 1)
    s = np.linspace(0.0, length, n + 1)
    step = length / n
    v = np.zeros(n + 1)
    mode = np.full(n + 1, BRAKE, dtype=np.int64)
    v_act = st.cruise_speed
    state, first = TRACTION, True
    vi = 0.0
    for i in range(n):
        x = float(s[i])
        vb2 = 2.0 * st.brake_decel * (length - float(s[i + 1]))  # braking curve at the end
        cap = min(model.ceiling(x), model.ceiling(float(s[i + 1])))
        if state == TRACTION:
            target = min(v_act, cap)
            v2 = vi * vi + 2.0 * model.traction_accel(vi, x) * step
            mode[i] = TRACTION if first else REACCELERATE
            if v2 >= target * target:
                v2 = target * target
                state, first = (CRUISE if kind == "conventional" else COAST), False
        elif state == CRUISE and x >= coast_from:
            state, low = COAST, 0.0
            v2 = vi * vi - 2.0 * model.drag(vi, x) * step
            mode[i] = COAST
        elif state == CRUISE:
            target = min(v_act, cap)
            v2 = min(vi * vi + 2.0 * model.traction_accel(vi, x) * step, target * target)
            mode[i] = CRUISE
        elif state == COAST:
            v2 = vi * vi - 2.0 * model.drag(vi, x) * step
            mode[i] = COAST
            if v2 >= cap * cap:
                v2, mode[i] = cap * cap, HOLD_LIMIT
            if v2 <= low * low:
                state = TRACTION
        else:
            v2 = vb2
        if v2 >= vb2:  # met the braking curve: brake to the stop from here
            v2, state = vb2, BRAKE
        vi = math.sqrt(max(v2, 0.0))
        v[i + 1] = vi
    v[-1] = 0.0
    return s, v, mode


def _times(s: np.ndarray, v: np.ndarray) -> np.ndarray:
    vsum = v[:-1] + v[1:]
    dt = 2.0 * np.diff(s) / np.where(vsum > 0, vsum, np.inf)
    return np.concatenate(([0.0], np.cumsum(dt)))


def _finish(kind: str, s: np.ndarray, v: np.ndarray, mode: np.ndarray, low: float,
            scheduled: float) -> SpeedProfile:
    # the final braking: every step from the last non-braking one on whose speed falls along
    # the braking curve is marked BRAKE (the last cruise/coast step may end on the curve)
    return SpeedProfile(kind, s, v, _times(s, v), mode, low, scheduled)


def generate(kind: str, route: Route, scheduled_time: float | None = None,
             train: Crh3Params | None = None,
             settings: ProfileSettings | None = None) -> SpeedProfile:
    """The ``kind`` (:data:`PROFILE_KINDS`) profile from the route's first station
    (or 0) to its end (``length_m``, the stop point) within ``scheduled_time`` (s; default the
    route's ``scheduled_time_s``)."""
    if kind not in PROFILE_KINDS:
        raise ValueError(f"profile {kind!r} must be one of {PROFILE_KINDS}")
    train = train or Crh3Params()
    settings = settings or ProfileSettings()
    settings.check()
    if scheduled_time is None or scheduled_time <= 0:
        scheduled_time = route.scheduled_time_s
    if kind == "eco" and scheduled_time is None:
        raise ValueError(f"route {route.name!r} has no scheduled_time_s: give scheduled_time")
    if kind in ("cruise", "fixed_family") and scheduled_time is None:
        raise ValueError(f"route {route.name!r} has no scheduled_time_s: give scheduled_time")
    key = (kind, id(route), float(scheduled_time or 0.0), train, settings)
    hit = _CACHE.get(key)
    if hit is None or hit[0] is not route:
        if len(_CACHE) > 32:
            _CACHE.clear()
        hit = _CACHE[key] = (route, _generate(kind, route, key[2], train, settings))
    return hit[1]


# per process (routes are frozen; the route is kept with its profile so its id stays unique)
_CACHE: dict[tuple, tuple[Route, SpeedProfile]] = {}


def _generate(kind: str, route: Route, scheduled: float, train: Crh3Params,
                     settings: ProfileSettings) -> SpeedProfile:
    model = _Model(train, route, settings)
    length = float(route.length_m)
    v_act = settings.cruise_speed
    s, v, mode = _run(model, length, "conventional", v_act)
    conventional = _finish("conventional", s, v, mode, v_act, scheduled)
    if kind == "conventional" or scheduled <= conventional.arrival_time:
        return conventional if kind == "conventional" else _finish(
            kind, s, v, mode, v_act, scheduled)
    if kind == "cruise":
        return _cruise(train, route, scheduled, settings)
    if kind == "fixed_family":
        return _fixed_family(train, route, scheduled, settings)
    return _eco(model, route, scheduled, train, settings)


def _eco(model: _Model, route: Route, scheduled: float, train: Crh3Params,
         settings: ProfileSettings) -> SpeedProfile:
    """The eco profile whose ``V_low``, found by bisection, meets the schedule."""
    length = float(route.length_m)

    def profile(low: float) -> SpeedProfile:
        return _finish("eco", *_run(model, length, "eco", low), low, scheduled)

    def search() -> tuple[np.ndarray]:
        lo, hi = settings.min_low_speed, settings.cruise_speed  # time(lo) >= time(hi)
        best: SpeedProfile | None = None
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            prof = profile(mid)
            if best is None or (abs(prof.arrival_time - scheduled)
                                < abs(best.arrival_time - scheduled)):
                best = prof
            if abs(prof.arrival_time - scheduled) <= settings.time_tolerance:
                break
            if prof.arrival_time > scheduled:
                lo = mid
            else:
                hi = mid
            if hi - lo < 1e-6:
                break
        if best is None or abs(best.arrival_time - scheduled) > settings.time_tolerance:
            raise ValueError(f"route {route.name!r}: no eco profile arrives within "
                             f"{settings.time_tolerance} s of scheduled_time = {scheduled} s "
                             f"(closest {best.arrival_time if best else float('nan'):.1f} s)")
        return (np.array([best.low_speed]),)

    # the bisection runs up to 60 passes over the line: its V_low is kept on disk, keyed by
    # every input and the code computing it
    (found,) = cached_arrays("eco_profile", _CODE_VERSION,
                             _profile_key(route, scheduled, train, settings), search)
    return profile(float(found[0]))


def _cruise(train: Crh3Params, route: Route, scheduled: float,
            settings: ProfileSettings) -> SpeedProfile:
    """The conventional shape at the cruising speed whose run time is ``scheduled``."""
    length = float(route.length_m)

    def profile(speed: float) -> SpeedProfile:
        st = dataclasses.replace(settings, cruise_speed=speed)
        s, v, mode = _run(_Model(train, route, st), length, "conventional", speed)
        return _finish("cruise", s, v, mode, speed, scheduled)

    lo, hi = settings.min_low_speed, settings.cruise_speed

    def search() -> tuple[np.ndarray]:
        slowest = profile(lo)
        if slowest.arrival_time < scheduled:
            raise ValueError(f"route {route.name!r}: cruising at min_low_speed = {lo:.2f} "
                             f"m/s arrives at {slowest.arrival_time:.1f} s, before "
                             f"scheduled_time = {scheduled} s")
        # run time falls by about L / V^2 per m/s: xtol 1e-6 m/s is well inside
        # time_tolerance
        return (np.array([scipy.optimize.brentq(
            lambda x: profile(x).arrival_time - scheduled, lo, hi, xtol=1e-6)]),)

    (found,) = cached_arrays("cruise_profile", _CODE_VERSION, _profile_key(
        route, scheduled, train, settings), search)
    speed = float(found[0])
    best = profile(speed)
    if abs(best.arrival_time - scheduled) > settings.time_tolerance:
        raise ValueError(f"route {route.name!r}: no cruise profile arrives within "
                         f"{settings.time_tolerance} s of scheduled_time = {scheduled} s "
                         f"(closest {best.arrival_time:.1f} s at {speed:.3f} m/s)")
    return best


def _fixed_family(train: Crh3Params, route: Route, scheduled: float,
             settings: ProfileSettings) -> SpeedProfile:
    """Hold ``V_h``, coast from ``s_c``, brake: both found for the schedule (module text)."""
    length = float(route.length_m)

    def run(speed: float, coast_from: float) -> SpeedProfile:
        st = dataclasses.replace(settings, cruise_speed=speed)
        s, v, mode = _run(_Model(train, route, st), length, "conventional", speed, coast_from)
        return _finish("fixed_family", s, v, mode, speed, scheduled)

    coast_point: dict[float, float] = {}  # V_h -> the s_c for_schedule chose

    def for_schedule(speed: float) -> SpeedProfile | None:
        """The coasting point of holding speed ``speed`` that meets the schedule."""
        late = run(speed, 0.0)  # coasts as soon as V_h is reached: the longest run
        if run(speed, length).arrival_time > scheduled + settings.time_tolerance:
            return None  # too slow even without coasting
        if late.arrival_time < scheduled:
            return None  # early even coasting from V_h on (V_h too high for this family)
        c = scipy.optimize.brentq(lambda x: run(speed, x).arrival_time - scheduled, 0.0,
                                  length, xtol=0.5 * settings.ds)
        # the run time is a step function of c on the ds grid: take the closer grid point
        c_best, best = min(((c + d, run(speed, c + d)) for d in (-settings.ds, 0.0, settings.ds)),
                           key=lambda cp: abs(cp[1].arrival_time - scheduled))
        coast_point[speed] = c_best
        return best if abs(best.arrival_time - scheduled) <= settings.time_tolerance else None

    cruise = _cruise(train, route, scheduled, settings)

    def work(speed: float) -> float:
        prof = for_schedule(speed)
        return math.inf if prof is None else net_energy(prof, route, train)

    # V_h ranges from the cruise speed (no coasting) to the speed that meets the schedule
    # coasting from the moment it is reached (above it the run is early whatever s_c)
    top = settings.cruise_speed
    if run(top, 0.0).arrival_time < scheduled:
        top = scipy.optimize.brentq(lambda x: run(x, 0.0).arrival_time - scheduled,
                                    cruise.low_speed, top, xtol=1e-4)
    def search() -> tuple[np.ndarray]:
        """(V_h, s_c) of the optimum; NaN: no coasting pays (the cruise profile)."""
        res = scipy.optimize.minimize_scalar(work, bounds=(cruise.low_speed, top),
                                             method="bounded", options={"xatol": 1e-3})
        best = for_schedule(float(res.x))
        if best is None or net_energy(best, route, train) > net_energy(cruise, route, train):
            return (np.array([math.nan, math.nan]),)
        return (np.array([float(res.x), coast_point[float(res.x)]]),)

    # the search costs seconds per process: its two numbers are kept on disk, keyed by every
    # input (route, schedule, train, settings) and the code computing them
    (found,) = cached_arrays("fixed_family_profile", _CODE_VERSION,
                             _profile_key(route, scheduled, train, settings), search)
    if np.isnan(found[0]):
        return dataclasses.replace(cruise, kind="fixed_family")  # no coasting pays
    return run(float(found[0]), float(found[1]))


def read_optimum(path: str | Path, route: Route, scheduled_time: float | None = None,
                 settings: ProfileSettings | None = None) -> SpeedProfile:
    """The optimum written by ``cosim optimal`` (a CSV whose first columns are
    :data:`OPTIMUM_COLUMNS` and whose last is ``regime``) as the profile ``"pmp"``; it must run
    from 0 to the route's end (``length_m``) and arrive within ``time_tolerance`` of
    ``scheduled_time`` (s; default the route's ``scheduled_time_s``)."""
    import csv

    settings = settings or ProfileSettings()
    if scheduled_time is None or scheduled_time <= 0:
        scheduled_time = route.scheduled_time_s
    try:
        with open(path, newline="") as f:
            rows = [r for r in csv.reader(line for line in f if not line.startswith("#")) if r]
    except OSError as exc:
        raise ValueError(f"optimum {str(path)!r}: {exc}") from exc
    header = tuple(rows[0]) if rows else ()
    if header[:3] != OPTIMUM_COLUMNS or header[-1] != "regime" or len(rows) < 3:
        raise ValueError(f"{path}: an optimum has the columns {OPTIMUM_COLUMNS} ... regime "
                         f"and at least two nodes; got {header}")
    try:
        s, v, t = (np.array([float(r[i]) for r in rows[1:]]) for i in range(3))
        mode = np.array([OPTIMUM_REGIMES[r[-1]] for r in rows[1:]], dtype=np.int64)
    except (ValueError, KeyError, IndexError) as exc:
        raise ValueError(f"{path}: bad optimum row: {exc}") from exc
    mode[-1] = BRAKE
    length = float(route.length_m)
    if abs(s[0]) > 1e-3 or abs(s[-1] - length) > 1e-3 or np.any(np.diff(s) <= 0.0):
        raise ValueError(f"{path}: the optimum runs from {s[0]} m to {s[-1]} m; route "
                         f"{route.name!r} runs from 0 to length_m = {length} m (increasing)")
    if scheduled_time is None or abs(t[-1] - scheduled_time) > settings.time_tolerance:
        raise ValueError(f"{path}: the optimum arrives at {t[-1]} s, not within "
                         f"{settings.time_tolerance} s of scheduled_time = {scheduled_time} s")
    return SpeedProfile("pmp", s, v, t, mode, float(np.max(v)), float(scheduled_time))


def _profile_key(route: Route, scheduled: float, train: Crh3Params,
                 settings: ProfileSettings) -> list[object]:
    """Cache-key inputs of a profile search: route, schedule, train and settings."""
    return [*_route_key(route), float(scheduled), *_dataclass_key(train),
            *_dataclass_key(settings)]


def _dataclass_key(obj: object) -> list[object]:
    """Field names and values of a dataclass (nested ones field by field), as cache-key
    inputs."""
    out: list[object] = []
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        out += [f.name, *(_dataclass_key(value) if dataclasses.is_dataclass(value)
                          else [value])]
    return out


def _route_key(route: Route) -> list[object]:
    """Everything of a route that the profiles depend on, as cache-key inputs."""
    out: list[object] = [route.name, float(route.length_m),
                         float(route.scheduled_time_s or 0.0)]
    for name in ("grade", "curve_resistance", "tunnel_resistance", "speed_limit"):
        prof: StepProfile = getattr(route, name)
        out += [name, prof.starts, prof.values]
    return out


def step_forces(profile: SpeedProfile, route: Route, train: Crh3Params | None = None
                ) -> np.ndarray:
    """Force (N) of each step of ``profile`` on the nominal model: ``m_eff (a + drag(v_mean,
    s))`` (> 0 traction, < 0 braking)."""
    model = _Model(train or Crh3Params(), route, ProfileSettings())
    vm = 0.5 * (profile.v[:-1] + profile.v[1:])
    drag = np.array([model.drag(float(v), float(x)) for v, x in zip(vm, profile.s[:-1])])
    return model.m_eff * (profile.accel[:-1] + drag)


def traction_work(profile: SpeedProfile, route: Route, train: Crh3Params | None = None) -> float:
    """Mechanical traction work (J) along ``profile`` on the nominal model: the sum over the
    steps of ``max(force, 0) ds`` (:func:`step_forces`; braking and coasting cost none)."""
    force = step_forces(profile, route, train)
    return float(np.sum(np.maximum(force, 0.0) * np.diff(profile.s)))


def net_energy(profile: SpeedProfile, route: Route, train: Crh3Params | None = None) -> float:
    """Eq. 9 energy (J) of ``profile`` on the nominal model without the auxiliary part:
    traction work / eta_M minus eta_b x braking work (all braking regenerative)."""
    train = train or Crh3Params()
    force = step_forces(profile, route, train) * np.diff(profile.s)
    return float(np.sum(np.maximum(force, 0.0)) / train.motor_efficiency
                 + train.regen_efficiency * np.sum(np.minimum(force, 0.0)))
