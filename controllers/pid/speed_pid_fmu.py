"""FMUs of :class:`controllers.pid.speed_pid.DistributedSpeedPid` for the EMU plants.

``EmuSpeedPid3`` drives ``Emu3`` (3 units), ``EmuSpeedPid8`` drives ``Emu8``. The reference is a
bundled profile name or a file (see :mod:`plants.route`), looked up by the measured head
position (speed-distance) or by time (speed-time).
"""

from __future__ import annotations

from controllers.pid.speed_pid import DistributedSpeedPid
from cosim.fmu.slave import SampledControllerSlave


class EmuSpeedPid3Fmu(SampledControllerSlave):
    """Speed-tracking PID with per-unit force distribution for a 3-unit EMU (seeds 001, 004)."""

    core_class = DistributedSpeedPid
    core_options = {"units": 3}
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2


class EmuSpeedPid8Fmu(EmuSpeedPid3Fmu):
    """Speed-tracking PID with per-unit force distribution for an 8-car EMU (seed 004)."""

    core_options = {"units": 8}
