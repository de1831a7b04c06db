"""Multi-model LMI robust MPC of seed 003 (section 3.2-3.3, eqs. 14-28) for the CRH3.

At every sample (T = 1 s) the controller

1. measures ``y(k)`` = speed (km/h) and updates the switching index of the ARX set with the
   one-step mismatch of every model (eqs. 27-28): the active model ``s``;
2. estimates the disturbance ``xi`` of eq. 13 as the filtered one-step residual of model ``s``
   (the paper's D xi term of eq. 14, handled by feed-forward instead of eq. 24's D column);
3. feeds forward ``u_ff = (y_r(k+1) - a_s y_r(k) - c_s - xi_hat) / b_s`` (the input that keeps
   model ``s`` on the reference speed ``y_r``) and regulates the tracking error
   ``x = [y - y_r (km/h), s - s_r (m)]``, whose model at vertex ``j`` is
   ``x+ = [[a_j, 0], [T/3.6, 1]] x + [b_j; 0] du``;
4. solves the Kothare LMI problem (eqs. 22-26, :class:`controllers.common.lmi.KothareLmi`)
   over the vertex set chosen by ``vertices``: ``"neighbours"`` (our reading of the paper's
   switching: the active model and its two neighbours in speed order span the polytope Omega
   of eq. 16), ``"all"`` (the six models) or ``"nominal"`` (the active model alone);
5. applies ``u = u_ff + F x`` (``F = Y Qv^-1``), clipped to the traction/brake envelope read from
   the plant and to the comfort bound ``|a| <= accel_max`` (section 4). An LMI problem the
   solver does not solve keeps the previous gain (counted in ``lmi_failures``).

Units: ``y`` km/h, ``u`` daN/kN (per cent of the train's weight, the unit that reconciles the
paper's a_i and b = 0.318, see :mod:`controllers.robust.multimodel`); the output is a force in N.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from controllers.common.lmi import LMI_SOLVERS, KothareLmi
from controllers.robust.multimodel import N_PER_KN_PER_UNIT, ArxSet, SwitchingIndex
from cosim.fmu.declare import param, sample_time
from cosim.fmu.state import StatefulCore

G = 9.81
STANDSTILL_KMH = 0.01  # below this, now and one sample before, the train is at rest
VERTEX_SETS = ("neighbours", "all", "nominal")
MODEL_SETS = ("identified", "paper")
DATA_DIR = Path(__file__).resolve().parent / "data"
IDENTIFIED_FILE = "crh3_arx.toml"


class Reference(Protocol):
    """A speed-time target: speed (m/s), position (m) and acceleration (m/s^2) at time t."""

    def speed(self, t: float) -> float: ...

    def position(self, t: float) -> float: ...

    def accel(self, t: float) -> float: ...


@dataclass(frozen=True)
class RmpcParams:
    """Section 4 of the paper: Q = diag(1, 1, 1), R = 1, |a| <= 1 m/s^2, T = 1 s."""

    sample_time: float = sample_time(1.0)
    q_speed: float = param(1.0, "1", "Q: weight on the speed error (km/h)^-2", min=0.0)
    q_position: float = param(1.0, "1", "Q: weight on the position error m^-2", min=0.0)
    r_input: float = param(1.0, "1", "R: weight on the input correction (daN/kN)^-2",
                           min=1e-9, name="R")
    u_max: float = param(3.0, "1", "bound on the LMI input correction |F z| over the "
                         "invariant ellipsoid (eq. 25), daN/kN", min=1e-6)
    vertices: str = param("neighbours", description='polytope of the LMI: "neighbours" '
                          '(active model and its neighbours), "all" or "nominal"')
    model_set: str = param("identified", description='ARX set: "identified" (fitted to our '
                           'CRH3 plant, controllers/robust/data) or "paper" (section 2)')
    switch_alpha: float = param(1.0, "1", "a: weight of the current mismatch (eq. 27)",
                                min=1e-9)
    switch_beta: float = param(1.0, "1", "b: weight of the past mismatches (eq. 27)", min=1e-9)
    switch_rho: float = param(0.8, "1", "forgetting factor rho (eq. 27)", min=1e-6,
                              max=0.999999)
    switch_horizon: int = param(10, "1", "past horizon l (eq. 27, samples)", min=0, max=1000)
    disturbance_gain: float = param(0.3, "1", "filter gain of the disturbance estimate",
                                    min=0.0, max=1.0)
    accel_max: float = param(1.0, "m/s2", "comfort bound |a| <= a_max (section 4)", min=0.0)
    mass: float = param(980e3, "kg", "train mass (converts unit force to N)", min=1.0)
    rotating_mass_factor: float = param(0.06, "1", "gamma of the train (for the comfort "
                                        "bound on the force)", min=0.0)
    error_clip_speed: float = param(30.0, "m/s", "speed error fed to the LMI clipped to "
                                    "+- this (conditioning)", min=0.0)
    error_clip_position: float = param(200.0, "m", "position error fed to the LMI clipped "
                                       "to +- this", min=0.0)
    lmi_floor: float = param(1.0, "1", "errors smaller than this (km/h, m) are scaled up to "
                             "it in the LMI problem (conditioning)", min=1e-6)
    solver: str = param("clarabel", description=f"SDP solver, one of {LMI_SOLVERS}")

    def check(self) -> None:
        if self.vertices not in VERTEX_SETS:
            raise ValueError(f"vertices = {self.vertices!r} must be one of {VERTEX_SETS}")
        if self.model_set not in MODEL_SETS:
            raise ValueError(f"model_set = {self.model_set!r} must be one of {MODEL_SETS}")
        if self.solver not in LMI_SOLVERS:
            raise ValueError(f"solver = {self.solver!r} must be one of {LMI_SOLVERS}")
        if int(self.switch_horizon) != self.switch_horizon:
            raise ValueError(f"switch_horizon = {self.switch_horizon} must be an integer")
        if not self.sample_time > 0:
            raise ValueError(f"sample_time = {self.sample_time} must be > 0")


def load_model_set(name: str, data_dir: Path | None = None) -> ArxSet:
    """The ARX set ``name`` ("paper" or "identified": the bundled file)."""
    if name == "paper":
        return ArxSet.paper()
    if name != "identified":
        raise ValueError(f"model_set = {name!r} must be one of {MODEL_SETS}")
    import tomllib

    path = (data_dir or DATA_DIR) / IDENTIFIED_FILE
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"model_set = 'identified': cannot read {path}: {exc}") from exc
    return ArxSet.from_toml(data, str(path))


class RobustMpcLaw(StatefulCore):
    """The per-event law of the module docstring, independent of FMI and of the profile."""

    state_fields: ClassVar[tuple[str, ...]] = (
        "switch", "xi_hat", "y_prev", "u_prev", "gain", "active", "gamma", "solve_times",
        "lmi_failures", "force", "last_status")

    def __init__(self, params: RmpcParams, models: ArxSet) -> None:
        params.check()
        self.p, self.models = params, models
        if abs(models.sample_time - params.sample_time) > 1e-9:
            raise ValueError(f"model set sampled at {models.sample_time} s, controller at "
                             f"sample_time = {params.sample_time} s")
        n_v = {"neighbours": min(3, models.size), "all": models.size, "nominal": 1}
        self.lmi = KothareLmi(2, 1, n_v[params.vertices],
                              np.diag([params.q_speed, params.q_position]),
                              np.array([[params.r_input]]), u_max=[params.u_max],
                              solver=params.solver)
        self.switch = SwitchingIndex(models, params.switch_alpha, params.switch_beta,
                                     params.switch_rho, int(params.switch_horizon))
        self.unit_force = params.mass * G / 1000.0 * N_PER_KN_PER_UNIT  # N per daN/kN
        self.xi_hat = 0.0
        self.y_prev: float | None = None
        self.u_prev = 0.0
        self.gain = [0.0, 0.0]
        self.active = 0
        self.gamma = 0.0
        self.solve_times: list[float] = []
        self.lmi_failures = 0
        self.force = 0.0
        self.last_status = ""

    def vertex_indices(self, s: int) -> list[int]:
        n = self.models.size
        if self.p.vertices == "all":
            return list(range(n))
        if self.p.vertices == "nominal":
            return [s]
        lo = min(max(s - 1, 0), max(n - 3, 0))
        return list(range(lo, lo + min(3, n)))

    def vertex(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        T, m = self.p.sample_time, self.models
        return (np.array([[m.a[i], 0.0], [T / 3.6, 1.0]]), np.array([[m.b[i]], [0.0]]))

    def step(self, v: float, s: float, v_ref: float, v_ref_next: float, s_ref: float,
             traction_limit: float, brake_limit: float) -> float:
        """One event: measured speed ``v`` (m/s) and position ``s`` (m), reference now and
        one sample ahead; returns the force (N)."""
        p, m = self.p, self.models
        y = 3.6 * v
        # at standstill (now and before) the ARX models say nothing: no switching, no update
        moving = self.y_prev is not None and max(y, self.y_prev) > STANDSTILL_KMH
        if moving:
            self.active = self.switch.update(y, self.y_prev, self.u_prev)
            i = self.active
            resid = y - (m.a[i] * self.y_prev + m.b[i] * self.u_prev + m.c[i])
            self.xi_hat += p.disturbance_gain * (resid - self.xi_hat)
        i = self.active
        yr, yr1 = 3.6 * v_ref, 3.6 * v_ref_next
        u_ff = (yr1 - m.a[i] * yr - m.c[i] - self.xi_hat) / m.b[i]
        clip_v = 3.6 * p.error_clip_speed
        x = np.array([min(max(y - yr, -clip_v), clip_v),
                      min(max(s - s_ref, -p.error_clip_position), p.error_clip_position)])
        # an error smaller than the LMI floor (|x| in km/h and m) is scaled up to it: the gain
        # F is applied to the true x; this keeps gamma ~ |x|^2 away from the solver's zero
        size = float(np.max(np.abs(x)))
        x_lmi = x * (p.lmi_floor / size) if size > 0 else np.array([p.lmi_floor, 0.0])
        x_lmi = x if size >= p.lmi_floor else x_lmi
        sol = self.lmi.solve(x_lmi, [self.vertex(j) for j in self.vertex_indices(i)])
        self.solve_times.append(sol.solve_time)
        self.last_status = sol.status
        if sol.ok:
            self.gain = [float(sol.F[0, 0]), float(sol.F[0, 1])]
            self.gamma = sol.gamma
        else:
            self.lmi_failures += 1
        u = u_ff + self.gain[0] * x[0] + self.gain[1] * x[1]
        f_comfort = p.mass * (1.0 + p.rotating_mass_factor) * p.accel_max
        hi = min(max(traction_limit, 0.0), f_comfort)
        lo = -min(max(brake_limit, 0.0), f_comfort)
        force = min(max(u * self.unit_force, lo), hi)
        self.force = force
        self.u_prev = force / self.unit_force
        self.y_prev = y
        return force

    def diagnostics(self) -> dict[str, Any]:
        t = self.solve_times
        return {
            "active_model": self.active + 1,
            "lmi_gamma": self.gamma,
            "lmi_failures": self.lmi_failures,
            "lmi_solves": len(t),
            "lmi_solve_time_median": statistics.median(t) if t else 0.0,
            "lmi_solve_time_total": math.fsum(t),
            "disturbance_estimate": self.xi_hat,
        }
