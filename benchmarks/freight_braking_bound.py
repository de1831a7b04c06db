"""Lower bound on the speed error of any freight controller at the final braking of seed 002
(prints figures, asserts nothing).

The onset is the reference's planned air-brake application
(:meth:`controllers.common.freight_blending.FreightBlending.planned_onsets`; the start of the
last braking segment for a reference without one). On the first reference the final
braking stepped from cruise to -0.2 m/s^2; the plant can brake that
hard only with its air brake, which it applies in pipe-reduction stages (the smallest, 50 kPa,
already gives about -0.19 m/s^2), which builds up from head to tail over seconds (eq. 9,
propagation along the pipe) and which is not partly releasable; while it acts the locomotive
may only brake (no power braking), with at most the electric-brake limit. This script takes
the nominal one-mass train of the shared blending (eq. 7, effective mass, modelled resistance
along the reference, air-brake force from the brake-pipe model at the reference speed) and, for
every application time ``t_app`` from 15 s before to 5 s after the onset (0.4 s grid) and the
two smallest pipe-reduction stages, solves the LP

    min z  s.t.  |v_k - v_ref,k| <= z,  v_{k+1} = v_k + h (f_k - F_air,k(t_app) - R_k) / M(1+gamma)
                 f_k in [-ED_k, traction_k] before t_app, [-ED_k, 0] after (no power braking)

for the locomotive force ``f`` with the eq. (15) lag (``--no-lag``: ``f`` switches instantly,
an even lower bound). The smallest ``z`` over ``t_app`` and the stages is the best train-mean
speed error any controller can reach there (the head speed adds the train-stretch modes).
``--power-braking`` drops the no-power-braking rule, to show what that rule costs.

    python benchmarks/freight_braking_bound.py [--no-lag] [--power-braking]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.common.freight_blending import BlendingParams, FreightBlending  # noqa: E402
from plants.freight import FreightTrain, friction_coefficient  # noqa: E402
from plants.route import load_route  # noqa: E402

H = 0.2  # s, the controllers' sample time


def braking_onset(profile) -> float:
    """Position (m) where the final braking segment of the reference starts."""
    acc = np.array([profile.accel(0.5 * (a + b)) for a, b in zip(profile.x[:-1], profile.x[1:])])
    last = len(acc) - 1
    while last > 0 and acc[last - 1] < 0:
        last -= 1
    return float(profile.x[last])


def bound(lag: bool, power_braking: bool, before: float = 25.0, after: float = 45.0,
          stages: tuple[float, ...] = (50e3, 60e3), apply_from: float = -15.0,
          apply_to: float = 5.0) -> tuple[float, float, float]:
    """(best max |v - v_ref| in km/h, its t_app relative to the onset in s, its reduction Pa)."""
    route = load_route("freight_20km")
    profile = route.reference
    blend = FreightBlending(BlendingParams(), profile, route)
    tp = blend.p.train
    times = profile.times()
    ok = np.isfinite(times)
    planned = blend.planned_onsets()  # the reference's planned air-brake application
    s_on = float(planned[-1]) if planned.size else braking_onset(profile)
    t_on = float(np.interp(s_on, profile.x[ok], times[ok]))
    t = t_on + np.arange(-before, after + 1e-9, H)
    s_ref = np.interp(t, times[ok], profile.x[ok])
    v_ref = np.array([profile.speed(x) for x in s_ref])
    K = t.size - 1
    m = blend.m_eff
    res = np.array([blend.resistance_accel(v, x) for v, x in zip(v_ref, s_ref)]) * m
    lim = [blend.model.traction_limits(v) for v in v_ref]
    trac = np.array([a for a, _ in lim])
    ed = np.array([b for _, b in lim])
    mu = friction_coefficient(v_ref)
    # locomotive force f = G u (lag + dead time of eq. 15, exact at the sample instants)
    delay = int(round(tp.traction_delay / H))
    if lag:
        a = math.exp(-H / tp.traction_time_constant)
        G = np.zeros((K, K))
        for k in range(K):
            for i in range(k - delay):
                G[k, i] = (1 - a) * a ** (k - delay - 1 - i)
    else:
        G = np.eye(K)
    # free response of f to the history: u = f_init (cruise force on the reference) before
    # the window, f_0 = f_init; zero input u from k = 0 on
    f_init = res[0] + m * (v_ref[1] - v_ref[0]) / H
    f_free = np.zeros(K)
    if lag:
        f = f_init
        for k in range(K):
            f_free[k] = f
            f = a * f + (1 - a) * (f_init if k < delay else 0.0)
    # cumulative sum: v_k - v_0 = h/m sum_{i<k} f_i ... for k = 1..K
    L = np.tril(np.ones((K, K))) * H / m
    best = (math.inf, math.nan, math.nan)
    for red in stages:
        model = FreightTrain(tp, route)
        air_scale = np.array([float(model.step_brakes(j * H, (j + 1) * H, red) @ model.brake_scale)
                              for j in range(K)])
        for k_app in range(int((before + apply_from) / H), int((before + apply_to) / H) + 1, 2):
            air = np.zeros(K)
            air[k_app:] = air_scale[: K - k_app] * mu[k_app:K]
            free = v_ref[0] + L @ (f_free - air - res[:K]) - v_ref[1:]  # v_k - v_ref_k, u = 0
            lo = -ed[:K]
            hi = trac[:K].copy()
            if not power_braking:
                hi[k_app:] = 0.0
            # variables [u_0..u_{K-1}, z]; f = G u must respect the bounds too
            M = L @ G
            A = np.vstack((np.hstack((M, -np.ones((K, 1)))), np.hstack((-M, -np.ones((K, 1)))),
                           np.hstack((G, np.zeros((K, 1)))), np.hstack((-G, np.zeros((K, 1))))))
            b = np.concatenate((-free, free, hi - f_free, f_free - lo))
            c = np.zeros(K + 1)
            c[-1] = 1.0
            bounds = [(lo[i], trac[i]) for i in range(K)] + [(0, None)]
            r = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
            if r.status == 0 and r.x[-1] * 3.6 < best[0]:
                best = (r.x[-1] * 3.6, t[k_app] - t_on, red)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-lag", action="store_true")
    ap.add_argument("--power-braking", action="store_true")
    a = ap.parse_args()
    z, t_app, red = bound(not a.no_lag, a.power_braking)
    print(f"final braking, one-mass train, lag={'no' if a.no_lag else 'eq. 15'}, "
          f"power braking={'allowed' if a.power_braking else 'forbidden'}: "
          f"best max |v - v_ref| = {z:.3f} km/h (air applied {t_app:+.1f} s from the onset, "
          f"reduction {red / 1e3:.0f} kPa)")


if __name__ == "__main__":
    main()
