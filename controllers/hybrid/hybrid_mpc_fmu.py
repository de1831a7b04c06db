"""FMUs of the seed 004 hybrid MPCs (:mod:`controllers.hybrid.hybrid_mpc`) for the 3-car EMU.

``Gmpc3`` is the MIQP of eq. 15 solved at every sample; ``MbMpc3`` the same with the inputs held
over blocks (3:4:3 for N = 10, eq. 17); ``Empc3`` the explicit law of eq. 18 looked up in
offline region data. All three drive ``Emu3`` with the ``crh3_3car``
configuration and track a speed-time reference.
"""

from __future__ import annotations

from controllers.hybrid.explicit_mpc import ExplicitMpc
from controllers.hybrid.hybrid_mpc import HybridMpc, MoveBlockingMpc
from cosim.fmu.slave import SampledControllerSlave


class Gmpc3Fmu(SampledControllerSlave):
    """Hybrid MPC (MIQP, traction/brake mode, PWA resistance) for a 3-car EMU (seed 004)."""

    core_class = HybridMpc
    core_options = {"units": 3}
    default_experiment_stop_time = 100.0
    default_experiment_step = 1.0


class MbMpc3Fmu(Gmpc3Fmu):
    """Move-blocking hybrid MPC (inputs held over blocks 3:4:3) for a 3-car EMU (seed 004)."""

    core_class = MoveBlockingMpc


class Empc3Fmu(Gmpc3Fmu):
    """Explicit hybrid MPC (offline mp-QP regions, bounding-box tree lookup) for a 3-car EMU."""

    core_class = ExplicitMpc
