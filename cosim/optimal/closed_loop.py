"""The optimal run in co-simulation: a shipped tracking controller follows it on the CRH3
plant FMU carrying the planned train, through the project's runner (``cosim optimal
--closed-loop``).

For a planned section this module writes

* the line as a route TOML (:func:`route_document`, the format :func:`plants.route.load_route`
  reads): grade steps, curves as ``[start, end, radius]`` intervals of the curve radius the
  plan resists (``600 / R`` N/kN), tunnels with the line's tunnel coefficient, speed limits,
  neutral sections and stations, in line positions (m);
* the optimal run as the reference CSV (:func:`cosim.optimal.output.write_csv`: speed against
  position, read by the controllers' ``reference`` parameter);
* a scenario TOML (:func:`scenario_document`): the plant ``Crh3Train``
  (:mod:`plants.crh3`) with the planned train's data (:func:`plant_parameters`), from rest at
  the section start, and the controller following the reference;

then the scenario is run by the project's runner (``cosim optimal`` passes
:func:`cosim.run.simulate.run_scenario`, what ``cosim run`` runs; this package does not import
the runner) and the closed loop is compared with the plan (:func:`compare`).

Controllers (:data:`CONTROLLERS`): ``pid``, the speed PID of seeds 001 and 004
(:class:`controllers.pid.speed_pid.DistributedSpeedPid`, FMU ``EmuSpeedPid3``) with its default
gains, the force of unit 1 driving the single-mass plant (the limits of units 2 and 3 are
constant inputs 0, so unit 1 takes the whole demand), its mass the train's effective mass and
its demand bounded by the train's force envelope (largest traction and total brake force per
unit effective mass; bounded by the comfort limits instead, the PID could not overcome the
resistance). The closed loop's largest acceleration and deceleration are reported. The
reference is looked up by the measured position; at the end of the reference the PID holds
the train with its holding brake.

Train to plant (:func:`plant_parameters`): mass, rotating mass factor, Davis terms, traction
force and power and top speed carry over as they are; traction efficiency is the plant's
``motor_efficiency`` and regenerative-brake efficiency its ``regen_efficiency``; no auxiliary
power (the plan has none); the plant's force lags (0.5 s) and integration sub-step stay the
plant's defaults; ``length`` 0 (a point mass, as the plan). The plant has one brake envelope
``min(F_b, P_b / v)``; the train has regenerative and friction brakes,
``min(F_r, P_r / v) + F_f``. The mapping is ``F_b = F_r + F_f`` (the two agree at low speed)
and ``P_b = P_r + F_f v_top`` (``v_top`` the train's top speed, or the line's highest limit):
the smallest ``P_b`` whose envelope covers the train's up to ``v_top`` (``v (min(F_r, P_r / v)
+ F_f)`` grows with ``v``), equal to it at ``v_top`` and at low speed, above it in between;
exact when the train has only one of the two brakes.

Energy, in the plan's accounting ``traction / eta_t - eta_r regenerated``: the plant's
``energy_traction`` is ``int max(F, 0) v dt / eta_t`` (exact, the plant's own integral); the
plant's ``energy_regen`` is ``eta_r int max(-F, 0) v dt``, all the braking work fed back, friction
included. The regenerated work of the closed loop is therefore computed from the recorded
applied force and speed, ``int min(max(-F, 0), min(F_r, P_r / v)) v dt`` (trapezoidal rule on
the output grid: regenerative brake first, friction for the rest, as the plan splits them);
the same quadrature of all the braking is reported beside the plant's exact ``brake_work`` as
its check. The closed-loop energy is counted from the start to the end of the run (standing
at the stop costs nothing: no auxiliary power, no speed).

Windows (:class:`Window`): those of seed 003 sec. 4 (``docs/papers/seed003.md``), the arrival
within Delta T_max = 5 s of the schedule (the running time the plan is for) and the stop within
Delta l_max = 0.5 m of the stopping point (seed 000's requirement too); with a TTOBench journey
also the section's arrival window (the earliest arrival less the latest departure up to the
latest arrival less the earliest departure) and its passing points.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.optimal.model import Section, Train
from cosim.optimal.output import write_csv
from cosim.optimal.regimes import OptimalRun
from cosim.optimal.ttobench import JourneySection
from plants.route import Route, StepProfile

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

PLANT_FMU = "Crh3Train"
STOP_WINDOW_M = 0.5  # m, Delta l_max of seed 003 sec. 4 (seed 000's requirement too)
TIME_WINDOW_S = 5.0  # s, Delta T_max of seed 003 sec. 4
SAMPLE_TIME = 0.2  # s, the speed PID's sample time (its default: a high-speed EMU)
RUN_MARGIN = 1.5  # the run lasts this many planned running times (the train stands at the end)
RECORDED = ("plant.v", "plant.s", "plant.a", "plant.applied_force", "plant.energy_traction",
            "plant.energy_regen", "plant.brake_work", "plant.power", "plant.speed_limit",
            "controller.v_ref", "controller.force_demand")


# -- route ------------------------------------------------------------------------------------
def _steps(profile: StepProfile, default: float) -> list[list[float]]:
    """``[[start, value], ...]`` of a step profile (the value before the first start is the
    first value, as :meth:`StepProfile.from_pairs` reads it); none when it is ``default``
    everywhere."""
    starts, values = profile.starts, profile.values
    if starts.size == 1:
        return [] if values[0] == default else [[0.0, float(values[0])]]
    return [[float(s), float(v)] for s, v in zip(starts[1:], values[1:])]


def _intervals(profile: StepProfile, outside: float, length: float
               ) -> list[tuple[float, float, float]]:
    """``(start, end, value)`` of the steps of a profile that differ from ``outside``, on the
    line ``[0, length]`` (m); a value that holds before the first start holds from 0, one that
    holds beyond the last start to 1 km past the line's end (the plant may overrun it)."""
    starts, values = profile.starts, profile.values
    ends = np.append(starts[1:], max(length, float(starts[-1])) + 1e3)
    out = []
    for start, end, value in zip(np.maximum(starts, 0.0), ends,
                                 values):
        if value != outside and end > start:
            out.append((float(start), float(end), float(value)))
    return out


def route_document(route: Route) -> dict[str, Any]:
    """The route TOML of ``route`` as a dict (module text; the tunnels' resistance as the
    one coefficient of the format, N/kN per m of tunnel length)."""
    doc: dict[str, Any] = {"name": route.name, "length_m": float(route.length_m)}
    grade = _steps(route.grade, 0.0)
    if grade:
        doc["grade"] = grade
    curves = [[a, b, r] for a, b, r in _intervals(route.curve_radius, math.inf, route.length_m)]
    if curves:
        doc["curves"] = curves
    tunnels = _intervals(route.tunnel, 0.0, route.length_m)
    if tunnels:
        w = {(a, b): r for a, b, r in _intervals(route.tunnel_resistance, 0.0, route.length_m)}
        coeffs = {w.get((a, b), 0.0) / (b - a) for a, b, _ in tunnels}
        if len(coeffs) > 1 and max(coeffs) - min(coeffs) > 1e-12 * max(coeffs):
            raise ValueError(f"route {route.name!r}: tunnels with different coefficients "
                             "(a route TOML has one)")
        doc["tunnels"] = [[a, b] for a, b, _ in tunnels]
        doc["tunnel_coefficient"] = coeffs.pop()
    limits = _steps(route.speed_limit, math.inf)
    if limits:
        doc["speed_limits"] = limits
    neutral = _intervals(route.neutral, 0.0, route.length_m)
    if neutral:
        doc["neutral_sections"] = [[a, b] for a, b, _ in neutral]
    if route.stations:
        doc["stations"] = [[name, float(x)] for name, x in route.stations]
    return doc


def _toml_value(value: Any) -> str:
    """A TOML literal of a number, string, bool or (nested) list of them."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ValueError(f"{value} has no TOML literal in a scenario")
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML literal for {value!r}")


def _toml_key(key: str) -> str:
    """A bare key where TOML allows one, else a quoted key."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def toml_text(doc: dict[str, Any], header: str = "") -> str:
    """TOML of ``doc``: plain keys first, then each table (nested dicts as dotted tables);
    read back with ``tomllib`` and compared, so what is written is what is meant."""
    lines = [f"# {line}" for line in header.splitlines()]

    def emit(table: dict[str, Any], name: str) -> None:
        plain = {k: v for k, v in table.items() if not isinstance(v, dict)}
        if name and (plain or not table):
            lines.extend(["", f"[{name}]"])
        for k, v in plain.items():
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in table.items():
            if isinstance(v, dict):
                emit(v, f"{name}.{k}" if name else k)

    emit(doc, "")
    text = "\n".join(lines) + "\n"
    if tomllib.loads(text) != json.loads(json.dumps(doc)):
        raise ValueError("TOML writer: the text does not read back as written")
    return text


def write_route(route: Route, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(toml_text(route_document(route), f"line {route.name} for the plant "
                              "(cosim optimal --closed-loop)"))
    return path


# -- plant and controllers ------------------------------------------------------------------
def top_speed(train: Train, route: Route) -> float:
    """The highest speed the train can reach on the line (m/s): its top speed, or the line's
    highest finite limit."""
    if math.isfinite(train.max_speed):
        return train.max_speed
    limits = route.speed_limit.values[np.isfinite(route.speed_limit.values)]
    if not limits.size:
        raise ValueError(f"train {train.name!r} has no top speed and line {route.name!r} no "
                         "speed limit: the plant's brake power needs one of them")
    return float(limits.max())


def plant_parameters(train: Train, route: Route) -> dict[str, float]:
    """``Crh3Train`` parameters of ``train`` (module text: the brake envelope mapping)."""
    v_top = top_speed(train, route)
    return {
        "mass": train.mass, "rotating_mass_factor": train.rotating_mass_factor,
        "davis_a": train.davis.a, "davis_b": train.davis.b, "davis_c": train.davis.c,
        "max_traction_force": train.max_traction_force,
        "max_traction_power": train.max_traction_power,
        "max_speed": v_top,
        "max_brake_force": train.max_regen_force + train.max_friction_force,
        "max_brake_power": train.max_regen_power + train.max_friction_force * v_top,
        "motor_efficiency": train.traction_efficiency,
        "regen_efficiency": train.regen_efficiency,
        "aux_power": 0.0, "length": 0.0,
    }


@dataclass(frozen=True)
class Controller:
    """A shipped tracking controller that takes a reference profile file."""

    fmu: str
    description: str
    component: Callable[[Train, Path], dict[str, Any]]  # [fmus.controller] table
    connections: dict[str, str]


def _pid(train: Train, reference: Path) -> dict[str, Any]:
    m = train.effective_mass
    brake = train.max_regen_force + train.max_friction_force
    return {"fmu": "EmuSpeedPid3", "sample_time": SAMPLE_TIME,
            "parameters": {"reference": str(reference), "mass": m, "accel_min": -brake / m,
                           "accel_max": train.max_traction_force / m},
            "inputs": {f"{kind}_limit[{i}]": 0.0 for kind in ("traction", "brake")
                       for i in (2, 3)}}


CONTROLLERS: dict[str, Controller] = {
    "pid": Controller("EmuSpeedPid3", "speed PID with reference-acceleration feedforward "
                      "(seeds 001, 004), default gains", _pid,
                      {"controller.v": "plant.v", "controller.s": "plant.s",
                       "controller.traction_limit[1]": "plant.traction_limit",
                       "controller.brake_limit[1]": "plant.brake_limit",
                       "plant.force": "controller.force[1]"}),
}


def controller(name: str) -> Controller:
    if name not in CONTROLLERS:
        raise ValueError(f"no closed-loop controller {name!r} (known: "
                         f"{', '.join(sorted(CONTROLLERS))})")
    return CONTROLLERS[name]


def scenario_document(section: Section, run: OptimalRun, train: Train, route_path: Path,
                      reference: Path, name: str, description: str) -> dict[str, Any]:
    """The scenario of the closed loop (module text)."""
    ctl = controller(name)
    return {
        "description": description,
        "simulation": {"stop_time": math.ceil(RUN_MARGIN * run.running_time + 30.0),
                       "output_interval": SAMPLE_TIME, "algorithm": "event",
                       "base_step": SAMPLE_TIME},
        "fmus": {"plant": {"fmu": PLANT_FMU, "parameters": {
                     "route": str(route_path), "v0": 0.0, "s0": float(section.start),
                     **plant_parameters(train, section.route)}},
                 "controller": ctl.component(train, reference)},
        "connections": ctl.connections,
        "record": {"variables": list(RECORDED)},
        "summary": {"position": "plant.s", "speed": "plant.v",
                    "reference_speed": "controller.v_ref",
                    "speed_limit": "plant.speed_limit", "command": "controller.force_demand",
                    "power": "plant.power", "stop_point": float(section.end),
                    "planned_arrival_time": run.running_time},
    }


# -- the closed loop against the plan --------------------------------------------------------
@dataclass(frozen=True)
class Window:
    """The windows the closed loop is checked against: the arrival within ``tolerance`` (s) of
    the ``schedule`` (the running time the plan is for, s from the departure), the stop within
    ``stop`` (m) of the stopping point (seed 003 sec. 4: Delta T_max = 5 s, Delta l_max =
    0.5 m), and with a journey its arrival window ``journey`` (earliest, latest running time,
    s)."""

    schedule: float
    tolerance: float = TIME_WINDOW_S
    stop: float = STOP_WINDOW_M
    journey: tuple[float, float] | None = None


@dataclass(frozen=True)
class Comparison:
    """Plan and closed loop of one section (energies J, times s, positions m)."""

    label: str
    planned_time: float
    planned_energy: float
    time: float | None  # running time of the closed loop (first sample at rest), None: moving
    reach_time: float | None  # first time the train is within the stop window (None: never)
    energy: float  # plan's accounting, regenerated work from the records
    plant_energy: float  # the plant's eq. 9 without auxiliary: all braking fed back
    traction_energy: float  # plant energy_traction
    regen_work: float  # recorded int min(B, B_r,max) v dt
    brake_work_records: float  # recorded int B v dt
    brake_work_plant: float  # plant brake_work (exact)
    stop_error: float
    max_speed_error: float  # m/s, largest |v - v_ref|
    over_limit: float  # m/s, largest excess of the speed over the line's limit (0: none)
    max_accel: float  # m/s2, largest acceleration of the closed loop
    max_decel: float  # m/s2, largest deceleration (> 0)
    window: Window
    missed: tuple[str, ...] = ()  # the journey's passing points the closed loop misses
    plan_missed: tuple[str, ...] = ()  # ... and those the plan misses (it plans the stops only)

    @property
    def arrival_error(self) -> float | None:
        """Closed-loop running time less the schedule (s; > 0 late)."""
        return None if self.time is None else self.time - self.window.schedule

    @property
    def on_time(self) -> bool:
        """Arrived within the tolerance of the schedule."""
        err = self.arrival_error
        return err is not None and abs(err) <= self.window.tolerance

    @property
    def in_journey_window(self) -> bool | None:
        """Arrived inside the journey's window (None without a journey)."""
        if self.window.journey is None:
            return None
        lo, hi = self.window.journey
        return self.time is not None and lo - 1e-9 <= self.time <= hi + 1e-9

    @property
    def stopped(self) -> bool:
        return self.time is not None and abs(self.stop_error) <= self.window.stop

    def verdict(self) -> list[str]:
        """What the closed loop misses (empty: every window kept)."""
        out = []
        if self.time is None:
            out.append("still moving at the end of the run")
        elif not self.on_time:
            out.append(f"arrival outside +-{self.window.tolerance:g} s")
        if self.time is not None and not self.stopped:
            out.append(f"stop outside +-{self.window.stop:g} m")
        if self.in_journey_window is False:
            out.append("outside the journey's window")
        planned = {m.split(" m ", 1)[0] for m in self.plan_missed}  # by position
        return out + [f"passing point {m}" + (" (so does the plan)" if m.split(" m ", 1)[0]
                                              in planned else "") for m in self.missed]

    def row(self) -> dict[str, Any]:
        lo, hi = self.window.journey or (None, None)
        return {"section": self.label, "schedule_s": self.window.schedule,
                "planned_time_s": self.planned_time, "time_s": self.time,
                "stop_window_reached_s": self.reach_time,
                "arrival_error_s": self.arrival_error, "time_window_s": self.window.tolerance,
                "on_time": self.on_time, "journey_earliest_s": lo, "journey_latest_s": hi,
                "in_journey_window": self.in_journey_window,
                "planned_energy_J": self.planned_energy, "energy_J": self.energy,
                "energy_ratio": self.energy / self.planned_energy if self.planned_energy else None,
                "plant_energy_J": self.plant_energy, "traction_energy_J": self.traction_energy,
                "regen_work_J": self.regen_work, "brake_work_records_J": self.brake_work_records,
                "brake_work_plant_J": self.brake_work_plant, "stop_error_m": self.stop_error,
                "stop_window_m": self.window.stop, "stopped_in_window": self.stopped,
                "max_speed_error_mps": self.max_speed_error, "over_limit_mps": self.over_limit,
                "max_accel_mps2": self.max_accel, "max_decel_mps2": self.max_decel,
                "missed_passing_points": "; ".join(self.missed),
                "plan_missed_passing_points": "; ".join(self.plan_missed),
                "verdict": "; ".join(self.verdict()) or "within the windows"}


def compare(label: str, run: OptimalRun, train: Train, frame: Any, summary: dict[str, Any],
            window: Window, journey: JourneySection | None = None) -> Comparison:
    """The closed loop's figures (module text) from its recorded ``frame`` and ``summary``;
    with ``journey``, the passing points it misses."""
    t = frame["time"].to_numpy(dtype=float)
    v = frame["plant.v"].to_numpy(dtype=float)
    force = frame["plant.applied_force"].to_numpy(dtype=float)
    brake = np.maximum(-force, 0.0)
    regen = np.minimum(brake, train.regen_limit(v) * train.effective_mass)
    traction = float(frame["plant.energy_traction"].iloc[-1])
    regen_work = float(np.trapezoid(regen * v, t))
    err = summary.get("arrival_time_error_s")
    s = frame["plant.s"].to_numpy(dtype=float)
    near = np.nonzero(np.abs(s - run.s[-1]) <= window.stop)[0]
    limit = frame["plant.speed_limit"].to_numpy(dtype=float)
    accel = frame["plant.a"].to_numpy(dtype=float)
    return Comparison(
        label=label, planned_time=run.running_time, planned_energy=run.energy,
        time=None if err is None else run.running_time + float(err),
        reach_time=float(t[near[0]]) if near.size else None,
        energy=traction - train.regen_efficiency * regen_work,
        plant_energy=traction - float(frame["plant.energy_regen"].iloc[-1]),
        traction_energy=traction, regen_work=regen_work,
        brake_work_records=float(np.trapezoid(brake * v, t)),
        brake_work_plant=float(frame["plant.brake_work"].iloc[-1]),
        stop_error=float(summary["stop_error_m"]),
        max_speed_error=float(np.max(np.abs(v - frame["controller.v_ref"].to_numpy()))),
        over_limit=float(max(np.max(v - limit), 0.0)),
        max_accel=float(max(np.max(accel), 0.0)), max_decel=float(max(-np.min(accel), 0.0)),
        window=window,
        missed=() if journey is None else tuple(journey.missed(s, t, v)),
        plan_missed=() if journey is None else tuple(journey.missed(run.s, run.t, run.v)))


#: runs a scenario file, writing its results into a folder: (recorded frame, summary)
Runner = Callable[[Path, Path], tuple[Any, dict[str, Any]]]


def run_section(label: str, section: Section, run: OptimalRun, train: Train, window: Window,
                out_dir: Path, route_path: Path, runner: Runner, controller_name: str = "pid",
                title: str = "", journey: JourneySection | None = None) -> Comparison:
    """Write the reference (``<label>.csv``) and scenario of a planned section into
    ``out_dir``, run it with
    ``runner`` (``cosim optimal`` passes the project's runner,
    :func:`cosim.run.simulate.run_scenario`; results in ``out_dir/<label>_<controller>/``) and
    compare it with the plan."""
    ctl = controller(controller_name)
    out_dir = Path(out_dir).resolve()
    reference = write_csv(run, train, out_dir / f"{label}.csv", title)
    doc = scenario_document(
        section, run, train, route_path.resolve(), reference, controller_name,
        f"{title or label}: {train.name} following the energy-optimal run, {ctl.description}")
    scenario = out_dir / f"{label}_{controller_name}.toml"
    scenario.write_text(toml_text(doc, "written by cosim optimal --closed-loop: the optimal "
                                  "run as the reference of a tracking controller"))
    frame, summary = runner(scenario, out_dir / f"{label}_{controller_name}")
    return compare(label, run, train, frame, summary, window, journey)


def write_table(rows: list[Comparison], path: Path) -> Path:
    """The comparisons as a CSV, a row per section (:meth:`Comparison.row`)."""
    import csv

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].row()))
        w.writeheader()
        for r in rows:
            w.writerow(r.row())
    return path
