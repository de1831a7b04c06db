"""Fuzzy PID speed tracking of the heavy freight train (seed 002 baseline, Fig. 11).

A PI speed controller (no derivative: the baseline PID of seed 002 has none either) whose gains
are tuned online by a Mamdani fuzzy system on the normalised head speed error
``E = e / e_scale`` and error rate ``EC = de/dt / ec_scale`` (``e = v_ref - v``), both on
``[-3, 3]`` with 7 triangular terms NB, NM, NS, ZO, PS, PM, PB centred at -3..3; outputs
``dKp``, ``dKi`` on ``[-3, 3]`` with the same terms. Rules: the usual tables of fuzzy
self-tuning PID (:data:`KP_RULES`, :data:`KI_RULES`: large error -> larger Kp, smaller Ki;
error being corrected -> smaller Kp), min for AND and implication, max aggregation, centroid
defuzzification, defined with scikit-fuzzy (membership functions, defuzzification). The rule
surfaces are precomputed at initialisation on the node grid (``fuzzy_nodes`` per axis) and
interpolated bilinearly at each event (microseconds instead of an inference)::

    Kp = kp + kp_scale dKp(E, EC),   Ki = max(ki + ki_scale dKi(E, EC), 0)
    u  = a_ff + a_res + Kp e + Ki int(e) dt

``e = v_ref - v_f`` with ``v_f`` the fed-back speed of
:class:`controllers.common.freight_blending.FreightTracker`. The classic fuzzy PID is a
feedback controller (``a_ff = 0``, ``reference_feedforward`` false): the demand needs an error,
so it lags the reference in traction and braking (paper: 0.6-1.2 km/h). With
``reference_feedforward`` ``a_ff`` is the freight PID's term,
:func:`controllers.pid.freight_pid.reference_feedforward`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import skfuzzy as fuzz

from controllers.common.freight_blending import BlendingParams, FreightTracker, tracker_outputs
from controllers.common.freight_tuning import tuned_param
from controllers.common.mean_observer import correction_time_param, mean_weight_param
from controllers.pid.freight_pid import preview_time_param, reference_feedforward
from cosim.fmu.c_text import ShippedValues, c_array, c_double
from cosim.fmu.declare import Checked, group, param, sample_time
from plants.route import ReferenceProfile, Route

TERMS = ("NB", "NM", "NS", "ZO", "PS", "PM", "PB")
# rows: E = NB..PB, columns: EC = NB..PB
KP_RULES = (("PB", "PB", "PM", "PM", "PS", "ZO", "ZO"),
            ("PB", "PB", "PM", "PS", "PS", "ZO", "NS"),
            ("PM", "PM", "PM", "PS", "ZO", "NS", "NS"),
            ("PM", "PM", "PS", "ZO", "NS", "NM", "NM"),
            ("PS", "PS", "ZO", "NS", "NS", "NM", "NM"),
            ("PS", "ZO", "NS", "NM", "NM", "NM", "NB"),
            ("ZO", "ZO", "NM", "NM", "NM", "NB", "NB"))
KI_RULES = (("NB", "NB", "NM", "NM", "NS", "ZO", "ZO"),
            ("NB", "NB", "NM", "NS", "NS", "ZO", "ZO"),
            ("NB", "NM", "NS", "NS", "ZO", "PS", "PS"),
            ("NM", "NM", "NS", "ZO", "PS", "PM", "PM"),
            ("NM", "NS", "ZO", "PS", "PS", "PM", "PB"),
            ("ZO", "ZO", "PS", "PS", "PM", "PB", "PB"),
            ("ZO", "ZO", "PS", "PM", "PM", "PB", "PB"))
UNIVERSE = np.linspace(-3.0, 3.0, 601)  # output universe of the centroid


_IN_MF = [fuzz.trimf(UNIVERSE, [c - 1.0, c, c + 1.0]) for c in range(-3, 4)]
_OUT_MF = np.array([fuzz.trimf(UNIVERSE, [c - 1.0, c, c + 1.0]) for c in range(-3, 4)])


def _memberships(x: float) -> np.ndarray:
    """Membership of ``x`` (clipped to +-3) in the 7 triangular terms."""
    x = min(max(float(x), -3.0), 3.0)
    return np.array([fuzz.interp_membership(UNIVERSE, mf, x) for mf in _IN_MF])


def _rule_index(rules: tuple[tuple[str, ...], ...]) -> np.ndarray:
    return np.array([[TERMS.index(term) for term in row] for row in rules])


def infer(E: float, EC: float, rules: tuple[tuple[str, ...], ...]) -> float:
    """Mamdani inference (min AND/implication, max aggregation, centroid) at one point."""
    firing = np.minimum.outer(_memberships(E), _memberships(EC))  # rule strengths (7 x 7)
    index = _rule_index(rules)
    strength = np.array([firing[index == k].max(initial=0.0) for k in range(7)])
    agg = np.max(np.minimum(strength[:, None], _OUT_MF), axis=0)
    if not np.any(agg > 0):
        return 0.0
    return float(fuzz.defuzz(UNIVERSE, agg, "centroid"))


@dataclass(frozen=True)
class FuzzyPidParams(Checked):
    blending: BlendingParams = group(BlendingParams(), "")
    sample_time: float = sample_time(0.2)
    kp: float = tuned_param("FPID", "kp", "1/s", "base proportional gain (m/s2 per m/s)",
                            min=0.0)
    ki: float = tuned_param("FPID", "ki", "1/s2", "base integral gain (m/s2 per m)", min=0.0)
    kp_scale: float = tuned_param("FPID", "kp_scale", "1/s", "Kp change per unit of dKp",
                                  min=0.0)
    ki_scale: float = tuned_param("FPID", "ki_scale", "1/s2", "Ki change per unit of dKi",
                                  min=0.0)
    e_scale: float = tuned_param("FPID", "e_scale", "m/s", "speed error of one unit of E",
                                 min=1e-9)
    ec_scale: float = tuned_param("FPID", "ec_scale", "m/s2", "error rate of one unit of EC",
                                  min=1e-9)
    fuzzy_nodes: int = param(13, "1", "nodes per axis of the precomputed rule surface",
                             min=2, max=1001, integer=True)
    reference_feedforward: bool = param(False, description="add the freight PID's "
                                        "reference-acceleration feedforward a_ref(s + v t_p) "
                                        "(false: the paper's feedback-only fuzzy PID)")
    preview_time: float = preview_time_param()
    mean_weight: float = mean_weight_param("FPID")
    observer_correction_time: float = correction_time_param()


class RuleSurface:
    """A Mamdani rule surface tabulated on a square node grid, interpolated bilinearly."""

    def __init__(self, rules: tuple[tuple[str, ...], ...], nodes: int) -> None:
        self.axis = np.linspace(-3.0, 3.0, nodes)
        self.table = np.array([[infer(E, EC, rules) for EC in self.axis] for E in self.axis])
        self.step = self.axis[1] - self.axis[0]

    def __call__(self, E: float, EC: float) -> float:
        n = self.axis.size - 1
        x = (min(max(E, -3.0), 3.0) + 3.0) / self.step
        y = (min(max(EC, -3.0), 3.0) + 3.0) / self.step
        i, j = min(int(x), n - 1), min(int(y), n - 1)
        fx, fy = x - i, y - j
        t = self.table
        return float((1 - fx) * ((1 - fy) * t[i, j] + fy * t[i, j + 1])
                     + fx * ((1 - fy) * t[i + 1, j] + fy * t[i + 1, j + 1]))


class FreightFuzzyPid(FreightTracker):
    """Fuzzy self-tuning PI + shared blending."""

    state_fields = (*FreightTracker.state_fields, "integral", "prev_error", "kp_now", "ki_now")
    params_class = FuzzyPidParams
    output_vars = tracker_outputs("fuzzy PID demand u")

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The tracker's build-time data (:meth:`FreightTracker.native_data`) and
        ``sources/ato_fuzzy_rules.h``: the rule surfaces of ``KP_RULES`` and ``KI_RULES``
        (:class:`RuleSurface`: the Mamdani inference of scikit-fuzzy on the node grid)
        tabulated at the declared default ``fuzzy_nodes``, and the grid step (a native FMU
        refuses another node count)."""
        nodes = int(FuzzyPidParams().fuzzy_nodes)
        kp = RuleSurface(KP_RULES, nodes)
        ki = RuleSurface(KI_RULES, nodes)
        header = "\n".join([
            "/* generated by cosim/build/native.py from controllers.fuzzy.fuzzy_pid; do not"
            " edit */", "#ifndef ATO_FUZZY_RULES_H", "#define ATO_FUZZY_RULES_H",
            f"#define FZ_NODES {nodes}", f"#define FZ_STEP {c_double(float(kp.step))}",
            c_array("FZ_KP", kp.table), c_array("FZ_KI", ki.table), "#endif"]) + "\n"
        return {**super().native_data(identifier, shipped),
                "sources/ato_fuzzy_rules.h": header}

    def __init__(self, params: FuzzyPidParams, profile: ReferenceProfile, route: Route) -> None:
        super().__init__(params, profile, route)
        self.kp_surface = RuleSurface(KP_RULES, params.fuzzy_nodes)
        self.ki_surface = RuleSurface(KI_RULES, params.fuzzy_nodes)
        self.integral = 0.0  # m
        self.prev_error: float | None = None
        self.kp_now, self.ki_now = params.kp, params.ki

    def accel_demand(self, t: float, v: float, s: float, a_res: float, lo: float,
                     hi: float) -> float:
        p = self.p
        T = p.sample_time
        if p.reference_feedforward:
            self.a_ref = a_ff = reference_feedforward(self.profile, v, s, p.preview_time)
        else:
            self.a_ref, a_ff = self.profile.accel(s), 0.0
        e = self.v_ref - self.v_feedback
        ec = 0.0 if self.prev_error is None else (e - self.prev_error) / T
        self.prev_error = e
        E, EC = e / p.e_scale, ec / p.ec_scale
        self.kp_now = max(p.kp + p.kp_scale * self.kp_surface(E, EC), 0.0)
        self.ki_now = max(p.ki + p.ki_scale * self.ki_surface(E, EC), 0.0)
        integral = self.integral + e * T
        raw = a_ff + a_res + self.kp_now * e + self.ki_now * integral
        u = min(max(raw, lo), hi)
        if not ((raw > hi and e > 0) or (raw < lo and e < 0)):  # conditional integration
            self.integral = integral
        return u
