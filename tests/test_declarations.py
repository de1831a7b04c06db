"""Declare once: FMU variables come from the cores' declarations (issue 8).

* the built FMUs' modelDescriptions equal those from before the move (digest in
  ``tests/data/model_descriptions_before_issue8.json``) except the improvements listed here;
* declarations and :func:`build` are inverse, groups flatten, per-configuration values keep;
* no wrapper declares a variable of its own, and ``docs/fmus.md`` is current.
"""

from __future__ import annotations

import ast
import dataclasses
import json
import zipfile
from pathlib import Path

import pytest

from cosim.fmu.build import ROOT, catalog
from cosim.fmu.declare import KEEP, Var, build, group, param, parameters
from cosim.fmu.reference import REFERENCE_PATH, fmu_reference
from cosim.run.model_digest import digest_model_description

BEFORE = json.loads((ROOT / "tests/data/model_descriptions_before_issue8.json").read_text())

# (FMU, variable) -> description after issue 8: one shared declaration, one wording.
IMPROVED_DESCRIPTIONS = {
    **{(f, "s0"): "initial position of the train front" for f in ("BrakeDelayTrain", "Emu3",
                                                               "Emu8")},
    **{(f, "stop_point"): "stop position s_stop" for f in ("StopMpc", "StopRmpc", "StopRsmpc")},
    ("FreightPid", "route"): "bundled route name or path of a route TOML file (its reference "
                             "profile is tracked)",
    **{(f, "terminal_set_scale"): "unused since issue 11 (the terminal set is the maximal "
                                  "robust positively invariant set)"
       for f in ("StopMpc", "StopRmpc", "StopRsmpc")},
}
# (FMU, variable) -> start changed on purpose since: issue 16 (the shared freight blending
# decides the air brake 2 s ahead: without power braking an earlier application slows the
# cruising train before the reference does)
CHANGED_STARTS = {("FreightPid", "air_preview_time"): "2.0"}

# Integer ranges now written into the modelDescription (issue 12: the scenario check catches
# N = 1000 before anything runs)
INTEGER_RANGES = {
    ("FreightTrain", "traction_model"): {"min": "0", "max": "1"},
    **{(f, "N"): {"min": "2", "max": "60"} for f in ("StopMpc", "StopRmpc", "StopRsmpc")},
}

# variables added since (FMU -> names), each by the issue that needed it
ADDED_VARIABLES = {
    **{f: {"qp_solver",  # issue 10
           # issue 11: nominal resistance, spread W, observer, Euler design rows, counters
           "nominal_resistance", "mass_uncertainty", "grade_uncertainty",
           "disturbance_observer", "observer_gain", "design_model",
           "qp_infeasible_after_stop", "events_moving", "events_standstill",
           "resistance_estimate"} for f in ("StopMpc", "StopRmpc", "StopRsmpc")},
    "BrakeDelayTrain": {"grade_scale"},  # issue 11: grade mismatch in the perturbation study
    "StopPid": {"hold_at_stop_point"},  # issue 11: the full-brake rule made a parameter
    **{f: {"disturbance_correlation_time", "disturbance_smooth"}  # issue 15
       for f in ("Emu3", "Emu8")},
    # issue 16: the shared freight blending's electric-brake final approach and the planned
    # stop application (stop_ed_share)
    "FreightPid": {"final_approach_distance", "stop_tolerance", "stop_ed_share"},
    **{f: {"stop_ed_share"} for f in ("FreightFpid", "FreightSmc")},
    # issue 16: the preview counts the air brake as a previewed disturbance and feeds back a
    # blend of the head speed and its train-mean speed observer
    "FreightPreview": {"stop_ed_share", "air_brake_preview", "mean_weight",
                       "observer_correction_time", "v_mean_estimate"},
}


# variables removed since (FMU -> names): issue 12, the run-dependent QP solve time is no
# output (the FMU logs it at fmi2Terminate, cosim.fmu.diagnostics)
REMOVED_VARIABLES = {f: {"qp_solve_time_median"} for f in ("StopMpc", "StopRmpc", "StopRsmpc")}


def test_model_descriptions_unchanged_but_for_listed_improvements(built_fmus) -> None:
    assert set(BEFORE) <= set(catalog())
    for identifier, before in BEFORE.items():
        with zipfile.ZipFile(built_fmus[identifier].path) as z:
            now = digest_model_description(z.read("modelDescription.xml"))
        added = ADDED_VARIABLES.get(identifier, set())
        removed = REMOVED_VARIABLES.get(identifier, set())
        before = {**before, "variables": {k: v for k, v in before["variables"].items()
                                          if k not in removed},
                  "output_dependencies": {k: v for k, v in before["output_dependencies"].items()
                                          if k not in removed}}
        for key in ("description", "default_experiment", "units"):
            assert now[key] == before[key], (identifier, key)
        deps = now["output_dependencies"]  # added outputs bring their own entries
        assert set(deps) - set(before["output_dependencies"]) <= added, identifier
        assert {k: deps[k] for k in before["output_dependencies"]} \
            == before["output_dependencies"], identifier
        assert set(now["variables"]) == set(before["variables"]) | added, identifier
        for name, old in before["variables"].items():
            expected = dict(old)
            if (identifier, name) in IMPROVED_DESCRIPTIONS:
                expected["description"] = IMPROVED_DESCRIPTIONS[identifier, name]
            expected.update(INTEGER_RANGES.get((identifier, name), {}))
            if (identifier, name) in CHANGED_STARTS:
                expected["start"] = CHANGED_STARTS[identifier, name]
            assert now["variables"][name] == expected, (identifier, name)


def _default_params(cls) -> object:
    """What the core's declared defaults stand for, written independently of the FMU."""
    from controllers.hybrid.hybrid_mpc import HybridMpcParams
    from controllers.pid.speed_pid import DistributedSpeedPidParams
    from plants.emu import DEFAULT_CONFIGURATION, emu_config
    from plants.freight import FreightParams

    core, units = cls.core_class, cls.core_options.get("units")
    if core.params_class is not None:
        return core.params_class()
    return {"Emu": lambda: emu_config(DEFAULT_CONFIGURATION[units]),
            "FreightTrain": FreightParams,
            "DistributedSpeedPid": lambda: DistributedSpeedPidParams(units=units),
            "HybridMpc": HybridMpcParams,
            "MoveBlockingMpc": lambda: HybridMpcParams(move_blocks="3:4:3"),
            "ExplicitMpc": lambda: HybridMpcParams(move_blocks="3:4:3"),
            }[core.__name__]()


@pytest.mark.parametrize("identifier", sorted(catalog()))
def test_declared_starts_build_the_default_core(identifier: str) -> None:
    """The core built from the declared starts has the declared defaults; a changed value
    reaches the core's parameters under its declared name (declarations and build inverse)."""
    cls = catalog()[identifier].load()
    starts = {v.name: v.start for v in cls.variables if v.causality == "parameter"}
    core = cls.core_class.from_parameters(starts, data_dir=ROOT, **cls.core_options)
    assert core.p == _default_params(cls)
    fixed = getattr(cls.core_class, "fixed_by_data", ())  # EMPC: design of its region data
    name = next(n for n, v in starts.items() if isinstance(v, float) and v > 0
                and n not in ("v0", "s0", *fixed))
    changed = cls.core_class.from_parameters({**starts, name: starts[name] * 2},
                                             data_dir=ROOT, **cls.core_options)
    assert changed.p != core.p
    again = {v.name: v.start for v in parameters(changed.p)} if dataclasses.is_dataclass(
        changed.p) else {}
    if name in again:
        assert again[name] == starts[name] * 2


def test_groups_flatten_with_prefix_and_names_alias() -> None:
    @dataclasses.dataclass(frozen=True)
    class Inner:
        a: float = param(1.0, "m", "inner a", min=0.0)

    @dataclasses.dataclass(frozen=True)
    class Outer:
        horizon: int = param(10, description="horizon", min=2, name="N")
        inner: Inner = group(Inner(), "in_")
        k: float = param(5.0, "N/m", "stiffness", per_configuration=True)
        hidden: float = 3.0  # not declared: not an FMU variable

    declared = {v.name: v for v in parameters(Outer())}
    assert list(declared) == ["N", "in_a", "k"]
    assert declared["in_a"] == Var("in_a", "parameter", 1.0, "m", "inner a", 0.0, None)
    assert declared["k"].start == KEEP and "configuration value" in declared["k"].description
    built = build(Outer(k=7.0), {"N": 4, "in_a": 2.5, "k": KEEP})
    assert built == Outer(horizon=4, inner=Inner(2.5), k=7.0)  # KEEP keeps 7.0
    assert build(Outer(), {"k": 9.0}).k == 9.0
    with pytest.raises(ValueError, match="k = -3"):
        build(Outer(), {"k": -3.0})
    with pytest.raises(ValueError, match="unit 'furlong'"):
        param(1.0, "furlong")


def _var_calls(path: Path) -> list[int]:
    tree = ast.parse(path.read_text())
    return [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Call)
            and getattr(node.func, "id", getattr(node.func, "attr", "")) in ("Var", "param")]


def test_wrappers_declare_nothing_themselves() -> None:
    """Names, units and defaults live on the cores: a ``*_fmu.py`` has no Var(...)/param(...)."""
    for spec in catalog().values():
        path = ROOT.joinpath(*spec.module.split(".")).with_suffix(".py")
        assert _var_calls(path) == [], f"{path}: declarations belong on the core"


def test_every_variable_name_is_declared_once_per_fmu() -> None:
    for identifier, spec in catalog().items():
        names = [v.name for v in spec.load().variables]
        assert len(names) == len(set(names)), identifier


def test_fmu_reference_is_current() -> None:
    assert REFERENCE_PATH.read_text() == fmu_reference(), "run `cosim docs`"


def test_catalog_read_from_source_equals_the_imported_wrappers() -> None:
    """The catalog is read from the wrapper modules' source (no import: a run needs one or
    two of 24 wrappers); importing them all finds the same FMUs, classes and descriptions
    (a wrapper class not named ``...Fmu``, or a ``...Fmu`` class that is no slave, fails)."""
    from cosim.fmu.build import _imported_catalog

    assert catalog() == _imported_catalog()
