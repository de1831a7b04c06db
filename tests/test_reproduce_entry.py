"""A reproduction entry as typed data (cosim.reproduce.entry): one loader whose errors name the
file, the table, the key and its value, suggest the nearest known key, and check the names one
table gives another; and the schema page generated from the same fields."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from cosim.reproduce.entry import (
    Figure,
    Metric,
    ReproduceError,
    Run,
    entry_names,
    load_entry,
)
from cosim.reproduce.fields import unknown_text
from cosim.reproduce.schema import SCHEMA_PATH, schema_markdown

ENTRY = """
title = "Test entry"
[[runs]]
name = "PID"
scenario = "seed000_stop_pid"
[[runs]]
name = "PID kp=30"
scenario = "seed000_stop_pid"
set = { "controller.kp" = 30.0 }
[[metrics]]
key = "stop_error_m"
label = "stop error (m)"
[[figures]]
file = "speed.png"
x = "plant.s"
y = ["plant.v"]
"""


def _load(tmp_path: Path, text: str) -> None:
    path = tmp_path / "seed999.toml"
    path.write_text(text)
    load_entry(str(path))


def test_entries_are_typed(tmp_path: Path) -> None:
    path = tmp_path / "e.toml"
    path.write_text('set = { "plant.disturbance_amplitude" = 0.02 }\n' + ENTRY)
    entry = load_entry(str(path))
    assert entry.runs == [
        Run(name="PID", scenario="seed000_stop_pid",
            overrides={"plant.disturbance_amplitude": 0.02}),
        Run(name="PID kp=30", scenario="seed000_stop_pid",
            overrides={"plant.disturbance_amplitude": 0.02, "controller.kp": 30.0})]
    assert entry.metrics == [Metric(key="stop_error_m", label="stop error (m)")]
    assert entry.metrics[0].heading == "stop error (m)"
    (figure,) = entry.figures
    assert isinstance(figure, Figure) and figure.kind == "overlay" and figure.runs is None
    # what cosim.run.figures reads: the keys given, the kind's default made explicit
    assert figure.spec() == {"file": "speed.png", "kind": "overlay", "x": "plant.s",
                             "y": ["plant.v"]}
    assert entry.name == "e" and entry.table == "table" and entry.claims == []


def test_shipped_figures_read_as_written() -> None:
    """The spec a figure draws from is its TOML table (the default kind aside)."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]

    for name in entry_names():
        entry = load_entry(name)
        written = tomllib.loads(entry.path.read_text()).get("figures", [])
        assert [f.spec() for f in entry.figures] == [
            {"kind": "overlay", **table} for table in written], name


@pytest.mark.parametrize(("patch", "message"), [
    # an unknown key: the nearest known one is suggested
    (ENTRY.replace('scenario = "seed000_stop_pid"\nset', 'scenaro = "seed000_stop_pid"\nset'),
     "seed999.toml: [[runs]] #2: unknown key 'scenaro' (did you mean 'scenario'?)"),
    ("titel = 'x'\n" + ENTRY, "seed999.toml: unknown key 'titel' (did you mean 'title'?)"),
    (ENTRY + '[[metrics]]\nkey = "x"\nratio = "PID"\n',
     "[[metrics]] #2: unknown key 'ratio' (did you mean 'ratio_to'?)"),
    (ENTRY + '[[claims]]\nid = "a"\ntext = "t"\nmetric = "m"\nkind = "below"\nrun = ["PID"]\n',
     "[[claims]] #1: unknown key 'run' (did you mean 'runs'?)"),
    (ENTRY + '[ensemble]\nseed = "plant.disturbance_seed"\n',
     "[ensemble]: unknown key 'seed' (did you mean 'seed_key'?)"),
    # a key of another kind of figure
    (ENTRY + '[[figures]]\nfile = "c.png"\nkind = "speed_classes"\ny = ["plant.v"]\nref = "r"\n'
     'classes = [0, 30]\nlimit_kmh = 2.0\nlimit_below_kmh = 30.0\nlimit_fraction = 0.02\n'
     'xlim = [0, 1]\n', "[[figures]] #2: unknown key 'xlim' for kind 'speed_classes' (known: "
     "classes, file, kind,"),
    # wrong types, named with the key and the value
    (ENTRY.replace('name = "PID"\n', 'name = 7\n', 1),
     "[[runs]] #1: name = 7: expected a string"),
    (ENTRY.replace('scenario = "seed000_stop_pid"\n[[runs]]',
                   'scenario = "seed000_stop_pid"\nrepeat = "3"\n[[runs]]'),
     "[[runs]] #1: repeat = '3': expected an integer"),
    (ENTRY.replace('scenario = "seed000_stop_pid"\n[[runs]]',
                   'scenario = "seed000_stop_pid"\nrepeat = true\n[[runs]]'),
     "[[runs]] #1: repeat = True: expected an integer"),
    (ENTRY + '[[paper]]\nrun = "PID"\nmetric = "stop_error_m"\nvalue = "0.3"\n',
     "[[paper]] #1: value = '0.3': expected a number"),
    (ENTRY.replace('y = ["plant.v"]', 'y = [1]'),
     "[[figures]] #1: y = [1]: expected a string or a list of strings"),
    ('runs = 3\ntitle = "t"\n', "runs = 3: expected [[runs]] tables"),
    # ranges
    (ENTRY + '[[paper]]\nrun = "PID"\nmetric = "stop_error_m"\nvalue = 0.3\n'
     'tolerance = -1.0\n', "tolerance = -1.0 must be >= 0"),
    (ENTRY + '[[paper]]\nrun = "PID"\nmetric = "stop_error_m"\nrange = [1.0, 0.0]\n',
     "range [1.0, 0.0] must be [low, high]"),
    # cross-references between the tables
    (ENTRY + '[[paper]]\nrun = "PDI"\nmetric = "stop_error_m"\nvalue = 0.3\n',
     "[[paper]] #1: run 'PDI' is not one of [[runs]] ['PID', 'PID kp=30']"),
    (ENTRY + '[[paper]]\nrun = "PID"\nmetric = "stop_err"\nvalue = 0.3\n',
     "[[paper]] #1: metric 'stop_err' is not in [[metrics]] ['stop_error_m']"),
    (ENTRY + '[[derived]]\nname = "d"\nkind = "saving_percent"\nmetric = "m"\nrun = "PID"\n'
     'baseline = "nobody"\n', "[[derived]] #1: baseline 'nobody' is not one of [[runs]]"),
    (ENTRY.replace('y = ["plant.v"]', 'y = ["plant.v"]\nruns = ["PID", "MPC"]'),
     "[[figures]] #1: runs ['MPC'] are not in [[runs]]"),
    (ENTRY + '[[claims]]\nid = "a"\ntext = "t"\nmetric = "m"\nkind = "below"\nruns = ["MPC"]\n'
     'threshold = 1.0\n', "[[claims]] 'a': runs: 'MPC' is not one of the entry's [[runs]]"),
])
def test_errors_name_the_file_key_and_value(tmp_path: Path, patch: str, message: str) -> None:
    with pytest.raises(ReproduceError, match=re.escape(message)):
        _load(tmp_path, patch)


def test_unknown_keys_without_a_near_name_list_the_known_ones() -> None:
    assert unknown_text(["zzz"], ["name", "scenario"]) == (
        "unknown key 'zzz' (known: name, scenario)")
    assert unknown_text(["nmae", "zzz"], ["name", "scenario"]) == (
        "unknown keys 'nmae' (did you mean 'name'?), 'zzz'")


def test_the_schema_page_is_current() -> None:
    assert SCHEMA_PATH.read_text() == schema_markdown(), "run `cosim docs`"


def test_the_schema_page_documents_every_key() -> None:
    """Every key an entry may have is on the page, with its meaning."""
    from cosim.reproduce.claims import CLAIM_KEYS
    from cosim.reproduce.ensemble import ENSEMBLE_KEYS
    from cosim.reproduce.entry import PARTS, Entry, Statement, Variant
    from cosim.reproduce.fields import keys_of

    page = schema_markdown()
    sections = re.split(r"^## ", page, flags=re.M)
    for heading, keys in [("The entry", [k for k, _ in keys_of(Entry)]),
                          *((f"`[[{key}]]`", [k for k, _ in keys_of(cls)])
                            for key, cls in PARTS.items()),
                          ("`[ensemble]`", list(ENSEMBLE_KEYS)), ("`[[claims]]`", CLAIM_KEYS),
                          ("`[[variants]]`", [k for k, _ in keys_of(Variant)]),
                          ("`[[statements]]`", [k for k, _ in keys_of(Statement)])]:
        (section,) = [s for s in sections if s.startswith(heading)]
        for key in keys:
            assert re.search(rf"^\| `{re.escape(key)}` \| .+ \| .{{6,}} \|$", section,
                             re.M), (heading, key)


def test_shipped_line_figures_fit_a_page() -> None:
    """Every shipped line figure draws at most MAX_PANELS axes (error panels counted), names
    its references and error among the recorded series it reads, and labels a y axis it names
    itself with a unit in parentheses."""
    from cosim.run.figures import MAX_PANELS, panel_count

    for name in entry_names():
        entry = load_entry(name)
        for figure in entry.figures:
            if not figure.line_kind():
                continue
            runs = figure.runs or [r.name for r in entry.runs]
            assert panel_count(figure.spec(), len(runs)) <= MAX_PANELS, (name, figure.file)
            ys = figure.y if isinstance(figure.y, list) else [figure.y]
            assert set(figure.reference or []) <= set(ys), (name, figure.file)
            if figure.ylabel is not None:
                assert re.search(r"\(\S+\)$", figure.ylabel), (name, figure.file)


def test_an_alias_names_the_same_entry_and_an_unknown_name_gets_the_nearest() -> None:
    """Every shipped entry has a reader's title (author-year, topic) and a distinct alias;
    the alias loads the same entry as the file's stem; a near miss is offered."""
    from cosim.reproduce.entry import entry_aliases, resolve_name

    aliases = entry_aliases()
    assert sorted(aliases.values()) == entry_names()  # one alias each, none shared
    for alias, stem in aliases.items():
        assert resolve_name(alias) == resolve_name(stem) == stem
        assert load_entry(alias) == load_entry(stem)
        assert not load_entry(stem).title.startswith("Seed")
    with pytest.raises(ReproduceError, match=r"no reproduction entry 'liu2021' \(did you mean "
                                             r"'liu2022'\?\)"):
        load_entry("liu2021")
    with pytest.raises(ReproduceError, match="known: seed000.*liu2022"):
        load_entry("nothing-like-it")


def test_a_bad_alias_names_the_file_and_value(tmp_path: Path) -> None:
    with pytest.raises(ReproduceError, match=r"seed999.toml: alias = 'Liu 2022' must be "
                                             "lower-case"):
        _load(tmp_path, 'alias = "Liu 2022"\n' + ENTRY)


def test_cosim_reproduce_takes_the_alias_and_suggests_for_a_typo(monkeypatch) -> None:
    """`cosim reproduce liu2022` and `cosim reproduce seed000` run the same entry; a typo is a
    one-line error with the nearest name."""
    from typer.testing import CliRunner

    import cosim.reproduce.page as page
    from cosim.cli import app

    ran: list[str] = []
    monkeypatch.setattr(page, "reproduce", lambda name, *a, **k: ran.append(name) or name)
    runner = CliRunner()
    for name in ("liu2022", "seed000"):
        assert runner.invoke(app, ["reproduce", name]).exit_code == 0
    assert ran == ["seed000", "seed000"]
    done = runner.invoke(app, ["reproduce", "li2023"])
    assert done.exit_code == 2 and "did you mean 'li2024'" in " ".join(done.output.split())
