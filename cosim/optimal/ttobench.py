"""Tracks, trains and journeys in TTOBench's JSON format (Kouzoupis, Pendharkar & Corman,
*TTOBench: an open-source library for train trajectory optimization*, Operations Research
Forum 4(67), 2023; https://github.com/nuorail/ttobench, BSD-2-Clause).

Every quantity is ``{"unit": ..., "value": ...}`` or a table ``{"units": {...}, "values":
[...]}``; units are converted to SI here and an unknown unit is an error. What is read:

* track: ``stops`` (m), ``speed limits`` ``[position, limit]``, ``gradients``
  ``[position, permil]`` (uphill > 0; optional: level), ``curvatures`` ``[position, radius at
  start, radius at end]`` (optional; ``"infinity"`` straight, the sign the direction, a
  clothoid between two radii). A curve is resisted as an equivalent grade ``600 / R`` N/kN
  (the rule :mod:`plants.route` uses), with the section's mean curvature ``(1/R_0 + 1/R_1) /
  2`` in magnitude. ``tunnels`` are listed in :attr:`Track.tunnels` but not resisted (their
  train-specific aerodynamic coefficient is not a grade); ETCS braking data are not read.
* train: mass, ``rho`` (rotating mass, %), traction power and force, regenerative braking
  power and force, pneumatic (friction) braking force, comfort acceleration and
  deceleration, top speed, Davis ``r0 + r1 v + r2 v^2`` (kN with v in km/h), traction and
  regenerative-brake efficiencies (% ; 100 % where missing).
* journey: ``timing points`` ``[position, earliest, latest, lowest speed, highest speed]``
  (null: none); stopping points have both speeds 0, and the journey's sections run from one
  stopping point to the next.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from cosim.optimal.model import Section, Train
from plants.resistance import Davis
from plants.route import Route, StepProfile

#: TTOBench's instances shipped in package ``cosim_data`` (cosim_data/ttobench/README.md:
#: source commit, BSD-2 licence, citation), or the copy at ``$TTOBENCH_DIR`` (same layout:
#: tracks/, trains/, journeys/).
DATA = Path(os.environ.get("TTOBENCH_DIR", str(resources.files("cosim_data") / "ttobench")))


def instance(kind: str, name: str) -> Path:
    """The JSON file of a TTOBench instance: ``kind`` tracks, trains or journeys, ``name``
    without ``.json`` (e.g. ``instance("tracks", "00_reference")``)."""
    if kind not in ("tracks", "trains", "journeys"):
        raise ValueError(f"TTOBench kind {kind!r}: tracks, trains or journeys")
    path = DATA / kind / f"{name}.json"
    if not path.is_file():
        have = sorted(p.stem for p in (DATA / kind).glob("*.json"))
        raise FileNotFoundError(f"no TTOBench {kind[:-1]} {name!r} in {DATA} (have: {have})")
    return path


_UNITS = {"m": 1.0, "km": 1e3, "kg": 1.0, "t": 1e3, "W": 1.0, "kW": 1e3, "MW": 1e6,
          "N": 1.0, "kN": 1e3, "m/s": 1.0, "km/h": 1.0 / 3.6, "m/s^2": 1.0, "%": 0.01,
          "-": 1.0, "s": 1.0, "permil": 1.0, "m^2": 1.0}


def _scale(unit: str, where: str) -> float:
    if unit not in _UNITS:
        raise ValueError(f"{where}: unit {unit!r} not understood (known: {sorted(_UNITS)})")
    return _UNITS[unit]


def _read(path: str | Path) -> dict[str, Any]:
    with open(path) as f:
        data = json.load(f)
    if not isinstance(data, dict) or "metadata" not in data:
        raise ValueError(f"{path}: not a TTOBench document (no metadata)")
    return data


def _quantity(data: dict[str, Any], key: str, where: str, default: float | None = None,
              si_unit: str | None = None) -> float:
    if key not in data:
        if default is None:
            raise ValueError(f"{where}: {key!r} missing")
        return default
    item = data[key]
    value = item["value"]
    if value is None:
        if default is None:
            raise ValueError(f"{where}: {key!r} is null")
        return default
    return float(value) * _scale(item.get("unit", si_unit or "-"), f"{where} {key!r}")


def _table(data: dict[str, Any], key: str, where: str) -> tuple[list[list[Any]], dict]:
    item = data[key]
    return item["values"], item.get("units", {})


def _radius(x: Any) -> float:
    if isinstance(x, str):
        if x.strip().lower() in ("infinity", "inf", "+infinity"):
            return math.inf
        raise ValueError(f"radius {x!r} is not a number or 'infinity'")
    return float(x)


@dataclass(frozen=True)
class Track:
    """A TTOBench track as a :class:`plants.route.Route` with its stops (m)."""

    route: Route
    stops: tuple[float, ...]
    tunnels: tuple[tuple[float, float, float], ...]  # (start m, length m, cross section m2)

    def section(self, start_stop: int = 0, end_stop: int = -1) -> Section:
        """The run from stop ``start_stop`` to stop ``end_stop`` (indices into ``stops``)."""
        return Section(self.route, self.stops[start_stop], self.stops[end_stop])


def load_track(path: str | Path) -> Track:
    """A TTOBench track JSON (module text)."""
    data = _read(path)
    where = str(path)
    name = str(data["metadata"].get("id", Path(path).stem))
    stops_raw = data["stops"]
    stops = [float(x) * _scale(stops_raw.get("unit", "m"), where) for x in stops_raw["values"]]
    if len(stops) < 2 or stops[0] != 0.0 or np.any(np.diff(stops) <= 0):
        raise ValueError(f"{where}: stops must start at 0 and increase, got {stops}")
    values, units = _table(data, "speed limits", where)
    kx = _scale(units.get("position", "m"), where)
    kv = _scale(units.get("velocity", "km/h"), where)
    limits = [[float(p) * kx, float(v) * kv] for p, v in values]
    grades: list[list[float]] = [[0.0, 0.0]]
    if "gradients" in data:
        values, units = _table(data, "gradients", where)
        kx = _scale(units.get("position", "m"), where)
        if units.get("slope", "permil") != "permil":
            raise ValueError(f"{where}: gradients must be in permil")
        grades = [[float(p) * kx, float(s)] for p, s in values]
    curve_w: list[list[float]] = []
    radius: list[list[float]] = []
    if "curvatures" in data:
        values, units = _table(data, "curvatures", where)
        kx = _scale(units.get("position", "m"), where)
        kr = _scale(units.get("radius at start", "m"), where)
        for p, r0, r1 in values:
            k = 0.5 * (abs(1.0 / (_radius(r0) * kr)) + abs(1.0 / (_radius(r1) * kr)))
            curve_w.append([float(p) * kx, 600.0 * k])
            radius.append([float(p) * kx, math.inf if k == 0 else 1.0 / k])
    tunnels: list[tuple[float, float, float]] = []
    if "tunnels" in data:
        values, units = _table(data, "tunnels", where)
        kx = _scale(units.get("position", "m"), where)
        tunnels = [(float(p) * kx, float(n) * kx, float(a)) for p, n, a in values]
    route = Route(name=name, length_m=stops[-1], grade=StepProfile.from_pairs(grades),
                  curve_radius=StepProfile.from_pairs(radius or None, math.inf),
                  speed_limit=StepProfile.from_pairs(limits, math.inf),
                  curve_resistance=StepProfile.from_pairs(curve_w or None, 0.0),
                  stations=tuple((f"stop {i}", x) for i, x in enumerate(stops)))
    return Track(route, tuple(stops), tuple(tunnels))


def load_train(path: str | Path) -> Train:
    """A TTOBench train JSON (module text)."""
    data = _read(path)
    where = str(path)
    q = lambda key, default=None: _quantity(data, key, where, default)  # noqa: E731

    def davis_coefficient(key: str, unit_kmh: str, power: int) -> float:
        item = data[key]
        unit = item.get("unit", unit_kmh)
        expected = {0: "kN", 1: "kN/(km/h)", 2: "kN/(km/h)^2"}[power]
        if unit != expected:
            raise ValueError(f"{where}: {key!r} in {unit!r}, expected {expected!r}")
        return float(item["value"])

    davis = Davis.from_kn_kmh(davis_coefficient("rolling resistance r0", "kN", 0),
                              davis_coefficient("rolling resistance r1", "kN/(km/h)", 1),
                              davis_coefficient("rolling resistance r2", "kN/(km/h)^2", 2))
    return Train(
        name=str(data["metadata"].get("id", Path(path).stem)),
        mass=q("mass"), rotating_mass_factor=q("rho", 0.0), davis=davis,
        max_traction_force=q("max traction force"), max_traction_power=q("max traction power"),
        max_regen_force=q("max reg braking force", 0.0),
        max_regen_power=q("max reg braking power", 0.0),
        max_friction_force=q("max pn braking force", 0.0),
        max_speed=q("max speed", math.inf), max_accel=q("max acceleration", math.inf),
        max_decel=q("max deceleration", math.inf),
        traction_efficiency=q("efficiency traction", 1.0),
        regen_efficiency=q("efficiency reg brake", 1.0),
        length=q("length", 0.0))


@dataclass(frozen=True)
class TimingPoint:
    position: float  # m
    earliest: float | None  # s from the journey's start
    latest: float | None
    lowest_speed: float | None  # m/s
    highest_speed: float | None

    @property
    def stopping(self) -> bool:
        return self.lowest_speed == 0.0 and self.highest_speed == 0.0


@dataclass(frozen=True)
class JourneySection:
    """A run between two stopping points: departure and arrival timing points and the
    passing points between them."""

    departure: TimingPoint
    arrival: TimingPoint
    passing: tuple[TimingPoint, ...]

    def running_time(self) -> float:
        """The longest running time the windows allow (s): from the earliest departure to the
        latest arrival (the energy falls with the running time)."""
        if self.arrival.latest is None:
            raise ValueError(f"the stop at {self.arrival.position} m has no latest time")
        return self.arrival.latest - (self.departure.earliest or 0.0)

    def window(self) -> tuple[float, float]:
        """(shortest, longest) running time (s) the windows allow."""
        dep_late = self.departure.latest if self.departure.latest is not None else (
            self.departure.earliest or 0.0)
        early = (self.arrival.earliest if self.arrival.earliest is not None else 0.0) - dep_late
        return max(early, 0.0), self.running_time()

    def missed(self, s: np.ndarray, t: np.ndarray, v: np.ndarray) -> list[str]:
        """The passing points a run (``s`` m, ``t`` s from its departure, ``v`` m/s) misses."""
        t0 = self.departure.earliest or 0.0
        out = []
        for p in self.passing:
            tp = t0 + float(np.interp(p.position, s, t))
            vp = float(np.interp(p.position, s, v))
            if p.earliest is not None and tp < p.earliest - 1e-9:
                out.append(f"{p.position:.1f} m passed at {tp:.1f} s < {p.earliest:.1f} s")
            if p.latest is not None and tp > p.latest + 1e-9:
                out.append(f"{p.position:.1f} m passed at {tp:.1f} s > {p.latest:.1f} s")
            if p.lowest_speed is not None and vp < p.lowest_speed - 1e-9:
                out.append(f"{p.position:.1f} m passed at {vp:.2f} m/s < {p.lowest_speed:.2f}")
            if p.highest_speed is not None and vp > p.highest_speed + 1e-9:
                out.append(f"{p.position:.1f} m passed at {vp:.2f} m/s > {p.highest_speed:.2f}")
        return out


@dataclass(frozen=True)
class Journey:
    name: str
    track: str  # id of the associated track
    sections: tuple[JourneySection, ...]


def load_journey(path: str | Path) -> Journey:
    """A TTOBench journey JSON (module text)."""
    data = _read(path)
    where = str(path)
    values, units = _table(data, "timing points", where)
    kx = _scale(units.get("position", "m"), where)
    kt = _scale(units.get("lower time constraint", "s"), where)
    kv = _scale(units.get("lower speed constraint", "km/h"), where)

    def num(x: Any, k: float) -> float | None:
        return None if x is None else float(x) * k

    points = [TimingPoint(float(p) * kx, num(a, kt), num(b, kt), num(c, kv), num(d, kv))
              for p, a, b, c, d in values]
    if len(points) < 2 or not points[0].stopping or not points[-1].stopping:
        raise ValueError(f"{where}: a journey starts and ends with a stopping point")
    sections = []
    start = 0
    for i in range(1, len(points)):
        if points[i].stopping:
            if points[i].position > points[start].position:
                sections.append(JourneySection(points[start], points[i],
                                               tuple(points[start + 1:i])))
            start = i
    meta = data["metadata"]
    return Journey(str(meta.get("id", Path(path).stem)), str(meta.get("associated track", "")),
                   tuple(sections))
