"""What a core ships to its native twin at build time (cosim/build/native.py, ``core_data``):
each core that has such data declares it (``native_data``), the builder asks every model's
core through the catalog, and the shipped parameter values it hands them are those of the
project's scenarios and reproduction runs."""

from __future__ import annotations

import pytest

from cosim.build.native import (
    NATIVE,
    core_data,
    native_sources,
    shipped_entries,
    shipped_scenarios,
    shipped_values,
)
from cosim.build.python import ROOT, bundled_files, catalog
from cosim.run.scenario import entry_files, scenario_files

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

# the models whose cores compute data for their C twin, and a file each ships
FROM_CORE = {
    "Empc3": "resources/regions/seed004_empc_crh3_3car.empc",
    "Gmpc3": "sources/ato_hybrid_model.h",
    "MbMpc3": "sources/ato_hybrid_model.h",
    "FreightPid": "sources/ato_freight_tracker.h",
    "FreightSmc": "sources/ato_freight_tracker.h",
    "FreightFpid": "sources/ato_fuzzy_rules.h",
    "FreightPreview": "resources/preview/default.gains",
    "EmuMfac3": "sources/ato_datadriven_const.h",
    "EmuIsmc3": "sources/ato_datadriven_const.h",
    "EmuIsmpc3": "sources/ato_datadriven_const.h",
    "EmuGpc3": "sources/ato_datadriven_const.h",
    "Crh3Gpc": "resources/eco_profiles/identified.arx",
    "StopMpc": "sources/ato_stop_mpc_sets.h",
    "StopRmpc": "sources/ato_stop_mpc_sets.h",
    "StopRsmpc": "sources/ato_stop_mpc_sets.h",
    "Emu3": "sources/Emu3_config.h",
    "Emu8": "sources/Emu8_config.h",
}


def test_the_builder_reads_the_scenarios_and_entries_the_runner_lists() -> None:
    assert shipped_scenarios() == list(scenario_files().values())
    assert shipped_entries() == list(entry_files().values())


@pytest.mark.parametrize("identifier", sorted(NATIVE))
def test_each_core_declares_what_it_ships_to_c(identifier: str) -> None:
    """Headers go to ``sources/``, data files to ``resources/``; a model whose core has
    nothing to ship gets nothing."""
    files = core_data(identifier, catalog()[identifier].load())
    assert all(rel.startswith(("sources/", "resources/")) for rel in files)
    assert all(text.endswith("\n") for text in files.values())
    if identifier in FROM_CORE:
        assert FROM_CORE[identifier] in files
    else:
        assert files == {}


def test_subclasses_ship_their_bases_data_and_their_own() -> None:
    """The preview and fuzzy PID trackers ship the freight tracker's header and their own
    file; the explicit MPC ships its regions, not the online hybrid MPC's models."""
    preview = core_data("FreightPreview", catalog()["FreightPreview"].load())
    fuzzy = core_data("FreightFpid", catalog()["FreightFpid"].load())
    pid = core_data("FreightPid", catalog()["FreightPid"].load())
    assert preview["sources/ato_freight_tracker.h"] == pid["sources/ato_freight_tracker.h"]
    assert fuzzy["sources/ato_freight_tracker.h"] == pid["sources/ato_freight_tracker.h"]
    assert set(pid) == {"sources/ato_freight_tracker.h"}
    empc = core_data("Empc3", catalog()["Empc3"].load())
    assert "sources/ato_hybrid_model.h" not in empc


def test_shipped_values_are_the_defaults_then_scenarios_then_runs() -> None:
    """For the tube MPCs: ``{}`` first, then each scenario's controller parameters in name
    order, then each reproduction run of those scenarios with its ``controller.*`` settings
    over them."""
    fmus = ("StopRmpc", "StopRsmpc")
    expected: list[dict] = [{}]
    used: dict[str, dict] = {}
    for name, path in scenario_files().items():
        for component, spec in tomllib.loads(path.read_text()).get("fmus", {}).items():
            if isinstance(spec, dict) and spec.get("fmu") in fmus:
                assert component == "controller"
                used[name] = dict(spec.get("parameters", {}))
                expected.append(used[name])
    assert used, "no shipped scenario runs a tube MPC"
    runs = 0
    for path in entry_files().values():
        for run in tomllib.loads(path.read_text()).get("runs", []):
            if run.get("scenario") in used:
                runs += 1
                expected.append({**used[run["scenario"]],
                                 **{k.removeprefix("controller."): v
                                    for k, v in run.get("set", {}).items()
                                    if k.startswith("controller.")}})
    assert runs > 0
    assert shipped_values(fmus) == expected
    assert shipped_values(("NoSuchFmu",)) == [{}]


def test_every_native_build_is_made_from_the_literals_it_is_written_with() -> None:
    """The builder writes every model's declarations with cosim/fmu/c_text.py, so that file is
    a source of every native FMU, also of one whose Python bundle does not hold it."""
    c_text = ROOT / "cosim" / "fmu" / "c_text.py"
    assert c_text not in bundled_files(catalog()["StopPid"].module)
    assert all(c_text in native_sources(identifier) for identifier in NATIVE)
