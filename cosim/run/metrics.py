"""Summary metrics of a run, driven by the scenario's ``[summary]`` table.

Keys of ``[summary]`` (all optional; variable references are ``FMU.variable``):

* ``position`` (m), ``speed`` (m/s), ``acceleration`` (m/s^2), ``command``, ``reference_speed``
  (m/s), ``speed_limit`` (m/s), ``power`` (W, traction minus regenerated),
  ``coupler_forces`` (list or ``"plant.coupler_force[*]"``, N);
* ``command``: gives ``command_switches``, the changes of the command (between successive
  values passed to the plant, or recorded when it is not connected) larger than
  ``command_resolution`` (command units; default 1e-6 of max |command| over the run), and
  ``command_switch_resolution``, the resolution used;
* ``stop_point`` (m): gives ``stop_error_m`` = final position - stop point (signed);
* ``reference_decel`` (m/s^2, with ``stop_point``): the speed metrics compare the speed with the
  stopping curve ``v_ref(s) = sqrt(2 a0 (s_stop - s))`` at the recorded positions instead of a
  recorded ``reference_speed`` (which a self-triggered controller holds between its events);
* ``planned_arrival_time`` (s): gives ``arrival_time_error_s`` (time the train came to rest
  minus the plan);
* ``accel_command`` (m/s^2): the controllers' acceleration demand, giving
  ``command_min``, ``command_max`` and ``command_total_variation`` (sum of |changes|, the
  chattering measure);
* ``metrics`` (list of names): the paper metrics registered in :mod:`cosim.papers` that the
  scenario uses; each reads its own ``[summary]`` keys (valid only where it is named) and adds
  its entries after the generic ones.

Always present: ``completed`` (False, with ``error``, for the partial results of a failed or
interrupted run), ``sim_time_s``, ``wall_time_s``, ``real_time_factor``, ``algorithm``,
``do_steps``, ``executions``, ``fmu_wall_time_s``; controller counters (``qp_solves``,
``qp_infeasible``; ``qp_solve_time_median_s``, ``qp_solve_time_total_s`` and
``qp_cpu_time_total_s``, the median and total wall time and the total CPU time of the run's
solves, which the FMU logs at fmi2Terminate (:mod:`cosim.fmu.diagnostics`; never outputs);
``qp_infeasible_after_stop``, ``events_moving``, ``events_standstill``, ``lmi_fallbacks``)
when an FMU publishes them; ``terminated_by``
(``{instance, time}``) when an FMU ended the run itself (fmi2Discard with fmi2Terminated, FMI
2.0.4 sec. 4.2.2; ``completed`` stays true).
"""

from __future__ import annotations

import importlib
import math
from typing import Any

import numpy as np

from cosim.fmu.profiles import StoppingCurve

KMH_PER_MPS = 3.6
PAPERS = "cosim.papers"  # the registry of paper metrics (a layer above this one)
STANDSTILL_MPS = 1e-3
STOP_WINDOW_M = 0.5  # m, the ATO stop window +-50 cm


def graded_allowance(v_ref: np.ndarray, limit: float, below: float,
                     fraction: float) -> np.ndarray:
    """A speed-error allowance graded by the reference speed: ``limit`` at or below ``below``,
    ``fraction`` of the speed above (the speeds and the result in the same unit)."""
    v = np.asarray(v_ref, dtype=float)
    return np.where(v <= below, limit, fraction * v)


def _series(frame: Any, ref: Any) -> np.ndarray | None:
    """The recorded column ``ref`` (None when absent, or when nothing was recorded)."""
    if isinstance(ref, str) and ref in frame.columns and len(frame):
        return frame[ref].to_numpy(dtype=float)
    return None


def matching_columns(frame: Any, ref: Any) -> list[str]:
    """The recorded columns named by ``ref``: a name, ``"plant.v[*]"`` (every column of that
    pattern) or a list of those; absent ones are left out."""
    refs = ref if isinstance(ref, list) else [ref]
    cols: list[str] = []
    for r in refs:
        if not isinstance(r, str):
            continue
        if "*" in r:
            head, _, tail = r.partition("*")
            cols += [c for c in frame.columns if c.startswith(head) and c.endswith(tail)]
        elif r in frame.columns:
            cols.append(r)
    return cols


# event counters an FMU may publish (outputs of the same name), reported per FMU like qp_solves
CONTROLLER_COUNTERS = ("qp_infeasible_after_stop", "events_moving", "events_standstill",
                       "lmi_fallbacks")


# default switch resolution, relative to the command's full scale (max |u| over the run): a
# change below a millionth of full scale is rounding or solver noise (DAQP solves exactly),
# not a decision of the controller
COMMAND_RESOLUTION_REL = 1e-6


def command_switches(values: Any, resolution: float | None = None) -> tuple[int, float]:
    """``(switches, resolution)``: how many times the command changed by more than
    ``resolution`` from one value to the next (a step between two successive values; a
    flat command with solver or rounding noise below the resolution has none, a slow ramp
    whose every step is below it neither). ``resolution`` (command units) defaults to
    ``COMMAND_RESOLUTION_REL`` times the command's full scale, max |u| over the run."""
    u = np.asarray(values, dtype=float)
    u = u[np.isfinite(u)]
    if resolution is None:
        resolution = COMMAND_RESOLUTION_REL * float(np.max(np.abs(u))) if u.size else 0.0
    count = int(np.count_nonzero(np.abs(np.diff(u)) > resolution)) if u.size > 1 else 0
    return count, float(resolution)


def compute_summary(result: Any) -> dict[str, Any]:
    """The ``summary.json`` content of a :class:`cosim.run.master.RunResult`."""
    cfg = result.scenario.summary
    frame = result.frame
    t = frame["time"].to_numpy(dtype=float)
    out: dict[str, Any] = {
        "scenario": result.scenario.name,
        "algorithm": result.algorithm,
        "sim_time_s": result.sim_time_s,
        "wall_time_s": round(result.wall_time_s, 4),
        "real_time_factor": (round(result.sim_time_s / result.wall_time_s, 2)
                             if result.wall_time_s > 0 else None),
        "completed": result.completed,
    }
    if result.error:
        out["error"] = result.error
    if getattr(result, "terminated_by", None):
        out["terminated_by"] = result.terminated_by  # an FMU ended the run (fmi2Terminated)
    pos = _series(frame, cfg.get("position"))
    speed = _series(frame, cfg.get("speed"))
    accel = _series(frame, cfg.get("acceleration"))
    ref = _series(frame, cfg.get("reference_speed"))
    if pos is not None and "reference_decel" in cfg and "stop_point" in cfg:
        curve = StoppingCurve(float(cfg["reference_decel"]), float(cfg["stop_point"]))
        ref = curve.speeds(pos)

    if pos is not None and "stop_point" in cfg:
        out["stop_error_m"] = float(pos[-1] - float(cfg["stop_point"]))
    if pos is not None:
        out["final_position_m"] = float(pos[-1])
    if speed is not None:
        out["final_speed_mps"] = float(speed[-1])
    command = cfg.get("command")
    if isinstance(command, str):
        # every value the master passed on when the command is connected, else the recording
        values = result.connection_values.get(command)
        if values is None:
            values = _series(frame, command)
        if values is not None:
            res = cfg.get("command_resolution")
            out["command_switches"], out["command_switch_resolution"] = command_switches(
                values, None if res is None else float(res))
    notes: list[str] = []  # metrics the recording cannot resolve: reported, never 0
    if speed is not None and ref is not None and np.count_nonzero(ref > 0.0) < 2:
        notes.append(f"speed-tracking metrics undefined: {np.count_nonzero(ref > 0.0)} recorded "
                     f"sample(s) while the reference is moving (output_interval "
                     f"{result.scenario.simulation.output_interval:g} s); they need at least "
                     "2: lower simulation.output_interval")
        for key in ("speed_rmse_mps", "speed_mse_kmh2", "iae_kmh_s", "max_abs_speed_error_kmh"):
            out[key] = None
    elif speed is not None and ref is not None:
        err = speed - ref
        moving = ref > 0.0
        err_m = err[moving] if np.any(moving) else err
        err_kmh = err_m * KMH_PER_MPS
        out["speed_rmse_mps"] = float(np.sqrt(np.mean(err_m**2)))
        out["speed_mse_kmh2"] = float(np.mean(err_kmh**2))
        out["iae_kmh_s"] = float(np.trapezoid(np.abs(err * KMH_PER_MPS), t))
        out["max_abs_speed_error_kmh"] = float(np.max(np.abs(err_kmh)))
    if accel is not None:
        out["max_abs_accel_mps2"] = float(np.max(np.abs(accel)))
        if accel.size > 1:
            jerk = np.diff(accel) / np.diff(t)
            if speed is not None:  # while moving: the step to rest at the stop is not ride jerk
                moving = (speed[:-1] > STANDSTILL_MPS) & (speed[1:] > STANDSTILL_MPS)
                jerk = jerk[moving]
            if jerk.size:
                out["max_jerk_mps3"] = float(np.max(np.abs(jerk)))
            else:
                out["max_jerk_mps3"] = None
                notes.append("max_jerk_mps3 undefined: fewer than 2 recorded samples while "
                             "moving: lower simulation.output_interval")
    cols = matching_columns(frame, cfg.get("coupler_forces"))
    if cols and len(frame):
        out["max_coupler_force_kn"] = float(np.max(np.abs(frame[cols].to_numpy())) / 1e3)
    power = _series(frame, cfg.get("power"))
    if power is not None:
        out["energy_kwh"] = float(np.trapezoid(power, t) / 3.6e6)
        out["energy_kj"] = out["energy_kwh"] * 3.6e3
    arrival_idx = _arrival_index(speed)
    if speed is not None and "planned_arrival_time" in cfg:
        if arrival_idx is not None:
            arrival = t[arrival_idx]
            out["arrival_time_error_s"] = float(arrival - float(cfg["planned_arrival_time"]))
        else:
            out["arrival_time_error_s"] = None  # never came to rest inside the run
    out.update(command_range(_series(frame, cfg.get("accel_command"))))
    out.update(paper_metrics(result.scenario.summary, frame, out, t, pos, speed, ref,
                             arrival_idx))
    out["executions"] = dict(result.executions)
    out["do_steps"] = dict(result.do_steps)
    out["fmu_wall_time_s"] = {k: round(v, 4) for k, v in result.fmu_wall_time_s.items()}
    for fmu, outputs in result.final_outputs.items():
        if "qp_solves" in outputs:
            out.setdefault("qp_solves", {})[fmu] = int(outputs["qp_solves"])
            out.setdefault("qp_infeasible", {})[fmu] = int(outputs.get("qp_infeasible", 0))
        timing = result.diagnostics.get(fmu, {})  # logged at fmi2Terminate, not outputs
        for name in ("qp_solve_time_median", "qp_solve_time_total", "qp_cpu_time_total",
                     "qp_cpu_time_median"):
            if name in timing and math.isfinite(timing[name]):
                out.setdefault(f"{name}_s", {})[fmu] = float(timing[name])
        for key in CONTROLLER_COUNTERS:  # published by the predictive laws
            if key in outputs:
                out.setdefault(key, {})[fmu] = int(outputs[key])
    out["warnings"] = warnings(result) + notes
    _flatten_single(out, ("qp_solves", "qp_infeasible", "qp_solve_time_median_s",
                          "qp_solve_time_total_s", "qp_cpu_time_total_s",
                          "qp_cpu_time_median_s", *CONTROLLER_COUNTERS))
    return out


def _arrival_index(speed: np.ndarray | None) -> int | None:
    """Index of the first sample of the final standstill (None: still moving at the end)."""
    if speed is None:
        return None
    moving_idx = np.nonzero(speed > STANDSTILL_MPS)[0]
    if moving_idx.size and moving_idx[-1] + 1 < speed.size:
        return int(moving_idx[-1] + 1)
    return None


def command_range(command: np.ndarray | None) -> dict[str, float]:
    """``command_min``, ``command_max`` and ``command_total_variation`` (sum of |changes|, the
    chattering measure) of a recorded command (nothing when it is not recorded)."""
    if command is None:
        return {}
    return {"command_min": float(np.min(command)), "command_max": float(np.max(command)),
            "command_total_variation": float(np.sum(np.abs(np.diff(command))))}


def paper_metrics(cfg: dict[str, Any], frame: Any, generic: dict[str, Any], t: np.ndarray,
                  pos: np.ndarray | None, speed: np.ndarray | None, ref: np.ndarray | None,
                  arrival_idx: int | None) -> dict[str, Any]:
    """The entries of the metrics ``[summary] metrics`` names (:mod:`cosim.papers`)."""
    names = cfg.get("metrics") or []
    if not names:
        return {}
    papers = importlib.import_module(PAPERS)  # the plug-ins above this layer, by name

    record = papers.RunRecord(frame=frame, summary=cfg, metrics=dict(generic), time=t,
                              position=pos, speed=speed, reference_speed=ref,
                              arrival_index=arrival_idx)
    return papers.compute(list(names), record)


def warnings(result: Any) -> list[str]:
    """Things that went wrong without stopping the run, for the user: today, events whose QP
    was infeasible (the controller then applied its fallback law), with the count and the
    first time (from the recorded counter, to the output interval)."""
    found: list[str] = []
    frame = result.frame
    for fmu, outputs in result.final_outputs.items():
        count = int(outputs.get("qp_infeasible", 0) or 0)
        if count <= 0:
            continue
        solves = int(outputs.get("qp_solves", 0) or 0)
        column = f"{fmu}.qp_infeasible"
        first = ""
        if column in frame.columns and len(frame):
            rising = np.nonzero(frame[column].to_numpy(dtype=float) > 0)[0]
            if rising.size:
                first = f", first by t = {float(frame['time'].iloc[rising[0]]):g} s"
        solved = f", {solves} QPs solved" if solves else ""
        found.append(f"{fmu}: infeasible QP at {count} events{first}{solved}; the fallback law "
                     "was applied (the constraints could not be met)")
    return found + non_finite(frame)


def non_finite(frame: Any) -> list[str]:
    """A warning per recorded real variable that was NaN or infinite: its first time and
    value (results.csv holds NaN as an empty cell)."""
    found: list[str] = []
    if np.isfinite(frame.select_dtypes("float").to_numpy()).all():
        return found  # one test over the whole recording; column by column only when one fails
    for column in frame.columns[1:]:
        if frame[column].dtype.kind != "f":
            continue
        values = frame[column].to_numpy()
        bad = np.nonzero(~np.isfinite(values))[0]
        if bad.size:
            first = bad[0]
            found.append(f"{column} is {values[first]} from t = "
                         f"{float(frame['time'].iloc[first]):g} s on ({bad.size} of "
                         f"{len(values)} recorded points are NaN or infinite)")
    return found


def _flatten_single(out: dict[str, Any], keys: tuple[str, ...]) -> None:
    """A counter published by exactly one FMU is reported as a plain number."""
    for key in keys:
        if isinstance(out.get(key), dict) and len(out[key]) == 1:
            out[key] = next(iter(out[key].values()))
