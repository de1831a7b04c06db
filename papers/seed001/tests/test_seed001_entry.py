"""Seed 001's entry declares the paper's figures (Figs. 6-10, Fig. 8 graded by CTCS-3)."""

from __future__ import annotations

import re

from cosim.reproduce.entry import load_entry


def test_seed001_declares_figures_6_to_10() -> None:
    """Figs. 6-10 of seed 001, Fig. 8 graded by CTCS-3 as data (2 km/h, 30 km/h, 2 %)."""
    figs = {re.match(r"fig(\d+)_", f.file).group(1): f for f in load_entry("seed001").figures}
    assert sorted(figs, key=int) == ["6", "7", "8", "9", "10"]
    fig8 = figs["8"]
    assert fig8.kind == "speed_classes" and (fig8.classes or [])[:3] == [0, 30, 50]
    assert (fig8.limit_kmh, fig8.limit_below_kmh, fig8.limit_fraction) == (2.0, 30.0, 0.02)
