"""Summary metrics of a run, driven by the scenario's ``[summary]`` table.

Keys of ``[summary]`` (all optional; variable references are ``FMU.variable``):

* ``position`` (m), ``speed`` (m/s), ``acceleration`` (m/s^2), ``command``, ``reference_speed``
  (m/s), ``speed_limit`` (m/s), ``power`` (W, traction minus regenerated),
  ``coupler_forces`` (list or ``"plant.coupler_force[*]"``, N);
* ``stop_point`` (m): gives ``stop_error_m`` = final position - stop point (signed);
* ``reference_decel`` (m/s^2, with ``stop_point``): the speed metrics compare the speed with the
  stopping curve ``v_ref(s) = sqrt(2 a0 (s_stop - s))`` at the recorded positions instead of a
  recorded ``reference_speed`` (which a self-triggered controller holds between its events);
* ``planned_arrival_time`` (s): gives ``arrival_time_error_s`` (time the train came to rest
  minus the plan).

Always present: ``completed`` (False, with ``error``, for the partial results of a failed or
interrupted run), ``sim_time_s``, ``wall_time_s``, ``real_time_factor``, ``algorithm``,
``do_steps``, ``executions``, ``fmu_wall_time_s``; controller counters (``qp_solves``,
``qp_infeasible``, ``qp_solve_time_median_s``, ``qp_infeasible_after_stop``, ``events_moving``,
``events_standstill``) when an FMU publishes them; ``terminated_by``
(``{instance, time}``) when an FMU ended the run itself (fmi2Discard with fmi2Terminated, FMI
2.0.4 sec. 4.2.2; ``completed`` stays true).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cosim.fmu.profiles import StoppingCurve

KMH_PER_MPS = 3.6
STANDSTILL_MPS = 1e-3


def ctcs3_speed_error_ok(v_ref_kmh: np.ndarray, error_kmh: np.ndarray) -> bool:
    """CTCS-3 rule: |error| <= 2 km/h at or below 30 km/h, <= 2 % of the speed above."""
    allowed = np.where(v_ref_kmh <= 30.0, 2.0, 0.02 * v_ref_kmh)
    return bool(np.all(np.abs(error_kmh) <= allowed + 1e-12))


def _series(frame: Any, ref: Any) -> np.ndarray | None:
    """The recorded column ``ref`` (None when absent, or when nothing was recorded)."""
    if isinstance(ref, str) and ref in frame.columns and len(frame):
        return frame[ref].to_numpy(dtype=float)
    return None


def _columns(frame: Any, ref: Any) -> list[str]:
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
CONTROLLER_COUNTERS = ("qp_infeasible_after_stop", "events_moving", "events_standstill")


def _count_changes(x: np.ndarray) -> int:
    return int(np.count_nonzero(np.diff(x) != 0.0)) if x.size > 1 else 0


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
        ref = np.array([curve.speed(x) for x in pos])

    if pos is not None and "stop_point" in cfg:
        out["stop_error_m"] = float(pos[-1] - float(cfg["stop_point"]))
    if pos is not None:
        out["final_position_m"] = float(pos[-1])
    if speed is not None:
        out["final_speed_mps"] = float(speed[-1])
    command = cfg.get("command")
    if isinstance(command, str):
        src = command
        if src in result.connection_changes:
            out["command_switches"] = result.connection_changes[src]
        else:
            series = _series(frame, src)
            if series is not None:
                out["command_switches"] = _count_changes(series)
    if speed is not None and ref is not None:
        err = speed - ref
        moving = ref > 0.0
        err_m = err[moving] if np.any(moving) else err
        err_kmh = err_m * KMH_PER_MPS
        out["speed_rmse_mps"] = float(np.sqrt(np.mean(err_m**2)))
        out["speed_mse_kmh2"] = float(np.mean(err_kmh**2))
        out["iae_kmh_s"] = float(np.trapezoid(np.abs(err * KMH_PER_MPS), t))
        out["max_abs_speed_error_kmh"] = float(np.max(np.abs(err_kmh)))
        out["ctcs3_speed_error_ok"] = ctcs3_speed_error_ok(ref[moving if np.any(moving) else
                                                               slice(None)] * KMH_PER_MPS,
                                                           err_kmh)
    if accel is not None:
        out["max_abs_accel_mps2"] = float(np.max(np.abs(accel)))
        if accel.size > 1:
            jerk = np.diff(accel) / np.diff(t)
            if speed is not None:  # while moving: the step to rest at the stop is not ride jerk
                moving = (speed[:-1] > STANDSTILL_MPS) & (speed[1:] > STANDSTILL_MPS)
                jerk = jerk[moving]
            out["max_jerk_mps3"] = float(np.max(np.abs(jerk))) if jerk.size else 0.0
    cols = _columns(frame, cfg.get("coupler_forces"))
    if cols and len(frame):
        out["max_coupler_force_kn"] = float(np.max(np.abs(frame[cols].to_numpy())) / 1e3)
    power = _series(frame, cfg.get("power"))
    if power is not None:
        out["energy_kwh"] = float(np.trapezoid(power, t) / 3.6e6)
    if speed is not None and "planned_arrival_time" in cfg:
        moving_idx = np.nonzero(speed > STANDSTILL_MPS)[0]
        if moving_idx.size and moving_idx[-1] + 1 < speed.size:
            arrival = t[moving_idx[-1] + 1]
            out["arrival_time_error_s"] = float(arrival - float(cfg["planned_arrival_time"]))
        else:
            out["arrival_time_error_s"] = None  # never came to rest inside the run

    out["executions"] = dict(result.executions)
    out["do_steps"] = dict(result.do_steps)
    out["fmu_wall_time_s"] = {k: round(v, 4) for k, v in result.fmu_wall_time_s.items()}
    for fmu, outputs in result.final_outputs.items():
        if "qp_solves" in outputs:
            out.setdefault("qp_solves", {})[fmu] = int(outputs["qp_solves"])
            out.setdefault("qp_infeasible", {})[fmu] = int(outputs.get("qp_infeasible", 0))
            median = outputs.get("qp_solve_time_median")
            out.setdefault("qp_solve_time_median_s", {})[fmu] = (
                float(median) if median is not None and math.isfinite(median) else None)
        for key in CONTROLLER_COUNTERS:  # published by the seed 000 predictive controllers
            if key in outputs:
                out.setdefault(key, {})[fmu] = int(outputs[key])
    _flatten_single(out, ("qp_solves", "qp_infeasible", "qp_solve_time_median_s",
                          *CONTROLLER_COUNTERS))
    return out


def _flatten_single(out: dict[str, Any], keys: tuple[str, ...]) -> None:
    """A counter published by exactly one FMU is reported as a plain number."""
    for key in keys:
        if isinstance(out.get(key), dict) and len(out[key]) == 1:
            out[key] = next(iter(out[key].values()))
