"""Route data and reference profiles: the one module for lines, grades and reference curves.

A route file is TOML with segments along the line (positions in metres from the line's origin)::

    name = "seed000_stop"
    length_m = 400.0
    grade = [[0.0, 12.0], [150.0, 28.0], [300.0, -6.0]]   # [start_m, permille], uphill > 0
    curves = [[1200.0, 1800.0, 5500.0]]                    # [start_m, end_m, radius_m]
    tunnels = [[3000.0, 4200.0]]                           # [start_m, end_m]
    speed_limits = [[0.0, 20.0]]                           # [start_m, limit_m_per_s]
    neutral_sections = [[25000.0, 25200.0]]                # [start_m, end_m], no traction power
    stations = [["Jinan West", 0.0], ["Tai'an", 43285.0]]  # [name, position_m]
    tunnel_coefficient = 0.00013                           # N/kN per m of tunnel length
    reference = "line_reference.csv"                       # optional reference profile file
    scheduled_time_s = 1290.0                              # optional timetable running time

``grade`` and ``speed_limits`` are ``[start, value]`` steps: each value holds from its start up to
the next start (the first value also before it). ``curves``, ``tunnels`` and ``neutral_sections``
are ``[start, end(, value)]`` intervals; outside them the line is straight / open / powered.
``reference`` names a reference-profile file relative to the route file (see below).
``scheduled_time_s`` is the timetable's running time from the first to the last station (s),
running-time supplement included: the time the energy-saving profiles of seed 003 use up.

Additional resistance (N/kN, i.e. per unit weight) is stored as step profiles so that the
length-share average over a vehicle is exact (``StepProfile.mean_over``, seed 002 sec. 1):

* grade ``i`` (permille, uphill positive): ``w_i = i`` (the small-angle reading of
  ``g sin(atan(i/1000))`` of seed 003; they differ by < 0.02 % at 20 permille);
* curve of radius ``R`` (m): ``w_r = 600 / R`` (Chinese traction rules, seeds 002/003);
* tunnel of length ``L_s`` (m): ``w_s = tunnel_coefficient * L_s`` over the tunnel (seed 003,
  rules value 0.00013 N/kN per m).

A vehicle of length ``l`` whose front is at ``s`` feels ``w(s) = mean of w over [s - l, s]``;
its force is ``m g w / 1000`` (N) — :meth:`Route.additional_resistance`.

Reference profiles (:class:`ReferenceProfile`) are CSV or TOML. CSV: a header naming the
columns, the first ``position_m`` (speed-distance) or ``time_s`` (speed-time), the second
``speed_kmh`` or ``speed_mps``; ``#`` lines are comments. TOML: ``kind = "distance" | "time"``,
``speed_unit = "km/h" | "m/s"``, ``points = [[x, v], ...]``. Between points a speed-distance
profile has constant acceleration (``v^2`` linear in ``s``), a speed-time profile too (``v``
linear in ``t``); the reference acceleration is that constant.

Bundled routes and profiles live beside this module in ``routes/``; :func:`load_route` and
:func:`load_reference` take a bundled name or a file path. ``routes/README.md`` says how each
bundled line was made.
"""

from __future__ import annotations

import bisect
import csv
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cosim.fmu.declare import Var
from plants.resistance import KMH  # noqa: F401 - m/s per km/h, also for route's importers

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

    @classmethod
    def from_intervals(cls, intervals: list[list[float]] | None, default: float = 0.0,
                       value: float | None = None) -> StepProfile:
        """``[[start, end, value], ...]`` (or ``[[start, end], ...]`` with ``value``) -> steps.

        Outside the intervals (also before the first) the profile is ``default``. Intervals
        must not overlap; touching intervals are fine.
        """
        starts: list[float] = [-math.inf]
        values: list[float] = [default]
        for row in sorted(intervals or []):
            start, end = float(row[0]), float(row[1])
            val = float(row[2]) if value is None else float(value)
            if not end > start:
                raise ValueError(f"interval [{start}, {end}] must have end > start")
            if start < starts[-1]:
                raise ValueError(f"interval starting at {start} overlaps the previous one")
            if start == starts[-1]:
                values[-1] = val
            else:
                starts.append(start)
                values.append(val)
            starts.append(end)
            values.append(default)
        return cls(np.array(starts), np.array(values))

    @classmethod
    def sum(cls, *profiles: StepProfile) -> StepProfile:
        """Pointwise sum of step profiles (a step profile on the union of their starts)."""
        finite = np.unique(np.concatenate([p.starts[1:] for p in profiles] + [np.empty(0)]))
        starts = np.concatenate(([-math.inf], finite))
        values = np.zeros(starts.size)
        for p in profiles:
            values += p.at_array(starts)
        return cls(starts, values)

    def at(self, s: float) -> float:
        """Value at position ``s`` (m): ``searchsorted(starts, s, 'right') - 1`` by bisection
        on plain lists (a tenth of numpy's per-call cost for one scalar)."""
        starts, values = self._lists
        return values[bisect.bisect_right(starts, s) - 1]

    @functools.cached_property
    def _lists(self) -> tuple[list[float], list[float]]:
        return self.starts.tolist(), [float(v) for v in self.values.tolist()]

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

    def mean_over_scalar(self, front: float, length: float) -> float:
        """:meth:`mean_over` for one vehicle (``length > 0``) in plain floats: the same
        operations as ``np.interp`` (``slope (x - x_j) + y_j``), without array overhead."""
        xs, ys = self._cumulative_lists
        return (_interp_scalar(front, xs, ys) - _interp_scalar(front - length, xs, ys)) / length

    @functools.cached_property
    def _cumulative_lists(self) -> tuple[list[float], list[float]]:
        xs, ys = self._cumulative
        return xs.tolist(), ys.tolist()

    @functools.cached_property
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


def _interp_scalar(x: float, xs: list[float], ys: list[float]) -> float:
    """``np.interp(x, xs, ys)`` for one point (constant beyond the ends)."""
    if x < xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    j = bisect.bisect_right(xs, x) - 1
    if xs[j] == x:
        return ys[j]
    return (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]) * (x - xs[j]) + ys[j]


TUNNEL_COEFFICIENT = 0.00013  # N/kN per m of tunnel length (seed 003, Chinese traction rules)


def _no_curves() -> StepProfile:
    return StepProfile.from_pairs(None, math.inf)


def _zero() -> StepProfile:
    return StepProfile.from_pairs(None, 0.0)


def _no_limit() -> StepProfile:
    return StepProfile.from_pairs(None, math.inf)


@dataclass(frozen=True)
class Route:
    """A line: grade (permille), curves, tunnels, speed limits, neutral sections by position (m).

    ``curve_radius`` is ``inf`` on straight track and ``tunnel`` is 1 inside a tunnel, 0 outside;
    the resistance profiles (N/kN) ``curve_resistance`` (600/R) and ``tunnel_resistance``
    (``tunnel_coefficient * L_s``) are what vehicles feel. ``neutral`` is 1 inside a neutral
    section (no traction power), 0 elsewhere. ``stations`` are ``(name, position_m)`` pairs.
    """

    name: str
    length_m: float
    grade: StepProfile
    curve_radius: StepProfile = field(default_factory=_no_curves)
    tunnel: StepProfile = field(default_factory=_zero)
    speed_limit: StepProfile = field(default_factory=_no_limit)
    curve_resistance: StepProfile = field(default_factory=_zero)
    tunnel_resistance: StepProfile = field(default_factory=_zero)
    neutral: StepProfile = field(default_factory=_zero)
    stations: tuple[tuple[str, float], ...] = ()
    reference: ReferenceProfile | None = None
    scheduled_time_s: float | None = None

    def grade_accel(self, s: float) -> float:
        """Grade resistance as an acceleration (m/s^2): ``g * i(s) / 1000``, uphill positive."""
        return GRAVITY * self.grade.at(s) / 1000.0

    @functools.cached_property
    def additional(self) -> StepProfile:
        """Grade + curve + tunnel resistance (N/kN) as one step profile."""
        return StepProfile.sum(self.grade, self.curve_resistance, self.tunnel_resistance)

    def additional_resistance(self, front: np.ndarray | float,
                              length: np.ndarray | float) -> np.ndarray:
        """Additional specific resistance (N/kN) of vehicles with fronts at ``front`` (m) and
        lengths ``length`` (m): grade, curve and tunnel averaged over the share of each
        vehicle's length on each segment (seed 002). Multiply by ``m g / 1000`` for newtons."""
        return self.additional.mean_over(front, length)

    def additional_accel(self, front: np.ndarray | float,
                         length: np.ndarray | float) -> np.ndarray:
        """:meth:`additional_resistance` as a deceleration (m/s^2): ``g w / 1000``."""
        return GRAVITY / 1000.0 * self.additional.mean_over(front, length)

    def station_position(self, name: str) -> float:
        """Position (m) of the station called ``name``."""
        for station, pos in self.stations:
            if station == name:
                return pos
        raise ValueError(f"route {self.name!r} has no station {name!r} "
                         f"(stations: {[n for n, _ in self.stations]})")

    @classmethod
    def flat(cls, length_m: float = 1e9) -> Route:
        return cls("flat", length_m, StepProfile.from_pairs(None, 0.0))


@dataclass(frozen=True)
class ReferenceProfile:
    """Reference speed against position (``kind = "distance"``) or time (``"time"``).

    ``x`` (m or s, increasing) and ``v`` (m/s, >= 0) are the profile points. Between points the
    acceleration is constant: ``v^2`` linear in position, or ``v`` linear in time. Outside the
    points the end speeds hold with zero acceleration.
    """

    kind: str
    x: np.ndarray
    v: np.ndarray

    def __post_init__(self) -> None:
        if self.kind not in ("distance", "time"):
            raise ValueError(f"reference kind {self.kind!r} must be 'distance' or 'time'")
        x = np.asarray(self.x, dtype=float)
        v = np.asarray(self.v, dtype=float)
        if x.ndim != 1 or x.shape != v.shape or x.size < 2:
            raise ValueError("reference needs at least two [x, v] points")
        if np.any(np.diff(x) <= 0):
            raise ValueError("reference positions/times must increase")
        if np.any(v < 0) or not np.all(np.isfinite(v)):
            raise ValueError("reference speeds must be finite and >= 0")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "v", v)

    @functools.cached_property
    def segment_accel(self) -> np.ndarray:
        """Reference acceleration (m/s^2) on each segment between the profile's points."""
        dx = np.diff(self.x)
        if self.kind == "distance":
            return np.diff(self.v**2) / (2.0 * dx)
        return np.diff(self.v) / dx

    def speed(self, x: float) -> float:
        """Reference speed (m/s) at position (m) or time (s) ``x``."""
        if self.kind == "distance":
            return math.sqrt(max(float(np.interp(x, self.x, self._v_squared)), 0.0))
        return float(np.interp(x, self.x, self.v))

    @functools.cached_property
    def _v_squared(self) -> np.ndarray:
        return self.v**2

    @functools.cached_property
    def _accel_lists(self) -> tuple[list[float], list[float]]:
        return self.x.tolist(), self.segment_accel.tolist()

    def accel(self, x: float) -> float:
        """Reference acceleration dv/dt (m/s^2) at ``x``: the constant of its segment."""
        xs, accel = self._accel_lists
        if x < xs[0] or x >= xs[-1]:
            return 0.0
        return accel[bisect.bisect_right(xs, x) - 1]

    def times(self) -> np.ndarray:
        """Time (s) at each point; for a distance profile, from ``x[0]`` at t = 0.

        A segment with zero speed at both ends cannot be crossed: ``inf`` from there on.
        """
        if self.kind == "time":
            return self.x.copy()
        dx = np.diff(self.x)
        vsum = self.v[:-1] + self.v[1:]
        with np.errstate(divide="ignore"):
            dt = np.where(vsum > 0, 2.0 * dx / np.where(vsum > 0, vsum, 1.0), math.inf)
        return np.concatenate(([0.0], np.cumsum(dt)))

    def run_time(self) -> float:
        """Time (s) to run the whole profile."""
        return float(self.times()[-1] - self.times()[0])

    def with_speed_unit(self, factor: float) -> ReferenceProfile:
        return ReferenceProfile(self.kind, self.x, self.v * factor)


def _read_reference_csv(path: Path) -> ReferenceProfile:
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(line for line in f if not line.lstrip().startswith("#"))
                if r]
    header = [h.strip() for h in rows[0]]
    kinds = {"position_m": "distance", "time_s": "time"}
    units = {"speed_kmh": KMH, "speed_mps": 1.0}
    if len(header) < 2 or header[0] not in kinds or header[1] not in units:
        raise ValueError(f"{path}: header must be position_m|time_s, speed_kmh|speed_mps; "
                         f"got {header}")
    data = np.array([[float(r[0]), float(r[1])] for r in rows[1:]])
    return ReferenceProfile(kinds[header[0]], data[:, 0], data[:, 1] * units[header[1]])


def _reference_from_dict(data: dict, where: str) -> ReferenceProfile:
    units = {"km/h": KMH, "m/s": 1.0}
    unit = data.get("speed_unit", "m/s")
    if unit not in units:
        raise ValueError(f"{where}: speed_unit {unit!r} must be 'km/h' or 'm/s'")
    pts = np.asarray(data["points"], dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{where}: points must be [[x, v], ...]")
    return ReferenceProfile(str(data.get("kind", "distance")), pts[:, 0], pts[:, 1] * units[unit])


def load_reference(name_or_path: str | Path, base: Path | None = None,
                   routes_dir: Path | None = None) -> ReferenceProfile:
    """Load a reference profile (CSV or TOML) by path, by path relative to ``base`` or by
    bundled name (``<routes_dir>/<name>.csv`` or ``.toml``; FMU wrappers pass ``routes_dir``
    as for :func:`load_route`)."""
    routes_dir = routes_dir or ROUTES_DIR
    path = Path(name_or_path)
    candidates = [path] if path.is_absolute() else (
        ([base / path] if base else []) + [routes_dir / path, path]
        + [routes_dir / f"{name_or_path}{ext}" for ext in (".csv", ".toml") if not path.suffix])
    found = next((c for c in candidates if c.is_file()), None)
    if found is None:
        raise ValueError(f"reference profile {str(name_or_path)!r} not found")
    try:
        if found.suffix == ".csv":
            return _read_reference_csv(found)
        with open(found, "rb") as f:
            data = tomllib.load(f)
        return _reference_from_dict(data.get("reference", data), str(found))
    except (KeyError, ValueError, TypeError, IndexError) as err:
        raise ValueError(f"{found}: bad reference profile: {err}") from err


_LOADED: dict[tuple, Route] = {}  # per process: (file, mtime, size) -> parsed (immutable) route


def _file_key(path: Path) -> tuple:
    st = path.stat()
    return (str(path.resolve()), st.st_mtime_ns, st.st_size)


def load_route(name_or_path: str | Path, routes_dir: Path | None = None) -> Route:
    """Load a route by bundled name (``<routes_dir>/<name>.toml``) or by file path.

    FMU wrappers must pass ``routes_dir=self.resource_path("plants", "routes")`` so that the
    data come from the instance's own resources folder (pythonfmu caches modules by name, so
    this module's ``__file__`` may point at another, already deleted, extraction of the FMU).
    """
    routes_dir = routes_dir or ROUTES_DIR
    path = Path(name_or_path)
    if not path.suffix:
        path = routes_dir / f"{name_or_path}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in routes_dir.glob("*.toml"))
        raise ValueError(f"route {str(name_or_path)!r} not found (bundled routes: {known})")
    # parsed once per process and file version (routes are frozen): a further FMU instance
    # does not parse the route and its reference profile again
    key = _file_key(path)
    route = _LOADED.get(key)
    if route is None:
        route = _LOADED[key] = _parse_route(path)
    return route


def _parse_route(path: Path) -> Route:
    with open(path, "rb") as f:
        data = tomllib.load(f)
    try:
        curves = data.get("curves", [])
        tunnels = data.get("tunnels", [])
        coeff = float(data.get("tunnel_coefficient", TUNNEL_COEFFICIENT))
        for c in curves:
            if not c[2] > 0:
                raise ValueError(f"curve radius {c[2]} must be > 0")
        reference = data.get("reference")
        scheduled = data.get("scheduled_time_s")
        if scheduled is not None and not float(scheduled) > 0:
            raise ValueError(f"scheduled_time_s = {scheduled} must be > 0")
        return Route(
            name=str(data.get("name", path.stem)),
            length_m=float(data["length_m"]),
            grade=StepProfile.from_pairs(data.get("grade"), 0.0),
            curve_radius=StepProfile.from_intervals(curves, math.inf),
            tunnel=StepProfile.from_intervals(tunnels, 0.0, value=1.0),
            speed_limit=StepProfile.from_pairs(data.get("speed_limits"), math.inf),
            curve_resistance=StepProfile.from_intervals(
                [[a, b, 600.0 / r] for a, b, r in curves], 0.0),
            tunnel_resistance=StepProfile.from_intervals(
                [[a, b, coeff * (b - a)] for a, b in tunnels], 0.0),
            neutral=StepProfile.from_intervals(data.get("neutral_sections"), 0.0, value=1.0),
            stations=tuple((str(n), float(x)) for n, x in data.get("stations", [])),
            reference=(load_reference(reference, base=path.parent) if reference else None),
            scheduled_time_s=None if scheduled is None else float(scheduled),
        )
    except (KeyError, ValueError, TypeError, IndexError) as err:
        raise ValueError(f"{path}: bad route data: {err}") from err


def routes_dir_in(data_dir: Path) -> Path:
    """The bundled routes folder under an FMU's data folder (or the project tree)."""
    return Path(data_dir) / "plants" / "routes"


def route_parameter(default: str, what: str = "") -> Var:
    """The ``route`` parameter shared by plants and route-reading controllers."""
    return Var("route", "parameter", default,
               description="bundled route name or path of a route TOML file"
               + (f" ({what})" if what else ""))


def initial_state_parameters(v0: float = 0.0, what: str = "") -> tuple[Var, ...]:
    """``v0`` and ``s0`` of a plant (``what``: whose speed, e.g. "of every unit")."""
    return (Var("v0", "parameter", v0, "m/s", f"initial speed{what}", min=0.0),
            Var("s0", "parameter", 0.0, "m", "initial position of the train front"))
