"""Seed 001's per-unit indices (eqs. 87-89) in papers/seed001/metrics.py, on analytic signals."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.papers import paper_metrics

unit_indices = paper_metrics("seed001").unit_indices


def test_mse_iae_and_ma_of_known_signals() -> None:
    """Two units, reference 10 m/s; unit 1 is 1 km/h too fast, unit 2 follows a ramp at
    0.5 m/s2 for 4 s (errors 0 .. 7.2 km/h). Over t = 0..10 s at 0.5 s:
    eq. 87: mean of e^2 over both units and every sample; eq. 88: (10 + int ramp) / 2;
    eq. 89 at 1 s: 0.5 m/s per sample (the ramp), at 2 s: 1.0."""
    t = np.arange(0.0, 10.0 + 1e-9, 0.5)
    ref = np.full(t.size, 10.0)
    ramp = 10.0 + 0.5 * np.minimum(t, 4.0)
    speeds = np.column_stack([ref + 1.0 / 3.6, ramp])
    out = unit_indices(t, speeds, ref, 1.0)
    e2 = (ramp - ref) * 3.6
    assert out["unit_mse_kmh2"] == pytest.approx((np.sum(np.ones(t.size)) + np.sum(e2**2))
                                                 / (2 * t.size))
    # trapezoid is exact for the piecewise-linear ramp error: 4 s ramp to 7.2 km/h, 6 s at it
    assert out["unit_iae_kmh_s"] == pytest.approx((10.0 + 0.5 * 4 * 7.2 + 6 * 7.2) / 2)
    assert out["unit_ma_mps_per_sample"] == pytest.approx(0.5)
    assert out["ma_sample_time_s"] == 1.0
    assert unit_indices(t, speeds, ref, 2.0)["unit_ma_mps_per_sample"] == pytest.approx(1.0)


def test_ma_is_a_speed_change_per_sample_not_the_peak_acceleration() -> None:
    """A 0.2-s pulse of 2 m/s2 changes the speed by 0.4 m/s: MA over 1 s is 0.4, while the
    instantaneous acceleration peaks at 2."""
    t = np.arange(0.0, 5.0 + 1e-9, 0.1)
    a = np.where((t >= 2.0) & (t < 2.2), 2.0, 0.0)
    v = np.concatenate([[0.0], np.cumsum(a[:-1] * 0.1)])
    out = unit_indices(t, v[:, None], np.zeros(t.size), 1.0)
    assert out["unit_ma_mps_per_sample"] == pytest.approx(0.4)
