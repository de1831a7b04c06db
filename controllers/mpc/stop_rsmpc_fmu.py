"""FMU wrapper of :class:`controllers.mpc.stop_mpc.SelfTriggeredStopMpc` (seed 000 RSMPC)."""

from __future__ import annotations

from controllers.mpc.stop_mpc import SelfTriggeredStopMpc, StopMpcParams
from controllers.mpc.stop_mpc_fmu import MPC_VARS, StopMpcSlave
from cosim.fmu.slave import Var

_D = StopMpcParams()


class StopRsmpcFmu(StopMpcSlave):
    """Robust self-triggered MPC for accurate stopping: holds the command M samples (sec. 3)."""

    core_class = SelfTriggeredStopMpc
    variables = (
        Var("beta", "parameter", _D.beta, "1",
            "beta >= 1: suboptimality traded for fewer executions (eq. 22, 25)", min=1.0),
        *MPC_VARS,
    )
