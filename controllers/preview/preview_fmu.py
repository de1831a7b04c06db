"""FMU of :class:`controllers.preview.preview.FreightPreview` (seed 002)."""

from __future__ import annotations

from controllers.preview.preview import FreightPreview
from cosim.fmu.slave import SampledControllerSlave


class FreightPreviewFmu(SampledControllerSlave):
    """Optimal preview speed tracking of the freight train with the shared blending (seed 002)."""

    core_class = FreightPreview
    default_experiment_stop_time = 100.0
    default_experiment_step = 0.2
