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
* ``ctcs3`` (bool): the scenario is speed tracking under the CTCS-3 rule (seeds 001, 004):
  gives ``ctcs3_speed_error_ok``, which means nothing for a stopping or freight scenario;
* ``reference_accel`` (m/s^2, with ``speed`` and ``reference_speed``): the moving samples are
  split by the sign of the reference acceleration into traction (> 0), cruise (0) and braking
  (< 0) and give ``max_abs_speed_error_{traction,cruise,braking}_kmh``; ``final_stop_window``
  (m, with ``stop_point`` and ``position``) leaves the last metres before the stop point out of
  these and gives ``max_abs_speed_error_outside_stop_kmh`` and ``speed_rmse_kmh`` over the same
  samples (seed 002);
* ``accel_command`` (m/s^2): the controllers' acceleration demand, giving
  ``command_min``, ``command_max`` and ``command_total_variation`` (sum of |changes|, the
  chattering measure);
* ``vehicle_speeds`` (list or glob, m/s): the train-mean speed (plain mean over the vehicles)
  against the reference gives ``train_mean_speed_rmse_kmh`` and
  ``max_abs_train_mean_speed_error_kmh`` (same samples and window as the mode errors);
* ``unit_speeds`` (list or ``"plant.v[*]"``, m/s, with ``reference_speed``): the per-power-unit
  indices of seed 001 (:func:`unit_indices`): ``unit_mse_kmh2`` (eq. 87), ``unit_iae_kmh_s``
  (eq. 88) and ``unit_ma_mps_per_sample`` (eq. 89) at the sample time ``ma_sample_time``
  (s, default 1.0; reported as ``ma_sample_time_s``), and the same in SI units,
  ``unit_mse_mps2`` and ``unit_iae_m`` (:mod:`cosim.papers.seed001`);
* ``unit_accelerations`` (list or ``"plant.a[*]"``, m/s^2) with ``comfort_limit`` (m/s^2,
  default 1): ``unit_max_abs_accel_mps2``, ``comfort_exceeded``, ``comfort_exceedance_s``
  and ``comfort_limit_mps2`` (:func:`cosim.papers.seed001.comfort`).
* ``energy_traction``, ``energy_regen``, ``energy_aux`` (recorded cumulative energies in J,
  seed 003 eq. 9: traction / eta_M, regenerated eta_b int(B v dt), auxiliary e0 t): give
  ``energy_traction_mj``, ``energy_regen_mj``, ``energy_aux_mj`` and ``energy_net_mj`` =
  traction - regen + aux (MJ), each counted from the first sample up to the arrival (the first
  sample of the final standstill, as for ``arrival_time_error_s``; the end of the run if the
  train never came to rest), so that standing at the terminus does not add auxiliary energy;
* ``phase`` (with the three energies: a recorded phase index, 1 accelerate, 2 run, 3 brake, as
  the seed-003 controllers publish it from their profile): ``energy_accelerate_mj``,
  ``energy_run_mj``, ``energy_brake_mj``, the net energy of eq. 9 over the output intervals
  that start in each phase (Table 2; the same window as ``energy_net_mj``, so they sum to it).

Always present: ``completed`` (False, with ``error``, for the partial results of a failed or
interrupted run), ``sim_time_s``, ``wall_time_s``, ``real_time_factor``, ``algorithm``,
``do_steps``, ``executions``, ``fmu_wall_time_s``; controller counters (``qp_solves``,
``qp_infeasible``; ``qp_solve_time_median_s``, ``qp_solve_time_total_s`` and
``qp_cpu_time_total_s``, the median and total wall time and the total CPU time of the run's
solves, which the FMU logs at fmi2Terminate (:mod:`cosim.fmu.diagnostics`; never outputs);
``qp_infeasible_after_stop``, ``events_moving``, ``events_standstill``) when an FMU publishes
them; ``terminated_by``
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


def ctcs3_allowance_kmh(v_ref_kmh: np.ndarray, limit_kmh: float = 2.0,
                        below_kmh: float = 30.0, fraction: float = 0.02) -> np.ndarray:
    """CTCS-3 speed-error allowance: ``limit_kmh`` at or below ``below_kmh``, else
    ``fraction`` of the speed (seed 001, sec. 4.2: 2 km/h, 30 km/h, 2 %)."""
    v = np.asarray(v_ref_kmh, dtype=float)
    return np.where(v <= below_kmh, limit_kmh, fraction * v)


def ctcs3_speed_error_ok(v_ref_kmh: np.ndarray, error_kmh: np.ndarray) -> bool:
    """CTCS-3 rule: |error| <= 2 km/h at or below 30 km/h, <= 2 % of the speed above."""
    return bool(np.all(np.abs(error_kmh) <= ctcs3_allowance_kmh(v_ref_kmh) + 1e-12))


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


def unit_indices(t: np.ndarray, speeds: np.ndarray, ref: np.ndarray,
                 ma_sample_time: float) -> dict[str, float]:
    """Seed 001's indices over the ``n`` power units (``speeds`` (T, n), m/s; ``ref`` (T,)):

    * eq. 87 ``MSE = 1/(nT) sum_i sum_t e_i(t)^2`` over every recorded sample, e in km/h;
    * eq. 88 ``IAE = 1/n sum_i int |e_i| dt`` (trapezoid), km/h s;
    * eq. 89 ``MA = max_{t,i} |y_i(t) - y_i(t-1)|``: the largest speed change of a unit over
      one sample of ``ma_sample_time`` seconds (m/s per sample; speeds interpolated on that
      grid from the start). With a 1 s sample it equals the largest mean acceleration over
      1 s in m/s^2, which is what Table 2 lists; it is not ``max_abs_accel_mps2`` (the largest
      instantaneous train acceleration).
    """
    err_kmh = (speeds - ref[:, None]) * KMH_PER_MPS
    grid = np.arange(t[0], t[-1] + 1e-9, ma_sample_time)
    sampled = np.column_stack([np.interp(grid, t, speeds[:, i]) for i in range(speeds.shape[1])])
    ma = float(np.max(np.abs(np.diff(sampled, axis=0)))) if grid.size > 1 else 0.0
    return {
        "unit_mse_kmh2": float(np.mean(err_kmh**2)),
        "unit_iae_kmh_s": float(np.mean(np.trapezoid(np.abs(err_kmh), t, axis=0))),
        "unit_ma_mps_per_sample": ma,
        "ma_sample_time_s": float(ma_sample_time),
    }


# event counters an FMU may publish (outputs of the same name), reported per FMU like qp_solves
CONTROLLER_COUNTERS = ("qp_infeasible_after_stop", "events_moving", "events_standstill")


# default switch resolution, relative to the command's full scale (max |u| over the run): a
# change below a millionth of full scale is rounding or solver noise (DAQP solves exactly; the
# seed 000 counts are unchanged by it but for 3 of RMPC's 199), not a decision of the controller
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
        ref = np.array([curve.speed(x) for x in pos])

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
    if out.get("max_abs_speed_error_kmh") is not None and cfg.get("ctcs3") is True:
        out["ctcs3_speed_error_ok"] = ctcs3_speed_error_ok(ref[moving if np.any(moving) else
                                                               slice(None)] * KMH_PER_MPS,
                                                           err_kmh)
    unit_cols = matching_columns(frame, cfg.get("unit_speeds"))
    if unit_cols and ref is not None:
        from cosim.papers import seed001

        unit_v = frame[unit_cols].to_numpy(dtype=float)
        out.update(unit_indices(t, unit_v, ref, float(cfg.get("ma_sample_time", 1.0))))
        out.update(seed001.unit_tracking_si(t, unit_v, ref))
    accel_cols = matching_columns(frame, cfg.get("unit_accelerations"))
    if accel_cols:
        from cosim.papers import seed001

        out.update(seed001.comfort(t, frame[accel_cols].to_numpy(dtype=float),
                                   float(cfg.get("comfort_limit", 1.0))))
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
        out["energy_kj"] = out["energy_kwh"] * 3.6e3  # seed 004's unit
    arrival_idx = _arrival_index(speed)
    if speed is not None and "planned_arrival_time" in cfg:
        if arrival_idx is not None:
            arrival = t[arrival_idx]
            out["arrival_time_error_s"] = float(arrival - float(cfg["planned_arrival_time"]))
        else:
            out["arrival_time_error_s"] = None  # never came to rest inside the run
    _energy_metrics(out, cfg, frame, arrival_idx)

    _seed002_metrics(out, cfg, frame, pos, speed, ref)
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
        for key in CONTROLLER_COUNTERS:  # published by the seed 000 predictive controllers
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


PHASES = ((1, "accelerate"), (2, "run"), (3, "brake"))


def _energy_metrics(out: dict[str, Any], cfg: dict[str, Any], frame: Any,
                    arrival_idx: int | None) -> None:
    """Seed 003 energy account (eq. 9) and Table 2's energy per phase, in MJ."""
    series = (_series(frame, cfg.get("energy_traction")), _series(frame, cfg.get("energy_regen")),
              _series(frame, cfg.get("energy_aux")))
    if any(v is None for v in series):
        return
    end = arrival_idx if arrival_idx is not None else len(frame) - 1
    trac, regen, aux = (values[: end + 1] for values in series)
    net = trac - regen + aux
    for key, values in (("traction", trac), ("regen", regen), ("aux", aux), ("net", net)):
        out[f"energy_{key}_mj"] = float(values[-1] - values[0]) / 1e6
    phase = _series(frame, cfg.get("phase"))
    if phase is None:
        return
    steps = np.diff(net)  # interval i: samples i -> i + 1, in the phase of sample i
    for index, name in PHASES:
        out[f"energy_{name}_mj"] = float(np.sum(steps[phase[:end] == index])) / 1e6


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
    return found


def _flatten_single(out: dict[str, Any], keys: tuple[str, ...]) -> None:
    """A counter published by exactly one FMU is reported as a plain number."""
    for key in keys:
        if isinstance(out.get(key), dict) and len(out[key]) == 1:
            out[key] = next(iter(out[key].values()))


def _seed002_metrics(out: dict[str, Any], cfg: dict[str, Any], frame: Any,
                     pos: np.ndarray | None, speed: np.ndarray | None,
                     ref: np.ndarray | None) -> None:
    """Per-mode speed errors, command range and variation, train-mean errors (seed 002)."""
    command = _series(frame, cfg.get("accel_command"))
    if command is not None:
        out["command_min"] = float(np.min(command))
        out["command_max"] = float(np.max(command))
        out["command_total_variation"] = float(np.sum(np.abs(np.diff(command))))
    accel = _series(frame, cfg.get("reference_accel"))
    if speed is None or ref is None:
        return
    keep = ref > 0.0
    if pos is not None and "final_stop_window" in cfg and "stop_point" in cfg:
        keep &= pos < float(cfg["stop_point"]) - float(cfg["final_stop_window"])
    err_kmh = (speed - ref) * KMH_PER_MPS
    if accel is not None and np.any(keep):
        out["speed_rmse_kmh"] = float(np.sqrt(np.mean(err_kmh[keep] ** 2)))
    if accel is not None:
        if "final_stop_window" in cfg:
            out["max_abs_speed_error_outside_stop_kmh"] = (
                float(np.max(np.abs(err_kmh[keep]))) if np.any(keep) else None)
        for mode, sel in (("traction", accel > 0), ("cruise", accel == 0),
                          ("braking", accel < 0)):
            part = err_kmh[keep & sel]
            out[f"max_abs_speed_error_{mode}_kmh"] = (float(np.max(np.abs(part)))
                                                     if part.size else None)
    cols = matching_columns(frame, cfg.get("vehicle_speeds"))
    if cols and np.any(keep):
        mean = frame[cols].to_numpy(dtype=float).mean(axis=1)
        e_mean = (mean - ref)[keep] * KMH_PER_MPS
        out["train_mean_speed_rmse_kmh"] = float(np.sqrt(np.mean(e_mean**2)))
        out["max_abs_train_mean_speed_error_kmh"] = float(np.max(np.abs(e_mean)))
