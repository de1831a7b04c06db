"""The regimes of a step of an optimal run, the run itself (:class:`OptimalRun`) and its hold
speeds: what the cost-to-go (:mod:`cosim.optimal.pontryagin`) and the exact switching points
(:mod:`cosim.optimal.switching`) both produce and read."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from cosim.optimal.model import Train

# regimes of a step of the optimal run
MAX_TRACTION, CRUISE_TRACTION, COASTING, CRUISE_BRAKE, MAX_BRAKE, MAX_REGEN = 1, 2, 3, 4, 5, 6
REGIME_NAMES = {MAX_TRACTION: "maximum traction", CRUISE_TRACTION: "cruise (partial traction)",
                COASTING: "coasting", CRUISE_BRAKE: "cruise (partial braking)",
                MAX_BRAKE: "maximum braking", MAX_REGEN: "maximum regenerative braking"}


@dataclass(frozen=True)
class OptimalRun:
    """The optimal run of a section: nodes ``s`` (m, line positions), speeds ``v`` (m/s) and
    times ``t`` (s); per step the ``regime`` and the mean ``force`` (N, traction > 0); the energy
    terms (J) and the multiplier."""

    s: np.ndarray
    v: np.ndarray
    t: np.ndarray
    regime: np.ndarray
    force: np.ndarray
    speed_limit: np.ndarray  # m/s on each step
    grade: np.ndarray  # additional resistance on each step (N/kN, grade + curves)
    traction_work: float  # J, int F_+ ds
    regen_work: float  # J, int B_r ds
    brake_work: float  # J, int (B_r + B_f) ds
    energy: float  # J, traction_work / eta_t - eta_r regen_work
    multiplier: float  # lambda (J/kg/s per unit effective mass): -dJ/dT / m_eff
    hold_speed: float  # V of psi(V) = eta_t lambda (m/s; nan if the resistance has no slope)
    brake_hold_speed: float  # W of psi(W) = lambda / eta_r (m/s; inf without regeneration)
    # the multiplier's accuracy (J/kg/s): the largest distance of the estimate from any one free
    # switching point's own -dJ/dz / (m_eff dT/dz); nan where not estimated (the cost-to-go's)
    multiplier_spread: float = math.nan

    @property
    def running_time(self) -> float:
        return float(self.t[-1])


def hold_speeds(train: Train, multiplier: float) -> tuple[float, float]:
    """(V, W) of ``psi(V) = eta_t lambda`` and ``psi(W) = lambda / eta_r`` (Albrecht et al.
    2016, part 1): the optimal cruising speed by traction and by regenerative braking."""

    def solve(target: float) -> float:
        if train.psi(1e3) <= target:
            return math.inf
        if target <= 0:
            return 0.0
        return scipy.optimize.brentq(lambda v: train.psi(v) - target, 0.0, 1e3, xtol=1e-10)

    if train.davis.b == 0 and train.davis.c == 0:
        return math.nan, math.nan
    v = solve(train.traction_efficiency * multiplier)
    w = math.inf if train.regen_efficiency <= 0 else solve(multiplier / train.regen_efficiency)
    return v, w
