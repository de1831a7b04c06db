"""Reference profiles shared by controller cores and the run-side metrics (bundled into FMUs).

Lives on the lowest layer so that controllers (which track these curves) and ``cosim.run.metrics``
(which measures against them) import one definition without an upward arrow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cosim.fmu.declare import param


@dataclass(frozen=True)
class StoppingCurve:
    """Reference stopping curve ``v_ref(s) = sqrt(2 a0 (s_stop - s))`` (seed 000, sec. 4).

    ``a0`` is the reference deceleration (m/s^2, positive), ``stop_point`` the stop position (m).
    """

    decel: float
    stop_point: float

    def speed(self, s: float) -> float:
        """Reference speed (m/s) at position ``s`` (m); zero at and beyond the stop point."""
        return math.sqrt(2.0 * self.decel * max(self.stop_point - s, 0.0))

    def speeds(self, s: np.ndarray) -> np.ndarray:
        """:meth:`speed` at each position of ``s`` (m/s), the same floating-point operations
        element by element."""
        return np.sqrt(2.0 * self.decel * np.maximum(self.stop_point - np.asarray(s, float),
                                                     0.0))

    def accel(self, s: float) -> float:
        """Reference acceleration dv/dt along the curve (m/s^2): ``-a0`` before the stop point."""
        return -self.decel if s < self.stop_point else 0.0

    def along_time(self, s_start: float, elapsed: np.ndarray | float,
                   rest: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Time-indexed reference (speed m/s, position m) ``elapsed`` s after leaving ``s_start``.

        Follows the curve at constant deceleration ``a0``: ``v = v_ref(s_start) - a0 t``,
        ``s = s_stop - v^2 / (2 a0)``. With ``rest`` it stays at the stop point once v reaches 0;
        without, it continues the constant-deceleration parabola (v < 0), which is what a
        linear design model that cannot represent the stop predicts under constant braking.
        """
        v = self.speed(s_start) - self.decel * np.asarray(elapsed, dtype=float)
        if rest:
            v = np.maximum(v, 0.0)
        return v, self.stop_point - v * v / (2.0 * self.decel)


def ref_decel_param(default: float = 0.5) -> float:
    """Declared field: a0 of the stopping curve (shared by the stopping controllers)."""
    return param(default, "m/s2", "a0: reference deceleration", min=1e-6)


def stop_point_param(default: float = 400.0) -> float:
    """Declared field: the stop position of the stopping curve."""
    return param(default, "m", "stop position s_stop")
