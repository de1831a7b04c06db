"""Console tables (cosim/run/console.py): no line longer than the width, nothing cut but the
key column, the shared prefix of the names stated once, blocks that repeat the key column."""

from __future__ import annotations

from cosim.run.console import cell, fit_table
from cosim.run.runner import Progress


def test_wide_tables_are_split_into_blocks_that_fit():
    columns = ["run", *(f"metric_{i}" for i in range(12))]
    rows = [{"run": f"seed009_{name}", **{c: 1234.5678 * (i + 1) for i, c in
                                            enumerate(columns[1:])}}
            for name in ("alpha", "beta_long_name")]
    text = fit_table(rows, columns, width=80)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 80
    assert lines[0] == "(run: seed009_...)"
    for c in columns[1:]:  # every column is shown, under its full header
        assert sum(c in line.split() for line in lines) == 1
    headers = [line for line in lines if line.startswith("run ")]
    assert len(headers) >= 2  # split, the key column repeated
    assert sum(line.startswith("beta_long_name") for line in lines) == len(headers)
    assert "1235" in text and "1.481e+04" in text  # 4 significant digits


def test_cells_and_progress_line():
    assert [cell(None), cell(float("nan")), cell(3.0), cell(-0.0123456, True), cell(True)] == \
        ["-", "-", "3", "-0.01235", "yes"]
    progress = Progress(4, "claims", quiet=True)
    assert progress.line().endswith("0/4 runs, 0 s elapsed, ETA ?")
    progress.step()
    assert "1/4 runs" in progress.line() and "ETA" in progress.line()
