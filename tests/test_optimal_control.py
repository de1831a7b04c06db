"""The optimum of optimal train control (cosim.optimal.pontryagin with its exact switching
points, cosim.optimal.switching) against an independent discretised optimum
(tests/optimal_oracle.py: a sequential convex program over position and kinetic energy, cvxpy +
Clarabel), on level, steeply graded and speed-limited lines; the regimes where the theory puts
them; the schedule kept.

Tolerance: both methods are run on a grid and on the grid halved (the theory: its cost-to-go's
grid and its integration step); the difference of the two results of each method estimates the
error of its finer result (first-order convergence: the error of the finer grid equals the
difference; faster convergence makes it smaller), so the two finer results may differ by the
sum of those differences; the oracle's also carries the energy of its solver's slack on the
running time. Energies are compared at the same running time: the theory's own (its runs are
on time; ``_at`` charges a run that is not ``lambda m_eff dT``, ``dJ/dT = -lambda m_eff``)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
import pytest

from cosim.optimal.model import Section, Train
from cosim.optimal.pontryagin import Grid, SectionSolver
from cosim.optimal.regimes import COASTING, CRUISE_BRAKE, CRUISE_TRACTION, MAX_TRACTION, OptimalRun
from plants.resistance import Davis
from plants.route import Route, StepProfile
from tests import optimal_oracle

# a 500 t train too weak to hold its cruising speed on +15 permille, fast enough to gain
# speed coasting down -20 permille; regenerative (60 %) and friction brakes
WEAK = Train("weak", 500e3, 0.06, Davis(7000.0, 150.0, 10.0), 250e3, 2.0e6, 250e3, 3.0e6,
             200e3, max_decel=0.8, traction_efficiency=0.9, regen_efficiency=0.6)
# a suburban train with every limit of a TTOBench train: comfort accelerations too
EMU = Train("emu", 300e3, 0.08, Davis(5000.0, 100.0, 8.0), 300e3, 4e6, 300e3, 4e6, 300e3,
            max_accel=1.0, max_decel=0.9, traction_efficiency=0.9, regen_efficiency=0.8)


def _line(name: str, length: float, grade: list[list[float]],
          limits: list[list[float]]) -> Section:
    route = Route(name, length, StepProfile.from_pairs(grade),
                  speed_limit=StepProfile.from_pairs(limits))
    return Section(route, 0.0, length)


LEVEL = _line("level", 4000.0, [[0.0, 0.0]], [[0.0, 25.0]])
STEEP = _line("steep", 9000.0, [[0.0, 0.0], [2500.0, -20.0], [3700.0, 0.0], [5500.0, 15.0],
                                [6700.0, 0.0]], [[0.0, 40.0]])
LIMITED = _line("limited", 6000.0, [[0.0, 0.0], [4000.0, 5.0]],
                [[0.0, 30.0], [2500.0, 15.0], [3500.0, 30.0]])
GRID = Grid(ds=50.0, speeds=400)


def _at(run: OptimalRun, T: float, m_eff: float) -> float:
    """Energy (J) of ``run`` carried to the running time ``T`` (s) with dJ/dT."""
    return run.energy - run.multiplier * m_eff * (T - run.running_time)


def oracle_error(coarse: optimal_oracle.OracleRun, fine: optimal_oracle.OracleRun, T: float,
                 dJ_dT: float) -> float:
    """The error estimate of the finer oracle (J): the two grids' difference, and the energy
    of the interior-point solver's slack on the running time (``|dJ/dT| |T - T_oracle|``; its
    start speed is zero only to the solver's tolerance, which shifts the computed time)."""
    return abs(coarse.energy - fine.energy) + abs(dJ_dT) * abs(T - fine.running_time)


def _compare(section: Section, train: Train, stretch: float) -> dict[str, float]:
    coarse = SectionSolver(section, train, GRID)
    T = stretch * coarse.fastest().running_time
    th_coarse = coarse.for_time(T)
    th_fine = SectionSolver(section, train, GRID.finer()).for_time(T)
    T = th_fine.running_time  # the comparison time: the finer theory run's own
    m = train.effective_mass
    or_coarse = optimal_oracle.solve(section, train, T, GRID.ds)
    or_fine = optimal_oracle.solve(section, train, T, GRID.ds / 2.0)
    return {"T": T, "theory": th_fine.energy, "oracle": or_fine.energy,
            "theory_error": abs(_at(th_coarse, T, m) - th_fine.energy),
            "oracle_error": oracle_error(or_coarse, or_fine, T, th_fine.multiplier * m),
            "oracle_time": or_fine.running_time}


@pytest.mark.slow
@pytest.mark.parametrize(("section", "train", "stretch"), [
    (LEVEL, EMU, 1.2), (STEEP, WEAK, 1.25), (LIMITED, EMU, 1.15)],
    ids=["level", "steep", "speed-limited"])
def test_the_theory_optimum_equals_the_convex_oracle_within_the_grid_error(
        section: Section, train: Train, stretch: float) -> None:
    c = _compare(section, train, stretch)
    assert c["oracle_time"] <= c["T"] * (1 + 1e-6)
    tol = c["theory_error"] + c["oracle_error"]
    assert abs(c["theory"] - c["oracle"]) <= tol, c


@pytest.fixture(scope="module")
def steep_run() -> OptimalRun:
    solver = SectionSolver(STEEP, WEAK, GRID)
    return solver.for_time(1.25 * solver.fastest().running_time)


def test_the_descent_is_steep_at_the_cruising_speed(steep_run: OptimalRun) -> None:
    """The premise of the regime tests: at the theory's cruising speed V coasting speeds the
    train up on -20 permille (a steep descent), and V is below the line limit."""
    V = steep_run.hold_speed
    assert V < 40.0
    assert WEAK.grade_accel(-20.0) + WEAK.resistance(np.array([V]))[0] < 0.0


def _step_before(run: OptimalRun, position: float) -> int:
    return int(np.searchsorted(run.s, position)) - 1


def test_coast_before_the_descent(steep_run: OptimalRun) -> None:
    """Howlett, Pudney & Vu (2009): a steep descent is entered coasting, below V, the
    coasting started before it."""
    r, V = steep_run, steep_run.hold_speed
    k = _step_before(r, 2500.0)
    assert r.v[k + 1] < V
    assert np.all(r.regime[k - 2:k + 1] == COASTING)


def test_no_holding_brake_below_the_braking_cruise_speed(steep_run: OptimalRun) -> None:
    """With regeneration below 100 % the train holds a speed by braking only at W (psi(W) =
    lambda / eta_r, above V) or at a speed limit: never at V on a descent."""
    r = steep_run
    W = r.brake_hold_speed
    assert W > r.hold_speed
    held = r.regime == CRUISE_BRAKE
    at = np.minimum(r.v[:-1], r.v[1:])[held]
    lim = r.speed_limit[held]
    dv = 40.0 / (GRID.speeds - 1)
    assert np.all((at >= W - 2 * dv) | (at >= lim - 2 * dv))


@pytest.fixture(scope="module")
def level_run() -> Callable[[float], tuple[float, OptimalRun]]:
    """k -> (T, the run of EMU on LEVEL in T = k times the fastest running time), each k
    solved once, all on one solver (for_time gives a fresh solver's run bit for bit,
    whatever ran on it before)."""
    solver = SectionSolver(LEVEL, EMU, GRID)
    T0 = solver.fastest().running_time

    @functools.cache
    def run(k: float) -> tuple[float, OptimalRun]:
        return k * T0, solver.for_time(k * T0)
    return run


@pytest.mark.parametrize("stretch", [1.1, 1.3])
def test_the_schedule_is_kept(level_run, stretch: float) -> None:
    """On time to the precision of the time's root (Brent's method to 1e-12 m on a switching
    point; the feasibility test of the program allows 1e-9 of the running time)."""
    T, run = level_run(stretch)
    assert T * (1 - 1e-9) <= run.running_time <= T * (1 + 1e-9)


def test_the_run_is_on_time_from_rest_to_rest_within_the_limits() -> None:
    solver = SectionSolver(LIMITED, EMU, GRID)
    T = 1.2 * solver.fastest().running_time
    run = solver.for_time(T)
    assert run.running_time <= T
    assert run.v[0] == 0.0 and run.v[-1] == 0.0
    assert np.all(run.v[1:-1] <= LIMITED.limit_on(run.s[:-2], run.s[1:-1], EMU) + 1e-9)
    assert np.all(run.v[1:-1] <= LIMITED.limit_on(run.s[1:-1], run.s[2:], EMU) + 1e-9)
    assert math.isfinite(run.energy)


def test_a_longer_schedule_needs_less_energy(level_run) -> None:
    energies = [level_run(k)[1].energy for k in (1.1, 1.2, 1.4)]
    assert energies[0] > energies[1] > energies[2]


# a 12 km level line long enough for a cruise; the steep test train on a line with a climb
# it cannot hold its cruising speed on (+15 permille) after 7 km of level
LONG = _line("long", 12000.0, [[0.0, 0.0]], [[0.0, 30.0]])
CLIMB = _line("climb", 16000.0, [[0.0, 0.0], [7000.0, 15.0], [8200.0, 0.0], [11000.0, -20.0],
                                [12200.0, 0.0]], [[0.0, 40.0]])


def _longest_hold(run: OptimalRun) -> float:
    """The speed (m/s) of the run's longest holding phase by partial traction below a limit."""
    held = (run.regime == CRUISE_TRACTION) & (run.v[:-1] < run.speed_limit * (1 - 1e-9))
    edges = np.flatnonzero(np.diff(np.r_[0, held.astype(int), 0]))
    starts, ends = edges[::2], edges[1::2]
    i = int(np.argmax(run.s[ends] - run.s[starts]))
    return float(run.v[starts[i] + 1])


@pytest.mark.slow
def test_the_cruise_is_at_the_holding_speed_of_the_multiplier() -> None:
    """The singular arc of the maximum principle: the train holds ``V`` with ``psi(V) = eta_t
    lambda`` (Howlett & Pudney 1995), ``lambda`` the run's own multiplier (``-dJ/dT / m_eff``
    from the stationarity of its switching points). Tolerance: the two grids' differences of
    the held speed and of ``V``, plus ``V``'s error from the multiplier's own accuracy (its
    spread over the switching points, through ``dV = eta_t dlambda / psi'(V)``)."""
    coarse = SectionSolver(LONG, EMU, GRID)
    T = 1.15 * coarse.fastest().running_time
    runs = [coarse.for_time(T), SectionSolver(LONG, EMU, GRID.finer()).for_time(T)]
    held = [_longest_hold(r) for r in runs]
    V = [r.hold_speed for r in runs]
    fine = runs[1]
    assert math.isfinite(fine.multiplier_spread)
    h = 1e-6 * V[1]
    slope = (EMU.psi(V[1] + h) - EMU.psi(V[1] - h)) / (2.0 * h)  # psi'(V), m/s^2
    from_multiplier = EMU.traction_efficiency * fine.multiplier_spread / slope
    tol = abs(held[0] - held[1]) + abs(V[0] - V[1]) + from_multiplier
    assert abs(held[1] - V[1]) <= tol, (held, V, from_multiplier)


@pytest.mark.slow
def test_power_before_a_steep_climb() -> None:
    """Howlett, Pudney & Vu (2009): on a climb too steep to hold the cruising speed the train
    powers before the climb, from the speed it held, and enters the climb above it."""
    solver = SectionSolver(CLIMB, WEAK, GRID)
    run = solver.for_time(1.3 * solver.fastest().running_time)
    V = _longest_hold(run)
    assert WEAK.traction_limit(np.array([V]))[0] < (WEAK.grade_accel(15.0)
                                                     + WEAK.resistance(np.array([V]))[0])
    k = _step_before(run, 7000.0)
    assert run.regime[k] == MAX_TRACTION
    first = k
    while run.regime[first - 1] == MAX_TRACTION:
        first -= 1
    assert run.s[first] < 7000.0 and run.regime[first - 1] == CRUISE_TRACTION
    assert run.v[k + 1] > V
