"""[simulation] fmi_version (and `cosim run --fmi`): which builds catalog FMU names resolve to;
explicit .fmu paths are used as written."""

from __future__ import annotations

import pytest

from cosim.build.python import FMU_DIR
from cosim.run.scenario import ScenarioError, find_scenario, load_scenario

PID = find_scenario("seed000_stop_pid")


def test_default_is_fmi2_builds():
    sc = load_scenario(PID)
    assert sc.simulation.fmi_version == 2
    assert sc.components["controller"].fmu_path == FMU_DIR / "StopPid.fmu"


def test_fmi3_resolves_catalog_names_to_the_fmi3_builds():
    sc = load_scenario(PID, ["simulation.fmi_version=3"])
    assert sc.components["controller"].fmu_path == FMU_DIR / "fmi3" / "StopPid.fmu"


def test_explicit_paths_are_kept(tmp_path):
    fmu = tmp_path / "x.fmu"
    fmu.write_bytes(b"")
    text = PID.read_text().replace('fmu = "StopPid"', f'fmu = "{fmu}"')
    path = tmp_path / "s.toml"
    path.write_text(text)
    sc = load_scenario(path, ["simulation.fmi_version=3"])
    assert sc.components["controller"].fmu_path == fmu


@pytest.mark.parametrize("bad", ["4", "true", '"3"'])
def test_other_versions_are_refused_naming_the_key(bad):
    with pytest.raises(ScenarioError, match=r"fmi_version.*expected one of \[2, 3\]"):
        load_scenario(PID, [f"simulation.fmi_version={bad}"])
