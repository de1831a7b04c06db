"""A deliberately non-compliant FMU for the compliance suite's own tests (plain pythonfmu).

Each fault is planted for one check; ``test_broken_fmu.py`` asserts each is reported:

* pythonfmu's stock modelDescription (outputs missing from InitialUnknowns, no units,
  no output dependencies)                          -> fmpy-validation, units, model-structure
* a module-level run counter shifts the output     -> reset, two-instances
* a hidden attribute not in the FMU state          -> fmu-state
* doStep before initialisation is accepted         -> wrong-state
* doStep after terminate raises: plain pythonfmu    -> wrong-state (fmi2Fatal, not fmi2Error)
  turns the Python exception into fmi2Fatal
* NaN/inf inputs are accepted and reach the output  -> non-finite-inputs
* a negative step size aborts the host process      -> invalid-step (reported as a crash)
* a NaN parameter never returns                     -> bad-parameters (reported as a hang)
"""

import math
import os
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

_RUNS = [0]  # shared by every instance in the process: instances are not independent


class BrokenTrain(Fmi2Slave):
    """Speed integrator with planted faults."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.gain = 1.0
        self.u = 0.0
        self.v = 0.0
        self._hidden = 0.0  # affects the output, not saved in the FMU state
        self._terminated = False
        self.register_variable(Real("gain", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed,
                                    setter=self._set_gain))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("v", causality=Fmi2Causality.output))

    def to_xml(self, model_options=None):
        # claims FMU state support although the hidden attribute is not part of the state
        options = dict(model_options or {})
        options.update(canGetAndSetFMUstate="true", canSerializeFMUstate="true")
        return super().to_xml(options)

    def _set_gain(self, value):
        while math.isnan(value):  # hangs the host
            time.sleep(0.05)
        self.gain = value

    def exit_initialization_mode(self):
        _RUNS[0] += 1

    def terminate(self):
        self._terminated = True

    def do_step(self, current_time, step_size):
        if self._terminated:  # a correct rejection, but pythonfmu reports it as fmi2Fatal
            raise RuntimeError("doStep after terminate")
        if step_size < 0:
            os.abort()
        self._hidden += step_size
        self.v += self.gain * self.u * step_size + 1e-3 * self._hidden + 1e-3 * _RUNS[0]
        return True
