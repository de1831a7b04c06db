"""Metrics of seed 003 (CRH3 energy-efficient operation): the energy account of eq. 9 and
Table 2's energy per driving phase, in MJ, and the distance-time tracking of Fig. 6."""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.papers import RunRecord, metric

PHASES = ((1, "accelerate"), (2, "run"), (3, "brake"))


@metric("energy", keys=("energy_traction", "energy_regen", "energy_aux"),
        description="eq. 9's energies from the recorded cumulative ones (J), from the start up "
                    "to the arrival (the first sample of the final standstill)",
        outputs={"energy_traction_mj": ("traction energy, int F v dt / eta_M", "MJ"),
                 "energy_regen_mj": ("regenerated energy, eta_b int B v dt", "MJ"),
                 "energy_aux_mj": ("auxiliary energy, e0 t", "MJ"),
                 "energy_net_mj": ("traction - regenerated + auxiliary", "MJ")})
def energy(run: RunRecord) -> dict[str, Any]:
    """From the recorded cumulative energies (J; eq. 9: traction / eta_M, regenerated
    eta_b int(B v dt), auxiliary e0 t): ``energy_traction_mj``, ``energy_regen_mj``,
    ``energy_aux_mj`` and ``energy_net_mj`` = traction - regen + aux (MJ), each counted from
    the first sample up to the arrival (the first sample of the final standstill; the end of
    the run if the train never came to rest), so that standing at the terminus adds no
    auxiliary energy."""
    net = _net(run)
    if net is None:
        return {}
    trac, regen, aux = net[1]
    return {f"energy_{key}_mj": float(values[-1] - values[0]) / 1e6
            for key, values in (("traction", trac), ("regen", regen), ("aux", aux),
                                ("net", net[0]))}


@metric("energy_phases", keys=("energy_traction", "energy_regen", "energy_aux", "phase"),
        description="eq. 9's net energy over the output intervals starting in each of Table "
                    "2's phases (1 accelerate, 2 run, 3 brake); they add up to energy_net_mj",
        outputs={"energy_accelerate_mj": ("net energy, accelerate phase", "MJ"),
                 "energy_run_mj": ("net energy, run phase", "MJ"),
                 "energy_brake_mj": ("net energy, brake phase", "MJ")})
def energy_phases(run: RunRecord) -> dict[str, Any]:
    """With ``phase`` (a recorded phase index, 1 accelerate, 2 run, 3 brake, as the
    controllers publish it from their profile): ``energy_accelerate_mj``, ``energy_run_mj``,
    ``energy_brake_mj``, the net energy of eq. 9 over the output intervals that start in each
    phase (Table 2; the window of :func:`energy`, so they sum to ``energy_net_mj``)."""
    net = _net(run)
    phase = run.series("phase")
    if net is None or phase is None:
        return {}
    end = net[0].size - 1
    steps = np.diff(net[0])  # interval i: samples i -> i + 1, in the phase of sample i
    return {f"energy_{name}_mj": float(np.sum(steps[phase[:end] == index])) / 1e6
            for index, name in PHASES}


def _net(run: RunRecord) -> tuple[np.ndarray, tuple[np.ndarray, ...]] | None:
    """(net, (traction, regen, aux)) up to the arrival, J; None when one is not recorded."""
    series = (run.series("energy_traction"), run.series("energy_regen"),
              run.series("energy_aux"))
    if any(v is None for v in series):
        return None
    end = run.arrival_index if run.arrival_index is not None else len(run.frame) - 1
    trac, regen, aux = (values[: end + 1] for values in series)
    return trac - regen + aux, (trac, regen, aux)


@metric("energy_brake_work", keys=("energy_traction", "energy_regen", "energy_aux", "phase",
                                   "brake_work"),
        description="Table 2's braking convention: the brakes' work over the brake phase "
                    "counted as a positive consumption",
        outputs={"energy_brake_work_mj": ("the brakes' work int B v dt over the brake phase, "
                                          "up to the arrival", "MJ"),
                 "energy_total_paper_mj": ("eq. 9's energy of the accelerate and run phases "
                                           "plus the brake work (Table 2's total)", "MJ")})
def energy_brake_work(run: RunRecord) -> dict[str, Any]:
    """Table 2's braking convention beside eq. 9's: Table 2 counts the braking phase as a
    positive "consumption" (the energy the brakes take out of the train, fed back and lost),
    which eq. 9 does not define. With ``brake_work`` (the recorded cumulative int(B v dt), J):
    ``energy_brake_work_mj``, the brakes' work over the output intervals that start in the
    brake phase, up to the arrival (MJ), and ``energy_total_paper_mj`` = the eq. 9 energy of
    the accelerate and run phases plus that (Table 2's total)."""
    net, work, phase = _net(run), run.series("brake_work"), run.series("phase")
    if net is None or work is None or phase is None:
        return {}
    end = net[0].size - 1
    brake = phase[:end] == PHASES[2][0]
    net_steps = np.diff(net[0])
    brake_work = float(np.sum(np.diff(work[: end + 1])[brake])) / 1e6
    return {"energy_brake_work_mj": brake_work,
            "energy_total_paper_mj": float(np.sum(net_steps[~brake])) / 1e6 + brake_work}


@metric("distance_tracking", keys=("reference_position",),
        description="the distance-time tracking of Fig. 6: the position error s - s_ref(t) "
                    "against the profile's time-indexed position, from the start up to the "
                    "arrival (the first sample of the final standstill)",
        outputs={"distance_rmse_m": ("RMS of s - s_ref(t) up to the arrival", "m"),
                 "max_abs_distance_error_m": ("largest absolute s - s_ref(t) up to the "
                                              "arrival", "m")})
def distance_tracking(run: RunRecord) -> dict[str, Any]:
    """With ``reference_position`` (the recorded s_ref(t), the profile's position at the time
    since departure, m) and the run's position: ``distance_rmse_m``, the RMS of s - s_ref over
    the recorded samples from the start up to the arrival (the end of the run if the train
    never came to rest), and ``max_abs_distance_error_m``, the largest |s - s_ref| there
    (m)."""
    ref = run.series("reference_position")
    if ref is None or run.position is None:
        return {}
    end = run.arrival_index if run.arrival_index is not None else len(ref) - 1
    err = run.position[: end + 1] - ref[: end + 1]
    return {"distance_rmse_m": float(np.sqrt(np.mean(err ** 2))),
            "max_abs_distance_error_m": float(np.max(np.abs(err)))}
