"""Generate the reference speed profile of the 20 km freight route (seed 002, 22.8 min run).

    python papers/seed002/make_freight_20km.py   # writes plants/routes/freight_20km_reference.csv

The line itself (``plants/routes/freight_20km.toml``) is hand-made; see its header. The
reference is a plan this train can follow (a freight ATO's planned profile): a one-mass run of
the seed 002 train (HXD1 + 108 loaded C80: masses, basic resistance, traction / electric-brake
envelope and air brake of :mod:`plants.freight`; grade/curve/tunnel resistance averaged over
the train length, eq. 5), integrated in time (``DT``) and written on a 10 m grid (denser
where the planned time between two points would exceed 1 s):

* the ceiling is the cruise speed ``V_c`` or the lowest speed limit under the whole train
  (the tail must clear a restriction before speeding up) minus 2 km/h;
* traction (forward pass): at most ``TRACTION_SHARE`` of the envelope minus the resistance and
  grade (the controller keeps the rest to correct errors), at most ``MAX_REF_ACCEL``; the speed
  falls where that share cannot hold it uphill;
* slowing ahead of lower limits (backward pass, reverse time) with the electric brake alone:
  ``ED_SHARE`` of it plus the resistance and grade, at most ``DECEL_LIMIT``;
* the reference's jerk is at most ``MAX_JERK`` wherever the locomotive changes its force
  (start, ends of traction and slowing, approach of a ceiling as ``a <= sqrt(2 J (c - v))``):
  a locomotive force ramp of ``dF/dt`` stretches or compresses the couplers, and the
  train-mean speed then differs from the head speed by ``N dF/dt / (3 k)`` (``N`` couplings of
  stiffness ``k`` carrying a force falling linearly along the train), 0.11 km/h at this
  ``MAX_JERK``;
* a planned start, written in the head's coordinate (the controllers read the reference at
  the locomotive): the locomotive force rises from zero at the jerk rule's rate
  ``m_eff MAX_JERK`` up to the breakaway resistance (the constant terms, 97 kN), the train
  (one mass) at rest while the head takes up the stretch (``START_*``), then the traction
  pass; the head's planned position is the one-mass position plus the quasi-static
  head-to-mean stretch of the planned force (:meth:`Planner.stretch`; at the end of the
  start's jerk ramp its growth ends within the jerk bound, :meth:`Planner._fade`, then it is
  held; a trailing average over ``START_SMOOTHING_S`` starts the creep smoothly, and the
  head's planned speed never falls) up to the first ceiling, where the constant speed
  absorbs it. A one-mass position read at the head would put the head that stretch (up to
  1.6 m) ahead in the plan, seconds of planned time at walking speed;
* the final stop is planned with the air brake as the blending applies it
  (:mod:`controllers.common.freight_blending`): from the speed on the line, the locomotive
  force ramps (``MAX_JERK``) to ``stop_ed_share`` of the electric brake; then the smallest
  pipe reduction (``min_reduction``) is applied, its force building up along the train as the
  plant's brake-pipe model gives it (propagation, eq. 9 filling), the electric brake staying
  at that share (fading below ``ed_fade_speed``) to the stop at 20 km; the start of that
  braking is found by bisection so that the train stops at 20 km. The locomotive then trims
  the planned braking either way by the rest of its electric brake. The last speed limit (the
  throat in front of the stop) is met by this curve (checked), not by a backward pass;
* ``V_c`` is found by bisection so that the run takes 22.8 min (1,368 s), the paper's figure;
  it reaches its 78 km/h ceiling, and the run takes 1,383.0 s (the planned start's take-up
  and its jerk ramp cannot be made up).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # papers/NAME/ -> the repository
sys.path.insert(0, str(ROOT))

from controllers.common.freight_blending import BlendingParams  # noqa: E402
from plants.freight import FreightParams, FreightTrain, friction_coefficient_at  # noqa: E402
from plants.route import GRAVITY, KMH, ReferenceProfile, load_route  # noqa: E402

NAME = "freight_20km"
RUN_TIME_S = 22.8 * 60.0
GRID_M = 10.0
MAX_POINT_TIME = 1.0  # s, at most between two written points
MIN_SPACING_M = 0.5  # m, at least between a timed point and a grid point
DT = 0.05  # s, time step of the plan
TRACTION_SHARE = 0.8
MAX_REF_ACCEL = 0.05  # m/s^2
MAX_JERK = 1e-3  # m/s^3
LIMIT_MARGIN_KMH = 2.0
ED_SHARE = 0.5  # share of the electric brake for slowing to lower limits
DECEL_LIMIT = 0.1  # m/s^2, at most, ahead of a lower speed limit
START_SMOOTHING_S = 2.0  # s, moving average of the planned start's stretch


class Planner:
    """One-mass model of the nominal train on the route (see the module doc)."""

    def __init__(self, route, params: FreightParams, stop_ed_share: float) -> None:
        self.route = route
        self.p = params
        self.train = FreightTrain(params, route)
        self.length = self.train.train_length
        self.m_eff = float(self.train.m_eff.sum())
        self.weight = float(self.train.mass.sum()) * GRAVITY
        self.res = (float(self.train.res_a.sum()), float(self.train.res_b.sum()),
                    float(self.train.res_c.sum()))
        self.stop_ed_share = stop_ed_share
        # lowest limit under the whole train [s - length, s], minus the margin, on a 1 m grid
        self.s_fine = np.arange(0.0, route.length_m + 1.0, 1.0)
        starts = route.speed_limit.starts
        lim = route.speed_limit.at_array(self.s_fine)
        lowest = lim.copy()
        for k in range(1, len(starts)):  # a limit stays under the train until its tail clears
            values = route.speed_limit.values
            if np.isfinite(starts[k]) and values[k] > values[k - 1]:
                behind = (self.s_fine >= starts[k]) & (self.s_fine < starts[k] + self.length)
                lowest[behind] = np.minimum(lowest[behind], values[k - 1])
        self.ceiling_fine = lowest - LIMIT_MARGIN_KMH * KMH
        self.last_limit_start = float(starts[-1])
        # additional resistance per unit effective mass, exact at the kinks of its mean
        steps = route.additional.starts[1:]
        self.add_knots = np.unique(np.concatenate((steps, steps + self.length, [0.0])))
        self.add_values = (route.additional_resistance(self.add_knots, self.length)
                           * self.weight / 1e3 / self.m_eff)
        # air-brake force per unit friction coefficient (N) after the smallest reduction
        model = FreightTrain(params, route)
        n = int(300.0 / DT) + 2
        self.air_scale = np.array([float(model.step_brakes(k * DT, (k + 1) * DT,
                                                           params.min_reduction)
                                         @ model.brake_scale) for k in range(n)])

    def ceiling(self, s: float, cruise: float) -> float:
        k = min(max(int(s), 0), self.s_fine.size - 1)  # limits start at whole metres
        return min(float(self.ceiling_fine[k]), cruise)

    def resistance(self, v: float, s: float) -> float:
        """Running resistance (N): basic (eqs. 3-4) + additional (eq. 5) of the train."""
        a, b, c = self.res
        add = float(np.interp(s, self.add_knots, self.add_values)) * self.m_eff
        return a + (b + c * v) * v + add

    def forward(self, cruise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Traction pass from rest: positions, speeds and accelerations every ``DT``."""
        s, v, a = 0.0, 0.0, 0.0
        xs, vs, acc = [0.0], [0.0], [0.0]
        end = self.route.length_m
        while s < end:
            c = self.ceiling(s, cruise)
            trac, _ = self.train.traction_limits(v)
            cap = min((TRACTION_SHARE * trac - self.resistance(v, s)) / self.m_eff,
                      MAX_REF_ACCEL)
            a = min(a + MAX_JERK * DT, cap, math.sqrt(2.0 * MAX_JERK * max(c - v, 0.0)))
            v1 = v + a * DT
            s += 0.5 * (v + v1) * DT
            v = v1
            if v >= self.ceiling(s, cruise):
                v, a = self.ceiling(s, cruise), min(a, 0.0)
            xs.append(s)
            vs.append(v)
            acc.append(a)
        return np.array(xs), np.array(vs), np.array(acc)

    def backward(self, forward: tuple[np.ndarray, np.ndarray, np.ndarray],
                 start: float) -> tuple[np.ndarray, np.ndarray]:
        """Slowing pass in reverse time from ``start`` back to 0 under the forward pass
        ``(positions, speeds, accelerations)``, leaving it tangentially: the gap ``g`` to it
        closes as ``a_f + d <= sqrt(2 J g)`` (``d`` the deceleration, ``a_f`` the forward
        acceleration). Increasing positions and speeds."""
        xf, vf, af = forward
        s = start
        v, d = float(np.interp(s, xf, vf)), -float(np.interp(s, xf, af))
        xs, vs = [s], [v]
        while s > 0.0 and v > 0.0:  # before that, the forward pass
            v_f, a_f = float(np.interp(s, xf, vf)), float(np.interp(s, xf, af))
            _, ed = self.train.traction_limits(max(v, 1.0))
            cap = min((ED_SHARE * ed + self.resistance(v, s)) / self.m_eff, DECEL_LIMIT)
            d = min(d + MAX_JERK * DT, cap,
                    math.sqrt(2.0 * MAX_JERK * max(v_f - v, 0.0)) - a_f)
            v1 = max(v + d * DT, 0.0)
            s -= 0.5 * (v + v1) * DT
            v = v1
            v_f = float(np.interp(s, xf, vf))
            if v >= v_f:
                v, d = v_f, -float(np.interp(s, xf, af))
            xs.append(s)
            vs.append(v)
        return np.array(xs[::-1]), np.array(vs[::-1])

    def stretch(self, force: float, a: float, v: float) -> float:
        """Head-to-mean displacement (m) of the train hauled by ``force`` (N) at acceleration
        ``a`` and speed ``v`` (quasi-static: identical wagons, so the coupler forces fall
        linearly from the first coupler's, the locomotive's force less its own inertia and
        resistance, to zero behind the tail; about ``N F / (3 k)``)."""
        t = self.train
        first = force - t.m_eff[0] * a - (t.res_a[0] + (t.res_b[0] + t.res_c[0] * v) * v)
        n = t.m_eff.size - 1
        couplers = max(first, 0.0) * np.arange(n, 0, -1) / n
        behind = np.concatenate(([0.0], np.cumsum(couplers / self.p.coupler_stiffness)))
        return float(behind.mean())

    def start(self, forward: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[np.ndarray,
                                                                                  np.ndarray]:
        """Planned start in the head's coordinate (see the module doc): head positions and
        speeds every ``DT`` from rest to the first ceiling of the traction pass ``forward``
        (its positions, speeds, accelerations every ``DT`` from rest)."""
        xf, vf, af = forward
        rate = self.m_eff * MAX_JERK  # N/s, the jerk rule's force rate
        breakaway = self.resistance(0.0, 0.0)
        creep = np.arange(0.0, breakaway / rate, DT)
        # at rest the constant resistance terms take their share of the rising force
        share = 1.0 - float(self.train.res_a[0]) / breakaway
        shift = [self.stretch(rate * t * share + float(self.train.res_a[0]), 0.0, 0.0)
                 if t > 0 else 0.0 for t in creep]
        mean = [0.0] * creep.size
        fade = None  # (stretch, its rate, time) at the end of the jerk ramp
        for i in range(xf.size):
            if fade is None and i > 0 and af[i] - af[i - 1] < 0.999 * MAX_JERK * DT:
                fade = (shift[-1], (shift[-1] - shift[-2]) / DT, 0.0)  # the ramp's end
            if fade is None:
                force = self.resistance(vf[i], xf[i]) + self.m_eff * af[i]
                shift.append(self.stretch(force, af[i], vf[i]))
            else:
                fade = (fade[0], fade[1], fade[2] + DT)
                shift.append(self._fade(*fade))
            mean.append(xf[i])
            if i > 0 and af[i] <= 0.0:  # the first ceiling
                break
        else:
            raise SystemExit("the traction pass reaches no ceiling")
        shift, mean = np.array(shift), np.array(mean)
        width = max(int(round(START_SMOOTHING_S / DT)), 1)  # trailing average, 0 before
        shift = np.convolve(np.concatenate((np.zeros(width - 1), shift)),
                            np.ones(width) / width, mode="valid")
        speed = np.gradient(mean + shift, DT)
        speed[0] = 0.0
        speed = np.maximum.accumulate(speed)  # never falling (clips rounding-size dips)
        speed[-1] = vf[i]
        head = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * DT)))
        return head, speed

    @staticmethod
    def _fade(held: float, rate: float, u: float) -> float:
        """Stretch (m) ``u`` s after the end of the start's jerk ramp, where it was ``held``
        growing at ``rate`` (m/s): the growth ends with its second derivative ramping at
        ``MAX_JERK`` down and back (over ``2 sqrt(rate / MAX_JERK)``), so the head's planned
        jerk stays within ``MAX_JERK``; then held."""
        rate = max(rate, 0.0)
        tau = math.sqrt(rate / MAX_JERK)
        if u < tau:
            return held + rate * u - MAX_JERK * u**3 / 6.0
        if u < 2.0 * tau:
            return held + rate * tau - MAX_JERK * (2.0 * tau - u) ** 3 / 6.0
        return held + rate * tau

    def _decel(self, v: float, s: float, k_air: int, force: float) -> float:
        """Deceleration (m/s^2) with the locomotive force ``force`` (N) and the air brake
        applied ``k_air`` steps ago (< 0: not applied)."""
        air = self.air_scale[k_air] * friction_coefficient_at(v) if k_air >= 0 else 0.0
        return (air - force + self.resistance(v, s)) / self.m_eff

    def stop(self, s0: float, v0: float, a0: float) -> tuple[np.ndarray, np.ndarray, float]:
        """Final braking from ``(s0, v0, a0)``: positions and speeds every ``DT`` to the stop,
        and the position where the air brake is applied."""
        m = self.m_eff
        force = m * a0 + self.resistance(v0, s0)  # locomotive force now (N)
        s, v = s0, v0
        xs, vs = [s], [v]
        applied_at = math.nan
        k_air = -1  # samples since the application
        while True:
            _, ed = self.train.traction_limits(v)
            target = -self.stop_ed_share * ed
            if k_air < 0:
                force = max(force - MAX_JERK * m * DT, target)
                if force <= target:
                    applied_at, k_air = s, 0
            else:
                force = target

            d0 = self._decel(v, s, k_air, force)
            vm = v - 0.5 * DT * d0
            dm = self._decel(max(vm, 0.0), s + 0.5 * DT * v, k_air, force)
            v1 = v - DT * dm
            if v1 <= 0.0:
                xs.append(s + v * v / (2.0 * dm))
                vs.append(0.0)
                return np.array(xs), np.array(vs), applied_at
            s += 0.5 * (v + v1) * DT
            v = v1
            if k_air >= 0:
                k_air += 1
            xs.append(s)
            vs.append(v)


def plan(cruise: float, planner: Planner) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Dense (positions, speeds) of the whole run for ``cruise`` (m/s), the start of the final
    braking, the air-brake application point and the end of the planned start (m)."""
    end = planner.route.length_m
    forward = planner.forward(cruise)
    xb, vb = planner.backward(forward, planner.last_limit_start - 1.0)
    grid = np.arange(0.0, end + 0.25, 0.5)
    base = np.minimum(np.interp(grid, forward[0], forward[1]),
                      np.interp(grid, xb, vb, left=np.inf, right=np.inf))
    accel = np.gradient(base**2, grid) / 2.0
    lo, hi = end - 4000.0, end - 600.0
    for _ in range(50):  # the braking start that stops the train at the end
        mid = 0.5 * (lo + hi)
        xs, _, _ = planner.stop(mid, float(np.interp(mid, grid, base)),
                                float(np.interp(mid, grid, accel)))
        lo, hi = (mid, hi) if xs[-1] < end else (lo, mid)
    start = 0.5 * (lo + hi)
    xs, vs, applied = planner.stop(start, float(np.interp(start, grid, base)),
                                   float(np.interp(start, grid, accel)))
    head, speed = planner.start(forward)
    keep = (grid > head[-1]) & (grid < start)
    if abs(float(np.interp(head[-1], grid, base)) - speed[-1]) > 1e-9:
        raise SystemExit(f"the planned start ends at {head[-1]:.1f} m off the ceiling")
    x = np.concatenate((head, grid[keep], xs))
    v = np.concatenate((speed, base[keep], vs))
    x[-1], v[-1] = end, 0.0
    return x, v, start, applied, float(head[-1])


def sample(x: np.ndarray, v: np.ndarray, extra: tuple[float, ...],
           start_end: float) -> tuple[np.ndarray, np.ndarray]:
    """The written points: the 10 m grid, points at most ``MAX_POINT_TIME`` apart in the
    planned time, and ``extra`` positions; positions to 1e-6 m. ``start_end``: the end of the
    planned start."""
    end = x[-1]
    ok = np.concatenate(([True], np.diff(x) > 0))
    x, v = x[ok], v[ok]
    t = np.concatenate(([0.0], np.cumsum(2.0 * np.diff(x) / np.maximum(v[:-1] + v[1:], 1e-9))))
    timed = np.interp(np.arange(0.0, t[-1], MAX_POINT_TIME), t, x)
    grid = np.unique(np.round(np.concatenate((np.arange(0.0, end + GRID_M / 2, GRID_M),
                                              extra)), 6))
    # past the start, a timed point within MIN_SPACING_M of a grid point would make a
    # segment whose acceleration is rounding noise: left out
    # (in the planned start, within half the distance planned between two timed points:
    # positions are written to 1e-6 m)
    gap = np.abs(timed[:, None] - grid[None, :]).min(axis=1)
    spacing = np.where(timed < start_end,
                       np.minimum(MIN_SPACING_M, 0.5 * MAX_POINT_TIME
                                  * np.sqrt(np.interp(timed, x, v**2))), MIN_SPACING_M)
    pts = np.unique(np.round(np.concatenate((grid, timed[gap >= spacing])), 6))
    speeds = np.sqrt(np.maximum(np.interp(pts, x, v**2), 0.0))
    speeds[-1] = 0.0
    return pts, speeds


def main() -> None:
    out = ROOT / "plants" / "routes"
    csv_path = out / f"{NAME}_reference.csv"
    if not csv_path.exists():
        csv_path.write_text("position_m,speed_kmh\n0.0,0.0\n1.0,0.0\n")  # to load the route
    route = load_route(out / f"{NAME}.toml")
    planner = Planner(route, FreightParams(), BlendingParams().stop_ed_share)
    lo, hi = 40.0 * KMH, 78.0 * KMH
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        x, v, _, _, _ = plan(mid, planner)
        lo, hi = (mid, hi) if ReferenceProfile("distance", x, v).run_time() > RUN_TIME_S \
            else (lo, mid)
    cruise = 0.5 * (lo + hi)
    x, v, start, applied, start_end = plan(cruise, planner)
    over = v - np.array([planner.ceiling(xi, math.inf) for xi in x])
    if over.max() > 1e-6:
        raise SystemExit(f"the plan exceeds the ceiling by {over.max() / KMH:.2f} km/h at "
                         f"{x[np.argmax(over)]:.0f} m")
    pts, speeds = sample(x, v, (start, applied), start_end)
    run = ReferenceProfile("distance", pts, speeds).run_time()
    lines = [f"# Reference speed-distance profile of {NAME} (HXD1 + 108 C80, {run:.1f} s run: "
             "the paper's 22.8 min and the planned start, "
             f"cruise {cruise / KMH:.2f} km/h, final braking from {start:.1f} m, air brake "
             f"applied at {applied:.1f} m);",
             "# generated by papers/seed002/make_freight_20km.py, see plants/routes/README.md",
             "position_m,speed_kmh"]
    lines += [f"{si:.6f},{vi / KMH:.6f}" for si, vi in zip(pts, speeds, strict=True)]
    csv_path.write_text("\n".join(lines) + "\n")
    print(f"{csv_path}: {pts.size} points, run time {run:.1f} s, cruise "
          f"{cruise / KMH:.2f} km/h, final braking from {start:.1f} m, air brake at "
          f"{applied:.1f} m, max {speeds.max() / KMH:.2f} km/h")


if __name__ == "__main__":
    main()
