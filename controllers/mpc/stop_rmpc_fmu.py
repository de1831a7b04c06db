"""FMU of :class:`controllers.mpc.stop_mpc.TubeStopMpc` (seed 000 tube RMPC)."""

from __future__ import annotations

from controllers.mpc.stop_mpc import TubeStopMpc
from controllers.mpc.stop_mpc_fmu import StopMpcFmu


class StopRmpcFmu(StopMpcFmu):
    """Tube-based robust MPC for accurate stopping, resistance as bounded disturbance (sec. 2.2)."""

    core_class = TubeStopMpc
