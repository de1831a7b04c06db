"""Python entry point: the runs of the ``cosim`` CLI, for a user who prefers code.

```python
from cosim import api

scenario = api.load("seed000_stop_pid", {"simulation.stop_time": 45.0})
run = api.run(scenario)     # builds the FMUs it needs, as `cosim run`
run.frame.head()            # the recorded signals
run.units["plant.v"]        # "m/s": the unit the FMU declares
run.with_units().head()     # columns (variable, unit)
run.summary["stop_error_m"] # the metrics of summary.json
run.save("out")             # results.csv, results.units.json, summary.json, plot.png
api.read_results("out")     # results.csv again, its units in .attrs["units"]
fig = run.figure()          # the figure of `cosim run` (plot.png)
other = api.run("seed000_stop_rmpc")
api.compare({"PID": run, "RMPC": other})  # metrics side by side
```

Each function calls what ``cosim run`` calls (``cosim.run.scenario``,
``cosim.run.master``, ``cosim.run.results``), so a run here and the same run from the
command line give the same results, summary and figure. Units and descriptions come from the
FMUs' modelDescriptions (``cosim.run.columns.variable_info``), which the FMUs derive from
their cores' declarations.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import pandas as pd

from cosim.cli import summary_rows
from cosim.run.columns import column_info
from cosim.run.figures.run import draw_run
from cosim.run.master import ProgressFn, RunResult
from cosim.run.results import PLOT_FORMATS, UNITS_FILE, write_results
from cosim.run.scenario import Scenario, load_scenario, scenario_files
from cosim.run.simulate import ensure_built, run_scenario

__all__ = ["Run", "build", "compare", "load", "read_results", "run", "scenarios"]

Overrides = Mapping[str, Any] | Sequence[str]


def scenarios() -> list[str]:
    """The names of the shipped scenarios (``scenarios/*.toml`` and each paper's
    ``papers/*/scenarios/*.toml``), as ``cosim list`` shows."""
    return list(scenario_files())


def load(scenario: str | Path, overrides: Overrides | None = None) -> Scenario:
    """A scenario by name (``"seed000_stop_pid"``) or path, with overrides applied as
    ``cosim run --set`` applies them: keys ``NAME.parameter``, ``NAME.inputs.VAR``,
    ``NAME.sample_time`` (and the other component keys), ``simulation.KEY``, ``summary.KEY``.

    ``overrides`` is a mapping of keys to Python values (``{"plant.mass": 539000.0}``) or a
    sequence of ``--set`` texts (``["plant.mass=539000"]``, each value read as a TOML literal).
    Raises ``cosim.run.scenario.ScenarioError`` naming the file, the key and, for a bad
    override, the override."""
    return load_scenario(scenario, overrides)


def build(scenario: str | Path | Scenario) -> list[Path]:
    """Build the scenario's FMUs that are missing or older than their sources (into
    ``fmus/``, in the scenario's FMI version); the paths built. ``run`` does this
    itself."""
    return ensure_built(scenario if isinstance(scenario, Scenario) else load(scenario))


def run(scenario: str | Path | Scenario, overrides: Overrides | None = None, *,
        algorithm: str | None = None, out_dir: str | Path | None = None, plot: bool = True,
        plot_format: str = "png", progress: ProgressFn | None = None) -> Run:
    """Run a scenario (a name, a path, or one from ``load``) as ``cosim run`` does:
    build the FMUs it needs, co-simulate, compute the summary and, with ``out_dir``, write
    results.csv, summary.json and (``plot``) the plot there.

    ``overrides`` as in ``load`` (with a name or path only: a loaded scenario has its
    own); ``algorithm``: ``"event"``, ``"fixed"`` or ``"jacobi"`` in place of the scenario's;
    ``progress(t, stop_time)`` is called as the run advances. Raises
    ``cosim.run.scenario.ScenarioError`` for a scenario that cannot run and
    ``cosim.run.master.SimulationError`` for a failure during the run (after writing
    the partial results to ``out_dir``)."""
    if isinstance(scenario, Scenario) and overrides:
        raise ValueError("overrides go with a scenario name or path; a loaded scenario has "
                         "its own (api.load(name, overrides))")
    if plot_format not in PLOT_FORMATS:
        raise ValueError(f"plot format {plot_format!r}: one of {', '.join(PLOT_FORMATS)}")
    return Run(run_scenario(scenario, overrides=overrides, algorithm=algorithm,
                            out_dir=out_dir, progress=progress, plot=plot,
                            plot_format=plot_format))


@dataclass
class Run:
    """One finished run: the recorded signals, their units and descriptions, the summary
    metrics and the standard figure."""

    result: RunResult

    @property
    def scenario(self) -> Scenario:
        """The scenario as run (overrides applied)."""
        return self.result.scenario

    @property
    def name(self) -> str:
        """The scenario's name."""
        return self.result.scenario.name

    @property
    def summary(self) -> dict[str, Any]:
        """The metrics ``cosim run`` writes to summary.json (see ``cosim.run.metrics``)."""
        return self.result.summary

    @property
    def frame(self) -> pd.DataFrame:
        """The recorded signals: column ``time`` (s), then one column per recorded
        ``instance.variable`` in the FMU's declared unit (the table of results.csv). The
        units are also in ``frame.attrs["units"]``."""
        frame = self.result.frame
        frame.attrs["units"] = self.units
        return frame

    @cached_property
    def variables(self) -> pd.DataFrame:
        """Per recorded column: its description and declared unit (None where the FMU
        declares none), read from the FMUs' modelDescriptions."""
        rows = column_info(self.scenario, self.result.frame.columns)
        return pd.DataFrame.from_dict(rows, orient="index", columns=["description", "unit"])

    @property
    def units(self) -> dict[str, str | None]:
        """Column name to declared unit (``"plant.v"`` -> ``"m/s"``)."""
        return {column: (unit if isinstance(unit, str) else None)
                for column, unit in self.variables["unit"].items()}

    def with_units(self) -> pd.DataFrame:
        """``frame`` with two-level columns (variable, unit); ``""`` for no unit."""
        frame = self.result.frame.copy()
        frame.columns = pd.MultiIndex.from_tuples(
            [(column, self.units.get(column) or "") for column in frame.columns],
            names=["variable", "unit"])
        return frame

    def figure(self) -> Any:
        """The standard run figure (a matplotlib Figure), the one ``cosim run`` saves as
        plot.png: speed and reference against position with the command, coupler forces when
        the scenario names them, else the outputs against time."""
        return draw_run(self.result)

    def save(self, out_dir: str | Path, plot: bool = True, plot_format: str = "png"
             ) -> list[Path]:
        """Write results.csv, its units (results.units.json), summary.json and the plot into
        ``out_dir``, as ``cosim run --out`` does; the paths written. ``read_results(out_dir)``
        reads the table back with its units."""
        return write_results(self.result, Path(out_dir), plot=plot, plot_format=plot_format)


def read_results(folder: str | Path) -> pd.DataFrame:
    """The ``results.csv`` of a run folder (``cosim run --out``, ``Run.save``) as a
    DataFrame, every float bit for bit, with its units (column -> declared unit, None where
    none) in ``frame.attrs["units"]`` from ``results.units.json`` when the folder has one
    (``{}`` otherwise)."""
    import json

    folder = Path(folder)
    frame = pd.read_csv(folder / "results.csv")
    sidecar = folder / UNITS_FILE
    frame.attrs["units"] = (json.loads(sidecar.read_text(encoding="utf-8"))
                            if sidecar.exists() else {})
    return frame


def compare(runs: Mapping[str, Run] | Sequence[Run],
            metrics: Sequence[str] | None = None) -> pd.DataFrame:
    """The runs' summary metrics side by side: a row per metric, a column per run (labelled
    by the mapping's keys, else by scenario name). ``metrics`` picks the rows; by default the
    metrics ``cosim run`` prints, in its order, that any of the runs has. A metric holding a
    value per FMU (``executions``) gives a row per FMU (``executions.controller``); a run
    without a metric shows NaN."""
    if isinstance(runs, Mapping):
        labelled = list(runs.items())
    else:
        labelled = []
        for i, one in enumerate(runs):
            label = one.name
            if any(label == seen for seen, _ in labelled):
                label = f"{label} ({i})"
            labelled.append((label, one))
    if metrics is None:
        metrics = []
        for _, one in labelled:
            metrics += [key for key, _ in summary_rows(one.summary) if key not in metrics]
    table: dict[str, dict[str, Any]] = {}
    for label, one in labelled:
        column: dict[str, Any] = {}
        for key in metrics:
            value = one.summary.get(key)
            if isinstance(value, dict):
                column.update({f"{key}.{sub}": v for sub, v in value.items()})
            elif value is not None:
                column[key] = value
        table[label] = column
    rows: list[str] = []
    for column in table.values():
        rows += [key for key in column if key not in rows]
    return pd.DataFrame(table, index=rows, columns=[label for label, _ in labelled])
