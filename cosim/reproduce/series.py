"""What a reproduction's record keeps of a run's table for the figures (the series), and the
loaded scenarios of an entry's runs the series are read against."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cosim.reproduce.entry import Entry, Figure
from cosim.reproduce.record import Record, read_csv
from cosim.run.figures import figure_columns
from cosim.run.metrics import matching_columns
from cosim.run.scenario import Scenario, load_scenario

MEMBER_ROWS = 2000  # rows of a member's series at most: the ensemble bands, evenly thinned


def record_series(record: Record, name: str, folder: Path, figures: list[Figure],
                  scenario: Any, scalars: bool = True, max_rows: int | None = None) -> None:
    """Keep of ``folder/results.csv`` as series ``name`` what ``figures`` draw: the columns they
    read, a ``y_reduce`` pattern (``plant.v[*]``) as one column of that name holding the
    reduction (not every vehicle's column), with ``scalars`` every column of one value per
    train too (no ``[i]`` index), and with ``max_rows`` evenly thinned rows (the last kept)."""
    path = folder / "results.csv"
    columns = list(pd.read_csv(path, nrows=0).columns)
    header = pd.DataFrame(columns=columns)
    keep = {c for c in columns if "[" not in c} if scalars else set()
    patterns: dict[str, list[str]] = {}
    for spec in (f.spec() for f in figures):
        if "y_reduce" in spec:
            keep |= figure_columns({**spec, "y": []}, scenario, columns)
            ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
            for y in ys:
                patterns[y] = matching_columns(header, y)
        else:
            keep |= figure_columns(spec, scenario, columns)
    wanted = keep.union(*patterns.values())
    frame = read_csv(path, usecols=[c for c in columns if c in wanted])
    reduced = pd.DataFrame({pattern: frame[cols].to_numpy(dtype=float).mean(axis=1)
                            for pattern, cols in patterns.items()},  # y_reduce = "mean"
                           index=frame.index)
    frame = pd.concat([frame[[c for c in frame.columns if c in keep]], reduced], axis=1)
    if max_rows is not None and len(frame) > max_rows:
        step = -(-len(frame) // max_rows)
        rows = np.unique(np.r_[np.arange(0, len(frame), step), len(frame) - 1])
        frame = frame.iloc[rows].reset_index(drop=True)
    record.series[name] = frame


def run_scenarios(entry: Entry) -> dict[str, Scenario]:
    """Run name -> its loaded scenario (with the run's ``set``)."""
    return {r.name: load_scenario(r.scenario, r.overrides) for r in entry.runs}
