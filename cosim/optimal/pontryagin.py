"""The energy-optimal run between two stops, by the theory of optimal train control.

Problem (per unit effective mass, :mod:`cosim.optimal.model`): from rest at the section start
to rest at its end within the running time ``T``, minimise
``J = int (F_+ / eta_t - eta_r B_r) ds`` subject to ``dE/ds = F - r(v) - g_w(s)``, the force
envelopes, the comfort limits and ``v <= V_lim(s)``.

Conditions (Pontryagin's maximum principle in the position domain; Howlett & Pudney, *Energy-
efficient train control*, Springer 1995; Khmelnitsky, IEEE TAC 45(7) 2000; Howlett, Pudney &
Vu, Automatica 45(11) 2009 for steep grades; Albrecht, Howlett, Pudney, Vu & Zhou, *The key
principles of optimal train control*, Transp. Res. B 94, 2016, parts 1 and 2, for
regenerative braking and speed limits). With the time multiplier ``lambda`` the Hamiltonian

    H = F_+ / eta_t - eta_r B_r + lambda / v + p (F - B - r(v) - g_w),
    dp/ds = -dH/dE = (lambda / v^2 + p r'(v)) / v                      (adjoint)

is minimised pointwise by the regimes: maximum traction (``p < -1/eta_t``); cruise by
partial traction (singular, ``p = -1/eta_t``); coasting (``-1/eta_t < p < -eta_r``); cruise
by partial regenerative braking (singular, ``p = -eta_r``); maximum regenerative braking
(``-eta_r < p < 0``: the friction brake, which returns nothing, stays off); maximum braking,
regenerative and friction (``p > 0``).
On a singular arc ``dp/ds = 0`` gives the holding speeds

    psi(V) = eta_t lambda,       psi(W) = lambda / eta_r,       psi(v) = v^2 r'(v),

so the cruising speed ``V`` follows from the multiplier and the braking-cruise speed ``W > V``
(none without regeneration): holding a speed by braking is optimal only at ``W`` (or at a
speed limit), never at ``V`` when ``eta_t eta_r < 1``. On a grade too steep to hold ``V``
uphill, power starts before the climb; on one too steep downhill, coasting starts before the
descent (Howlett, Pudney & Vu 2009, the *local energy minimisation* conditions, which are the
adjoint's return to ``p = -1/eta_t`` after the steep section); below a speed limit the train
holds the limit by partial traction or partial braking (Albrecht et al. 2016, part 2).

Solution: the adjoint is the gradient ``p = dJ*/dE`` of the cost-to-go ``J*(s, E)`` (Bellman's
principle; the Hamilton-Jacobi-Bellman equation is the maximum principle's characteristic
form). The cost-to-go of the Lagrangian ``J + lambda T`` is computed backwards over position on
a speed grid with these regimes as the controls (each step integrated by the explicit midpoint
rule in ``s``, ``sub_steps`` per step, the cost-to-go interpolated linearly in ``E``; holding a
speed only where a singular arc may be, at ``V``, ``W`` or a limit; traction at a share of the
maximum over a step standing for a switch inside it); the run is then integrated forwards from
rest choosing at each step the regime that minimises step cost plus cost-to-go at its exact
state, so every switching point (the coasting point, the start of power before a climb, the
braking point) comes from the adjoint condition it stands for. ``lambda`` is the one number the
schedule fixes: the running time decreases with it, and a 1-D root finder
(``scipy.optimize.brentq`` on ``log lambda``) finds the ``lambda`` whose running time is ``T``
(the energy's sensitivity to the running time is ``dJ/dT = -lambda``). On the grid the running
time is not continuous in ``lambda`` (the run of the root is on time but can be early) and a
switching point is known to within a step: :mod:`cosim.optimal.switching` takes this run's
sequence of regimes and finds its switching points exactly, the run on time
(:meth:`SectionSolver.for_time`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
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
from cosim.optimal.switching import refine

# controls of the cost-to-go: those of cosim.optimal.model.control_force
# a switch between maximum traction and coasting inside a step: the step's traction at these
# shares of the maximum (to first order in the step length the same motion and cost as
# maximum traction over that share of the step, then coasting)
_SWITCH_SHARES = (0.25, 0.5, 0.75)
_SHARES = np.array(_SWITCH_SHARES)
_CONTROLS = np.arange(5 + len(_SWITCH_SHARES))
_N = _CONTROLS.size
_BIG = 1e30  # cost-to-go of a state from which the stop cannot be reached


@dataclass(frozen=True)
class Grid:
    """Discretisation of the cost-to-go: position step ``ds`` (m, the breakpoints of grade and
    speed limit are nodes too), ``speeds`` nodes from rest to the highest limit, ``sub_steps``
    midpoint steps per position step."""

    ds: float = 50.0
    speeds: int = 600
    sub_steps: int = 2
    step: float = 2.0  # m, the integration step of the exact switching points (grown in
    # proportion on sections beyond 20 km)

    def finer(self) -> Grid:
        """Half the position step, speed spacing and integration step (the second grid of an
        error estimate)."""
        return Grid(self.ds / 2.0, 2 * self.speeds - 1, self.sub_steps, self.step / 2.0)


class _Steps:
    """Per-step data of a section on a position grid."""

    def __init__(self, section: Section, train: Train, ds: float) -> None:
        x = section.grid(ds)
        self.x = x
        self.h = np.diff(x)
        self.g = np.asarray(train.grade_accel(section.w_on(x[:-1], x[1:])))
        self.w = section.w_on(x[:-1], x[1:])
        self.limit = section.limit_on(x[:-1], x[1:], train)
        self.cap = 0.5 * self.limit**2  # E cap of each step


@numba.njit(cache=True)
def _control_forces(v: np.ndarray, g: float, p: np.ndarray, shares: np.ndarray) -> np.ndarray:
    out = np.empty_like(v)
    for i in range(v.shape[0]):
        control = i if i < 5 else POWER
        share = 1.0 if i < 5 else shares[i - 5]
        for j in range(v.shape[1]):
            out[i, j] = share * control_force(control, v[i, j], g, p)
    return out


class _Dynamics:
    def __init__(self, train: Train, sub_steps: int) -> None:
        self.train = train
        self.n = sub_steps
        self.eta = train.traction_efficiency
        self.rho = train.regen_efficiency

    def force(self, v: np.ndarray, g: float) -> np.ndarray:
        """Force per unit effective mass (m/s2): row ``i`` of ``v`` (first axis: the
        controls) under control ``_CONTROLS[i]`` (maximum traction, hold, coast, maximum
        braking, maximum regenerative braking alone, then the switching shares), by
        :func:`cosim.optimal.model.control_force`."""
        a = np.asarray(v, dtype=float)
        rows = np.ascontiguousarray(a.reshape(a.shape[0], -1))
        return _control_forces(rows, float(g), self.train.vector, _SHARES).reshape(a.shape)

    def advance(self, E: np.ndarray, h: float, g: float, cap: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every control from ``E`` (first axis: ``_CONTROLS``) over ``h`` (m): (E at the step end,
        cost J/kg, time s, works per unit mass: traction, regenerative, all braking)."""
        tr = self.train
        hs = h / self.n
        cost = np.zeros_like(E)
        dt = np.zeros_like(E)
        wt = np.zeros_like(E)
        wr = np.zeros_like(E)
        wb = np.zeros_like(E)
        for _ in range(self.n):
            v0 = np.sqrt(2.0 * E)
            f0 = self.force(v0, g)
            em = np.clip(E + 0.5 * hs * (f0 - tr.resistance(v0) - g), 0.0, cap)
            vm = np.sqrt(2.0 * em)
            rm = tr.resistance(vm)
            e1 = np.clip(E + hs * (self.force(vm, g) - rm - g), 0.0, cap)
            feff = (e1 - E) / hs + rm + g
            trac = np.maximum(feff, 0.0) * hs
            brake = np.maximum(-feff, 0.0)
            regen = np.minimum(brake, tr.regen_limit(vm)) * hs
            wt += trac
            wr += regen
            wb += brake * hs
            cost += trac / self.eta - self.rho * regen
            v1 = np.sqrt(2.0 * e1)
            vs = v0 + v1
            dt += np.where(vs > 0, 2.0 * hs / np.where(vs > 0, vs, 1.0), np.inf)
            E = e1
        return E, cost, dt, np.stack([wt, wr, wb])

    def stop(self, E: np.ndarray, h: float, g: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Constant deceleration ``E / h`` onto the stop at the step end: (feasible, cost,
        time, works); the force is taken at the mean kinetic energy ``E / 2``."""
        tr = self.train
        vm = np.sqrt(E)
        f = tr.resistance(vm) + g - E / h
        ok = (f >= -tr.brake_limit(vm)) & (E / h <= tr.max_decel) & (f <= tr.traction_limit(vm))
        trac = np.maximum(f, 0.0) * h
        brake = np.maximum(-f, 0.0)
        regen = np.minimum(brake, tr.regen_limit(vm)) * h
        v0 = np.sqrt(2.0 * E)
        dt = np.where(v0 > 0, 2.0 * h / np.where(v0 > 0, v0, 1.0), np.inf)
        return ok & (E > 0), trac / self.eta - self.rho * regen, dt, np.stack(
            [trac, regen, brake * h])


class SectionSolver:
    """Cost-to-go and optimal run of one section for a train on a grid (module text).

    The speed nodes at position ``s_k`` are the grid's speeds below the *feasibility
    boundary* ``v_f(s_k)`` and ``v_f(s_k)`` itself: the highest speed from which the stop
    and every speed limit ahead can still be kept (the maximum-braking curves onto the stop
    and onto each lower limit, and the limit itself, found backwards from the stop by
    inverting the braking step with Brent's method). On the boundary only maximum braking (or
    holding the limit) stays feasible, so the braking points come out exactly rather than a
    speed node early. The speed limits are speed nodes too.
    """

    def __init__(self, section: Section, train: Train, grid: Grid | None = None) -> None:
        self.section, self.train = section, train
        self.grid = grid or Grid()
        self.steps = st = _Steps(section, train, self.grid.ds)
        self.dyn = _Dynamics(train, self.grid.sub_steps)
        top = float(st.limit.max())
        self.v_nodes = np.unique(np.concatenate((np.linspace(0.0, top, self.grid.speeds),
                                                 st.limit)))
        self._spacing = top / (self.grid.speeds - 1)
        n = len(st.h)
        # node cap: the lower limit of the two steps at each node
        lim = st.limit
        node_cap = 0.5 * np.minimum(np.r_[lim[0], lim], np.r_[lim, lim[-1]]) ** 2
        ef = np.zeros(n + 1)
        ef[n - 1] = min(self._stop_boundary(float(st.h[-1]), float(st.g[-1])), node_cap[n - 1])
        for k in range(n - 2, -1, -1):
            ef[k] = self._brake_inverse(k, ef[k + 1], float(node_cap[k]))
        self.e_bound = ef
        self.nodes = []
        for k in range(n + 1):
            vf = math.sqrt(2.0 * ef[k])
            self.nodes.append(np.concatenate((self.v_nodes[self.v_nodes < vf * (1 - 1e-12)],
                                              [vf])))
        # per-step transitions of every node under every control: they do not depend on
        # lambda, so they are computed once and reused by every cost-to-go
        self._moves = [self._transitions(k) for k in range(n)]

    def _advance(self, k: int, E: np.ndarray) -> tuple[np.ndarray, ...]:
        st = self.steps
        return self.dyn.advance(E, float(st.h[k]), float(st.g[k]), float(st.cap[k]))

    def _stop_boundary(self, h: float, g: float) -> float:
        """Largest E from which the constant-deceleration stop over the last step is
        feasible."""
        ok = lambda e: bool(self.dyn.stop(np.array([e]), h, g)[0][0])  # noqa: E731
        hi = float(self.steps.cap[-1])
        if ok(hi):
            return hi
        lo = 0.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
        return lo

    def _brake_inverse(self, k: int, e_next: float, cap: float) -> float:
        """E at node k whose maximum-braking step lands on ``e_next`` (at most ``cap``)."""
        def land(e: float) -> float:
            return float(self._advance(k, np.full(_N, e))[0][BRAKE]) - e_next

        if land(cap) <= 0.0:
            return cap
        return scipy.optimize.brentq(land, 0.0, cap, xtol=1e-13 * max(cap, 1.0), rtol=1e-14)

    def _transitions(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        st = self.steps
        h, g = float(st.h[k]), float(st.g[k])
        e = 0.5 * self.nodes[k] ** 2
        if k == len(st.h) - 1:
            ok, cost, dt, _ = self.dyn.stop(e, h, g)
            ok |= np.arange(e.size) == e.size - 1  # the boundary node: on the stop curve
            return (np.zeros((1, e.size)), np.where(ok, cost, _BIG)[None, :],
                    np.where(ok, dt, 0.0)[None, :])
        e1, cost, dt, _ = self._advance(k, np.broadcast_to(e, (_N, e.size)))
        v1 = self._snap(k + 1, np.sqrt(2.0 * e1))
        bad = ~np.isfinite(dt) | (v1 > self.nodes[k + 1][-1])
        return v1, np.where(bad, _BIG, cost), np.where(bad, 0.0, dt)

    def _snap(self, k: int, v: np.ndarray) -> np.ndarray:
        """Speeds within rounding of the boundary of node ``k`` put on it."""
        vf = self.nodes[k][-1]
        return np.where((v > vf) & (v <= vf * (1 + 1e-9) + 1e-12), vf, v)

    def cost_to_go(self, multiplier: float) -> list[Callable[[np.ndarray], np.ndarray]]:
        """J*(s_k, v) + lambda T of the remaining run, as a function of the speed at each
        node position: linear in E between the values at ``self.nodes[k]``, infeasible above
        the boundary."""
        n = len(self.steps.h)
        J: list[Callable[[np.ndarray], np.ndarray]] = [lambda v: np.zeros_like(v)] * (n + 1)
        for k in range(n - 1, -1, -1):
            v1, cost, dt = self._moves[k]
            if k < n - 1:
                cost = cost.copy()
                cost[HOLD] = np.where(self._may_hold(k, self.nodes[k], multiplier), cost[HOLD],
                                      _BIG)
            nxt = J[k + 1](v1) if k < n - 1 else np.zeros_like(v1)
            J[k] = self._interpolant(k, np.minimum((cost + multiplier * dt + nxt).min(axis=0),
                                                   _BIG), multiplier)
        return J

    def _may_hold(self, k: int, v: np.ndarray, multiplier: float) -> np.ndarray:
        """Where a speed may be held (a singular arc of the maximum principle): at the
        cruising speeds V (partial traction) and W (partial braking) of ``multiplier``, within
        the speed grid's spacing, or at the speed limit; anywhere else holding is never
        optimal (``dp/ds = 0`` needs ``psi(v) = eta_t lambda`` or ``lambda / eta_r``), and
        allowing it would let the grid's interpolation error pick it."""
        V, W = hold_speeds(self.train, multiplier)
        if math.isnan(V):  # no resistance slope: no singular speed, hold anywhere
            return np.ones(v.shape, dtype=bool)
        dv = self._spacing
        cap = float(self.steps.limit[k])
        return (np.abs(v - V) <= dv) | (np.abs(v - W) <= dv) | (v >= cap - dv)

    def _interpolant(self, k: int, values: np.ndarray, multiplier: float
                     ) -> Callable[[np.ndarray], np.ndarray]:
        # linear in E: the cost-to-go's energy part is close to linear in kinetic energy (the
        # energy a speed is worth)
        e = 0.5 * self.nodes[k] ** 2
        top = self.nodes[k][-1]
        return lambda v: np.where(v <= top, np.interp(0.5 * v * v, e, values), _BIG)

    def run(self, multiplier: float) -> OptimalRun:
        """The run from rest that follows the cost-to-go of ``multiplier``."""
        J = self.cost_to_go(multiplier)
        st, dyn, tr = self.steps, self.dyn, self.train
        n = len(st.h)
        E = np.zeros(1)
        v = [0.0]
        t = [0.0]
        regime = np.zeros(n, dtype=np.int64)
        force = np.zeros(n)
        works = np.zeros(3)
        for k in range(n):
            h, g, cap = float(st.h[k]), float(st.g[k]), float(st.cap[k])
            if k == n - 1:
                ok, cost, dt, w = dyn.stop(E, h, g)
                if not ok[0] and not E[0] <= self.e_bound[k] * (1 + 1e-9):
                    raise ValueError(f"no stop from {math.sqrt(2 * E[0]):.3f} m/s within the "
                                     f"last {h:.1f} m")
                choice, e1 = BRAKE, np.zeros(1)
            else:
                e1s, cost, dts, ws = self._advance(k, np.full(_N, E[0]))
                v1 = self._snap(k + 1, np.sqrt(2.0 * e1s))
                cost[HOLD] = cost[HOLD] if self._may_hold(k, np.sqrt(2.0 * E), multiplier)[0] \
                    else _BIG
                vals = cost + multiplier * dts + J[k + 1](v1)
                i = int(np.argmin(vals))
                if vals[i] >= 0.1 * _BIG:
                    raise ValueError(f"the stop at {self.section.end:.1f} m cannot be reached "
                                     f"within the speed limits from "
                                     f"{self.section.start + st.x[k]:.1f} m")
                choice, dt, w = int(_CONTROLS[i]), dts[i:i + 1], ws[:, i:i + 1]
                e1 = 0.5 * v1[i:i + 1] ** 2
            works += w[:, 0]  # per unit mass
            force[k] = (w[0, 0] - w[2, 0]) / h * tr.effective_mass
            regime[k] = _regime(choice, float(E[0]), float(e1[0]), cap, force[k], h, tr)
            E = e1
            v.append(math.sqrt(2.0 * float(E[0])))
            t.append(t[-1] + float(dt[0]))
        m = tr.effective_mass
        V, W = hold_speeds(tr, multiplier)
        trac, regen, brake = works * m
        return OptimalRun(
            s=st.x + self.section.start, v=np.array(v), t=np.array(t), regime=regime,
            force=force, speed_limit=st.limit, grade=st.w, traction_work=float(trac),
            regen_work=float(regen), brake_work=float(brake),
            energy=float(trac / tr.traction_efficiency - tr.regen_efficiency * regen),
            multiplier=multiplier, hold_speed=V, brake_hold_speed=W)

    def fastest(self) -> OptimalRun:
        """The shortest run (the multiplier large: time dominates)."""
        return self.run(self._lam_hi())

    def _lam_hi(self) -> float:
        # lambda of a time cost far above any energy: psi at the highest limit, x 1e3
        vmax = float(self.v_nodes[-1])
        return max(1e3 * (self.train.psi(vmax) + vmax * 10.0), 1.0)

    def for_time(self, running_time: float, rtol: float = 1e-4, exact: bool = True
                 ) -> OptimalRun:
        """The optimal run whose running time is ``running_time`` (s): ``lambda`` by Brent's
        method on ``log lambda`` (the running time decreases with ``lambda``), the run of the
        bracket end that is on time (not late); with ``exact`` its switching points then
        found exactly and the run on time (:func:`cosim.optimal.switching.refine`)."""
        run = self._for_time(running_time, rtol)
        if not exact:
            return run
        # the integration step grows with sections beyond 20 km (10000 steps at most)
        step = self.grid.step * max(1.0, self.section.length / 20000.0)
        return refine(self.section, self.train, run, running_time, step, self.grid.ds)

    def _for_time(self, running_time: float, rtol: float) -> OptimalRun:
        hi = math.log(self._lam_hi())
        fastest = self.run(math.exp(hi))
        if fastest.running_time > running_time:
            raise ValueError(f"running time {running_time:.1f} s is below the shortest run "
                             f"{fastest.running_time:.1f} s")
        lo = hi - 8.0
        while self.run(math.exp(lo)).running_time < running_time:
            lo -= 8.0
            if lo < hi - 80:
                raise ValueError(f"no run as slow as {running_time:.1f} s")
        runs: dict[float, OptimalRun] = {}

        def late(x: float) -> float:
            runs[x] = self.run(math.exp(x))
            return runs[x].running_time - running_time

        x = scipy.optimize.brentq(late, lo, hi, xtol=1e-9, rtol=rtol)
        cand = runs.get(x)
        if cand is not None and cand.running_time <= running_time:
            return cand
        on_time = [r for r in runs.values() if r.running_time <= running_time]
        return min(on_time, key=lambda r: running_time - r.running_time)


def _regime(choice: int, e0: float, e1: float, cap: float, force: float, h: float,
            train: Train) -> int:
    if choice == BRAKE:
        return MAX_BRAKE
    if choice == REGEN:
        return MAX_REGEN
    if choice >= 5:  # a switch inside the step: the regime of the larger share
        return MAX_TRACTION if _SWITCH_SHARES[choice - 5] >= 0.5 else COASTING
    if choice == COAST:
        return COASTING
    if choice == POWER:
        return CRUISE_TRACTION if e1 >= cap * (1 - 1e-12) else MAX_TRACTION
    return CRUISE_TRACTION if force >= 0 else CRUISE_BRAKE


def trade_off(solver: SectionSolver, times: np.ndarray) -> list[OptimalRun]:
    """The energy / running-time trade-off: the optimal run for each running time (s)."""
    return [solver.for_time(float(T)) for T in times]
