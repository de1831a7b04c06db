"""Seed 003 robust MPC law (controllers/robust/rmpc.py) on a single-mass test plant."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controllers.robust.multimodel import ArxSet
from controllers.robust.rmpc import RmpcParams, RobustMpcLaw, load_model_set

M, G, GAMMA = 980e3, 9.81, 0.06
F_MAX = 300e3


def w0(v_kmh: float) -> float:
    """Unit basic resistance of the paper's Table 1 (N/kN)."""
    return 0.76 + 0.00636 * v_kmh + 0.000115 * v_kmh**2


def trapezoid(v_top: float = 60 / 3.6, acc: float = 0.25, cruise: float = 20.0,
              dec: float = 0.25):
    """Speed-time trapezoid (v, s at t) and its end time and length."""
    t1 = v_top / acc
    t2 = t1 + cruise
    t3 = t2 + v_top / dec

    def v(t: float) -> float:
        return float(np.clip(min(acc * t, v_top, v_top - dec * (t - t2)), 0.0, None)) \
            if t > 0 else 0.0

    def s(t: float) -> float:
        t = min(max(t, 0.0), t3)
        if t <= t1:
            return 0.5 * acc * t * t
        if t <= t2:
            return 0.5 * acc * t1 * t1 + v_top * (t - t1)
        return 0.5 * acc * t1 * t1 + v_top * cruise + v_top * (t - t2) - 0.5 * dec * (t - t2)**2

    return v, s, t3, s(t3)


def run(law: RobustMpcLaw, seconds: int, v_ref, s_ref) -> tuple[np.ndarray, float, float]:
    """Closed loop with a 0.1 s Euler single-mass plant (a = g f_c / (1000 (1 + gamma)));
    returns the speed errors at the samples (km/h), final position and speed."""
    v = s = 0.0
    errors = []
    for k in range(seconds):
        t = float(k)
        errors.append(3.6 * (v - v_ref(t)))
        force = law.step(v, s, v_ref(t), v_ref(t + 1.0), s_ref(t), F_MAX, F_MAX)
        for _ in range(10):
            fc = force / (M * G / 1000.0) - (w0(3.6 * v) if v > 0 else 0.0)
            v = max(v + 0.1 * G * fc / (1000.0 * (1.0 + GAMMA)), 0.0)
            s += 0.1 * v
    return np.array(errors), s, v


def test_tracks_a_trapezoid_and_stops_at_the_end():
    v_ref, s_ref, t_end, s_end = trapezoid()
    law = RobustMpcLaw(dataclasses.replace(RmpcParams(), model_set="paper"),
                       load_model_set("paper"))
    err, s, v = run(law, int(t_end) + 20, v_ref, s_ref)
    assert law.lmi_failures == 0
    # the reference's acceleration steps are 0.25 m/s^2: one sample behind at most
    # (0.25 m/s^2 x 1 s = 0.9 km/h) while the disturbance estimate settles
    assert np.abs(err).max() < 0.9
    assert np.sqrt(np.mean(err**2)) < 0.3
    # at rest (or creeping the last centimetres to the stop point) within the paper's 0.5 m
    assert v < 0.01 and abs(s - s_end) < 0.5


def test_vertex_sets_and_parameter_errors():
    law = RobustMpcLaw(dataclasses.replace(RmpcParams(), model_set="paper"), ArxSet.paper())
    assert law.vertex_indices(0) == [0, 1, 2]
    assert law.vertex_indices(3) == [2, 3, 4]
    assert law.vertex_indices(5) == [3, 4, 5]
    allv = RobustMpcLaw(dataclasses.replace(RmpcParams(), vertices="all"), ArxSet.paper())
    assert allv.vertex_indices(2) == list(range(6))
    for field, bad, match in (("vertices", "some", "vertices"), ("solver", "mosek", "solver"),
                              ("model_set", "x", "model_set")):
        with pytest.raises(ValueError, match=match):
            RobustMpcLaw(dataclasses.replace(RmpcParams(), **{field: bad}), ArxSet.paper())
