"""FMUs of :class:`plants.emu.Emu`: one per number of units (FMI variables are fixed).

``Emu3`` runs the 3-unit configurations (``crh380a_3unit``, ``crh3_3car``), ``Emu8`` the 8-car
``crh3_8car``. The ``configuration`` parameter selects the data; the coupler parameters set to
-1 keep the configuration's value.
"""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave
from plants.emu import Emu


class Emu3Fmu(PlantSlave):
    """EMU with 3 units and spring-damper couplers (CRH380A seed 001, CRH3 3-car seed 004)."""

    core_class = Emu
    core_options = {"units": 3}
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2


class Emu8Fmu(Emu3Fmu):
    """EMU with 8 cars and spring-damper couplers (CRH3 8-car, seed 004)."""

    core_options = {"units": 8}
