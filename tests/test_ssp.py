"""SSP export: schema-valid (fmpy), complete, and it runs in libcosim with our results."""

from __future__ import annotations

import zipfile

import pytest
from fmpy.ssp.ssd import read_ssd
from matrix import by_scenario

from cosim.interop.libcosim import compare_frames, run_ssp
from cosim.interop.ssp import export_ssp
from cosim.run.scenario import find_scenario, load_scenario, scenario_files
from cosim.run.simulate import run_scenario

SCENARIOS = list(scenario_files().values())
SHORT = {"simulation.stop_time": 30.0}


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_export_is_valid_and_complete(path, tmp_path, built_fmus):
    sc = load_scenario(path, SHORT)
    out = export_ssp(sc, tmp_path / "x.ssp")
    ssd = read_ssd(str(out), validate=True)  # raises on a schema violation
    assert ssd.name == sc.name
    elements = {e.name: e for e in ssd.system.elements}
    assert set(elements) == set(sc.components)
    names = set(zipfile.ZipFile(out).namelist())
    for comp in sc.components.values():
        element = elements[comp.name]
        assert element.source in names and element.source.endswith(".fmu")
        bound = {p.name: p.value for b in element.parameterBindings
                 for pset in b.parameterValues for p in pset.parameters}
        for key, value in comp.parameters.items():
            if isinstance(value, bool):  # SSD writes xs:boolean: true / false
                assert str(bound[key]).lower() == str(value).lower(), key
                continue
            assert str(bound[key]) == str(value) or float(bound[key]) == float(value), key
    got = {(c.startElement, c.startConnector, c.endElement, c.endConnector)
           for c in ssd.system.connections}
    assert got == {(c.src, c.src_var, c.dst, c.dst_var) for c in sc.connections}


@pytest.mark.parametrize("path", by_scenario(SCENARIOS))
def test_ssp_in_libcosim_matches_our_jacobi(path, tmp_path, built_fmus):
    """libcosim in this process (``isolated=False``: the same frame as in its child process);
    test_ssp_carries_parameter_values runs the SSP through the child."""
    sc = load_scenario(path, SHORT)
    out = export_ssp(sc, tmp_path / "x.ssp")
    ours = run_scenario(sc, algorithm="jacobi", plot=False).frame
    refs = [c for c in ours.columns if c != "time"]
    theirs = run_ssp(out, refs, sc.simulation.stop_time,
                     sc.simulation.base_step or sc.simulation.output_interval, isolated=False)
    diffs = compare_frames(ours, theirs)
    assert len(diffs) == len(refs) and max(diffs.values()) <= 1e-9, diffs


def test_ssp_carries_parameter_values(tmp_path, built_fmus):
    """A changed parameter reaches libcosim through the SSP (not just FMU defaults)."""
    path = find_scenario("seed000_stop_pid")
    runs = {}
    for kp in (60.0, 20.0):
        sc = load_scenario(path, {**SHORT, "controller.kp": kp, "plant.mass": 539000.0})
        out = export_ssp(sc, tmp_path / f"kp{kp}.ssp")
        ours = run_scenario(sc, algorithm="jacobi", plot=False).frame
        theirs = run_ssp(out, ["plant.v", "controller.brake_command"], 30.0,
                         sc.simulation.base_step)
        assert max(compare_frames(ours, theirs).values()) <= 1e-9
        runs[kp] = theirs
    assert max(compare_frames(runs[60.0], runs[20.0]).values()) > 1e-3


def test_export_rejects_unknown_parameter(tmp_path, built_fmus):
    path = find_scenario("seed000_stop_pid")
    sc = load_scenario(path)
    sc.components["plant"].parameters["no_such_parameter"] = 1.0
    with pytest.raises(ValueError, match="no_such_parameter"):
        export_ssp(sc, tmp_path / "bad.ssp", build=False)
