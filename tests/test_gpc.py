"""GPC with RLS (controllers/common/gpc.py): identification and zero steady-state error."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.common.gpc import Gpc, GpcParams


def _run(gpc: Gpc, A: np.ndarray, B: np.ndarray, c: np.ndarray, refs: np.ndarray,
         noise: float = 0.0) -> np.ndarray:
    """ARX plant ``y(t+1) = A y(t) + B u(t) + c`` under GPC; returns y over time."""
    rng = np.random.default_rng(0)
    y = np.zeros(A.shape[0])
    out = []
    for r in refs:
        gpc.observe(y)
        u = gpc.control(np.tile(r, (gpc.p.Ny, 1)))
        y = A @ y + B @ u + c + noise * rng.normal(size=y.shape)
        out.append(y)
    return np.array(out)


@pytest.mark.parametrize("forgetting", [0.9, 1.0])
def test_tracks_a_known_arx_plant_with_zero_steady_error(forgetting: float) -> None:
    """2x2 coupled ARX plant with a constant load c, references stepping twice: the
    incremental model gives integral action, so the error goes to zero (to the round-off
    of the RLS update, ~1e-12 measured; 1e-8 allowed)."""
    A = np.array([[0.9, 0.05], [0.02, 0.8]])
    B = np.array([[0.2, 0.05], [0.03, 0.3]])
    c = np.array([0.5, -0.3])
    refs = np.array([[5.0, 2.0]] * 200 + [[3.0, 4.0]] * 200)
    gpc = Gpc(GpcParams(forgetting=forgetting), 2)
    y = _run(gpc, A, B, c, refs)
    assert np.abs(y[195:200] - refs[195:200]).max() < 1e-8
    assert np.abs(y[-5:] - refs[-5:]).max() < 1e-8
    assert gpc.updates > 0


def test_rls_identifies_the_incremental_model_under_excitation() -> None:
    """Random inputs (excitation), f = 0.98: the prior is forgotten geometrically and the
    estimate reaches [A B] of the incremental model."""
    A = np.array([[0.9]])
    B = np.array([[0.2]])
    gpc = Gpc(GpcParams(forgetting=0.98, p0=1e3), 1)
    rng = np.random.default_rng(4)
    y, u = np.zeros(1), np.zeros(1)
    for _ in range(3000):
        gpc.observe(y)
        u = rng.normal(size=1)
        gpc.applied(u)
        y = A @ y + B @ u
    # dy(t) = 0.9 dy(t-1) + 0.2 du(t-1) exactly: noise-free data, exact estimate
    assert gpc.theta == pytest.approx(np.array([[0.9, 0.2]]), abs=1e-6)


def test_clipping_is_remembered() -> None:
    gpc = Gpc(GpcParams(), 1)
    gpc.observe(np.zeros(1))
    u = gpc.control(np.full((3, 1), 100.0), lo=np.array([-1.0]), hi=np.array([1.0]))
    assert u[0] == 1.0 and gpc.u_prev[0] == 1.0 and gpc.du_hist[0, 0] == 1.0


def test_covariance_trace_is_bounded_without_excitation() -> None:
    gpc = Gpc(GpcParams(forgetting=0.9, p_max=500.0), 1)
    gpc.observe(np.zeros(1))
    gpc.applied(np.array([1.0]))
    for _ in range(200):  # constant output increment and no moves: P would grow as 0.9^-k
        gpc.observe(gpc.y_prev + 0.1)
        gpc.applied(gpc.u_prev)
    assert np.trace(gpc.P) <= 500.0 * (1 + 1e-12)


def test_nu_larger_than_ny_is_rejected() -> None:
    with pytest.raises(ValueError, match="Nu = 4"):
        Gpc(GpcParams(Ny=3, Nu=4), 1)
