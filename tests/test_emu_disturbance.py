"""Coloured disturbance of the EMU plant (plants/emu.py coloured_noise)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plants.emu import COLOURED_COMPONENTS, Emu, coloured_noise, emu_config
from plants.route import Route


def test_coloured_noise_is_unit_variance_with_the_stated_correlation_time() -> None:
    """Ensemble over 300 seeds x 3 units (random phases: E x(t)^2 = 1, E x(t) x(t+s) =
    E cos(omega s) = exp(-s/tau)). With 900 samples the standard errors are about 0.05 for
    the variance and 0.03 for the correlations: 0.2 and 0.12 are allowed (4 sigma)."""
    tau, t0 = 20.0, 1234.5
    def at(t: float) -> np.ndarray:
        return np.concatenate([coloured_noise(seed, 3, t, tau) for seed in range(300)])

    x0 = at(t0)
    assert np.mean(x0**2) == pytest.approx(1.0, abs=0.2)
    for lag in (1.0, tau, 3 * tau):
        corr = np.mean(x0 * at(t0 + lag))
        assert corr == pytest.approx(math.exp(-lag / tau), abs=0.12)
    assert COLOURED_COMPONENTS == 64


def test_coloured_disturbance_is_a_function_of_seed_and_time_only() -> None:
    """Same seed: the same forces whatever the sub-step; another seed: different."""
    def forces(seed: int, max_step: float) -> np.ndarray:
        p = emu_config("crh380a_3unit", disturbance_accel_std=0.05, disturbance_interval=0.2,
                       disturbance_seed=seed, disturbance_correlation_time=20.0,
                       max_step=max_step)
        emu = Emu(p, Route.flat())
        return np.array([emu._noise(int(k * 1e8)) for k in range(50)])

    a, b, c = forces(1, 0.05), forces(1, 0.1), forces(2, 0.05)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    assert np.abs(a).max() < 0.05 * 1.836e5 * 6  # bounded by sqrt(2K) sigma m, far less


def test_negative_correlation_time_is_rejected() -> None:
    with pytest.raises(ValueError, match="disturbance_correlation_time"):
        Emu(emu_config("crh380a_3unit", disturbance_correlation_time=-1.0), Route.flat())


def test_smooth_disturbance_has_the_gaussian_correlation_and_small_second_differences() -> None:
    """``smooth``: E x(t) x(t+s) = E cos(omega s) = exp(-s^2 / (2 tau^2)) (same ensemble and
    4-sigma tolerances as above), and the second difference over T = 0.2 s (assumption 3, eq.
    28) has E (d2 x)^2 = 6 - 8 r(T) + 2 r(2T) ~ 3 (T / tau)^4, far below the Ornstein-Uhlenbeck
    signal's 4 T / tau (its increments are nearly white; its 64 frequencies cover the tail
    sparsely, hence 0.1 of it)."""
    tau, t0, T = 10.0, 1234.5, 0.2
    def at(t: float, smooth: bool) -> np.ndarray:
        return np.concatenate([coloured_noise(seed, 3, t, tau, smooth=smooth)
                               for seed in range(300)])

    x0 = at(t0, True)
    assert np.mean(x0**2) == pytest.approx(1.0, abs=0.2)
    for lag in (2.0, tau, 2 * tau):
        assert np.mean(x0 * at(t0 + lag, True)) == pytest.approx(
            math.exp(-lag**2 / (2 * tau**2)), abs=0.12)
    def d2(smooth: bool) -> float:
        x = [at(t0 + k * T, smooth) for k in range(3)]
        return float(np.mean((x[2] - 2 * x[1] + x[0]) ** 2))
    assert d2(True) < 10 * 3 * (T / tau) ** 4   # ensemble spread of the 64 frequencies
    assert d2(False) > 0.1 * 4 * T / tau
