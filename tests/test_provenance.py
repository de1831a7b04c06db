"""A paper page knows the inputs it was made from (cosim.run.provenance) and `cosim docs --check`
names every page whose inputs the tree no longer has."""

from __future__ import annotations

from pathlib import Path

from cosim import site
from cosim.build.python import ROOT
from cosim.reproduce.record import Record, build_of, save
from cosim.run.provenance import entry_digest, entry_inputs, simulation_digest


def _rel(paths: list[Path]) -> set[str]:
    return {p.relative_to(ROOT).as_posix() for p in paths}


def test_inputs_are_the_entry_its_scenarios_their_cores_and_the_evaluation() -> None:
    files = _rel(entry_inputs("seed000"))
    assert "papers/seed000/entry.toml" in files
    assert "papers/seed000/scenarios/seed000_stop_pid.toml" in files
    assert "controllers/pid/stop_pid.py" in files  # the core behind StopPid
    assert "plants/brake_delay.py" in files  # the plant behind BrakeDelayTrain
    assert "cosim/reproduce/claims.py" in files
    assert "cosim/site.py" not in files  # the page writer is not an input
    assert not any(f.startswith("papers/seed001/scenarios/") for f in files)
    # every paper's metric plug-ins (the registry loads them all), not its tuning or scripts
    assert {f"papers/seed00{n}/metrics.py" for n in range(1, 5)} <= files
    assert not any(f.startswith("papers/") and f.endswith(("tuning.py", "README.md"))
                   for f in files)
    assert "controllers/datadriven/laws.py" not in files  # another paper's law
    # another package's data (the hybrid MPC's regions, the eco optimum)
    assert not any(f.startswith(("controllers/hybrid/data/", "controllers/eco/data/"))
                   for f in files)
    assert "plants/routes/seed000_stop.toml" in files  # the data a bundled module reads


def test_the_native_build_adds_the_c_models_it_runs() -> None:
    python = _rel(entry_inputs("seed000"))
    native = _rel(entry_inputs("seed000", "native"))
    # a Python record's only C input is the master's loop (it runs the Python builds too)
    assert [f for f in python if f.endswith(".c")] == ["cosim/run/master/native_loop.c"]
    assert {"cosim/fmu/native/plants/brake_delay.c", "cosim/fmu/native/controllers/stop_mpc.c",
            "cosim/build/native.py"} <= set(native)
    assert set(python) < set(native)
    assert simulation_digest("seed000", "native") != simulation_digest("seed000")


def test_digest_is_a_function_of_contents(monkeypatch) -> None:
    first = entry_digest("seed000")
    assert entry_digest("seed000") == first
    target = ROOT / "controllers" / "pid" / "stop_pid.py"
    original = Path.read_bytes

    def edited(self: Path) -> bytes:
        data = original(self)
        return data + b"\n# edited\n" if self == target else data

    monkeypatch.setattr(Path, "read_bytes", edited)
    assert entry_digest("seed000") != first
    assert entry_digest("seed001") == entry_digest("seed001")


def test_stale_papers_names_runs_and_pages_made_from_other_inputs(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(site, "paper_names", lambda: ["seed000"])
    run = tmp_path / "seed000"
    run.mkdir()
    (run / "claims.md").write_text("## claims\n")
    (run / site.INPUTS_FILE).write_text(entry_digest("seed000") + "\n")
    with monkeypatch.context() as m:  # the local run decides where no current page does
        m.setattr(site, "_page_digest", lambda name: None)
        (line,) = site.stale_papers(tmp_path)  # no record behind it: not publishable
        assert "cannot be published" in line and "no record" in line
        save(Record("seed000", simulation_digest("seed000"), 3, True), run)  # too few members
        (line,) = site.stale_papers(tmp_path)
        assert "K = 3 members, the entry declares 20" in line and "--seeds 20" in line
        save(Record("seed000", simulation_digest("seed000"), 20, True), run)
        assert site.stale_papers(tmp_path) == []
        page = site.paper_page("seed000", run)[site.DOCS / "papers" / "seed000.md"]
        assert f"<!-- inputs {entry_digest('seed000')} -->" in page.decode()
        (run / site.INPUTS_FILE).write_text("0" * 64 + "\n")
        (line,) = site.stale_papers(tmp_path)
        # the record's simulation inputs are still the tree's: redrawn, not rerun
        assert "other inputs" in line and "run `cosim docs`" in line and "no simulation" in line
        save(Record("seed000", "0" * 64, 20, True), run)  # a record of other simulation inputs
        (line,) = site.stale_papers(tmp_path)
        folder = site.DOCS / "papers" / "seed000"
        committed = site.record_simulation(folder)
        if committed != simulation_digest("seed000", build_of(folder)):
            assert "run `cosim reproduce seed000`, then `cosim docs`" in line
    (run / "claims.md").unlink()  # no run here: the committed page's header decides
    committed = site.DOCS / "papers" / "seed000.md"
    text = committed.read_text() if committed.is_file() else site.NOT_REPRODUCED
    found = site._INPUTS.search(text)
    if found is None:  # the page saying how to make it carries no result: not stale
        expect_stale = text != site.NOT_REPRODUCED.format(name="seed000")
    else:
        expect_stale = found.group(1) != entry_digest(
            "seed000", build_of(site.DOCS / "papers" / "seed000"))
    assert bool(site.stale_papers(tmp_path)) == expect_stale
