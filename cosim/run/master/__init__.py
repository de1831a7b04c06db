"""Co-simulation master on fmpy, FMI 2.0 and FMI 3.0 co-simulation FMUs side by side.

The parts, as in libcosim:

* units (:mod:`.unit`, one subclass per standard: :mod:`.fmi2`, :mod:`.fmi3`) handle one FMU
  instance behind one interface (values by name, doStep, events, state, terminate);
* algorithms (:mod:`.algorithms`: event-driven, fixed step, Jacobi) decide when each FMU
  steps and in which order values flow;
* observers (:mod:`.observers`) keep what happens at the output points;
* :mod:`.core` ties them together for a scenario (:class:`Master`), returning a result and
  writing nothing (:func:`cosim.run.simulate.run_scenario` writes it).
"""

from cosim.run.master.algorithms import (
    ALGORITHM_CLASSES,
    Algorithm,
    EventDriven,
    FixedStep,
    Jacobi,
)
from cosim.run.master.core import (
    WARNING_COUNTER,
    Link,
    Master,
    ProgressFn,
    RunResult,
)
from cosim.run.master.errors import FmuCallError, FmuTerminated, SimulationError
from cosim.run.master.fmi2 import CheckedSlave, Fmi2Unit, logging_callbacks
from cosim.run.master.loading import _EXTRACTED, extract_once, read_fmu, unit_class, warm_up
from cosim.run.master.observers import Observer, Recorder
from cosim.run.master.unit import MAX_HALVINGS, Unit, Variable

FmuUnit = Fmi2Unit  # the FMI 2.0 unit (the name tests and plug-ins patch)

__all__ = [
    "ALGORITHM_CLASSES", "MAX_HALVINGS", "WARNING_COUNTER", "_EXTRACTED", "Algorithm",
    "CheckedSlave", "EventDriven", "FixedStep", "Fmi2Unit", "FmuCallError", "FmuTerminated",
    "FmuUnit", "Jacobi", "Link", "Master", "Observer", "ProgressFn", "Recorder", "RunResult",
    "SimulationError", "Unit", "Variable", "extract_once", "logging_callbacks",
    "read_fmu", "unit_class", "warm_up",
]
