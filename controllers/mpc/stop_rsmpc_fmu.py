"""FMU of :class:`controllers.mpc.stop_mpc.SelfTriggeredStopMpc` (seed 000 RSMPC)."""

from __future__ import annotations

from controllers.mpc.stop_mpc import SelfTriggeredStopMpc
from controllers.mpc.stop_mpc_fmu import StopMpcFmu


class StopRsmpcFmu(StopMpcFmu):
    """Robust self-triggered MPC for accurate stopping: holds the command M samples (sec. 3)."""

    core_class = SelfTriggeredStopMpc
