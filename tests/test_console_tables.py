"""Console tables (cosim/run/console.py): no line longer than the width, nothing cut but the
key column, the shared prefix of the names stated once, blocks that repeat the key column."""

from __future__ import annotations

import math

from cosim.run.console import cell, column_cells, decimal_exponent, fit_table
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
    assert "1235" in text and "14815" in text  # 4 significant digits on the largest


def test_cells_and_progress_line():
    assert [cell(None), cell(float("nan")), cell(3.0), cell(-0.0123456, True), cell(True)] == \
        ["-", "-", "3", "-0.01235", "yes"]
    progress = Progress(4, "claims", quiet=True)
    assert progress.line().endswith("0/4 runs, 0 s elapsed, ETA ?")
    progress.step()
    assert "1/4 runs" in progress.line() and "ETA" in progress.line()


def test_each_column_has_one_notation():
    """Integers as integers, fixed decimals per column (4 significant digits on its largest
    value), scientific only for a column fixed-point cannot show; never mixed in a column."""
    assert column_cells([440000, 539000]) == ["440000", "539000"]
    assert column_cells([0.1504, -2.945e-05, 0.257, None], signed=True) == \
        ["+0.1504", "-0.0000", "+0.2570", "-"]
    assert column_cells([89.03, 100.0, 0]) == ["89", "100", "0"]
    assert column_cells([0.5, 0.55]) == ["0.50", "0.55"]  # no zeros every value has
    assert column_cells([2.5e-5, 3e-6]) == ["2.500e-05", "3.000e-06"]
    assert column_cells([3, 7], signed=True) == ["+3", "+7"]
    rows = [{"run": "a", "mass": 440000, "err": 0.1504}, {"run": "b", "mass": 539000,
                                                          "err": -2.945e-05}]
    text = fit_table(rows, ["run", "mass", "err"], signed=["err"])
    assert "e+05" not in text and "e-05" not in text
    assert text.splitlines()[-1].split() == ["b", "539000", "-0.0000"]


def test_decimal_exponent_is_the_printed_one_at_and_below_powers_of_ten():
    """The exponent is the one Python prints: exact at every power of ten (no log10 rounding),
    the next power's for a value that rounds up to it, its own just below that."""
    for k in range(-12, 13):
        power = float(f"1e{k}")
        assert decimal_exponent(power, 3) == k
        assert decimal_exponent(math.nextafter(power, 0.0), 3) == k  # prints 1.00e{k}
        assert decimal_exponent(-power, 4) == k
    assert decimal_exponent(9.996e-4, 3) == -3  # 1.00e-03
    assert decimal_exponent(9.994e-4, 3) == -4  # 9.99e-04
    assert decimal_exponent(9.9996e-4, 4) == -3 and decimal_exponent(9.9994e-4, 4) == -4


def test_column_notation_at_the_edges_of_fixed_point():
    """A column whose largest value prints as 1.000e-03 is fixed-point (it lies in the fixed
    range as printed), one that prints 9.999e-04 or 1.000e+06 is scientific."""
    assert column_cells([0.001]) == ["0.001"]
    assert column_cells([math.nextafter(0.001, 0.0)]) == ["0.001"]
    assert column_cells([9.9996e-4]) == ["0.001"]
    assert column_cells([9.999e-4]) == ["9.999e-04"]
    assert column_cells([999999.9]) == ["1.000e+06"]


def test_every_block_repeats_every_key_column():
    """Rows that differ only in a grid value stay apart in every block."""
    columns = ["scenario", "N", *(f"metric_{i}" for i in range(12))]
    rows = [{"scenario": "seed000_stop_rmpc", "N": n, **{c: 0.5 * n for c in columns[2:]}}
            for n in (5, 10)]
    lines = fit_table(rows, columns, keys=2, width=80).splitlines()
    headers = [i for i, line in enumerate(lines) if line.startswith("scenario")]
    assert len(headers) >= 2
    for i in headers:
        assert lines[i].split()[:2] == ["scenario", "N"]
        assert [line.split()[1] for line in lines[i + 2:i + 4]] == ["5", "10"]
