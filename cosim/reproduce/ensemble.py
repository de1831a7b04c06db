"""The ``[ensemble]`` table of a reproduction entry: how an entry's runs are varied into the
members of its claims (report and calibration seeds, plant-mismatch draws, the perturbed
floating-point reruns, repeats), checked (schema: :mod:`cosim.reproduce.entry`)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from cosim.run.perturbation import parse_perturb

REQUIRED = "required"
ENSEMBLES = ("disturbance", "mismatch", "repeat")  # the members of a claim
ROUNDING_RELATIVE = 1e-12  # relative change of each [ensemble].rounding_perturb parameter
# The keys of the [ensemble] table: key -> (type, default, meaning); the schema page
# (docs/reproduce_schema.md) is written from them.
ENSEMBLE_KEYS: dict[str, tuple[str, str, str]] = {
    "seed_key": ("a string FMU.PARAMETER", "none", "the override key taking a member's seed "
                 "(none: no random input; a \"disturbance\" claim is then one run)"),
    "report_seeds": ("\"A..B\", \"A..B, C\" or a list of integers", "\"1..20\"",
                     "the seeds of the members; ``--seeds K`` takes the first K"),
    "calibration_seeds": ("as report_seeds", "none", "the seeds used for tuning only; "
                          "disjoint from report_seeds (checked)"),
    "perturb": ("a list of strings", "[]", "the plant-mismatch distribution of a "
                "\"mismatch\" claim, as ``--perturb`` (``plant.mass=+-10%``)"),
    "perturb_seed": ("an integer", "0", "the seed of the mismatch draws"),
    "rounding_perturb": ("a list of strings FMU.PARAMETER", "[]", "parameters scaled by "
                         "1 + 1e-12 on the perturbed floating-point rerun"),
    "rounding_perturb_second": ("a list of strings FMU.PARAMETER", "[]", "parameters scaled "
                                "by 1 + 1e-12 on a second perturbed rerun, independent of the "
                                "first (other parameters; never the numpy reference path); "
                                "none: one rerun"),
    "rounding_reference_path": ("true or false", "true", "the rerun also takes the plants' "
                                "numpy reference path (``ATO_COSIM_NO_KERNELS=1``) where a "
                                "Python build runs (a run of native C builds alone has none); "
                                "false keeps the compiled kernels (rounding_perturb alone "
                                "perturbs it)"),
    "repeats": ("an integer >= 1", "none", "the members of a \"repeat\" claim: repetitions of "
                "the nominal run, whatever ``--seeds`` (no rounding rerun)"),
    "members": ("an integer in [1, report seeds]", "20, or every report seed if fewer",
                "K a published page needs"),
}
_ENSEMBLE_KEYS = set(ENSEMBLE_KEYS)


class ClaimsError(ValueError):
    """Claims data that cannot be used (the message names the file, key and value)."""


@dataclass
class Ensemble:
    """How an entry's runs are varied (see :mod:`cosim.reproduce.entry`)."""

    seed_key: str | None = None
    report_seeds: list[int] = field(default_factory=lambda: list(range(1, 21)))
    calibration_seeds: list[int] = field(default_factory=list)
    perturb: list[str] = field(default_factory=list)
    perturb_seed: int = 0
    rounding_perturb: list[str] = field(default_factory=list)
    rounding_perturb_second: list[str] = field(default_factory=list)
    rounding_reference_path: bool = True

    def rounding_paths(self) -> tuple[int, ...]:
        """The perturbed floating-point paths of a member: 1 (``rounding_perturb``, with the
        numpy reference path unless ``rounding_reference_path`` is false) and, where
        ``rounding_perturb_second`` names parameters, 2."""
        return (1, 2) if self.rounding_perturb_second else (1,)

    def rounding_keys(self, path: int) -> list[str]:
        """The parameters scaled by 1 + 1e-12 on perturbed path ``path``."""
        return self.rounding_perturb if path == 1 else self.rounding_perturb_second
    repeats: int | None = None  # members of a "repeat" claim (None: no such claim allowed)
    members: int | None = None  # K a published page needs (None: 20, or every report seed)

    def declared_k(self) -> int:
        """K the entry's page is published from (``members``, else min(20, report seeds))."""
        return self.members if self.members is not None else min(20, len(self.report_seeds))


def parse_seeds(where: str, key: str, value: Any) -> list[int]:
    """``"1..20"``, ``"1..5, 9"`` or a list of integers -> the seeds (errors name the key)."""
    if isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool)
                                       for v in value):
        seeds = list(value)
    elif isinstance(value, str):
        seeds = []
        for part in value.replace(" ", "").split(","):
            m = re.fullmatch(r"(-?\d+)(?:\.\.(-?\d+))?", part)
            if not m:
                raise ClaimsError(f"{where}: {key} = {value!r}: expected 'A..B', 'A, B' or a "
                                  "list of integers")
            lo, hi = int(m[1]), int(m[2] if m[2] is not None else m[1])
            if hi < lo:
                raise ClaimsError(f"{where}: {key} = {value!r}: empty range {lo}..{hi}")
            seeds += list(range(lo, hi + 1))
    else:
        raise ClaimsError(f"{where}: {key} = {value!r}: expected 'A..B' or a list of integers")
    if len(set(seeds)) != len(seeds) or not seeds:
        raise ClaimsError(f"{where}: {key} = {value!r}: seeds must be distinct and not empty")
    return seeds


def check_ensemble(where: str, data: dict[str, Any] | None) -> Ensemble:
    """The ``[ensemble]`` table, checked (calibration and report seeds disjoint)."""
    if data is None:
        return Ensemble()
    unknown = sorted(set(data) - _ENSEMBLE_KEYS)
    if unknown:
        raise ClaimsError(f"{where}: [ensemble]: unknown key(s) {unknown} (allowed: "
                          f"{sorted(_ENSEMBLE_KEYS)})")
    ens = Ensemble()
    if "seed_key" in data:
        if not (isinstance(data["seed_key"], str) and "." in data["seed_key"]):
            raise ClaimsError(f"{where}: [ensemble] seed_key = {data['seed_key']!r}: expected "
                              "an override key FMU.PARAMETER")
        ens.seed_key = data["seed_key"]
    if "report_seeds" in data:
        ens.report_seeds = parse_seeds(f"{where}: [ensemble]", "report_seeds",
                                       data["report_seeds"])
    if "calibration_seeds" in data:
        ens.calibration_seeds = parse_seeds(f"{where}: [ensemble]", "calibration_seeds",
                                            data["calibration_seeds"])
    both = sorted(set(ens.report_seeds) & set(ens.calibration_seeds))
    if both:
        raise ClaimsError(f"{where}: [ensemble]: calibration_seeds and report_seeds share "
                          f"{both}: tuning seeds must be disjoint from report seeds")
    for key in ("perturb", "rounding_perturb", "rounding_perturb_second"):
        value = data.get(key, [])
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ClaimsError(f"{where}: [ensemble] {key} = {value!r}: expected a list of "
                              "strings")
    try:
        parse_perturb(data.get("perturb", []))
    except ValueError as err:
        raise ClaimsError(f"{where}: [ensemble] perturb: {err}") from err
    ens.perturb = list(data.get("perturb", []))
    for name in ("rounding_perturb", "rounding_perturb_second"):
        for key in data.get(name, []):
            if "." not in key:
                raise ClaimsError(f"{where}: [ensemble] {name}: {key!r} is not "
                                  "FMU.PARAMETER")
    ens.rounding_perturb = list(data.get("rounding_perturb", []))
    ens.rounding_perturb_second = list(data.get("rounding_perturb_second", []))
    shared = sorted(set(ens.rounding_perturb) & set(ens.rounding_perturb_second))
    if shared:
        raise ClaimsError(f"{where}: [ensemble] rounding_perturb_second shares {shared} with "
                          "rounding_perturb: the second path must perturb other parameters")
    ref_path = data.get("rounding_reference_path", True)
    if not isinstance(ref_path, bool):
        raise ClaimsError(f"{where}: [ensemble] rounding_reference_path = {ref_path!r}: "
                          "expected true or false")
    if not ref_path and not ens.rounding_perturb:
        raise ClaimsError(f"{where}: [ensemble] rounding_reference_path = false needs "
                          "rounding_perturb: the rerun would repeat the main path")
    ens.rounding_reference_path = ref_path
    seed = data.get("perturb_seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ClaimsError(f"{where}: [ensemble] perturb_seed = {seed!r}: expected an integer")
    ens.perturb_seed = seed
    if "repeats" in data:
        rep = data["repeats"]
        if isinstance(rep, bool) or not isinstance(rep, int) or rep < 1:
            raise ClaimsError(f"{where}: [ensemble] repeats = {rep!r}: expected an integer "
                              ">= 1 (the repetitions of a 'repeat' claim's nominal run)")
        ens.repeats = rep
    if "members" in data:
        k = data["members"]
        if (isinstance(k, bool) or not isinstance(k, int) or not
                1 <= k <= len(ens.report_seeds)):
            raise ClaimsError(f"{where}: [ensemble] members = {k!r}: expected an integer in "
                              f"[1, {len(ens.report_seeds)}] (K of a published page, at most "
                              "the report seeds)")
        ens.members = k
    return ens
