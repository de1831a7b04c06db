"""Seed 003 (Ren, Xia) metrics beside eq. 9's energy account (:mod:`cosim.run.metrics`).

Table 2 counts the braking phase as a positive "consumption" (the energy the brakes take out of
the train, fed back and lost), which eq. 9 does not define; eq. 9's braking-phase net is
auxiliary minus regenerated energy, negative. With the summary key ``brake_work`` (a recorded
cumulative ``int(B v dt)``, J) and ``phase`` (1 accelerate, 2 run, 3 brake):

* ``energy_brake_work_mj``: the brakes' work over the output intervals that start in the brake
  phase, up to the arrival (MJ): Table 2's braking-phase convention;
* ``energy_total_paper_mj``: ``energy_accelerate_mj + energy_run_mj + energy_brake_work_mj``,
  the total in Table 2's convention (the paper's 11,302.2 and 9,205.4 MJ are such sums).
"""

from __future__ import annotations

from typing import Any

import numpy as np

BRAKE_PHASE = 3


def metrics(out: dict[str, Any], cfg: dict[str, Any], frame: Any, arrival_idx: int | None
            ) -> None:
    """Add the keys of the module docstring to ``out`` where the recording has them."""
    key, phase_key = cfg.get("brake_work"), cfg.get("phase")
    if not (isinstance(key, str) and isinstance(phase_key, str)):
        return
    if key not in frame or phase_key not in frame:
        return
    end = arrival_idx if arrival_idx is not None else len(frame) - 1
    work = frame[key].to_numpy(dtype=float)[: end + 1]
    phase = frame[phase_key].to_numpy(dtype=float)[:end]
    steps = np.diff(work)  # interval i: samples i -> i + 1, in the phase of sample i
    out["energy_brake_work_mj"] = float(np.sum(steps[phase == BRAKE_PHASE])) / 1e6
    if "energy_accelerate_mj" in out and "energy_run_mj" in out:
        out["energy_total_paper_mj"] = (out["energy_accelerate_mj"] + out["energy_run_mj"]
                                        + out["energy_brake_work_mj"])
