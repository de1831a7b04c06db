"""Seed 002's entry judges the speed target on the train-mean speed and draws its error."""

from __future__ import annotations

from cosim.reproduce.entry import load_entry


def test_seed002_plots_the_train_mean_error() -> None:
    """The 0.3 km/h target is judged on the train-mean speed; its error is a figure."""
    figs = [f for f in load_entry("seed002").figures if f.y_reduce == "mean"]
    assert [(f.y, f.y_minus) for f in figs] == [(["plant.v[*]"], "controller.v_ref")]
