"""The switching points of the optimal run, exact: the regime sequence of the cost-to-go's run
(:mod:`cosim.optimal.pontryagin`), its switching points found by a nonlinear program.

The cost-to-go on its grid decides *which* regimes the optimal run passes through, in which
order; where it switches between them it can only say to within a step, and the running time
of its run jumps with the multiplier (so the run it finds for a schedule is early). Here the
run is a sequence of phases ``[b_i, b_{i+1})`` of position, each in one control of the maximum
principle (:func:`cosim.optimal.model.control_force`): maximum traction (held at a speed limit
by the bound below), holding the speed it enters with (partial traction or partial braking,
the singular arcs), or coasting. Braking at the maximum follows *braking curves*: onto the
stop and onto every lower speed limit the run brakes for, maximum regenerative braking and,
over the last ``l_j`` metres before the target, maximum braking (regenerative and friction),
found backwards from the target by the integration's own rule; a phase that meets a curve
follows it. A lower limit the run only coasts onto is a constraint instead (its speed at the
limit's start at most the limit), so the program stays smooth where the run reaches a limit
exactly. The speed limits themselves and the stop are kept by the *feasibility boundary* (the
highest kinetic energy from which every lower limit ahead and the stop can still be kept at
maximum braking), which the run follows where it would pass it. The unknowns ``z = (b, l)``
solve

    minimise J(z)   subject to   T(z) <= T,   b_1 <= b_2 <= ...,   E(limit start) <= E_limit,

``J`` the energy of the model (:mod:`cosim.optimal.model`) and ``T`` the running time, both
integrated by the explicit midpoint rule in position on a grid of at most ``step`` metres with
every switching point, grade change and speed-limit change as a node, and a step that meets
the bound split where it meets it (so ``J`` and ``T`` are continuous and piecewise smooth in
``z``, and the integration second order). Solved by SLSQP (``scipy.optimize.minimize``) with
central-difference gradients of the compiled integration (numba), from the cost-to-go's run,
the unknowns scaled by its position step; SLSQP is run again, with the phases it shrank to
nothing removed, until the energy stops falling, and one unknown is then moved by Brent's
method so that the run is exactly on time.

At a solution the program's first-order (KKT) conditions hold: ``dJ/dz_i = -mu dT/dz_i`` at
every unknown not at a bound, ``mu`` the multiplier of the schedule, which is the maximum
principle's ``lambda m_eff = -dJ/dT`` (the switching conditions of Howlett & Pudney 1995 and
Khmelnitsky 2000 are these stationarity conditions for the switching points of a fixed
sequence). A phase the cost-to-go's run lacks can therefore not appear; a holding phase of zero
length is put between every maximum-traction phase and the coasting after it, so a cruise the
grid missed can grow.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.optimize

from cosim.optimal.model import (
    BRAKE,
    COAST,
    HOLD,
    POWER,
    REGEN,
    Section,
    Train,
    control_force,
    regen_at,
    resistance_at,
)
from cosim.optimal.regimes import (
    COASTING,
    CRUISE_BRAKE,
    CRUISE_TRACTION,
    MAX_BRAKE,
    MAX_REGEN,
    MAX_TRACTION,
    OptimalRun,
    hold_speeds,
)

_MODE_OF_REGIME = {MAX_TRACTION: POWER, CRUISE_TRACTION: HOLD, COASTING: COAST,
                   CRUISE_BRAKE: HOLD, MAX_REGEN: REGEN, MAX_BRAKE: BRAKE}
_REGIME_OF_MODE = {POWER: MAX_TRACTION, COAST: COASTING, REGEN: MAX_REGEN, BRAKE: MAX_BRAKE}
# kinetic energy per unit mass (J/kg) below which the run does not fall before the stop (0.05
# m/s): a run that would stop short creeps on, slowly and late, so time and energy stay
# continuous in the switching points; no solution comes near it
_E_FLOOR = 0.5 * 0.05**2
# SLSQP's ftol: it stops when an iteration changes the scaled energy (units of its largest
# change over the position step) by less than this. Where the energy is flat (cruising a
# little above V on one stretch and below on another) the points stay where it stopped.
SLSQP_FTOL = 1e-12
# SLSQP's iteration bound: well above the iterations it takes to reach its ftol on the lines
# here; a round stopped by the bound leaves points SLSQP would still move
SLSQP_MAX_ITER = 1000


@numba.njit(cache=True)
def _boundary(x: np.ndarray, g: np.ndarray, cap: np.ndarray, p: np.ndarray,
              mode: np.ndarray, target: np.ndarray, to_cap: bool) -> np.ndarray:
    """A braking curve (kinetic energy per unit mass) at the nodes ``x``: zero at the stop,
    backwards by the midpoint rule under ``mode`` per step (maximum braking or maximum
    regenerative braking), capped at every node by the limits of its two steps (``cap`` per
    step). With ``to_cap`` the curve goes on from every cap it meets (the feasibility
    boundary). Without, it ends where it meets a cap (``inf`` beyond) and starts again at
    each node of ``target`` (a lower speed limit's start) from that limit: the braking curves
    onto the stop and onto every lower limit."""
    n = x.size - 1
    e = np.zeros(n + 1)
    for k in range(n - 1, -1, -1):
        c = cap[k] if k == 0 else min(cap[k], cap[k - 1])
        e1 = e[k + 1]
        if not math.isfinite(e1):
            e[k] = c if target[k] else math.inf
            continue
        h = x[k + 1] - x[k]
        v1 = math.sqrt(2.0 * e1)
        d1 = control_force(mode[k], v1, g[k], p) - resistance_at(v1, p) - g[k]
        em = max(e1 - 0.5 * h * d1, 0.0)
        vm = math.sqrt(2.0 * em)
        dm = control_force(mode[k], vm, g[k], p) - resistance_at(vm, p) - g[k]
        ek = max(e1 - h * dm, 0.0)
        e[k] = min(ek, c) if to_cap or target[k] or ek < c else math.inf
    return e


@numba.njit(cache=True)
def _works(e0: float, e1: float, h: float, g: float, p: np.ndarray, vm: float
           ) -> tuple[float, float, float, float, float]:
    """A piece of length ``h`` from ``e0`` to ``e1`` at constant acceleration, resisted at
    speed ``vm``: (mean force per unit mass, traction, regenerative and braking work per unit
    mass, time)."""
    f = (e1 - e0) / h + resistance_at(vm, p) + g
    if f > 0.0:
        return f, f * h, 0.0, 0.0, 2.0 * h / (math.sqrt(2.0 * e0) + math.sqrt(2.0 * e1))
    regen = min(-f, regen_at(vm, p))
    return f, 0.0, regen * h, -f * h, 2.0 * h / (math.sqrt(2.0 * e0) + math.sqrt(2.0 * e1))


@numba.njit(cache=True)
def _integrate(x: np.ndarray, g: np.ndarray, cap: np.ndarray, mode: np.ndarray,
               bound: np.ndarray, p: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float,
                          float, float]:
    """The run from rest under ``mode`` per step, kept under ``bound`` (per node, linear in
    between): kinetic energy per node, and what it would be without the bound at that node;
    per step the mean force (m/s2), the time (s) and the share of the step on the bound;
    traction, regenerative and all braking work per unit mass (J/kg). A step that meets the
    bound is split where it meets it (linear in the step), so the run joins the bound at the
    crossing and not at a node."""
    n = x.size - 1
    E = np.zeros(n + 1)
    free = np.zeros(n + 1)
    force = np.zeros(n)
    dt = np.zeros(n)
    held = np.zeros(n)
    wt = 0.0
    wr = 0.0
    wb = 0.0
    for k in range(n):
        h = x[k + 1] - x[k]
        e0 = E[k]
        v0 = math.sqrt(2.0 * e0)
        gk = g[k]
        f0 = control_force(mode[k], v0, gk, p)
        em = min(max(e0 + 0.5 * h * (f0 - resistance_at(v0, p) - gk), 0.0), cap[k])
        vm = math.sqrt(2.0 * em)
        e1 = max(e0 + h * (control_force(mode[k], vm, gk, p) - resistance_at(vm, p) - gk),
                 _E_FLOOR)
        free[k + 1] = e1
        b0, b1 = bound[k], bound[k + 1]
        theta = 1.0
        if e1 > b1:
            # where the step meets the bound: e0 + th (e1 - e0) = b0 + th (b1 - b0)
            den = (e1 - e0) - (b1 - b0)
            theta = min(max((b0 - e0) / den, 0.0), 1.0) if den > 0.0 else 0.0
            e1 = b1
        if theta < 1.0 and theta * h > 1e-9:
            ec = b0 + theta * (b1 - b0)
            fa, ta, ra, ba, sa = _works(e0, ec, theta * h, gk, p, math.sqrt(e0 + ec))
            fb, tb, rb, bb, sb = _works(ec, e1, (1.0 - theta) * h, gk, p, math.sqrt(ec + e1))
            force[k] = theta * fa + (1.0 - theta) * fb
            wt += ta + tb
            wr += ra + rb
            wb += ba + bb
            dt[k] = sa + sb
        else:
            f, ta, ra, ba, sa = _works(e0, e1, h, gk, p, vm if theta == 1.0 else
                                       math.sqrt(e0 + e1))
            force[k] = f
            wt += ta
            wr += ra
            wb += ba
            dt[k] = sa
        held[k] = 1.0 - theta
        E[k + 1] = e1
    return E, free, force, dt, held, wt, wr, wb


def phases_of(run: OptimalRun, targets: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The run's phases: (controls, switching points in m from the section start; for each of
    ``targets``, the lower limits' starts and the stop in m from the section start, the length
    in m of the maximum braking that ends there and whether the run brakes onto it). Steps of
    one control make one phase (traction at the maximum up to a limit, and holding the limit,
    are one: maximum traction held at the limit by the bound); braking at the maximum
    (regenerative or all) is left to the braking curves onto the targets; a holding phase of
    zero length goes between maximum traction and the coasting after it."""
    modes: list[int] = []
    starts: list[float] = []
    x = run.s - run.s[0]
    for k, regime in enumerate(run.regime):
        m = _MODE_OF_REGIME[int(regime)]
        if regime == CRUISE_TRACTION and (run.v[k + 1] > run.v[k] * (1.0 + 1e-9) or
                                          run.v[k + 1] >= run.speed_limit[k] * (1.0 - 1e-9)):
            # traction at the maximum up to a limit within the step, or holding the limit:
            # maximum traction held at the limit by the bound (one phase, no switching point
            # that changes nothing)
            m = POWER
        if m in (BRAKE, REGEN):
            continue
        if not modes or modes[-1] != m:
            modes.append(m)
            starts.append(float(x[k]))
    out_m: list[int] = [modes[0]]
    out_b: list[float] = []
    for m, s in zip(modes[1:], starts[1:]):
        if out_m[-1] == POWER and m == COAST:
            out_m.append(HOLD)
            out_b.append(s)
        out_m.append(m)
        out_b.append(s)
    braking = run.regime == MAX_BRAKE
    slowing = braking | (run.regime == MAX_REGEN)
    lengths = []
    braked = []
    for xt in targets:
        k = int(np.searchsorted(x, xt - 1e-9))  # node of the target
        j = k
        while j > 0 and braking[j - 1]:
            j -= 1
        lengths.append(float(x[k] - x[j]))
        braked.append(bool(k > 0 and slowing[k - 1]))
    return (np.array(out_m, dtype=np.int64), np.array(out_b), np.array(lengths),
            np.array(braked, dtype=bool))


@dataclass(frozen=True)
class Switching:
    """The phases of an optimal run: their controls, switching points (m from the section
    start) and the lengths (m) of maximum braking onto each braking target; whether the run is
    on time and keeps its coasted limits (``converged``), and SLSQP's message."""

    modes: np.ndarray
    points: np.ndarray
    brake_lengths: np.ndarray
    converged: bool
    message: str


class SwitchingProblem:
    """The run of a section as a function of its switching points (module text); ``step``
    (m) the largest integration step.

    Braking targets: the stop and the start of every lower speed limit the run brakes onto
    (``brakes``, one flag per lower limit; all by default). Onto each the run brakes along a
    braking curve: maximum braking over the last ``brake_lengths[j]`` metres before it,
    maximum regenerative braking before that (a train without a regenerative brake brakes at
    its maximum throughout); the forward phases follow a curve from where they meet it. A
    lower limit the run does not brake onto is a constraint instead: the run reaches it at or
    below the limit (so the program stays smooth where the run coasts onto a limit exactly)."""

    def __init__(self, section: Section, train: Train, modes: np.ndarray,
                 step: float = 2.0, brakes: np.ndarray | None = None) -> None:
        self.section, self.train = section, train
        self.step = step
        self.p = train.vector
        x = section.grid(step)
        self.base = x
        self.base_g = np.asarray(train.grade_accel(section.w_on(x[:-1], x[1:])), dtype=float)
        self.base_w = section.w_on(x[:-1], x[1:])
        self.base_limit = section.limit_on(x[:-1], x[1:], train)
        self.base_cap = 0.5 * self.base_limit**2
        no_target = np.zeros(x.size, dtype=np.bool_)
        self.base_bound = _boundary(x, self.base_g, self.base_cap, self.p,
                                    np.full(x.size - 1, BRAKE, dtype=np.int64), no_target, True)
        self.length = section.length
        self.drops = x[1:-1][self.base_cap[1:] < self.base_cap[:-1]]  # lower limits' starts
        self.regen = train.max_regen_force > 0 and train.max_regen_power > 0
        self._phases(modes, brakes)

    def _phases(self, modes: np.ndarray, brakes: np.ndarray | None) -> None:
        self.modes = np.asarray(modes, dtype=np.int64)
        self.n_points = self.modes.size - 1
        brakes = (np.ones(self.drops.size, dtype=bool) if brakes is None
                  else np.asarray(brakes, dtype=bool))
        self.targets = np.r_[self.drops[brakes], self.length]
        self.coasted = self.drops[~brakes]  # reached at or below their limit
        self.coasted_cap = self.base_cap[np.searchsorted(self.base, self.coasted)]

    def with_phases(self, modes: np.ndarray, brakes: np.ndarray | None) -> SwitchingProblem:
        """The same section, train and grid with other phases and braking targets."""
        other = copy.copy(self)
        other._phases(modes, brakes)
        return other

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Switching points and braking lengths of the unknowns ``z`` (m)."""
        if self.regen:
            return z[:self.n_points], np.clip(z[self.n_points:], 0.0, self.length)
        return z, np.full(self.targets.size, self.length)

    def unknowns(self, points: np.ndarray, brake_lengths: np.ndarray) -> np.ndarray:
        return np.r_[points, brake_lengths] if self.regen else np.asarray(points, dtype=float)

    def grid(self, z: np.ndarray) -> tuple[np.ndarray, ...]:
        """(nodes; per step: control, g, cap, limit, w, the braking curves' control; per node:
        the bound and the braking curves onto the targets) for the unknowns ``z`` (m): the base
        grid with the switching points and the starts of maximum braking as nodes (a point
        within 1e-9 m of a node is that node)."""
        points, lengths = self.split(z)
        L = self.length
        b = np.maximum.accumulate(np.clip(points, 0.0, L))
        extra = np.r_[b, np.maximum(self.targets - lengths, 0.0)]
        base = self.base
        i = np.searchsorted(base, extra)
        near = np.zeros(extra.size, dtype=bool)
        for off in (-1, 0):
            j = np.clip(i + off, 0, base.size - 1)
            near |= np.abs(base[j] - extra) <= 1e-9
        x = np.union1d(base, extra[~near])
        mid = 0.5 * (x[:-1] + x[1:])
        step_of = np.clip(np.searchsorted(base, mid) - 1, 0, base.size - 2)
        mode = self.modes[np.searchsorted(b, mid)]
        g, cap = self.base_g[step_of], self.base_cap[step_of]
        ahead = np.searchsorted(self.targets, mid)  # the target each step brakes onto
        tail_mode = np.where(self.targets[ahead] - mid <= lengths[ahead], BRAKE,
                             REGEN).astype(np.int64)
        target = np.zeros(x.size, dtype=np.bool_)
        target[np.searchsorted(x, self.targets[:-1])] = True
        tail = _boundary(x, g, cap, self.p, tail_mode, target, False)
        bound = np.minimum(np.interp(x, base, self.base_bound), tail)
        return (x, mode, g, cap, self.base_limit[step_of], self.base_w[step_of], tail_mode,
                bound, tail)

    def evaluate(self, z: np.ndarray) -> tuple[float, float, np.ndarray]:
        """(energy J, running time s, the margin of each coasted lower limit: ``1 - E / E_lim``
        at its start, unbounded) of the unknowns ``z`` (m)."""
        x, mode, g, cap, _, _, _, bound, _ = self.grid(z)
        tr = self.train
        _, free, _, dt, _, wt, wr, _ = _integrate(x, g, cap, mode, bound, self.p)
        m = tr.effective_mass
        margin = 1.0 - free[np.searchsorted(x, self.coasted)] / self.coasted_cap
        return (m * (wt / tr.traction_efficiency - tr.regen_efficiency * wr), float(dt.sum()),
                margin)

    def gradients(self, z: np.ndarray, delta: float = 1e-2
                  ) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(J, T, margins, dJ/dz, dT/dz, d margins/dz) by central differences of ``delta``
        m."""
        J, T, c = self.evaluate(z)
        gJ = np.zeros(z.size)
        gT = np.zeros(z.size)
        gc = np.zeros((c.size, z.size))
        for i in range(z.size):
            up = z.copy()
            dn = z.copy()
            up[i] += delta
            dn[i] -= delta
            ju, tu, cu = self.evaluate(up)
            jd, td, cd = self.evaluate(dn)
            gJ[i] = (ju - jd) / (2.0 * delta)
            gT[i] = (tu - td) / (2.0 * delta)
            gc[:, i] = (cu - cd) / (2.0 * delta)
        return J, T, c, gJ, gT, gc

    def _stationarity_rows(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(dJ/dz, dT/dz)`` of the unknowns free of their bounds (switching points that
        coincide move as one), those with ``|dT/dz| > 1e-12``."""
        points, lengths = self.split(z)
        _, _, _, gJ, gT, _ = self.gradients(z)
        L = self.length
        rows_J, rows_T = [], []
        edges = np.r_[0.0, points, L]
        i = 0
        while i < points.size:
            j = i
            while j + 1 < points.size and points[j + 1] - points[j] <= 1e-6:
                j += 1
            if edges[i] > 1e-6 and edges[j + 2] - points[j] > 1e-6 and points[i] > 1e-6:
                rows_J.append(gJ[i:j + 1].sum())
                rows_T.append(gT[i:j + 1].sum())
            i = j + 1
        if self.regen:
            for k, ell in enumerate(lengths):
                if 1e-6 < ell < L - 1e-6:
                    rows_J.append(gJ[self.n_points + k])
                    rows_T.append(gT[self.n_points + k])
        gj, gt = np.array(rows_J), np.array(rows_T)
        keep = np.abs(gt) > 1e-12
        return gj[keep], gt[keep]

    def multiplier(self, z: np.ndarray) -> tuple[float, float]:
        """``(mu / m_eff, its accuracy)`` (J/kg/s) of the stationarity ``dJ/dz = -mu dT/dz``
        over the unknowns free of their bounds (switching points that coincide move as one),
        by least squares; the accuracy is the largest distance of the estimate from one free
        unknown's own ``-dJ/dz / (m_eff dT/dz)`` (0 with one unknown; both nan with none). At
        an exact optimum every unknown gives the same value; SLSQP stops at its ftol."""
        gj, gt = self._stationarity_rows(z)
        if not gt.size:
            return math.nan, math.nan
        m = self.train.effective_mass
        lam = -float(gj @ gt / (gt @ gt)) / m
        return lam, float(np.max(np.abs(-gj / gt / m - lam)))

    def feasible(self, z: np.ndarray, running_time: float) -> bool:
        """On time (to 1e-9 relative) and every coasted limit kept (to 1e-9 of its energy)."""
        _, T, c = self.evaluate(z)
        return T <= running_time * (1.0 + 1e-9) and bool(np.all(c >= -1e-9))

    def solve(self, points: np.ndarray, brake_lengths: np.ndarray, running_time: float,
              scale: float = 50.0, max_iter: int = SLSQP_MAX_ITER) -> Switching:
        """The switching points and braking lengths of least energy on time, from ``points``
        and ``brake_lengths`` (module text), made exactly on time by :meth:`on_time`.

        The unknowns are measured in ``scale`` metres from the start (the start's own
        precision: the cost-to-go's position step) and the energy, the time and the margins
        in units of their largest change over ``scale`` at the start, so SLSQP's first step
        (its Hessian starts as the identity) moves a switching point by about ``scale``."""
        z0 = self.unknowns(points, brake_lengths)
        n = z0.size
        if n == 0:
            return Switching(self.modes, points, brake_lengths, self.feasible(z0, running_time),
                             "nothing to choose")
        L = self.length
        cache: dict[bytes, tuple[float, float, np.ndarray, np.ndarray, np.ndarray,
                                 np.ndarray]] = {}

        def at(y: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray,
                                       np.ndarray]:
            key = y.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self.gradients(z0 + scale * y)
            return cache[key]

        J0, _, _, gJ0, gT0, gc0 = at(np.zeros(n))
        sJ = max(float(np.abs(gJ0).max()) * scale, 1e-12 * max(abs(J0), 1.0))
        sT = max(float(np.abs(gT0).max()) * scale, 1e-12 * running_time)
        sc = np.maximum(np.abs(gc0).max(axis=1) * scale, 1e-12) if gc0.size else gc0
        npts = self.n_points
        order = np.zeros((max(npts - 1, 0), n))
        for i in range(npts - 1):
            order[i, i], order[i, i + 1] = -1.0, 1.0
        cons = [{"type": "ineq", "fun": lambda y: (running_time - at(y)[1]) / sT,
                 "jac": lambda y: -at(y)[4] * scale / sT}]
        if self.coasted.size:
            cons.append({"type": "ineq", "fun": lambda y: at(y)[2] / sc,
                         "jac": lambda y: at(y)[5] * scale / sc[:, None]})
        if npts > 1:
            cons.append({"type": "ineq", "fun": lambda y: order @ (z0 / scale + y),
                         "jac": lambda y: order})
        lo, hi = -z0 / scale, (L - z0) / scale
        res = scipy.optimize.minimize(lambda y: (at(y)[0] - J0) / sJ, np.zeros(n),
                                      jac=lambda y: at(y)[3] * scale / sJ, method="SLSQP",
                                      bounds=list(zip(lo, hi)), constraints=cons,
                                      options={"maxiter": max_iter, "ftol": SLSQP_FTOL})
        pts, lengths = self.split(np.clip(z0 + scale * res.x, 0.0, L))
        z = self.on_time(self.unknowns(np.maximum.accumulate(pts), lengths), running_time)
        pts, lengths = self.split(z)
        return Switching(self.modes, pts, lengths, self.feasible(z, running_time),
                         str(res.message))

    def on_time(self, z: np.ndarray, running_time: float) -> np.ndarray:
        """``z`` with the one unknown the running time is most sensitive to moved so that the
        run is on time (Brent's method; the energy changes by ``-mu dT``, to first order the
        optimum of the new time): SLSQP meets the time only to its own tolerance."""
        _, T, _, _, gT, _ = self.gradients(z)
        if abs(T - running_time) <= 1e-12 * running_time:
            return z
        for i in np.argsort(-np.abs(gT)):
            if abs(gT[i]) < 1e-12:
                break
            step = (running_time - T) / gT[i]

            def late(t: float, i: int = i) -> float:
                y = z.copy()
                y[i] += t
                return self.evaluate(y)[1] - running_time

            hi = step
            for _ in range(8):  # a bracket around the Newton step
                if late(0.0) * late(2.0 * hi) < 0.0:
                    break
                hi *= 2.0
            else:
                continue
            t = scipy.optimize.brentq(late, 0.0, 2.0 * hi, xtol=1e-12, rtol=1e-14)
            y = z.copy()
            y[i] += t
            if late(t, i) > 0.0:  # the on-time side of the root
                y[i] += math.copysign(1e-12 * max(abs(y[i]), 1.0), -gT[i])
            if self.feasible(y, running_time):
                return y
        return z

    def run(self, points: np.ndarray, brake_lengths: np.ndarray, multiplier: float,
            multiplier_spread: float = math.nan) -> OptimalRun:
        """The run of the switching points as an :class:`OptimalRun` on the integration grid
        (``multiplier_spread``: the multiplier's accuracy, :meth:`multiplier`)."""
        x, mode, g, cap, limit, w, tail_mode, bound, tail = self.grid(
            self.unknowns(points, brake_lengths))
        tr = self.train
        E, _, force, dt, share, wt, wr, wb = _integrate(x, g, cap, mode, bound, self.p)
        held = share >= 0.5
        node_cap = np.minimum(np.r_[cap[0], cap], np.r_[cap, cap[-1]])
        on_tail = held & (tail[1:] <= bound[1:])
        on_curve = held & (bound[1:] < node_cap[1:] * (1.0 - 1e-12))
        regime = np.array([_REGIME_OF_MODE.get(int(m), 0) for m in mode], dtype=np.int64)
        cruise = np.where(force >= 0.0, CRUISE_TRACTION, CRUISE_BRAKE)
        regime = np.where(mode == HOLD, cruise, regime)
        regime = np.where(held, cruise, regime)
        regime = np.where(on_curve, MAX_BRAKE, regime)
        regime = np.where(on_tail & on_curve,
                          np.where(tail_mode == BRAKE, MAX_BRAKE, MAX_REGEN), regime)
        m = tr.effective_mass
        trac, regen, brake = wt * m, wr * m, wb * m
        V, W = hold_speeds(tr, multiplier) if math.isfinite(multiplier) else (math.nan,
                                                                             math.nan)
        t = np.r_[0.0, np.cumsum(dt)]
        nodes, steps = _output_nodes(x)
        return OptimalRun(
            s=x[nodes] + self.section.start, v=np.sqrt(2.0 * E[nodes]), t=t[nodes],
            regime=regime[steps], force=force[steps] * m, speed_limit=limit[steps],
            grade=w[steps],
            traction_work=float(trac), regen_work=float(regen), brake_work=float(brake),
            energy=float(trac / tr.traction_efficiency - tr.regen_efficiency * regen),
            multiplier=multiplier, hold_speed=V, brake_hold_speed=W,
            multiplier_spread=multiplier_spread)


_MIN_OUTPUT_STEP = 0.05  # m: nodes closer than this to the one before are not written out


def _output_nodes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, steps) of ``x`` to write out: every node at least ``_MIN_OUTPUT_STEP`` beyond
    the last one kept, and the last node (a switching point a fraction of a millimetre from a
    grid node makes a step a table of positions in millimetres cannot show); each kept step
    takes the quantities of the longest step it spans. Speeds and times at the kept nodes are
    those of the integration."""
    keep = [0]
    for i in range(1, x.size):
        if x[i] - x[keep[-1]] >= _MIN_OUTPUT_STEP:
            keep.append(i)
    if keep[-1] != x.size - 1:
        if len(keep) > 1:
            keep[-1] = x.size - 1
        else:
            keep.append(x.size - 1)
    nodes = np.array(keep)
    h = np.diff(x)
    steps = np.array([a + int(np.argmax(h[a:b])) for a, b in zip(nodes[:-1], nodes[1:])])
    return nodes, steps


def _simplify(modes: np.ndarray, points: np.ndarray, length: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """The phases without those of zero length (1e-6 m), neighbours of one control merged."""
    starts = np.r_[0.0, points]
    ends = np.r_[points, length]
    out_m: list[int] = []
    out_s: list[float] = []
    for m, a, b in zip(modes, starts, ends):
        if b - a <= 1e-6 and len(modes) > 1:
            continue
        if out_m and out_m[-1] == m:
            continue
        out_m.append(int(m))
        out_s.append(float(a))
    if not out_m:
        return modes[:1], np.zeros(0)
    return np.array(out_m, dtype=np.int64), np.array(out_s[1:])


def refine(section: Section, train: Train, run: OptimalRun, running_time: float,
           step: float = 2.0, scale: float = 50.0, rounds: int = 6) -> OptimalRun:
    """The optimal run on time with exact switching points, from the cost-to-go's ``run``
    (module text); ``scale`` (m) the precision of its switching points (its position step).
    SLSQP is run again from where it stopped, with the phases it shrank to
    nothing removed, until the energy stops falling (it stops early on a function that is only
    piecewise smooth, and phases of zero length leave it directions that change nothing). The
    cost-to-go's run, integrated on the same grid, is returned instead when no on-time run
    improves on it (it is then early, as it was)."""
    modes = phases_of(run, np.zeros(0))[0]
    problem = SwitchingProblem(section, train, modes, step)
    braked = phases_of(run, problem.drops)[3]
    problem = problem.with_phases(modes, braked)
    _, points, lengths, _ = phases_of(run, problem.targets)
    start = problem.run(points, lengths, run.multiplier)
    best: tuple[float, SwitchingProblem, Switching] | None = None
    for _ in range(rounds):
        sol = problem.solve(points, lengths, running_time, scale)
        energy = problem.evaluate(problem.unknowns(sol.points, sol.brake_lengths))[0]
        if not sol.converged or (best is not None and energy >= best[0] * (1.0 - 1e-10)):
            break
        best = (energy, problem, sol)
        modes, points = _simplify(sol.modes, sol.points, problem.length)
        lengths = sol.brake_lengths
        problem = problem.with_phases(modes, braked)
    if best is None:
        return start
    _, problem, sol = best
    z = problem.unknowns(sol.points, sol.brake_lengths)
    lam, spread = problem.multiplier(z)
    if not math.isfinite(lam):
        lam, spread = run.multiplier, math.nan
    refined = problem.run(sol.points, sol.brake_lengths, lam, spread)
    if refined.energy <= start.energy or start.running_time > running_time:
        return refined
    return start
