"""Route data and reference profiles: the one module for lines, grades and reference curves.

A route file is TOML with piecewise-constant segments along the line (positions in metres)::

    name = "seed000_stop"
    length_m = 400.0
    grade = [[0.0, 12.0], [150.0, 28.0], [300.0, -6.0]]   # [start_m, permille], uphill > 0
    curves = [[1200.0, 1800.0, 5500.0]]                    # [start_m, end_m, radius_m]
    tunnels = [[3000.0, 4200.0]]                           # [start_m, end_m]
    speed_limits = [[0.0, 20.0]]                           # [start_m, limit_m_per_s]

Each segment list gives the value from its start position up to the next start. Bundled routes
live beside this module in ``routes/``; :func:`load_route` takes a bundled name or a file path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

GRAVITY = 9.81  # m/s^2
ROUTES_DIR = Path(__file__).resolve().parent / "routes"


@dataclass(frozen=True)
class StepProfile:
    """A piecewise-constant function of position: ``value[i]`` on ``[starts[i], starts[i+1])``."""

    starts: np.ndarray
    values: np.ndarray

    @classmethod
    def from_pairs(cls, pairs: list[list[float]] | None, default: float = 0.0) -> StepProfile:
        if not pairs:
            return cls(np.array([-math.inf]), np.array([default]))
        arr = np.asarray(pairs, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"expected [[start_m, value], ...], got {pairs!r}")
        if np.any(np.diff(arr[:, 0]) <= 0):
            raise ValueError(f"segment starts must increase: {arr[:, 0].tolist()}")
        starts = np.concatenate(([-math.inf], arr[:, 0]))
        values = np.concatenate(([arr[0, 1]], arr[:, 1]))
        return cls(starts, values)

    def at(self, s: float) -> float:
        """Value at position ``s`` (m)."""
        return float(self.values[np.searchsorted(self.starts, s, side="right") - 1])

    def at_array(self, s: np.ndarray) -> np.ndarray:
        return self.values[np.searchsorted(self.starts, s, side="right") - 1]

    def mean_over(self, front: np.ndarray, length: np.ndarray | float) -> np.ndarray:
        """Length-weighted mean over ``[front - length, front]`` (share of a vehicle's length)."""
        front = np.atleast_1d(np.asarray(front, dtype=float))
        length = np.broadcast_to(np.asarray(length, dtype=float), front.shape)
        rear = front - length
        cum = self._cumulative
        total = np.interp(front, cum[0], cum[1]) - np.interp(rear, cum[0], cum[1])
        out = np.where(length > 0, total / np.where(length > 0, length, 1.0), self.at_array(front))
        return out

    @property
    def _cumulative(self) -> tuple[np.ndarray, np.ndarray]:
        finite = self.starts[1:]
        if finite.size == 0:
            xs = np.array([-1e9, 1e9])
            return xs, xs * self.values[0]
        lo, hi = finite[0] - 1e7, finite[-1] + 1e7
        xs = np.concatenate(([lo], finite, [hi]))
        vals = self.values  # value on [xs[i], xs[i+1])
        integral = np.concatenate(([0.0], np.cumsum(np.diff(xs) * vals)))
        return xs, integral


@dataclass(frozen=True)
class Route:
    """A line: grade (permille), curves, tunnels and speed limits by position (m)."""

    name: str
    length_m: float
    grade: StepProfile
    curve_radius: StepProfile = field(default_factory=lambda: StepProfile.from_pairs(None, math.inf))
    tunnel: StepProfile = field(default_factory=lambda: StepProfile.from_pairs(None, 0.0))
    speed_limit: StepProfile = field(default_factory=lambda: StepProfile.from_pairs(None, math.inf))

    def grade_accel(self, s: float) -> float:
        """Grade resistance as an acceleration (m/s^2): ``g * i(s) / 1000``, uphill positive."""
        return GRAVITY * self.grade.at(s) / 1000.0

    @classmethod
    def flat(cls, length_m: float = 1e9) -> Route:
        return cls("flat", length_m, StepProfile.from_pairs(None, 0.0))


def _segments_to_steps(triples: list[list[float]] | None, default: float) -> list[list[float]]:
    """[[start, end, value], ...] -> [[start, value], [end, default], ...]."""
    pairs: list[list[float]] = []
    for start, end, *value in sorted(triples or []):
        pairs.append([start, value[0] if value else 1.0])
        pairs.append([end, default])
    merged: list[list[float]] = []
    for start, value in pairs:
        if merged and merged[-1][0] == start:
            merged[-1][1] = value
        else:
            merged.append([start, value])
    return merged


def load_route(name_or_path: str | Path) -> Route:
    """Load a route by bundled name (``routes/<name>.toml``) or by file path."""
    path = Path(name_or_path)
    if not path.suffix:
        path = ROUTES_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in ROUTES_DIR.glob("*.toml"))
        raise ValueError(f"route {str(name_or_path)!r} not found (bundled routes: {known})")
    with open(path, "rb") as f:
        data = tomllib.load(f)
    try:
        return Route(
            name=str(data.get("name", path.stem)),
            length_m=float(data["length_m"]),
            grade=StepProfile.from_pairs(data.get("grade"), 0.0),
            curve_radius=StepProfile.from_pairs(_segments_to_steps(data.get("curves"), math.inf)
                                                or None, math.inf),
            tunnel=StepProfile.from_pairs(_segments_to_steps(
                [[a, b, 1.0] for a, b in data.get("tunnels", [])], 0.0) or None, 0.0),
            speed_limit=StepProfile.from_pairs(data.get("speed_limits"), math.inf),
        )
    except (KeyError, ValueError, TypeError) as err:
        raise ValueError(f"{path}: bad route data: {err}") from err


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

    def accel(self, s: float) -> float:
        """Reference acceleration dv/dt along the curve (m/s^2): ``-a0`` before the stop point."""
        return -self.decel if s < self.stop_point else 0.0
