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

from __future__ import annotations

import importlib
from typing import Any

# name -> (module of this package, its name there): imported on first use (PEP 562), so that a
# process that needs one part (the compliance worker: the FMI 2 logging callbacks) does not
# import the others (the algorithms' compiled C loop and its builder)
_PARTS: dict[str, tuple[str, str]] = {
    **{n: ("algorithms", n) for n in ("ALGORITHM_CLASSES", "Algorithm", "EventDriven",
                                      "FixedStep", "Jacobi")},
    **{n: ("core", n) for n in ("WARNING_COUNTER", "Link", "Master", "ProgressFn",
                                "RunResult")},
    **{n: ("errors", n) for n in ("FmuCallError", "FmuTerminated", "SimulationError")},
    **{n: ("fmi2", n) for n in ("CheckedSlave", "Fmi2Unit", "logging_callbacks")},
    **{n: ("loading", n) for n in ("_EXTRACTED", "extract_once", "open_fmu", "read_fmu",
                                   "unit_class", "warm_up")},
    **{n: ("observers", n) for n in ("Observer", "Recorder")},
    **{n: ("unit", n) for n in ("MAX_HALVINGS", "Unit", "Variable")},
    "FmuUnit": ("fmi2", "Fmi2Unit"),  # the FMI 2.0 unit (the name tests and plug-ins patch)
}


def __getattr__(name: str) -> Any:
    if name not in _PARTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, attr = _PARTS[name]
    value = getattr(importlib.import_module(f"{__name__}.{module}"), attr)
    globals()[name] = value  # later reads (and a monkeypatch) see a plain attribute
    return value


__all__ = sorted(_PARTS)
