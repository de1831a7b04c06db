"""Data-driven speed control of a multi-unit EMU (seed 001): one interface, four laws.

Every controller here is the same core around a different law of :mod:`.laws`
(FFDL-MFAC, FFDL-ISMC, FFDL-ISMPC, GPC), so swapping one for another is one line of a
scenario (the FMU name):

* inputs: per-unit measured speeds ``v[i]`` (m/s), the head position ``s`` (m, for the
  speed-distance reference), and the force each unit can give now, ``traction_limit[i]`` and
  ``brake_limit[i]`` (N, >= 0: the plant's constant-force / constant-power envelope, zero
  traction in a neutral section);
* outputs: per-unit force demands ``force[i]`` (N, traction > 0), their sum ``force_demand``,
  the reference ``v_ref``, ``a_ref`` and the mean speed error ``speed_error`` = mean v - v_ref.

Scaling (:mod:`controllers.common.ffdl`; ours): ``y_i = c_y v_i``, ``u_i = c_u F_i / m`` with
``m = M / n`` the mean unit mass, ``c_y = output_scale``, ``c_u = input_scale``: km/h and m/s^2
for GPC (3.6, 1), km/h and m/s^2 times ``FFDL_SCALE`` for the FFDL laws (below). The input
box of unit ``i`` is ``c_u max(-accel_max, -brake_limit_i / m) <= u_i <= c_u min(accel_max,
traction_limit_i / m)``: the plant's envelope and the comfort limit |a| <= 1 m/s^2 (section
4.3) on each unit's force per unit mass (so the train's mean is within it too). The reference
of the next sample is ``y_r(t+1) = c_y v_ref(s + v_1 T + a_ref T^2 / 2)``: a ``v(s)`` profile
looked up at the head position predicted for the next sample (:meth:`next_reference`).
At the end of the profile (zero reference and the mean speed below ``stop_speed``) every unit
holds ``hold_accel`` of braking; the laws' data models follow without learning.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from controllers.common.ffdl import KMH_PER_MPS
from controllers.datadriven.laws import (
    SHARE_INVERSE,
    GpcLaw,
    GpcLawParams,
    Ismc,
    IsmcParams,
    Ismpc,
    IsmpcParams,
    Mfac,
    MfacParams,
    SlidingLaw,
)
from cosim.fmu.c_text import ShippedValues, c_double
from cosim.fmu.declare import Checked, Declared, Var, build, group, param, parameters, sample_time
from cosim.fmu.state import StatefulCore
from plants.route import load_reference, routes_dir_in

# The paper's sample: eq. 89 defines MA = max |y_i(t) - y_i(t-1)|
# over the control samples t and Table 2 gives it in m/s2, equal to the largest acceleration
# the text reports for every law (ISMPC 0.9249, MFAC 0.9749, GPC 1.0124 m/s2, sec. 4.3 and the
# abstract): a speed change per sample equals an acceleration only for y in m/s sampled every
# 1 s. So the seed-001 laws sample at 1 s, and the FFDL laws work on y in m/s and u in m/s2
# per mean unit mass, where a free unit has Phi_1 = I, Phi_2 = T I = I: the paper's start
# Phi(1) = 0.5 I (0.52 I for MFAC) is of the truth's size, as the paper's mu = 1, beta = 0.05,
# delta = 1 then are in these units. GPC keeps its own km/h, m/s2 (its control weight).
PAPER_SAMPLE_TIME = 1.0


@dataclass(frozen=True)
class DriveParams(Checked):
    """The interface part shared by the four controllers."""

    mass: float = param(479.5e3, "kg", "train mass M (u_i = F_i n / M)", min=1.0)
    accel_max: float = param(1.0, "m/s2", "comfort limit on each unit's force per unit mass",
                             min=0.0)
    hold_accel: float = param(-0.5, "m/s2", "brake demand holding the train at the final "
                              "stop", max=0.0)
    stop_speed: float = param(0.3, "m/s", "below this mean speed with a zero reference the "
                              "holding brake is applied", min=0.0)
    output_scale: float = param(KMH_PER_MPS, "s/m", "data scaling of the outputs: y_i = "
                                "output_scale v_i (3.6: km/h; not in the paper; the FFDL laws' "
                                "own Delta, b, theta and thresholds are converted with it, the "
                                "paper's values and GPC's weights are numbers in these units)",
                                min=1e-6)
    input_scale: float = param(1.0, "s2/m", "data scaling of the inputs: u_i = input_scale "
                               "F_i / m (1: m/s2 per mean unit mass; not in the paper)",
                               min=1e-6)
    reference_at_next_position: bool = param(True, description="y_r(t+1) is the profile at "
                                             "the predicted head position s + max(v_1 T + "
                                             "a_ref T^2 / 2, 0) (time profiles: at t + T); "
                                             "false: v_ref "
                                             "+ a_ref T, the slope of the current segment, "
                                             "which misses a profile point crossed within the "
                                             "sample (a diagnostic)")
    sample_time: float = sample_time(PAPER_SAMPLE_TIME)



def rescaled(law: Any, gy: float, gu: float) -> Any:
    """``law``'s parameters (MFAC, ISMC or ISMPC, set for y in km/h and u in m/s2) for the
    scaling ``y = gy`` km/h, ``u = gu`` m/s2, with the paper's values unchanged and ours
    converted to keep their meaning (the core does this with its ``output_scale`` /
    ``input_scale``, so ours are declared for km/h and m/s2 whatever the scaling): the
    boundary layer Delta (x gy), b of eq. 18 (x gy^(1 - alpha): F sums sig^alpha(e)), theta of
    eq. 66 (x (gy / gu)^2), and the estimator's reset threshold (x gy / gu), excitation gate
    (x min(gy, gu)) and pinv eps (x (gy / gu)^2)."""
    g = gy / gu  # factor on Phi_2
    f = law.ffdl
    changes: dict[str, Any] = {"ffdl": dataclasses.replace(
        f, reset_threshold=f.reset_threshold * g, excitation=f.excitation * min(gy, gu),
        pinv_regularisation=f.pinv_regularisation * g * g)}
    if hasattr(law, "surface"):
        changes["surface"] = dataclasses.replace(
            law.surface, b=law.surface.b * gy ** (1.0 - law.surface.alpha))
    if hasattr(law, "boundary_layer"):
        changes["boundary_layer"] = law.boundary_layer * gy
    if hasattr(law, "theta"):
        changes["theta"] = law.theta * g * g
    return dataclasses.replace(law, **changes)


FFDL_DRIVE = DriveParams(output_scale=1.0, input_scale=1.0)


class DataDrivenEmuControl(StatefulCore, Declared):
    """Core of the seed-001 controllers; subclasses name ``law_class`` and ``params_class``
    (a dataclass with the groups ``drive`` (:class:`DriveParams`) and ``law``)."""

    law_class: ClassVar[type]
    state_fields = ("law", "forces", "v_ref", "a_ref", "speed_error", "holding")
    setup_vars = (Var("reference", "parameter", "jinan_xuzhou_east_reference", description=
                      "bundled reference profile name or path of a CSV/TOML profile"),)
    output_vars = (
        Var.output("force_demand", "N", "sum of the force demands"),
        Var.output("v_ref", "m/s", "reference speed"),
        Var.output("a_ref", "m/s2", "reference acceleration"),
        Var.output("speed_error", "m/s", "mean unit speed - v_ref"),
    )

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`):
        ``sources/ato_datadriven_const.h``, the constants of the seed-001 data-driven laws that
        are not FMU variables: the km/h per m/s of the laws' rescaling (``KMH_PER_MPS``), the
        anti-windup's bound tolerance (``SlidingLaw.BOUND_TOL``) and the regularised inverse
        of GPC's force sharing (``SHARE_INVERSE``: eps, cutoff)."""
        rows = {"DD_KMH_PER_MPS": KMH_PER_MPS, "DD_BOUND_TOL": SlidingLaw.BOUND_TOL,
                "DD_SHARE_EPS": SHARE_INVERSE.pinv_regularisation,
                "DD_SHARE_CUTOFF": SHARE_INVERSE.pinv_cutoff}
        return {"sources/ato_datadriven_const.h": "\n".join([
            "/* generated by cosim/build/native.py from controllers/common/ffdl.py and"
            " controllers/datadriven/laws.py; do not edit */",
            *(f"#define {k} {c_double(float(v))}" for k, v in rows.items())]) + "\n"}

    @classmethod
    def declarations(cls, units: int = 3) -> tuple[Var, ...]:
        indices = range(1, units + 1)
        return (
            *parameters(cls.params_class()),
            *cls.setup_vars,
            *[Var.input(f"v[{i}]", "m/s", f"measured speed of unit {i}") for i in indices],
            Var.input("s", "m", "measured head position"),
            *[Var.input(f"traction_limit[{i}]", "N", f"traction force unit {i} can give now")
              for i in indices],
            *[Var.input(f"brake_limit[{i}]", "N", f"brake force unit {i} can give now")
              for i in indices],
            *[Var.output(f"force[{i}]", "N", f"force command of unit {i}") for i in indices],
            *cls.output_vars,
        )

    @classmethod
    def from_parameters(cls, values: dict[str, Any], data_dir: Path, t0: float = 0.0,
                        units: int = 3) -> DataDrivenEmuControl:
        params = build(cls.params_class(), values)
        profile = load_reference(values["reference"], routes_dir=routes_dir_in(data_dir))
        return cls(params, profile, units)

    def __init__(self, params: Any, profile, units: int = 3) -> None:
        params.check()
        self.p = params
        self.drive = drive = params.drive
        self.n = units
        self.unit_mass = drive.mass / units
        self.profile = profile
        # ours (Delta, b, theta, the estimator's thresholds) are declared for km/h and m/s2;
        # the paper's values (mu, lambda, beta, ...) are numbers in the scaled units
        law = params.law
        if hasattr(law, "ffdl"):
            law = rescaled(law, drive.output_scale / KMH_PER_MPS, drive.input_scale)
        self.law = self.law_class(law, units)
        self.forces = [0.0] * units
        self.v_ref = 0.0
        self.a_ref = 0.0
        self.speed_error = 0.0
        self.holding = False

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        d, n = self.drive, self.n
        v = np.array([float(inputs[f"v[{i}]"]) for i in range(1, n + 1)])
        x = inputs["s"] if self.profile.kind == "distance" else t
        self.v_ref = v_ref = self.profile.speed(x)
        self.a_ref = a_ref = self.profile.accel(x)
        m = self.unit_mass / d.input_scale  # force per unit of u
        trac = np.array([max(float(inputs[f"traction_limit[{i}]"]), 0.0)
                         for i in range(1, n + 1)])
        brake = np.array([max(float(inputs[f"brake_limit[{i}]"]), 0.0)
                          for i in range(1, n + 1)])
        a_max = d.accel_max * d.input_scale
        hi = np.minimum(a_max, trac / m)
        lo = np.minimum(np.maximum(-a_max, -brake / m), hi)
        c = d.output_scale
        y = c * v
        self.holding = v_ref <= 0.0 and a_ref <= 0.0 and float(v.sum()) < d.stop_speed * n
        if self.holding:
            u = np.clip(np.full(n, d.hold_accel * d.input_scale), lo, hi)
            self.law.hold(y, u)
        else:
            u = self.law.step(y, c * v_ref, c * self.next_reference(x, v, v_ref, a_ref),
                              lo, hi)
        self.forces = [float(f) for f in m * u]
        self.speed_error = float(v.sum()) / n - v_ref
        return self.outputs(), 1

    def next_reference(self, x: float, v: np.ndarray, v_ref: float, a_ref: float) -> float:
        """The reference speed (m/s) at the next sample, ``y_r(t+1) / c_y`` of eqs. 17, 24,
        26, 75: the profile at the head position predicted from the head unit's speed and the
        reference's acceleration, ``s + max(v_1 T + a_ref T^2 / 2, 0)`` (a time profile: at
        ``t + T``).
        ``v_ref + a_ref T`` (``reference_at_next_position`` false) is the same inside a segment
        of the profile but misses a point crossed within the sample: at the seed-001
        profile's kinks it was off by up to 0.33 km/h."""
        T = self.drive.sample_time
        if not self.drive.reference_at_next_position:
            return max(v_ref + a_ref * T, 0.0)
        if self.profile.kind != "distance":
            return self.profile.speed(x + T)
        # a braking train stops, it does not reverse: the displacement is >= 0
        return self.profile.speed(x + max(float(v[0]) * T + 0.5 * a_ref * T * T, 0.0))

    def outputs(self) -> dict[str, float]:
        out = {f"force[{i + 1}]": f for i, f in enumerate(self.forces)}
        out.update({"force_demand": float(sum(self.forces)), "v_ref": self.v_ref,
                    "a_ref": self.a_ref, "speed_error": self.speed_error})
        return out


@dataclass(frozen=True)
class EmuMfacParams(Checked):
    """Parameters of the FFDL-MFAC FMU: the common interface part and the law's."""

    drive: DriveParams = group(FFDL_DRIVE, "")
    law: MfacParams = group(MfacParams(), "")


class EmuMfac(DataDrivenEmuControl):
    """FFDL-MFAC baseline."""

    law_class = Mfac
    params_class = EmuMfacParams


@dataclass(frozen=True)
class EmuIsmcParams(Checked):
    """Parameters of the FFDL-ISMC FMU: the common interface part and the law's."""

    drive: DriveParams = group(FFDL_DRIVE, "")
    law: IsmcParams = group(IsmcParams(), "")


class EmuIsmc(DataDrivenEmuControl):
    """FFDL-ISMC (eq. 26 with the boundary layer of eq. 27)."""

    law_class = Ismc
    params_class = EmuIsmcParams


@dataclass(frozen=True)
class EmuIsmpcParams(Checked):
    """Parameters of the FFDL-ISMPC FMU: the common interface part and the law's."""

    drive: DriveParams = group(FFDL_DRIVE, "")
    law: IsmpcParams = group(IsmpcParams(), "")


class EmuIsmpc(DataDrivenEmuControl):
    """FFDL-ISMPC (eq. 75): equivalent control + N-step MPC on the sliding variable."""

    law_class = Ismpc
    params_class = EmuIsmpcParams
    output_vars = (*DataDrivenEmuControl.output_vars,
                   Var.output("qp_solves", "1", "QPs handed to DAQP so far (unconstrained "
                              "MPC moves outside the input box)"),
                   Var.output("qp_infeasible", "1", "QPs DAQP did not solve (moves set to 0)"))

    def outputs(self) -> dict[str, float]:
        out = super().outputs()
        out.update({"qp_solves": float(self.law.qp_solves),
                    "qp_infeasible": float(self.law.qp_failures)})
        return out


@dataclass(frozen=True)
class EmuGpcParams(Checked):
    """Parameters of the GPC FMU: the common interface part and the law's."""

    drive: DriveParams = group(DriveParams(), "")
    law: GpcLawParams = group(GpcLawParams(), "")


class EmuGpc(DataDrivenEmuControl):
    """GPC baseline (RLS on an incremental ARX model)."""

    law_class = GpcLaw
    params_class = EmuGpcParams

