"""FMUs of the seed-001 data-driven controllers for the 3-unit EMU (``Emu3``).

All four share one interface (:mod:`controllers.datadriven.emu_control`): per-unit speeds
``v[i]``, head position ``s`` and the plant's ``traction_limit[i]``/``brake_limit[i]`` in,
per-unit ``force[i]`` out, so a scenario swaps them by the FMU name.
"""

from __future__ import annotations

from controllers.datadriven.emu_control import EmuGpc, EmuIsmc, EmuIsmpc, EmuMfac
from cosim.fmu.slave import SampledControllerSlave


class EmuMfac3Fmu(SampledControllerSlave):
    """FFDL-MFAC speed control of a 3-unit EMU (seed 001 baseline)."""

    core_class = EmuMfac
    core_options = {"units": 3}
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2


class EmuIsmc3Fmu(EmuMfac3Fmu):
    """FFDL integral sliding-mode speed control of a 3-unit EMU (seed 001 eq. 26)."""

    core_class = EmuIsmc


class EmuIsmpc3Fmu(EmuMfac3Fmu):
    """FFDL integral sliding-mode predictive speed control of a 3-unit EMU (seed 001 eq. 75)."""

    core_class = EmuIsmpc


class EmuGpc3Fmu(EmuMfac3Fmu):
    """GPC speed control of a 3-unit EMU with RLS identification (seed 001 baseline)."""

    core_class = EmuGpc
