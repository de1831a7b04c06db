"""``cosim reproduce``: entries are data, tables put ours beside the paper's (issue 15 item 4)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from claim_rows import claim_row

from cosim.reproduce.entry import Figure, ReproduceError, entry_names, load_entry
from cosim.reproduce.figures import draw_speed_classes, figure_section
from cosim.reproduce.page import redraw_entry, reproduce
from cosim.reproduce.tables import ranking_markdown, ranking_rows, summary_value
from cosim.run.figures import speed_class_errors
from cosim.run.simulate import run_scenario

# measurements of a run, not results of it (wall, CPU and solver times)
MEASURED_PREFIXES = ("wall_time_s", "real_time_factor", "fmu_wall_time_s", "qp_solve_time_",
                     "qp_cpu_time_", "host")

ENTRY = """
title = "Test entry"
notes = "why we differ"
build = "python"  # the runner's mechanics on the Python FMUs (the native campaign: below)
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
[[metrics]]
key = "executions.controller"
[[paper]]
run = "PID"
metric = "stop_error_m"
value = 0.2898
range = [-0.5, 0.5]
source = "sec. 4"
[[paper]]
run = "PID kp=30"
metric = "stop_error_m"
value = 0.2898
tolerance = 1e-6
[[figures]]
file = "speed.png"
kind = "overlay"
x = "plant.s"
y = ["plant.v"]
"""


def test_shipped_entries_load() -> None:
    assert "seed000" in entry_names()
    for name in entry_names():
        entry = load_entry(name)
        assert entry.runs and entry.metrics


def test_reproduce_writes_ours_beside_the_paper(built_fmus, tmp_path: Path) -> None:
    path = tmp_path / "entry.toml"
    path.write_text(ENTRY)
    table = reproduce(str(path), tmp_path / "out", workers=1)
    rows = pd.read_csv(tmp_path / "out" / "table.csv")
    # ours: the same numbers as an independent run of the same scenario and override
    alone = run_scenario("seed000_stop_pid", overrides={"controller.kp": 30.0}).summary
    row = rows[(rows.run == "PID kp=30") & (rows.metric == "stop_error_m")].iloc[0]
    assert row.ours == pytest.approx(alone["stop_error_m"], abs=1e-12)
    assert not row.within  # 1e-6 around the paper's 0.2898: ours is not that
    pid = rows[(rows.run == "PID") & (rows.metric == "stop_error_m")].iloc[0]
    assert pid.within == (-0.5 <= pid.ours <= 0.5)
    execs = rows[(rows.run == "PID") & (rows.metric == "executions.controller")].iloc[0]
    summary = json.loads((tmp_path / "out/runs/pid/summary.json").read_text())
    assert execs.ours == summary_value(summary, "executions.controller") == 301
    text = table.read_text()
    assert "| PID |" in text and "0.2898 (in [-0.5, 0.5])" in text and "why we differ" in text
    assert (tmp_path / "out" / "speed.png").stat().st_size > 10_000


@pytest.mark.parametrize(("patch", "message"), [
    ('[[paper]]\nrun = "nobody"\nmetric = "stop_error_m"\nvalue = 1.0\n', "run 'nobody'"),
    ('[[paper]]\nrun = "PID"\nmetric = "nope"\nvalue = 1.0\n', "metric 'nope'"),
    ('[[paper]]\nrun = "PID"\nmetric = "stop_error_m"\nrange = [1, 0]\n', "must be [low, high]"),
    ('[[figures]]\nfile = "x.png"\nx = "time"\ny = ["plant.v"]\nkind = "pie"\n', "kind 'pie'"),
    ('[[figures]]\nfile = "x.png"\nx = "time"\ny = ["plant.v[*]"]\ny_reduce = "max"\n',
     "y_reduce 'max'"),
    ('colour = "red"\n', "unknown key 'colour' (known: alias, build, citation, claims,"),
    ('tilte = "red"\n', "unknown key 'tilte' (did you mean 'title'?)"),
    ('[[figures]]\nfile = "x.png"\nx = "time"\ny = ["plant.v"]\nxlim = [5, 1]\n',
     "xlim = [5, 1]: expected [low, high] with low < high"),
    ('[[figures]]\nfile = "x.png"\nx = "time"\ny = ["plant.v"]\nband_x = [1, 2, "w", 4]\n',
     "band_x = [1, 2, 'w', 4]: expected [low, high] or [low, high, label]"),
    ('table = "../t"\n', "must be a file name"),
    ('build = "fast"\n', 'build = \'fast\' must be "native" or "python"'),
    ('set = 3\n', "set = 3: expected a table"),
    ('[[rankings]]\nmetric = "nope"\nruns = ["PID"]\n', "metric 'nope' is not in [[metrics]]"),
    ('[[rankings]]\nmetric = "stop_error_m"\nruns = ["PID", "PID"]\n', "must be distinct"),
    ('[[rankings]]\nmetric = "stop_error_m"\nruns = ["PID", "PID kp=30"]\npaper = ["PID"]\n',
     "must order the same runs"),
    ('[[figures]]\nfile = "c.png"\nkind = "speed_classes"\ny = ["plant.v"]\nclasses = [0, 30]\n'
     'limit_kmh = 2.0\nlimit_below_kmh = 30.0\nlimit_fraction = 0.02\n', "missing key(s) ['ref']"),
    ('[[figures]]\nfile = "c.png"\nkind = "speed_classes"\ny = ["plant.v"]\nref = "r"\n'
     'classes = [0, 50, 30]\nlimit_kmh = 2.0\nlimit_below_kmh = 30.0\nlimit_fraction = 0.02\n',
     "must be increasing edges"),
    ('[[sweeps]]\nname = "s"\nscenarios = ["seed000_stop_pid"]\n'
     'grid = { "controller.kp" = "1,2" }\nlabels = { seed000_stop_pidx = "PID" }\n',
     "labels name scenarios ['seed000_stop_pidx']"),
])
def test_bad_entries_name_the_file_and_key(tmp_path: Path, patch: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    top = patch.startswith(("colour", "tilte", "table", "set"))  # before the first table
    if patch.startswith("build"):  # in place of the entry's own
        text = re.sub(r"^build = .*$", patch.strip(), ENTRY, flags=re.M)
    else:
        text = patch + "\n" + ENTRY if top else ENTRY + patch
    path.write_text(text)
    with pytest.raises(ReproduceError, match=re.escape(message)) as err:
        load_entry(str(path))
    assert str(path) in str(err.value)


def test_ranking_orders_the_runs_and_names_the_pairs_the_other_way_round(
        tmp_path: Path) -> None:
    """Lowest first; ties keep the entry's order; a run without the figure ranks last; the
    verdict lists every pair of the paper's order that ours reverses."""
    path = tmp_path / "entry.toml"
    path.write_text(ENTRY.replace('[[runs]]\nname = "PID kp=30"', '[[runs]]\nname = "A"\n'
                                  'scenario = "seed000_stop_pid"\n[[runs]]\nname = "B"\n'
                                  'scenario = "seed000_stop_pid"\n[[runs]]\nname = "PID kp=30"')
                    + '[[rankings]]\nname = "main"\nmetric = "stop_error_m"\n'
                      'runs = ["PID", "A", "B", "PID kp=30"]\n'
                      'paper = ["PID", "A", "B", "PID kp=30"]\n'
                      '[[rankings]]\nmetric = "stop_error_m"\nruns = ["A", "B"]\n')
    entry = load_entry(str(path))
    summaries = {"PID": {"stop_error_m": 0.3}, "A": {"stop_error_m": 0.1},
                 "B": {"stop_error_m": 0.1}, "PID kp=30": {}}
    main, plain = ranking_rows(entry, summaries)
    assert main.ours == "A < B < PID < PID kp=30"
    assert main.paper == "PID < A < B < PID kp=30"
    assert main.source == "A < PID; B < PID" and main.within is False
    assert main.metric == "rank:stop_error_m" and main.label == "stop error (m)"
    assert plain.ours == "A < B" and plain.paper is None and plain.within is None
    summaries["PID"]["stop_error_m"] = 0.05
    (agree, _) = ranking_rows(entry, summaries)
    assert agree.within is True and agree.source == ""
    text = ranking_markdown([agree, plain])
    assert "| stop error (m) | main | PID < A < B < PID kp=30 ✓ |" in text
    assert "| stop error (m) |  | A < B | - | - |" in text


def test_unknown_entry_lists_the_known_ones() -> None:
    with pytest.raises(ReproduceError, match="seed000"):
        load_entry("seed999")


def test_repeated_run_gives_median_and_spread_and_ratio(built_fmus, tmp_path: Path) -> None:
    """``repeat = 3``: three runs; a deterministic metric has min = median = max, a timing
    metric lies in [min, max]; ``ratio_to`` divides the medians (ours and the paper's)."""
    path = tmp_path / "entry.toml"
    path.write_text('table = "table2"\n'  # the entry names its table files
                    + ENTRY.replace('set = { "controller.kp" = 30.0 }',
                                    'set = { "controller.kp" = 30.0 }\nrepeat = 3')
                    + '[[metrics]]\nkey = "fmu_wall_time_s.controller"\nratio_to = "PID"\n'
                    + '[[paper]]\nrun = "PID"\nmetric = "fmu_wall_time_s.controller"\n'
                    + 'value = 2.0\n[[paper]]\nrun = "PID kp=30"\n'
                    + 'metric = "fmu_wall_time_s.controller"\nvalue = 1.0\n')
    table = reproduce(str(path), tmp_path / "out", workers=1)
    assert table.name == "table2.md" and not (tmp_path / "out" / "table.md").exists()
    rows = pd.read_csv(tmp_path / "out" / "table2.csv")
    rep = rows[rows.run == "PID kp=30"].set_index("metric")
    assert (tmp_path / "out/runs/pid_kp_30/repeat_03/summary.json").is_file()
    err = rep.loc["stop_error_m"]
    assert err.repeats == 3 and err.ours_min == err.ours == err.ours_max
    wall = rep.loc["fmu_wall_time_s.controller"]
    assert wall.ours_min <= wall.ours <= wall.ours_max
    pid_wall = rows[(rows.run == "PID") & (rows.metric == "fmu_wall_time_s.controller")]
    assert wall.ratio == pytest.approx(wall.ours / pid_wall.ours.iloc[0], rel=1e-12)
    assert wall.paper_ratio == pytest.approx(0.5, rel=1e-12)
    assert "ratio to PID" in table.read_text() and "median [min, max]" in table.read_text()


def test_bad_repeat_and_ratio_name_the_key(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(ENTRY.replace('scenario = "seed000_stop_pid"\n[[runs]]',
                                  'scenario = "seed000_stop_pid"\nrepeat = 0\n[[runs]]', 1))
    with pytest.raises(ReproduceError, match="repeat = 0"):
        load_entry(str(path))
    path.write_text(ENTRY + '[[metrics]]\nkey = "x"\nratio_to = "nobody"\n')
    with pytest.raises(ReproduceError, match="ratio_to 'nobody'"):
        load_entry(str(path))


CLASSES = {"file": "fig8.png", "kind": "speed_classes", "ref": "v_ref", "y": ["v1", "v2"],
           "y_scale": 3.6, "classes": [0, 30, 50, 300], "limit_kmh": 2.0,
           "limit_below_kmh": 30.0, "limit_fraction": 0.02}


def _graded_frame() -> pd.DataFrame:
    """A reference ramp 0 -> 300 km/h; unit 1 is 1.5 km/h fast below 30 km/h (within +-2),
    unit 2 is 0.7 km/h slow from 30 to 40 km/h (beyond 2 % of the speed below 35 km/h) and
    1 % slow above 50 km/h (within 2 %)."""
    import numpy as np

    v_kmh = np.concatenate([[0.0], 0.05 + 0.1 * np.arange(3000)])  # rest, then off the edges
    e1 = np.where(v_kmh <= 30.0, 1.5, 0.0)
    e2 = np.where((v_kmh > 30.0) & (v_kmh <= 40.0), -0.7,
                  np.where(v_kmh > 50.0, -0.01 * v_kmh, 0.0))
    return pd.DataFrame({"v_ref": v_kmh / 3.6, "v1": (v_kmh + e1) / 3.6,
                         "v2": (v_kmh + e2) / 3.6})


def test_speed_classes_grade_the_error_against_ctcs3() -> None:
    """Fig. 8 (seed 001): per class, the max |error| over the units and the CTCS-3 verdict
    per sample (2 km/h at or below 30 km/h, 2 % of the speed above)."""
    rows = {r["class"]: r for r in speed_class_errors(_graded_frame(), CLASSES)}
    tol = 1e-9  # km/h: the m/s round trip of the synthetic speeds
    low, mid, high = rows["0-30"], rows["30-50"], rows["50-300"]
    assert low["max_abs_error"] == pytest.approx(1.5, abs=tol) and low["met"]
    assert low["limit"] == 2.0 and low["samples"] == 300  # v = 0 (at rest) is not graded
    assert mid["max_abs_error"] == pytest.approx(0.7, abs=tol) and not mid["met"]
    assert mid["limit"] == pytest.approx(0.02 * 30.05, abs=tol)  # the class's lowest sample
    assert high["max_abs_error"] == pytest.approx(2.9995, abs=tol) and high["met"]


def test_speed_classes_figure_writes_table_and_csv(tmp_path: Path) -> None:
    text, written = draw_speed_classes(Figure(**CLASSES, paper="A fails at 30"),
                                       {"A": _graded_frame(), "B": _graded_frame()},
                                       tmp_path / "fig8.png")
    assert written == [tmp_path / "fig8.png", tmp_path / "fig8.svg"]
    assert (tmp_path / "fig8.png").stat().st_size > 10_000
    csv = pd.read_csv(tmp_path / "fig8.csv")
    assert len(csv) == 6 and set(csv.run) == {"A", "B"}
    assert "| 30-50 | 0.601 | 0.700 ✗ | 0.700 ✗ |" in text and "Paper: A fails at 30" in text


@pytest.mark.parametrize("spec", [CLASSES, {"file": "track.png", "x": "time",
                                             "y": ["v1", "v_ref"], "reference": ["v_ref"]}],
                         ids=["speed_classes", "overlay"])
def test_page_figure_is_png_and_the_same_svg_on_every_draw(tmp_path: Path,
                                                          spec: dict[str, Any]) -> None:
    """A page figure is drawn as png (the image) with its svg beside it, linked under the image
    as "SVG"; two draws write byte-identical files (no date, the svg's ids fixed), so a
    redrawn page stays current."""
    import numpy as np

    frame = _graded_frame().assign(time=lambda f: 0.1 * np.arange(len(f)))
    pages = {}
    for draw in ("one", "two"):
        out = tmp_path / draw
        out.mkdir()
        lines = figure_section(Figure(**spec), {"A": frame, "B": frame * 1.01}, out, "png", {})
        pages[draw] = "\n".join(lines)
        [image] = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", pages[draw])
        [svg] = re.findall(r"(?<!!)\[SVG\]\(([^)]+)\)", pages[draw])
        assert (image, svg) == (spec["file"], spec["file"].replace(".png", ".svg"))
        assert (out / image).read_bytes().startswith(b"\x89PNG")
        assert b"<svg" in (out / svg).read_bytes() and b"<dc:date>" not in (out / svg).read_bytes()
    assert pages["one"] == pages["two"]
    one = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*"))
    assert one == sorted(p.relative_to(tmp_path / "two") for p in (tmp_path / "two").rglob("*"))
    for rel in one:
        assert (tmp_path / "one" / rel).read_bytes() == (tmp_path / "two" / rel).read_bytes(), rel


def test_figure_series_mean_of_pattern_minus_reference() -> None:
    """``y_reduce = "mean"`` over ``plant.v[*]`` and ``y_minus``: the train-mean speed error
    of seed 002's figure, exactly the mean of the vehicle columns less the reference."""
    from cosim.run.figures import FigureError, figure_series

    frame = pd.DataFrame({"time": [0.0, 1.0], "plant.v[1]": [1.0, 4.0], "plant.v[2]": [3.0, 8.0],
                          "plant.v_tail": [100.0, 100.0], "controller.v_ref": [0.5, 5.0]})
    spec = {"file": "f.png", "y_reduce": "mean", "y_minus": "controller.v_ref"}
    assert figure_series(frame, spec, "plant.v[*]", "A").tolist() == [1.5, 1.0]
    assert figure_series(frame, {"file": "f.png"}, "plant.v[2]", "A").tolist() == [3.0, 8.0]
    with pytest.raises(FigureError, match="run 'A' recorded no 'plant.a'"):
        figure_series(frame, {"file": "f.png"}, "plant.a", "A")
    with pytest.raises(FigureError, match="recorded no 'controller.x'"):
        figure_series(frame, {**spec, "y_minus": "controller.x"}, "plant.v[*]", "A")


def test_reproduce_out_that_cannot_be_written_is_a_clear_error(tmp_path: Path,
                                                               monkeypatch) -> None:
    """--out under a file is refused before any run; a write refused during the run (a folder
    made read-only) names the file and the reason instead of an OSError traceback."""
    from typer.testing import CliRunner

    from cosim import cli
    from cosim.reproduce import page as reproduce_module

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    ran: list[str] = []
    monkeypatch.setattr(reproduce_module, "reproduce", lambda *a, **k: ran.append("run"))
    result = CliRunner().invoke(cli.app, ["reproduce", "seed000", "--out", str(blocker / "x")])
    assert result.exit_code == 2 and not ran
    assert f"--out {blocker / 'x'}: {blocker} is a file, not a folder" in " ".join(
        result.output.split())

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(tmp_path / "ro" / "table.md"))

    monkeypatch.setattr(reproduce_module, "reproduce", refused)
    result = CliRunner().invoke(cli.app, ["reproduce", "seed000", "--out", str(tmp_path / "ro")])
    assert result.exit_code == 2 and result.exception is not None  # typer.Exit, no traceback
    assert isinstance(result.exception, SystemExit)
    assert f"cannot write {tmp_path / 'ro' / 'table.md'}: Permission denied" in " ".join(
        result.output.split())


def test_entry_set_overrides_every_run_and_sweep_and_a_runs_own_set_wins(
        tmp_path: Path) -> None:
    """The entry-level set (the entry's disturbance) reaches every run and every sweep's grid;
    a key a run sets itself keeps the run's value."""
    path = tmp_path / "entry.toml"
    path.write_text('set = { "plant.disturbance_amplitude" = 0.02, "controller.kp" = 50.0 }\n'
                    + ENTRY + '[[sweeps]]\nname = "n"\nscenarios = ["seed000_stop_rmpc"]\n'
                    'grid = { "controller.N" = "3..4" }\n')
    entry = load_entry(str(path))
    plain, kp30 = entry.runs
    assert plain.overrides == {"plant.disturbance_amplitude": 0.02, "controller.kp": 50.0}
    assert kp30.overrides == {"plant.disturbance_amplitude": 0.02, "controller.kp": 30.0}
    assert entry.sweeps[0].grid == {"plant.disturbance_amplitude": 0.02,
                                       "controller.kp": 50.0, "controller.N": "3..4"}
    # the sweep's own key stays first: its figure's x axis
    assert list(entry.sweeps[0].grid)[0] == "controller.N"


def test_sweep_figure_plots_against_the_first_key_and_makes_no_series_of_held_keys() -> None:
    import pandas as pd

    from cosim.run.figures.sweep import draw_sweep

    frame = pd.DataFrame({"scenario": ["a"] * 3 + ["b"] * 3, "controller.N": [3, 4, 5] * 2,
                          "plant.disturbance_amplitude": [0.02] * 6,
                          "stop_error_m": [0.01, 0.02, 0.03, 0.0, 0.01, 0.02],
                          "command_switches": [5, 4, 3, 6, 5, 4],
                          "controller_executions": [10, 9, 8, 7, 6, 5]})
    fig = draw_sweep(frame, ["controller.N", "plant.disturbance_amplitude"])
    ax1 = fig.axes[0]
    assert [ln.get_label() for ln in ax1.get_lines() if not ln.get_label().startswith("_")] == [
        "a", "b"]
    assert list(ax1.get_lines()[0].get_xdata()) == [3, 4, 5]


def test_reproduce_prints_80_columns_and_draws_in_the_chosen_format(built_fmus, tmp_path,
                                                                    capsys) -> None:
    """The console gets ours per run and metric (columns named below the table), where the
    full tables are, and the progress of the runs (stderr); figures in --format."""
    path = tmp_path / "entry.toml"
    path.write_text(ENTRY)
    reproduce(str(path), tmp_path / "out", workers=1, plot_format="svg")
    printed = capsys.readouterr()
    lines = printed.out.splitlines()
    assert lines[0] == "Test entry"
    assert max(len(line) for line in lines if str(tmp_path) not in line) <= 80
    assert "m1 stop error (m); m2 executions.controller" in printed.out
    assert f"full tables in {tmp_path / 'out'}/:\n  table.md, table.csv" in printed.out
    assert "|" not in printed.out  # no raw markdown
    assert "entry runs: 2/2 runs" in printed.err and "ETA" in printed.err
    assert (tmp_path / "out" / "speed.svg").stat().st_size > 0
    assert not (tmp_path / "out" / "speed.png").exists()
    assert "![speed.svg](speed.svg)" in (tmp_path / "out" / "table.md").read_text()


def test_wide_paper_tables_are_split_and_keep_each_metric_together() -> None:
    """Many metrics: several markdown tables of at most TABLE_COLUMNS columns, each led by the
    run column; a metric's ours / paper columns in one table; no "paper" column where the paper
    gives no value for any run."""
    from cosim.reproduce.entry import Entry, Metric, Run
    from cosim.reproduce.tables import TABLE_COLUMNS, Cell, table_markdown

    metrics = [Metric(key=f"m{i}", label=f"metric {i}") for i in range(11)]
    runs = [Run(name=n, scenario="s") for n in ("A", "B")]
    rows = [Cell(run=r.name, metric=m.key, ours=float(i), ours_min=None, ours_max=None,
                 repeats=1, paper=2.0 if i % 3 == 0 else None, paper_range=None,
                 tolerance=None, source="", ratio=None, within=None)
            for r in runs for i, m in enumerate(metrics)]
    entry = Entry(name="e", path=Path("e.toml"), title="t", runs=runs, metrics=metrics)
    text = table_markdown(entry, rows)
    headers = [line for line in text.splitlines() if line.startswith("| run |")]
    assert len(headers) > 1
    cells = [h.strip("| ").split(" | ") for h in headers]
    assert all(len(c) <= TABLE_COLUMNS for c in cells)
    shown = [c for cs in cells for c in cs if c.startswith("metric")]
    assert shown == [m.label for m in metrics]  # each once, in order
    for cs in cells:  # a paper column right after each metric the paper gives, only there
        for i, c in enumerate(cs):
            if c.startswith("metric "):
                given = int(c.split()[1]) % 3 == 0
                assert (i + 1 < len(cs) and cs[i + 1] == "paper") == given
    assert sum(line.startswith("| B |") for line in text.splitlines()) == len(headers)


CLAIMED = ENTRY + """
[ensemble]
seed_key = "plant.disturbance_seed"
report_seeds = "1..3"
calibration_seeds = "101..103"
[[claims]]
id = "pid_stops_in_window"
text = "PID stops within 0.5 m"
metric = "stop_error_m"
kind = "below"
runs = ["PID"]
threshold = 0.5
"""


@pytest.fixture(scope="module")
def claimed_campaign(built_fmus, tmp_path_factory) -> Path:
    """A folder with ``entry.toml`` (:data:`CLAIMED`, its overlay figure drawing "PID" only)
    and ``out/``, what ``reproduce(entry, out, workers=1, seeds=2)`` wrote: run once per
    module; each test works on its own copy (:func:`copy_campaign`)."""
    folder = tmp_path_factory.mktemp("claimed")
    path = folder / "entry.toml"
    path.write_text(CLAIMED.replace("kind = \"overlay\"", "kind = \"overlay\"\nruns = [\"PID\"]"))
    reproduce(str(path), folder / "out", workers=1, seeds=2, echo=False)
    return folder


def copy_campaign(campaign: Path, tmp_path: Path) -> tuple[Path, Path]:
    """(entry.toml, out) of a copy of ``campaign`` in ``tmp_path``: the test's own."""
    import shutil

    shutil.copytree(campaign, tmp_path, dirs_exist_ok=True)
    return tmp_path / "entry.toml", tmp_path / "out"


def test_redraw_makes_the_same_tables_claims_and_figures_from_the_record_alone(
        claimed_campaign: Path, tmp_path: Path, monkeypatch) -> None:
    """Everything after the simulations is a function of the record: redrawn with every
    simulation entry point disabled it is byte for byte what the run wrote; a changed claim
    is re-evaluated on the recorded members; a run the record lacks is named."""
    import cosim.reproduce.members as ensemble
    import cosim.reproduce.page as page
    import cosim.reproduce.run as rep

    path, out = copy_campaign(claimed_campaign, tmp_path)
    made = {f: (out / f).read_bytes() for f in ("table.md", "table.csv", "claims.csv",
                                                "claims.md", "speed.png",
                                                "speed_ensemble.png",
                                                "speed_ensemble.svg")}
    page_text = made["table.md"].decode()
    # the ensemble figure (png shown, svg linked) follows its single run's figure
    assert (page_text.index("(speed.png)") < page_text.index("(speed_ensemble.png)")
            < page_text.index("[SVG](speed_ensemble.svg)"))
    assert "over the claims' 2 report seeds" in page_text
    for f in made:
        (out / f).unlink()

    def no_simulation(*args, **kwargs):
        raise AssertionError("simulated while redrawing")

    monkeypatch.setattr(rep, "_run_one", no_simulation)
    monkeypatch.setattr(ensemble, "_run_member", no_simulation)
    monkeypatch.setattr(page, "simulate", no_simulation)
    redraw_entry(str(path), out, echo=False)
    assert {f: (out / f).read_bytes() for f in made} == made
    path.write_text(path.read_text().replace("threshold = 0.5", "threshold = 1e-9"))
    redraw_entry(str(path), out, echo=False)
    claim = pd.read_csv(out / "claims.csv").iloc[0]
    members = [m for m in json.loads(_record_json(out))["jobs"] if m["kind"] == "member"
               and not m["key"][3]]
    assert len(members) == 2
    assert (claim.verdict == "holds") == all(m["result"]["stop_error_m"] < 1e-9
                                             for m in members)
    path.write_text(path.read_text() + '[[runs]]\nname = "new"\nscenario = "seed000_stop_pid"\n')
    with pytest.raises(ReproduceError, match=r"no run \['new', 0\]"):
        redraw_entry(str(path), out, echo=False)


def _record_json(out: Path) -> str:
    import gzip

    return gzip.decompress((out / "record" / "record.json.gz").read_bytes()).decode()


@pytest.mark.parametrize(("patch", "message"), [
    ('[[statements]]\ntext = "PID stops"\nclaims = ["nope"]\n', "claims: 'nope' is not one"),
    ('[[statements]]\ntext = "PID stops"\n', "give claims = \\[ids\\] or untestable"),
    ('[[statements]]\ntext = "PID stops"\nclaims = ["pid_stops_in_window"]\n'
     'untestable = "x"\n', "one of them"),
    ('[[statements]]\ntext = "x"\nclaims = []\nsee = 1\n', "unknown key 'see' \\(known: "),
    ('[[statements]]\ntext = "PID stops"\nuntestable = "no metric"\nheadline = true\n',
     "headline = true needs claims"),
])
def test_bad_statements_name_the_file_and_key(tmp_path: Path, patch: str, message: str) -> None:
    path = tmp_path / "entry.toml"
    path.write_text(CLAIMED + patch)
    with pytest.raises(ReproduceError, match=message):
        load_entry(str(path))


def test_the_headline_reads_reproduced_only_when_every_claim_holds() -> None:
    """The page's headline line: a statement is reproduced when all its claims hold (adjusted
    verdicts), not reproduced when one fails, undecided otherwise; it names the claims that
    decide it; statements not marked as headline stay out of it."""
    from cosim.reproduce.page import headline_markdown
    from cosim.reproduce.parts import Statement
    from cosim.reproduce.verdicts import ClaimRow

    def row(cid: str, verdict: str, adjusted: str, k: int) -> ClaimRow:
        return claim_row(id=cid, verdict=verdict, adjusted=adjusted, k=k, K=20)

    rows = [row("a", "holds", "holds", 20), row("b", "holds", "inconclusive", 14),
            row("c", "fails", "fails", 0)]
    cases = [(["a"], "**reproduced** (`a` holds 20/20)"),
             (["a", "b"], "**undecided** (`b` inconclusive 14/20)"),
             (["a", "b", "c"], "**not reproduced** (`b` inconclusive 14/20; `c` fails 0/20)")]
    for claims, expected in cases:
        text = headline_markdown([Statement(text="S", claims=claims, headline=True),
                                  Statement(text="T", claims=["c"])], rows)
        assert text == f"**Headline** (the results the paper is about): S: {expected}."
    assert headline_markdown([Statement(text="T", claims=["c"])], rows) == ""


def test_every_shipped_statement_names_claims_or_why_not() -> None:
    """Each paper's statements table: every statement is tested by claims of its entry or
    says why it is not (load_entry refuses anything else), and every paper has one."""
    for name in entry_names():
        entry = load_entry(name)
        assert entry.statements, name
        tested = {c for st in entry.statements for c in st.claims or []}
        assert tested <= {c.id for c in entry.claims}
        assert any(st.headline for st in entry.statements), f"{name}: no headline statement"


def _no_simulation(*args, **kwargs):
    """A simulation entry point that fails: module-level, so a worker process can run it."""
    raise AssertionError("simulated a job the record holds")


def test_resume_runs_only_what_the_record_lacks(claimed_campaign: Path, tmp_path: Path,
                                                 monkeypatch, capsys) -> None:
    """--resume takes every job the folder's record holds (same specification) from it: with
    every simulation entry point disabled the whole entry reproduces byte for byte; a record
    that lost a member gets that member run again and the same claims."""
    import gzip

    import cosim.reproduce.members as ensemble
    import cosim.reproduce.run as rep
    from cosim.reproduce.record import load, save

    path, out = copy_campaign(claimed_campaign, tmp_path)
    made = {f: (out / f).read_bytes() for f in ("table.md", "claims.csv")}
    rec = load(out)
    lost = next(ident for ident, job in rec.jobs.items() if job.kind == "member")
    del rec.jobs[lost], rec.results[lost]
    save(rec, out)
    reproduce(str(path), out, workers=1, seeds=2, echo=False, resume=True)
    assert {f: (out / f).read_bytes() for f in made} == made
    assert lost in load(out).jobs

    monkeypatch.setattr(rep, "_run_one", _no_simulation)
    monkeypatch.setattr(ensemble, "_run_member", _no_simulation)
    reproduce(str(path), out, workers=1, seeds=2, echo=False, resume=True)
    assert {f: (out / f).read_bytes() for f in made} == made
    body = gzip.decompress((out / "record" / "record.json.gz").read_bytes())
    assert b'"seeds": 2' in body
    capsys.readouterr()
    with pytest.raises(ReproduceError, match="simulated a job"):  # K = 3: nothing reused
        reproduce(str(path), out, workers=1, seeds=3, echo=False, resume=True)
    assert "has other K: nothing of it is reused" in capsys.readouterr().err


def test_the_table_runs_are_member_one_of_the_disturbance_ensemble() -> None:
    """A single run of the table takes the first report seed (so it is member 1 of the
    claims' ensemble, and its seed is named on the page); entries without a random input
    add nothing."""
    from cosim.reproduce.members import claim_jobs
    from cosim.reproduce.run import run_jobs, table_seed

    entry = load_entry("seed000")
    key = entry.ensemble.seed_key
    assert table_seed(entry) == {key: entry.ensemble.report_seeds[0]}
    table = {job.key[0]: job.overrides for job in run_jobs(entry)}
    first = {j[0][0]: j[2] for j in claim_jobs(entry, 1, rounding=False)
             if j[0][1] == "disturbance"}
    assert first and all(table[name] == overrides for name, overrides in first.items())
    assert table_seed(load_entry("seed004")) == {}  # no random input


def test_single_run_cells_whose_printed_figure_moves_on_the_rerun_are_marked() -> None:
    """A single-run cell is marked ‡ when the same run on the perturbed floating-point path
    prints another figure; a change below the printed digits is no mark, and a run without
    such a rerun has none to give (None)."""
    from cosim.reproduce.tables import table_markdown, table_rows

    entry = load_entry("seed000")
    keys = [m.key for m in entry.metrics if "." not in m.key]  # flat summary keys
    summaries = {run.name: {k: 0.1234 for k in keys} for run in entry.runs}
    first, second = entry.runs[0].name, entry.runs[1].name
    perturbed = {first: [{k: 0.1234 for k in keys},  # one path moves the 4th digit: marked
                         {k: 0.1236 for k in keys}],
                 second: [{k: 0.123401 for k in keys}]}  # below the printed digits
    rows = table_rows(entry, summaries, perturbed)
    moves = {(r.run, r.metric): r.rounding_moves for r in rows}
    assert all(moves[first, k] is True for k in keys)
    assert all(moves[second, k] is False for k in keys)
    assert all(moves[r.name, k] is None for r in entry.runs[2:] for k in keys)
    text = table_markdown(entry, rows)  # 0.1234 printed 0.123, the rerun's 0.1236 0.124
    assert "0.123‡" in text and "‡: the printed figure moves" in text


def test_fixed_notation_keeps_three_digits_of_the_smallest_magnitude() -> None:
    """One fixed notation per set of numbers: whole numbers without decimals, else enough
    decimals for three significant digits of the smallest non-zero magnitude."""
    from cosim.reproduce.numbers import MAX_DECIMALS, decimals_for, fixed

    assert decimals_for([31130.0, 2.0, 0.0]) == 0
    assert decimals_for([1.518e-4, 0.004643]) == 6  # 0.000152: 3 digits
    assert decimals_for([16.13, 107.0]) == 1
    assert decimals_for([0.5, None, "x", True, float("nan")]) == 3
    assert decimals_for([1e-30]) == MAX_DECIMALS
    assert [fixed(v, 6) for v in (1.518e-4, 0.004643)] == ["0.000152", "0.004643"]
    assert fixed(31130.0, 0) == "31130" and fixed(-1e-9, 3) == "0.000"
    assert fixed(float("nan"), 2) == "-"


def test_fixed_notation_at_and_just_below_powers_of_ten() -> None:
    """At an exact power of ten, just below it (printed as that power) and at values rounding
    up to it, :func:`number` prints exactly three significant digits: the exponent comes from
    the printed digits, not from log10's last bit."""
    import math

    from cosim.reproduce.numbers import decimals_for, number

    def significant(text: str) -> int:
        return len(text.replace("-", "").replace(".", "").lstrip("0"))

    for k in range(-6, 0):  # 1e-6 needs 8 decimals: within MAX_DECIMALS
        power = float(f"1e{k}")
        for value in (power, math.nextafter(power, 0.0), power * 0.9996, power * 0.9994,
                      -power):
            assert significant(number(value)) == 3, (value, number(value))
    assert decimals_for([0.001]) == 5 and number(0.001) == "0.00100"
    assert number(math.nextafter(0.001, 0.0)) == "0.00100"
    assert number(9.996e-4) == "0.00100" and number(9.994e-4) == "0.000999"


def test_single_run_columns_have_one_fixed_notation_each() -> None:
    """Each metric's column of the single-run table prints every value with the same
    decimals, never in scientific notation, whatever the magnitudes of the runs."""
    from cosim.reproduce.tables import table_markdown, table_rows

    entry = load_entry("seed000")
    keys = [m.key for m in entry.metrics if "." not in m.key]
    magnitudes = [3.113e4, 1.518e-4, 2.0, 0.5, 12.25]
    summaries = {run.name: {k: magnitudes[i % len(magnitudes)] * (1 + i) for k in keys}
                 for i, run in enumerate(entry.runs)}
    text = table_markdown(entry, table_rows(entry, summaries))
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    body = [[c.strip() for c in line.strip("|").split("|")] for line in lines[1:]]
    assert "e+" not in text and "e-" not in text
    for key in keys:
        label = next(m.heading for m in entry.metrics if m.key == key)
        column = [re.match(r"-?\d+(\.\d+)?", row[header.index(label)]) for row in body
                  if row[0] in summaries]
        places = {len(m.group(1) or ".") - 1 for m in column}
        assert places == {6}, (key, column)  # 0.000152: 3 digits of the smallest


def test_the_native_build_runs_each_fmu_that_has_a_native_model() -> None:
    """--build native: NAME.build = "native" for the FMUs with a native model, never over a
    build the run sets itself; the Python FMUs of the others; a clear error otherwise."""
    from cosim.reproduce.builds import build_overrides
    from cosim.reproduce.run import run_jobs, sweep_jobs

    assert build_overrides("seed000_stop_rsmpc", {}, "native") == {
        "plant.build": "native", "controller.build": "native"}
    assert build_overrides("seed000_stop_rsmpc", {}, "python") == {}
    assert build_overrides("seed000_stop_rsmpc", {"controller.build": "python"},
                           "native") == {"plant.build": "native"}
    # seed 003's GPC has a native model, its LMI MPC none: the plant alone
    assert build_overrides("seed003_crh3_gpc_eco", {}, "native") == {
        "plant.build": "native", "controller.build": "native"}
    assert build_overrides("seed003_crh3_lmimpc_eco", {}, "native") == {
        "plant.build": "native"}
    with pytest.raises(ReproduceError, match="--build fast: one of native, python"):
        build_overrides("seed000_stop_rsmpc", {}, "fast")
    entry = load_entry("seed000")
    native = {j.key: j.overrides for j in run_jobs(entry, "native")}
    python = {j.key: j.overrides for j in run_jobs(entry, "python")}
    for key, over in native.items():  # the same job with the builds added
        assert {k: v for k, v in over.items() if not k.endswith(".build")} == python[key]
        assert over["plant.build"] == "native"
    [sweep] = sweep_jobs(entry, "native")
    assert list(sweep.overrides)[0] == "controller.N"  # the figure's axis stays first
    assert sweep.overrides["plant.build"] == "native"


def test_a_native_rounding_rerun_needs_a_perturbed_parameter(tmp_path: Path) -> None:
    """A native FMU has no numpy reference path: without [ensemble] rounding_perturb its
    rounding rerun would repeat the main run, so it is refused, naming the key."""
    from dataclasses import replace

    from cosim.reproduce.members import claim_jobs

    shipped = load_entry("seed002")
    entry = replace(shipped, ensemble=replace(shipped.ensemble, rounding_perturb=[]))
    with pytest.raises(ReproduceError, match=r"\[ensemble\] rounding_perturb: empty"):
        claim_jobs(entry, 2, rounding=True, build="native")
    assert claim_jobs(entry, 2, rounding=False, build="native")  # no rerun: nothing to refuse
    jobs = claim_jobs(load_entry("seed000"), 2, rounding=True, build="native")
    for path, key in ((1, "plant.v0"), (2, "plant.mass")):  # each path its own parameter
        reruns = [ov for k, _sc, ov in jobs if k[3] == path]
        assert reruns and all(ov["plant.build"] == "native" and key in ov for ov in reruns)


@pytest.mark.slow
def test_a_native_campaign_gives_the_python_campaigns_verdicts(tmp_path: Path) -> None:
    """Seed 002's claims at K = 2 on the native builds (plant and every controller in C) and
    on the Python builds: the same verdicts and members on the claimed side."""
    from cosim.reproduce.verdicts import run_claims

    entry = load_entry("seed002")
    rows = {build: run_claims(entry, tmp_path / build, 2, workers=2, rounding=False,
                              build=build) for build in ("native", "python")}
    assert [(r.claim.id, r.verdict, r.main.k) for r in rows["native"]] == [
        (r.claim.id, r.verdict, r.main.k) for r in rows["python"]]


def test_each_table_run_writes_what_the_record_reads_unless_all_is_asked(
        built_fmus, tmp_path: Path) -> None:
    """``--run-files figures`` (the default): a run a figure draws keeps its results.csv (the
    record's series are read from it), a run no figure draws and every later repetition only
    its summary.json, no run its plot; ``all``: every run's files as ``cosim run`` writes
    them. The table is the same either way."""
    path = tmp_path / "entry.toml"
    path.write_text(ENTRY.replace('set = { "controller.kp" = 30.0 }',
                                  'set = { "controller.kp" = 30.0 }\nrepeat = 2')
                    + 'runs = ["PID"]\n')  # the figure draws "PID" only
    reproduce(str(path), tmp_path / "lean", workers=1)
    files = {p.relative_to(tmp_path / "lean" / "runs").as_posix()
             for p in (tmp_path / "lean" / "runs").rglob("*") if p.is_file()}
    assert files == {"pid/results.csv", "pid/results.units.json", "pid/summary.json",
                     "pid_kp_30/summary.json", "pid_kp_30/repeat_02/summary.json"}
    reproduce(str(path), tmp_path / "all", workers=1, run_files="all")
    for run in ("pid", "pid_kp_30", "pid_kp_30/repeat_02"):
        assert {p.name for p in (tmp_path / "all" / "runs" / run).iterdir() if p.is_file()} \
            == {"results.csv", "results.units.json", "summary.json", "plot.png"}
    lean, full = (pd.read_csv(tmp_path / out / "table.csv") for out in ("lean", "all"))
    measured = lean.metric.str.startswith(MEASURED_PREFIXES)
    pd.testing.assert_frame_equal(lean[~measured], full[~measured], check_exact=True)
    with pytest.raises(ReproduceError, match="--run-files every: one of figures, all"):
        reproduce(str(path), tmp_path / "bad", workers=1, run_files="every")


def _lean_cases() -> list[tuple[str, str]]:
    """(entry, run) of each distinct scenario the shipped entries' table runs use (its first
    run)."""
    seen: dict[str, tuple[str, str]] = {}
    for name in entry_names():
        for run in load_entry(name).runs:
            seen.setdefault(run.scenario, (name, run.name))
    return sorted(seen.values())


@pytest.mark.slow
@pytest.mark.parametrize(("entry", "run"), _lean_cases())
def test_a_run_recording_only_what_its_summary_reads_gives_the_same_summary(
        entry: str, run: str) -> None:
    """A table run or claim member that records only what its summary reads
    (:func:`cosim.reproduce.members.member_scenario`, how the campaigns run them) gives the
    summary of the same run recording every ``[record]`` variable, bit for bit but for the
    measured times: every metric, the paper's plug-ins among them, finds what it reads."""
    from cosim.reproduce.builds import build_overrides
    from cosim.reproduce.members import member_scenario
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import ensure_built

    spec = next(r for r in load_entry(entry).runs if r.name == run)
    overrides = {**build_overrides(spec.scenario, spec.overrides, load_entry(entry).build),
                 **spec.overrides}
    sc = load_scenario(spec.scenario, overrides)
    ensure_built(sc)
    full = run_scenario(sc, build=False, plot=False).summary
    lean = run_scenario(member_scenario(sc), build=False, plot=False).summary
    def results(summary: dict[str, Any]) -> str:  # NaN equals NaN, every float by its repr
        return json.dumps({k: v for k, v in summary.items()
                           if not k.startswith(MEASURED_PREFIXES)}, sort_keys=True, default=repr)

    assert results(lean) == results(full)


def _without_measured(value: Any, columns: list[str] | None = None) -> Any:
    """``value`` (a summary, or a sweep's rows under ``columns``) without the measured times,
    as JSON text in which NaN equals NaN and each float is its repr."""
    if columns is not None:  # a sweep: rows of cells
        keep = [i for i, c in enumerate(columns) if not c.startswith(MEASURED_PREFIXES)]
        value = [[row[i] for i in keep] for row in value]
    elif isinstance(value, dict):
        if "columns" in value and "rows" in value:
            return _without_measured(value["rows"], value["columns"])
        value = {k: v for k, v in value.items() if not k.startswith(MEASURED_PREFIXES)}
    return json.dumps(value, sort_keys=True, default=repr)


@pytest.mark.slow
def test_a_small_k_campaign_gives_the_published_records_results_job_for_job(
        tmp_path: Path) -> None:
    """The published page's record (``docs/papers/seed000/record/``, K = 20) was made by the
    code of its commit; this tree's campaign at K = 2 with both rounding paths gives every job
    both records hold (every table run, the sweep, the first two members of every claim on
    every path) the same result bit for bit, the measured times left out, and its table
    (every metric but the measured ones) equals the one redrawn from the published record.
    Skipped only where the page is not current (`cosim docs --check` fails then)."""
    import shutil

    from cosim.reproduce.record import load
    from cosim.run.provenance import simulation_digest

    published = Path(__file__).resolve().parent.parent / "docs" / "papers" / "seed000"
    before = load(published)
    if before.simulation != simulation_digest("seed000", before.build):
        pytest.skip("the seed000 page was made from other simulation inputs")
    reproduce("seed000", tmp_path / "now", seeds=2, echo=False)
    now = load(tmp_path / "now")
    assert now.build == before.build
    common = now.jobs.keys() & before.jobs.keys()
    assert len(common) == len(now.jobs)  # every job of K = 2 is one of K = 20's
    differ = [ident for ident in sorted(common, key=repr)
              if _without_measured(now.results[ident]) != _without_measured(
                  before.results[ident])]
    assert not differ, differ[:5]
    shutil.copytree(published / "record", tmp_path / "published" / "record")
    redraw_entry("seed000", tmp_path / "published")
    tables = [pd.read_csv(tmp_path / out / "table.csv") for out in ("now", "published")]
    kept = [t[~t.metric.str.startswith(MEASURED_PREFIXES)].reset_index(drop=True)
            for t in tables]
    pd.testing.assert_frame_equal(kept[0], kept[1], check_exact=True)
