"""Train-mean speed observer of the freight speed controllers (seed 002)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers.common.freight_blending import FreightTracker
from controllers.preview.preview import FreightPreview, PreviewParams
from plants.freight import FreightParams
from plants.route import load_route
from tests.freight_loop import closed_loop

KMH = 3.6


@pytest.fixture(scope="module")
def route():
    return load_route("freight_20km")


def _observer_run(route, params: FreightParams | None = None) -> tuple[np.ndarray, ...]:
    core = FreightPreview(PreviewParams(mean_weight=0.7), route.reference, route)  # t_c = 45 s
    run = closed_loop(core, route, 1400.0, params=params, extra=("v_mean_estimate",))
    moving = run["s"] < 19950.0
    err = KMH * (run["v_mean_estimate"] - run["v_mean"])[moving]
    return err, KMH * (run["v"] - run["v_mean"])[moving], run["s"][-1]


def test_observer_tracks_the_plants_mean_speed_on_the_closed_loop(route) -> None:
    """Whole freight_20km run (plant core at 0.01 s, 109 vehicles, stretch modes, the planned
    air-brake stop) with the blend w = 0.7, t_c = 45 s: the observer follows the plant's
    (m (1 + gamma)-weighted) mean speed within 0.2 km/h, 0.07 rms, while the head differs
    from the mean by more than 0.3 km/h (the stretch modes and the start's stretch rate,
    which the observer must not follow)."""
    err, head, stop = _observer_run(route)
    assert np.abs(err).max() < 0.2
    assert np.sqrt(np.mean(err**2)) < 0.07
    assert np.abs(head).max() > 0.3
    assert stop == pytest.approx(20000.0, abs=2.0)  # still stops at the stop point


def test_observer_does_not_drift_with_a_resistance_error(route) -> None:
    """The plant's wagon resistance 30 % above the observer's nominal one (a bias of about
    5e-3 m/s^2 at cruise): the bias state takes it up, the estimate stays within 0.35 km/h,
    0.1 rms (a correction on the speed alone would leave t_c times the bias)."""
    base = FreightParams()
    plant = replace(base, wagon_resistance=tuple(1.3 * c for c in base.wagon_resistance))
    err, _, _ = _observer_run(route, plant)
    assert np.abs(err).max() < 0.35
    assert np.sqrt(np.mean(err**2)) < 0.1


class _Today(FreightPreview):
    """The preview controller without the observer's path: the head speed fed back."""

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        self.v_feedback = float(inputs["v"])
        FreightTracker._track(self, t, self.v_feedback, float(inputs["s"]))
        return self.outputs(), 1


def test_mean_weight_zero_is_todays_head_feedback_exactly(route) -> None:
    """w = 0: every command of a closed-loop run from 17 km through the planned air-brake stop
    is bit-identical to the controller fed the head speed with no observer, whatever the
    observer's correction time."""
    runs = []
    for core in (_Today(PreviewParams(mean_weight=0.0), route.reference, route),
                 FreightPreview(PreviewParams(mean_weight=0.0, observer_correction_time=5.0),
                                route.reference, route)):
        runs.append(closed_loop(core, route, 120.0, s0=18000.0,
                                v0=route.reference.speed(18000.0)))
    assert np.any(runs[0]["pipe_reduction"] > 0)
    for name in ("force_demand", "pipe_reduction", "v", "v_mean"):
        assert np.array_equal(runs[0][name], runs[1][name]), name


def test_fed_back_speed_is_the_blend(route) -> None:
    """The servo's speed is (1 - w) v_head + w v_mean; the observer starts at the head speed
    and then moves from it by its own force balance."""
    core = FreightPreview(PreviewParams(mean_weight=0.25), route.reference, route)
    core.compute(0.0, {"v": 10.0, "s": 1000.0})
    assert core.observer.speed == 10.0 and core.v_feedback == 10.0
    core.compute(0.2, {"v": 11.0, "s": 1002.0})
    v_mean = core.observer.speed
    assert v_mean != 11.0
    # the same IEEE operations as the core (1 - 0.25 is exact): equal on any CPU
    assert core.v_feedback == (1.0 - 0.25) * 11.0 + 0.25 * v_mean
    assert core.outputs()["v_mean_estimate"] == v_mean


def test_observer_needs_a_positive_correction_time(route) -> None:
    with pytest.raises(ValueError, match="correction_time"):
        FreightPreview(PreviewParams(observer_correction_time=0.0), route.reference, route)
    with pytest.raises(ValueError, match="mean_weight"):
        FreightPreview(PreviewParams(mean_weight=1.5), route.reference, route)
