"""Hybrid MPC of the multi-mass CRH3 (seed 004): GMPC (eq. 15) and move-blocking MB-MPC (eq. 17).

At every sample (Ts = 1 s) the controller

1. reads the car speeds ``v[i]``, the head position ``s`` and the coupler forces, and rebuilds
   the state ``x = [v_1..v_n, x_1..x_n]`` with displacements relative to the head
   (``x_1 = 0``, ``x_j - x_j+1 = (F_j - d (v_j - v_j+1)) / k``);
2. references every car's speed to ``v_ref(t + s Ts)`` and its displacement to
   ``s_ref(t + s Ts) - s`` (``s_ref``: the integral of the speed-time target profile; the
   timetable reading, with memory of the position error) or, with ``position_reference =
   "horizon"``, to the reference distance from now (no memory);
3. fixes the mode schedule of section 3 (``delta = 0`` from ``brake_from`` until the measured
   mean speed has fallen to ``brake_until_speed``, 1 otherwise; ``delta_mode = "optimise"``
   leaves delta to the MIQP instead);
4. solves the MIQP of eq. 15 (:class:`controllers.hybrid.miqp.HybridMiqp`, DAQP's branch and
   bound) with the envelope read from the plant (``traction_limit[i]``, ``brake_limit[i]``,
   held over the horizon; a move block spanning a mode change is cut there, so each stage
   keeps its mode) and applies the first input. An infeasible MIQP (none seen in the
   seed 004 runs) applies the previous plan's next input, counted in ``qp_infeasible``.

The control model (:class:`controllers.hybrid.model.ChainModel`) takes the train data of a
plant ``configuration`` (masses, Davis terms, couplers, motored cars), so the controller knows
the train as the paper's does (Table 1); the PWA resistance is fitted to its Davis curve.
Forces are output in N. MB-MPC is the same controller with ``move_blocks = "3:4:3"``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.hybrid.miqp import _RETRY_SETTINGS as RETRY_SETTINGS
from controllers.hybrid.miqp import (
    ENUMERATE_MAX_FREE,
    EPS_REG,
    HybridMiqp,
    MiqpResult,
    parse_blocks,
)
from controllers.hybrid.model import KN, ChainModel, Limits, PwlResistance
from cosim.fmu.c_text import ShippedValues, c_array, c_double, c_string
from cosim.fmu.declare import Checked, Declared, Var, build, param, parameters, sample_time
from cosim.fmu.diagnostics import SolveTimes
from cosim.fmu.state import StatefulCore
from plants.emu import CONFIGURATIONS, EmuParams, emu_config
from plants.route import ReferenceProfile, load_reference, routes_dir_in

DELTA_MODES = ("schedule", "optimise")
POSITION_REFERENCES = ("horizon", "timetable")


@dataclass(frozen=True)
class HybridMpcParams(Checked):
    """Case 1 of the paper by default (Np = Nu = 10, R = 0.5 I3, Q = 10 I6; no eq. 11)."""

    horizon: int = param(10, description="prediction = control horizon Np = Nu", min=1, max=40,
                         integer=True, name="N")
    q_speed: float = param(10.0, "1", "Q: weight on each car's speed error (m/s)^-2", min=0.0)
    q_position: float = param(10.0, "1", "Q: weight on each car's position error (m)^-2",
                              min=0.0)
    r_force: float = param(0.5, "1", "R: weight on each car's force (kN)^-2 (eq. 10)",
                           min=0.0, name="R")
    r_increment: float = param(0.0, "1", "dR: weight on each car's force increment (kN)^-2 "
                               "(eq. 11; the paper prints no value: 0 leaves eq. 11 out)",
                               min=0.0, name="dR")
    move_blocks: str = param("", description='input blocks, e.g. "3:4:3" (MB-MPC); empty: '
                             "every stage free (GMPC)")
    sample_time: float = sample_time(1.0)
    configuration: str = param("crh3_3car", description="train data of the control model "
                               f"(one of {sorted(CONFIGURATIONS)})",
                               choices=tuple(sorted(CONFIGURATIONS)))
    fit_speed_max: float = param(350.0 / 3.6, "m/s", "PWA resistance fitted on [0, this] in "
                                 "three equal segments", min=1.0)
    coupler_force_max: float = param(1.0e6, "N", "coupler force limit (state constraint)",
                                     min=1.0)
    speed_max: float = param(350.0 / 3.6, "m/s", "speed limit of every car (state "
                             "constraint)", min=0.0)
    position_reference: str = param("timetable", description='"timetable": the displacement '
                                    "reference of stage s is s_ref(t + s Ts) - s (x_d of eq. "
                                    "12 on the timetable: the accumulated position error is "
                                    'corrected); "horizon": the reference distance from now, '
                                    "int_t^(t+s Ts) v_ref (no memory of past error)",
                                    choices=POSITION_REFERENCES)
    delta_mode: str = param("schedule", description='"schedule": delta fixed as in section 3; '
                            '"optimise": delta a decision of the MIQP',
                            choices=DELTA_MODES)
    brake_from: float = param(600.0, "s", "delta = 0 (braking) from this time ...")
    brake_until_speed: float = param(30.0, "m/s", "... until the mean speed has fallen to this",
                                     min=0.0)

    def check_relations(self) -> None:
        parse_blocks(self.move_blocks, int(self.horizon))
        if not (self.r_force >= 0 and self.r_increment >= 0
                and self.r_force + self.r_increment > 0):
            raise ValueError(f"R = {self.r_force}, dR = {self.r_increment}: both >= 0 and one "
                             "> 0 (the QP needs a weight on the forces or their increments)")


def chain_model(train: EmuParams, p: HybridMpcParams) -> ChainModel:
    """The control model of ``train``: PWA resistance fitted to its summed Davis curve."""
    mass = float(sum(train.masses))
    res = PwlResistance.fit(sum(train.davis_a), sum(train.davis_b), sum(train.davis_c), mass,
                            p.fit_speed_max)
    return ChainModel(train.masses, train.coupler_stiffness, train.coupler_damping, res,
                      p.sample_time, motored=[f > 0 for f in train.max_traction_force],
                      speed_range=(-10.0, max(100.0, p.fit_speed_max, p.speed_max) + 5.0))


def reference_position(profile: ReferenceProfile, t: float) -> float:
    """``s_ref(t) = int_0^t v_ref`` (m) of a speed-time profile (v linear between points)."""
    x, v = profile.x, profile.v
    if t <= x[0]:
        return v[0] * (t - x[0])
    seg = np.diff(x) * 0.5 * (v[:-1] + v[1:])
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    if t >= x[-1]:
        return float(cum[-1] + v[-1] * (t - x[-1]))
    i = int(np.searchsorted(x, t, side="right") - 1)
    dt = t - x[i]
    a = (v[i + 1] - v[i]) / (x[i + 1] - x[i])
    return float(cum[i] + v[i] * dt + 0.5 * a * dt * dt)


class HybridMpc(StatefulCore, Declared):
    """GMPC (eq. 15) for an n-car EMU; MB-MPC with ``move_blocks``."""

    default_params: ClassVar[HybridMpcParams] = HybridMpcParams()
    state_fields: ClassVar[tuple[str, ...]] = (
        "forces", "delta", "braking_done", "plan", "v_ref", "s_ref", "speed_error",
        "qp_solves", "qp_infeasible", "nodes", "last_failure",
        "qp_rescued")
    setup_vars = (Var("reference", "parameter", "seed004_crh3_reference", description=
                      "bundled speed-time reference profile name or path of a CSV/TOML file"),)
    output_vars = (
        Var.output("force_demand", "N", "total force command"),
        Var.output("delta", "1", "mode applied: 1 traction, 0 braking", start=1.0),
        Var.output("v_ref", "m/s", "reference speed"),
        Var.output("s_ref", "m", "reference position (integral of v_ref)"),
        Var.output("speed_error", "m/s", "mean speed - v_ref"),
        Var.output("qp_solves", "1", "MIQPs solved so far", start=0),
        Var.output("qp_infeasible", "1", "events with an infeasible MIQP (previous plan "
                   "used)", start=0),
        Var.output("qp_rescued", "1", "events DAQP solved only on a retry with other settings "
                   "or by enumerating the binaries", start=0),
        Var.output("bnb_nodes", "1", "branch-and-bound nodes summed over all events", start=0),
    )

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`):
        ``sources/ato_hybrid_model.h``, the control models (:func:`chain_model`) of every
        3-car configuration at the declared default ``sample_time`` and ``fit_speed_max``
        (the zero-order-hold matrices ``A0``, ``B``, ``g``, the mean-speed weights ``c``, the
        coupler rows and the PWA resistance least-squares fitted to the Davis curve), computed
        by the core itself, and the MIQP's constants (``EPS_REG``, the retry settings,
        ``ENUMERATE_MAX_FREE``) from :mod:`controllers.hybrid.miqp`. A native FMU refuses
        another sample time or fit speed."""
        p = HybridMpcParams()
        lines = ["/* generated by cosim/build/native.py from controllers.hybrid (chain_model"
                 " at the default sample_time and fit_speed_max); do not edit */",
                 "#ifndef ATO_HYBRID_MODEL_H", "#define ATO_HYBRID_MODEL_H",
                 f"#define HY_SAMPLE_TIME {c_double(float(p.sample_time))}",
                 f"#define HY_FIT_SPEED_MAX {c_double(float(p.fit_speed_max))}",
                 f"#define HY_EPS_REG {c_double(EPS_REG)}",
                 f"#define HY_ENUMERATE_MAX_FREE {int(ENUMERATE_MAX_FREE)}"]
        keys = ("cycle_tol", "pivot_tol", "primal_tol")
        retries = RETRY_SETTINGS
        if any(set(r) - set(keys) for r in retries):
            raise ValueError(f"retry settings {retries}: only {keys} are exported")
        lines += [f"#define HY_N_RETRIES {len(retries)}",
                  "typedef struct { int cycle_tol; double pivot_tol, primal_tol; } hy_retry;",
                  "/* -1: DAQP's default */",
                  "static const hy_retry HY_RETRIES[HY_N_RETRIES] = {"
                  + ", ".join(f"{{{int(r.get('cycle_tol', -1))}, "
                              f"{c_double(float(r.get('pivot_tol', -1.0)))}, "
                              f"{c_double(float(r.get('primal_tol', -1.0)))}}}"
                              for r in retries)
                  + "};"]
        rows = []
        for k, name in enumerate(sorted(CONFIGURATIONS)):
            train = emu_config(name)
            if train.n != 3:
                continue
            md = chain_model(train, p)
            arrays = {"m": md.m, "motored": md.motored.astype(float), "A0": md.A0, "B": md.B,
                      "g": md.g, "c": md.c, "coupler_rows": md.coupler_rows,
                      "breakpoints": md.res.breakpoints, "alpha": md.res.alpha,
                      "beta": md.res.beta}
            lines += [c_array(f"HY_{k}_{key}", value) for key, value in arrays.items()]
            rows.append(f"    {{{c_string(name)}, {c_double(md.k)}, {c_double(md.d)}, "
                        f"{c_double(md.U)}, " + ", ".join(f"HY_{k}_{key}" for key in arrays)
                        + "},")
        lines += ["typedef struct { const char* name; int cars; } hy_config;",
                  f"#define HY_N_CONFIGS {len(CONFIGURATIONS)}",
                  "static const hy_config HY_CONFIGS[HY_N_CONFIGS] = {"
                  + ", ".join(f"{{{c_string(name)}, {emu_config(name).n}}}"
                              for name in sorted(CONFIGURATIONS)) + "};"]
        lines += ["typedef struct { const char* name; double k, d, U; const double *m, "
                  "*motored, *A0, *B, *g, *c, *coupler_rows, *breakpoints, *alpha, *beta; }"
                  " hy_model;",
                  f"#define HY_N_MODELS {len(rows)}",
                  "static const hy_model HY_MODELS[HY_N_MODELS] = {", *rows, "};", "#endif"]
        return {"sources/ato_hybrid_model.h": "\n".join(lines) + "\n"}

    @classmethod
    def declarations(cls, units: int = 3) -> tuple[Var, ...]:
        idx = range(1, units + 1)
        return (
            *parameters(cls.default_params),
            *cls.setup_vars,
            *[Var.input(f"v[{i}]", "m/s", f"measured speed of car {i}") for i in idx],
            Var.input("s", "m", "measured head position"),
            *[Var.input(f"coupler_force[{j}]", "N", f"measured force in coupler {j} "
                        "(> 0 in tension)") for j in range(1, units)],
            *[Var.input(f"traction_limit[{i}]", "N", f"traction force car {i} can give now")
              for i in idx],
            *[Var.input(f"brake_limit[{i}]", "N", f"brake force car {i} can give now")
              for i in idx],
            *[Var.output(f"force[{i}]", "N", f"force command of car {i}") for i in idx],
            *cls.output_vars,
        )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path, t0: float = 0.0,
                        units: int = 3) -> HybridMpc:
        params = build(cls.default_params, values)
        profile = load_reference(values["reference"], routes_dir=routes_dir_in(data_dir))
        return cls(params, profile, units=units)

    def __init__(self, params: HybridMpcParams, profile: ReferenceProfile,
                 units: int = 3) -> None:
        params.check()
        if profile.kind != "time":
            raise ValueError(f"reference: hybrid MPC tracks a speed-time profile, got a "
                             f"{profile.kind!r} one")
        train = emu_config(params.configuration)
        if train.n != units:
            raise ValueError(f"configuration = {params.configuration!r} has {train.n} cars, "
                             f"this controller has {units}")
        self.p, self.profile, self.n = params, profile, units
        self.train = train
        self.model = chain_model(train, params)
        self.N = int(params.horizon)
        self.miqp = HybridMiqp(self.model, self.N, [params.q_speed] * units
                               + [params.q_position] * units, params.r_force,
                               parse_blocks(params.move_blocks, self.N), params.r_increment)
        self.forces = [0.0] * units
        self.delta = 1
        self.braking_done = False
        self.plan: list[list[float]] = []
        self.v_ref = self.s_ref = self.speed_error = 0.0
        self.qp_solves = self.qp_infeasible = self.nodes = 0
        # MIQP wall and CPU times: run-dependent, so neither state nor outputs; bounded;
        # logged at fmi2Terminate (cosim.fmu.diagnostics)
        self.timing = SolveTimes()
        self.qp_rescued = 0
        self.last_failure: tuple[float, str] | None = None

    # -- event -----------------------------------------------------------------------------
    def state_vector(self, inputs: dict[str, float]) -> np.ndarray:
        """``[v_1..v_n, x_1..x_n]`` with displacements relative to the head (x_1 = 0)."""
        n, k, d = self.n, self.train.coupler_stiffness, self.train.coupler_damping
        v = np.array([float(inputs[f"v[{i}]"]) for i in range(1, n + 1)])
        x = np.zeros(n)
        for j in range(n - 1):
            f = float(inputs[f"coupler_force[{j + 1}]"])
            x[j + 1] = x[j] - (f - d * (v[j] - v[j + 1])) / k
        return np.concatenate([v, x])

    def schedule(self, t: float, v_mean: float) -> list[int | None]:
        """delta per stage (section 3): 0 from ``brake_from`` until the speed is down."""
        p = self.p
        if p.delta_mode == "optimise":
            return [None] * self.N
        if t >= p.brake_from and v_mean <= p.brake_until_speed:
            self.braking_done = True
        out: list[int | None] = []
        for s in range(self.N):
            ts = t + s * p.sample_time
            braking = (ts >= p.brake_from and not self.braking_done
                       and (s == 0 or self.profile.speed(ts) > p.brake_until_speed))
            out.append(0 if braking else 1)
        return out

    def references(self, t: float, s_head: float) -> np.ndarray:
        n, Ts = self.n, self.p.sample_time
        ref = np.empty((self.N + 1, 2 * n))
        origin = (reference_position(self.profile, t) if self.p.position_reference == "horizon"
                  else s_head)
        for s in range(self.N + 1):
            ts = t + s * Ts
            ref[s, :n] = self.profile.speed(ts)
            ref[s, n:] = reference_position(self.profile, ts) - origin
        return ref

    def solve(self, t: float, inputs: dict[str, float]) -> tuple[MiqpResult, list[int | None]]:
        """One MIQP at time ``t`` for the measured ``inputs`` (no side effects on the plan)."""
        x0 = self.state_vector(inputs)
        n = self.n
        lim = Limits(np.array([max(float(inputs[f"traction_limit[{i}]"]), 0.0) / KN
                               for i in range(1, n + 1)]),
                     np.array([max(float(inputs[f"brake_limit[{i}]"]), 0.0) / KN
                               for i in range(1, n + 1)]),
                     coupler=self.p.coupler_force_max / KN, speed=self.p.speed_max)
        delta = self.schedule(t, float(self.model.c @ x0))
        ref = self.references(t, float(inputs["s"]))
        return self.miqp.solve(x0, ref, lim, delta, np.array(self.forces) / KN), delta

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        res, delta = self.solve(t, inputs)
        self.qp_solves += 1
        self.nodes += res.nodes
        self.timing.add(res.solve_time, res.cpu_time)
        md = self.model
        if res.feasible:
            self.qp_rescued += res.status != "solved"
            u = res.u0
            self.plan = [list(map(float, st)) for st in res.stage_w[1:, :self.n]]
            d0 = int(round(float(res.stage_w[0, md.i_delta])))
        else:
            self.qp_infeasible += 1
            self.last_failure = (t, res.status)
            u = np.array(self.plan.pop(0)) if self.plan else np.array(self.forces) / KN
            d0 = 1 if delta[0] is None else int(delta[0])
        # project onto the mode to the solver's tolerance: no trailer force while pulling
        u = np.where(md.motored, np.maximum(u, 0.0), 0.0) if d0 == 1 else np.minimum(u, 0.0)
        self.delta = d0
        self.forces = [float(f) * KN for f in u]
        self.v_ref = self.profile.speed(t)
        self.s_ref = reference_position(self.profile, t)
        v = np.array([float(inputs[f"v[{i}]"]) for i in range(1, self.n + 1)])
        self.speed_error = float(md.c[:self.n] @ v) - self.v_ref
        return self.outputs(), 1

    def diagnostics(self) -> dict[str, float]:
        """MIQP wall and CPU times of the events computed by this instance (run-dependent)."""
        return self.timing.diagnostics()

    def outputs(self) -> dict[str, Any]:
        out: dict[str, Any] = {f"force[{i + 1}]": f for i, f in enumerate(self.forces)}
        out.update({
            "force_demand": float(sum(self.forces)),
            "delta": float(self.delta),
            "v_ref": self.v_ref,
            "s_ref": self.s_ref,
            "speed_error": self.speed_error,
            "qp_solves": self.qp_solves,
            "qp_infeasible": self.qp_infeasible,
            "qp_rescued": self.qp_rescued,
            "bnb_nodes": self.nodes,
        })
        return out



class MoveBlockingMpc(HybridMpc):
    """MB-MPC (eq. 17): the GMPC with the inputs held over blocks 3:4:3 of N = 10."""

    default_params = replace(HybridMpcParams(), move_blocks="3:4:3")
