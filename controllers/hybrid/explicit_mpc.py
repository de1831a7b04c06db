"""Explicit hybrid MPC (EMPC, section 2.3, eq. 18) of the multi-mass CRH3: region lookup online.

Same interface as the GMPC (:class:`controllers.hybrid.hybrid_mpc.HybridMpc`): per sample it
rebuilds the parameter ``theta`` of :mod:`controllers.hybrid.explicit` from the measurements
(mean speed error, speed differences, coupler forces, reference speed and its least-squares
slope over the horizon, the envelope of the mode), picks the region set of the scheduled mode
(delta of stage 0, held over the horizon) and of the segment of the mean speed, locates the
region by its bounding-box tree and applies ``u = F_i theta + f_i``. A ``theta`` outside the
parameter box is clipped into it (counted in ``empc_outside``, as is a point on a gap between
regions, where the least-violated leaf region is used).

The region data are built offline for one design (horizon, blocks, Q, R, train) by
``papers/seed004/make_empc_regions.py``; the controller refuses data built for another design.

What it is: the explicit solution of a *reduced* MPC (mode and PWA segment held over the
horizon, the reference linearised, inputs blocked 3:4:3, the coupler-force and speed rows left
out; :mod:`controllers.hybrid.explicit`), exact for that problem, not the GMPC's MIQP made
explicit. ``evaluation = "online"`` is its online twin: the same mp-QP solved at the same
``theta`` by DAQP every event (:func:`controllers.hybrid.explicit.solve_parametric`) instead of
the region lookup, so the two differ only in how the law is evaluated.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.hybrid.explicit import (
    DATA_DIR,
    MODES,
    PARAM_NAMES,
    ExplicitLaw,
    ParametricQp,
    parametric_qp,
    solve_parametric,
)
from controllers.hybrid.hybrid_mpc import (
    HybridMpc,
    HybridMpcParams,
    chain_model,
    reference_position,
)
from controllers.hybrid.miqp import parse_blocks
from controllers.hybrid.model import KN, ChainModel
from cosim.fmu.c_text import ShippedValues, numbers_line
from cosim.fmu.declare import Var, build
from plants.emu import EmuParams, emu_config
from plants.route import ReferenceProfile, load_reference, routes_dir_in

REGIONS_DEFAULT = "seed004_empc_crh3_3car"
EVALUATIONS = ("explicit", "online")


def regions_path(name: str, data_dir: Path | None = None) -> Path:
    """A bundled region file by name (under ``controllers/hybrid/data``) or a path."""
    if name.endswith(".npz"):
        return Path(name)
    base = DATA_DIR if data_dir is None else Path(data_dir) / "controllers" / "hybrid" / "data"
    return base / f"{name}.npz"


class ExplicitMpc(HybridMpc):
    """EMPC: the piecewise-affine law of PPOPT's mp-QPs, evaluated by point location."""

    # the reduced problem linearises the reference from now: the "horizon" position reading
    default_params: ClassVar[HybridMpcParams] = replace(HybridMpcParams(), move_blocks="3:4:3",
                                                        position_reference="horizon")
    # parameters the region data are built for (another value is refused at construction)
    fixed_by_data: ClassVar[tuple[str, ...]] = (
        "N", "move_blocks", "q_speed", "q_position", "R", "configuration", "sample_time",
        "fit_speed_max", "position_reference")
    state_fields: ClassVar[tuple[str, ...]] = (*HybridMpc.state_fields, "outside", "region")
    setup_vars = (*HybridMpc.setup_vars,
                  Var("regions", "parameter", REGIONS_DEFAULT, description="bundled EMPC "
                      "region data (controllers/hybrid/data/NAME.npz) or path of an .npz "
                      "written by papers/seed004/make_empc_regions.py"),
                  Var("evaluation", "parameter", "explicit", description='"explicit": the '
                      'region lookup of eq. 18; "online": the same reduced mp-QP solved at '
                      "theta by DAQP every event (the explicit law's online twin)"))
    output_vars = (*HybridMpc.output_vars,
                   Var.output("empc_outside", "1", "events whose parameter lay outside the "
                              "regions (clipped into the box, or nearest region)", start=0),
                   Var.output("empc_region", "1", "region applied at the last event "
                              "(index in its mode/segment set)", start=-1))

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`; the hybrid
        MPC's control models are not among them: the regions hold the law):
        ``resources/regions/<name>.empc`` per bundled region file
        (``controllers/hybrid/data/*.npz``): its design settings (``meta key value``), the
        design constants of the online law (mean-speed weights ``c``, PWA ``breakpoints``,
        ``motored`` cars, per-mode limit ratios) and per mode and segment the parameter box,
        the regions (E, e, row offsets, first-move F, f, tolerance) and the bounding-box tree
        (:class:`controllers.hybrid.explicit.BoxTree`) built from them; one ``key count
        values...`` line per array (%.17g via repr: exact)."""
        tables = {}
        for path in sorted(DATA_DIR.glob("*.npz")):
            law = ExplicitLaw.load(path)
            meta = law.meta
            train = emu_config(str(meta["configuration"]))
            params = replace(HybridMpcParams(), fit_speed_max=float(meta["fit_speed_max"]),
                             sample_time=float(meta["sample_time"]),
                             configuration=str(meta["configuration"]))
            model = chain_model(train, params)
            lines = [f"# EMPC region data {path.stem} (from {path.name}; generated)"]
            lines += [f"meta {key} {value}" for key, value in meta.items()]
            lines += [numbers_line("c", model.c[:model.n]),
                      numbers_line("breakpoints", model.res.breakpoints),
                      numbers_line("motored", model.motored),
                      *(numbers_line(f"ratio{m}", cls.limit_ratio(train, m)) for m in MODES),
                      numbers_line("keys", sorted(law.sets))]
            for (mode, seg), rs in sorted(law.sets.items()):
                p = f"m{mode}s{seg}_"
                tree = rs.tree
                lines += [numbers_line(p + "box", law.boxes[mode, seg]),
                          numbers_line(p + "E", rs.E), numbers_line(p + "e", rs.e),
                          numbers_line(p + "rows", rs.rows),
                          numbers_line(p + "na", [rs.F.shape[1]]),
                          numbers_line(p + "F", rs.F), numbers_line(p + "f", rs.f),
                          numbers_line(p + "tol", [rs.tol]),
                          *(numbers_line(p + name, getattr(tree, name))
                            for name in ("dim", "thr", "left", "right", "start", "stop",
                                         "items"))]
            tables[f"resources/regions/{path.stem}.empc"] = "\n".join(lines) + "\n"
        return tables

    # -- design (shared with the offline script) ----------------------------------------------
    @staticmethod
    def limit_ratio(train: EmuParams, mode: int) -> np.ndarray:
        """Per-car multiple of the ``limit`` parameter (motor traction; brake ~ mass)."""
        if mode == 1:
            ft = np.asarray(train.max_traction_force, float)
            return np.where(ft > 0, 1.0, 0.0)
        fb = np.asarray(train.max_brake_force, float)
        return fb / fb[0]

    @staticmethod
    def envelope_limit(train: EmuParams, mode: int, v: float) -> float:
        """``limit`` (kN) at speed ``v``: motor-car traction or car-1 brake force."""
        va = max(abs(v), 1e-9)
        if mode == 1:
            i = int(np.argmax(np.asarray(train.max_traction_force) > 0))
            return min(train.max_traction_force[i], train.max_traction_power[i] / va) / KN
        return min(train.max_brake_force[0], train.max_brake_power[0] / va) / KN

    @classmethod
    def parameter_box(cls, model: ChainModel, train: EmuParams, mode: int,
                      segment: int) -> np.ndarray:
        """Bounds (ntheta, 2) of ``theta`` for one mode and segment: speed error +-3 m/s,
        speed differences +-2 mm/s and coupler forces +-60 kN (seed 004 runs: 0.05 mm/s and
        14 kN at most), reference speeds of the segment +-3 m/s, slopes +-0.6 m/s^2, the
        envelope over those speeds widened by 5 %."""
        bps = [0.0, *model.res.breakpoints, model.v_hi]
        v_lo, v_hi = max(0.0, bps[segment] - 3.0), bps[segment + 1] + 3.0
        lims = [cls.envelope_limit(train, mode, v) for v in np.linspace(v_lo, v_hi, 200)]
        box = {"e": (-3.0, 3.0), "dv12": (-2.0, 2.0), "dv23": (-2.0, 2.0),
               "f12": (-60.0, 60.0), "f23": (-60.0, 60.0), "v_ref": (v_lo, v_hi),
               "a_ref": (-0.6, 0.6), "limit": (0.95 * min(lims), 1.05 * max(lims))}
        return np.array([box[name] for name in PARAM_NAMES])

    @staticmethod
    def design_meta(p: HybridMpcParams) -> dict[str, float | str]:
        """The settings region data are built for (checked at load)."""
        return {"N": float(p.horizon), "move_blocks": p.move_blocks or "1" * int(p.horizon),
                "q_speed": float(p.q_speed), "q_position": float(p.q_position),
                "R": float(p.r_force), "configuration": p.configuration,
                "sample_time": float(p.sample_time), "fit_speed_max": float(p.fit_speed_max),
                "position_reference": p.position_reference}

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path, t0: float = 0.0,
                        units: int = 3) -> ExplicitMpc:
        params = build(cls.default_params, values)
        profile = load_reference(values["reference"], routes_dir=routes_dir_in(data_dir))
        path = regions_path(str(values["regions"]), data_dir)
        return cls(params, profile, units=units, regions=path,
                   evaluation=str(values.get("evaluation", "explicit")))

    def __init__(self, params: HybridMpcParams, profile: ReferenceProfile, units: int = 3,
                 regions: Path | None = None, evaluation: str = "explicit") -> None:
        super().__init__(params, profile, units=units)
        if evaluation not in EVALUATIONS:
            raise ValueError(f"evaluation = {evaluation!r} must be one of {EVALUATIONS}")
        self.evaluation = evaluation
        if params.r_increment != 0.0:
            raise ValueError(f"dR = {params.r_increment}: the EMPC's reduced problem has no "
                             "force-increment term (eq. 11); its regions are built for dR = 0")
        if params.delta_mode != "schedule":
            raise ValueError(f"delta_mode = {params.delta_mode!r}: EMPC needs the scheduled "
                             "mode (its regions are per mode)")
        path = regions_path(REGIONS_DEFAULT) if regions is None else Path(regions)
        if not path.is_file():
            raise ValueError(f"regions = {str(path)!r}: no such file (make it with "
                             "papers/seed004/make_empc_regions.py)")
        self.law = ExplicitLaw.load(path)
        want = self.design_meta(params)
        for key, value in want.items():
            have = self.law.meta.get(key)
            same = (math.isclose(float(have), float(value)) if isinstance(value, float)
                    and have is not None else str(have) == str(value))
            if not same:
                raise ValueError(f"regions = {path.name!r} were built for {key} = {have}, "
                                 f"this controller has {value!r}: regenerate them with "
                                 "papers/seed004/make_empc_regions.py")
        self.ratio = {m: self.limit_ratio(self.train, m) for m in (0, 1)}
        # the online twin: the mp-QP of every mode and segment, solved at theta per event
        self.online: dict[tuple[int, int], ParametricQp] = {}
        if evaluation == "online":
            q = [params.q_speed] * units + [params.q_position] * units
            blocks = parse_blocks(params.move_blocks, self.N)
            self.online = {key: parametric_qp(self.model, self.N, blocks, q, params.r_force,
                                              key[0], key[1], self.law.boxes[key],
                                              self.ratio[key[0]])
                           for key in self.law.sets}
        self.outside = 0
        self.region = -1

    # -- event --------------------------------------------------------------------------------
    def theta(self, t: float, inputs: dict[str, float], mode: int) -> np.ndarray:
        n, Ts, N = self.n, self.p.sample_time, self.N
        v = np.array([float(inputs[f"v[{i}]"]) for i in range(1, n + 1)])
        vm = float(self.model.c[:n] @ v)
        vd = self.profile.speed(t)
        s = np.arange(1, N + 1) * Ts
        vs = np.array([self.profile.speed(t + x) for x in s])
        slope = float(s @ (vs - vd) / (s @ s))  # least squares over the horizon
        ratio = self.ratio[mode]
        if mode == 1:
            lim = min(float(inputs[f"traction_limit[{i + 1}]"]) / KN / ratio[i]
                      for i in range(n) if ratio[i] > 0)
        else:
            lim = min(float(inputs[f"brake_limit[{i + 1}]"]) / KN / ratio[i] for i in range(n))
        return np.array([vm - vd, 1e3 * (v[0] - v[1]), 1e3 * (v[1] - v[2]),
                         float(inputs["coupler_force[1]"]) / KN,
                         float(inputs["coupler_force[2]"]) / KN, vd, slope, max(lim, 0.0)])

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        t0, c0 = time.perf_counter(), time.thread_time()
        md, n = self.model, self.n
        v = np.array([float(inputs[f"v[{i}]"]) for i in range(1, n + 1)])
        vm = float(md.c[:n] @ v)
        mode = self.schedule(t, vm)[0]
        mode = 1 if mode is None else int(mode)
        seg = md.res.segment(vm)
        theta = self.theta(t, inputs, mode)
        box = self.law.boxes[mode, seg]
        clipped = np.clip(theta, box[:, 0], box[:, 1])
        regions = self.law.sets[mode, seg]
        u = np.zeros(n)
        if self.online:  # the online twin: no region, the mp-QP solved at theta
            i = -1
            self.outside += bool(np.any(clipped != theta))
            qp = self.online[mode, seg]
            u = qp.first_input(solve_parametric(qp, clipped), n)
        else:
            i, viol = regions.locate(clipped)
            self.outside += bool(np.any(clipped != theta) or viol > regions.tol)
            if i >= 0:
                active = np.flatnonzero(self.ratio[mode] > 0) if mode == 1 else np.arange(n)
                u[active] = regions.control(i, clipped)
            else:
                self.qp_infeasible += 1
                self.last_failure = (t, "no region in the leaf")
                u = np.array(self.forces) / KN
        u = np.where(md.motored, np.maximum(u, 0.0), 0.0) if mode == 1 else np.minimum(u, 0.0)
        self.region = i
        self.delta = mode
        self.forces = [float(f) * KN for f in u]
        self.qp_solves += 1
        self.timing.add(time.perf_counter() - t0, time.thread_time() - c0)
        self.v_ref = self.profile.speed(t)
        self.s_ref = reference_position(self.profile, t)
        self.speed_error = vm - self.v_ref
        return self.outputs(), 1

    def outputs(self) -> dict[str, Any]:
        out = super().outputs()
        out["empc_outside"] = self.outside
        out["empc_region"] = self.region
        return out
