"""FMI 2.0 co-simulation slave base classes that wrap a plain-Python core.

This module is bundled into every FMU (it imports only the standard library, numpy and
pythonfmu), so it must not import anything else from this package.

What it adds to pythonfmu's ``Fmi2Slave``:

* declarative variables (:class:`Var`) with units, min/max and descriptions, written into a
  modelDescription.xml that passes ``fmpy.validation.validate_fmu`` (UnitDefinitions,
  InitialUnknowns, and ModelStructure/Outputs with the *real* dependencies: a plant's outputs
  depend on no input, a controller's outputs depend on its inputs);
* FMU state (get/set/serialize) covering the *whole* core state, not only registered variables;
* the timing contract of ``SPEC.md`` for sampled and self-triggered controllers: at an event,
  outputs are computed on read from the current inputs (nothing committed) and the event is
  committed by doStep from the inputs it is given; outputs hold until the next event; the
  events inside a longer doStep are executed with the inputs held at the step's start (said
  once in the log; the parameter ``strict_steps`` refuses such a step instead), and a doStep
  that does not continue from the controller's time is refused.

Times are kept in integer nanoseconds so that sample times ``k * T`` never drift.
"""

from __future__ import annotations

import copy
import ctypes
import functools
import json
import math
import sys
from pathlib import Path
from typing import Any, ClassVar
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from cosim.fmu import diagnostics
from cosim.fmu.declare import UNITS, Var, out_of_range
from cosim.fmu.state import to_seconds, to_ticks

BUNDLE_DIR = "atocosim_bundle"  # project code and data inside an FMU's resources folder

_TYPES = {float: Real, int: Integer, bool: Boolean, str: String}


CONTROLLER_TIMING_VARS: tuple[Var, ...] = (
    Var("next_event_time", "output", 0.0, "s",
        "time of this controller's next event (sample or self-triggered)"),
    Var("executions", "output", 0, "1", "number of events computed so far"),
    Var("strict_steps", "parameter", False, description=(
        "true: refuse a doStep that passes over one of this controller's events; false: "
        "execute every event inside the step with the inputs held at the step's start")),
)


class FmuStateError(ValueError):
    """A serialized FMU state that does not belong to this FMU."""


def _encode(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": str(obj.dtype), "shape": list(obj.shape)}
    if isinstance(obj, dict):
        return {"__dict__": [[_encode(k), _encode(v)] for k, v in obj.items()]}
    if isinstance(obj, tuple):
        return {"__tuple__": [_encode(v) for v in obj]}
    if isinstance(obj, list):
        return [_encode(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return {"__float__": repr(obj)}
    return obj


def _decode(obj: Any) -> Any:
    if isinstance(obj, list):
        return [_decode(v) for v in obj]
    if isinstance(obj, dict):
        if "__ndarray__" in obj:
            return np.array(obj["__ndarray__"], dtype=obj["dtype"]).reshape(obj["shape"])
        if "__dict__" in obj:
            return {_decode(k): _decode(v) for k, v in obj["__dict__"]}
        if "__tuple__" in obj:
            return tuple(_decode(v) for v in obj["__tuple__"])
        if "__float__" in obj:
            return float(obj["__float__"])
    return obj


# FMI calls a master can make on a slave (pythonfmu method names); see ``_guarded``.
_FMI_ENTRY_POINTS = (
    "setup_experiment", "enter_initialization_mode", "exit_initialization_mode", "do_step",
    "terminate", "get_real", "get_integer", "get_boolean", "get_string", "set_real",
    "set_integer", "set_boolean", "set_string", "_get_fmu_state", "_set_fmu_state",
)


def _keep_alive_after_pythonfmu_error(slave: Fmi2Slave) -> None:
    """Undo pythonfmu 0.7's spurious reference drops when a Python exception reaches it.

    ``PySlaveInstance::handle_py_exception`` (pythonfmu 0.7.x) calls ``cleanPyObject``, which
    decrements the references it holds to the slave class, the slave instance and its log queue
    without clearing them, then returns fmi2Fatal. After a few rejected calls the live instance
    is freed and the host crashes (use after free). One extra reference per exception keeps the
    instance valid (the master may still read, reset or free it); the price is a small leak.
    """
    incref = ctypes.pythonapi.Py_IncRef
    incref.argtypes = [ctypes.py_object]
    incref.restype = None
    for obj in (type(slave), slave, slave.log_queue):
        incref(obj)


def _hold_entry_module_globals(cls: type) -> None:
    """Undo pythonfmu 0.7's release of a borrowed reference on every fmi2Instantiate.

    Its ``findClass`` re-executes the FMU entry module and then decrements the reference count
    of the module's globals dict, which it only borrowed (``PyModule_GetDict``). Without this
    extra reference the third instance of one FMU in a process frees the dict: instantiation
    fails ("module has no attribute ''") or the host crashes. Called once per slave object.
    """
    module = sys.modules.get(cls.__module__)
    if module is not None:
        incref = ctypes.pythonapi.Py_IncRef
        incref.argtypes = [ctypes.py_object]
        incref.restype = None
        incref(module.__dict__)


def _guarded(name: str, method):
    """Wrap an FMI entry point: log a rejected call clearly and keep the instance alive.

    The exception still propagates, so pythonfmu returns a non-OK status (fmi2Fatal in 0.7.x:
    it maps every Python exception to fmi2Fatal) and logs it; only the outermost call of a
    nested chain (``super()``) compensates pythonfmu's reference drops.
    """

    @functools.wraps(method)
    def call(self, *args: Any, **kwargs: Any) -> Any:
        depth = self.__dict__.get("_fmi_depth", 0)
        self._fmi_depth = depth + 1
        try:
            return method(self, *args, **kwargs)
        except BaseException as err:
            if depth == 0:
                self.log(f"{self.instance_name}: {name} rejected: {err}", Fmi2Status.error)
                _keep_alive_after_pythonfmu_error(self)
            raise
        finally:
            self._fmi_depth = depth

    call._fmi_guarded = True  # type: ignore[attr-defined]
    return call


class CoreSlave(Fmi2Slave):
    """Base of every FMU in this project: variables, modelDescription, state handling.

    A subclass names its ``core_class`` (and ``core_options``, e.g. ``{"units": 3}``); its
    ``variables`` are the core's declarations (``core_class.declarations(**core_options)``, see
    :mod:`cosim.fmu.declare`) and the core is built by
    ``core_class.from_parameters(values, data_dir, t0, **core_options)``, which raises
    ``ValueError`` naming the parameter on a bad value.
    """

    variables: ClassVar[tuple[Var, ...]] = ()
    core_class: ClassVar[Any] = None
    core_options: ClassVar[dict[str, Any]] = {}
    output_variability: ClassVar[str] = "continuous"
    default_experiment_stop_time: ClassVar[float] = 10.0
    default_experiment_step: ClassVar[float] = 0.1

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.description = self.__class__.__doc__.strip().splitlines()[0] if self.__doc__ else None
        self.author = "ato-cosim"
        self.version = "0.1.0"
        self.values: dict[str, Any] = {}
        self.core: Any = None
        self.outputs: dict[str, Any] = {}
        self.initialized = False
        self.executions = 0
        self.start_ticks = 0
        # FMI 2 state: instantiated, initialization, initialized, terminated
        self.mode = "instantiated"
        _hold_entry_module_globals(type(self))
        for var in self.variables:
            if var.causality in ("parameter", "input"):
                self.values[var.name] = var.start
        self._by_name = {v.name: v for v in self.variables}
        self._input_names = tuple(v.name for v in self.variables if v.causality == "input")
        # value reference -> name of each Real output: get_real reads them in one pass
        self._real_outputs = {vr: v.name for vr, v in enumerate(self.variables)
                              if v.causality == "output" and v.type is float}
        for var in self.variables:
            self._register(var)

    # -- variables -------------------------------------------------------------------------
    def resource_path(self, *parts: str) -> Path:
        """Path of a bundled data file or folder, e.g. ``("plants", "routes")``.

        Inside an FMU this is the instance's own resources folder (never a module's
        ``__file__``: pythonfmu caches modules by name, so a module may come from another
        extraction of the same FMU); outside an FMU, the project tree.
        """
        if self.resources:
            bundled = Path(self.resources).joinpath(BUNDLE_DIR, *parts)
            if bundled.exists():
                return bundled
        return Path(__file__).resolve().parents[2].joinpath(*parts)

    def _register(self, var: Var) -> None:
        cls = _TYPES[var.type]
        causality = getattr(Fmi2Causality, var.causality)
        variability = getattr(Fmi2Variability, var.resolved_variability(self.output_variability))
        if var.causality == "output":
            getter = self._output_getter(var.name)
            setter = None
        else:
            getter = self._value_getter(var.name)
            setter = self._value_setter(var)
        self.register_variable(
            cls(var.name, causality=causality, variability=variability, description=var.description,
                getter=getter, setter=setter),
            nested=False,
        )

    def _value_getter(self, name: str):
        return lambda: self.values[name]

    def _value_setter(self, var: Var):
        kind = var.type

        def setter(value: Any) -> None:
            if var.causality == "parameter" and self.initialized:
                raise ValueError(f"parameter {var.name!r} is fixed after initialisation")
            if kind is float:
                value = float(value)
                if not math.isfinite(value):
                    raise ValueError(f"{var.name} = {value}: not a finite number")
            if var.min is not None and value < var.min or var.max is not None and value > var.max:
                if var.causality == "parameter":
                    raise ValueError(f"{var.name} = {out_of_range(value, var.min, var.max)}")
            self.values[var.name] = kind(value)
            if var.causality == "parameter":
                self.core = None  # rebuilt from the new parameters on next use
            else:
                self.on_input(var.name)

        return setter

    def _output_getter(self, name: str):
        def getter() -> Any:
            self.ensure_core()
            self.refresh_outputs()
            return self.outputs[name]

        return getter

    # -- hooks for subclasses ------------------------------------------------------------------
    @classmethod
    def declared_variables(cls) -> tuple[Var, ...]:
        """The FMU's variables: the core's declarations (controllers add their timing)."""
        return tuple(cls.core_class.declarations(**cls.core_options))

    def make_core(self) -> Any:
        return self.core_class.from_parameters(self.values, data_dir=self.resource_path(),
                                               t0=to_seconds(self.start_ticks),
                                               **self.core_options)

    def core_outputs(self) -> dict[str, Any]:
        """Current output values computed from the core's state."""
        return self.core.outputs()

    def on_input(self, name: str) -> None:
        """Called after an input was set."""

    def refresh_outputs(self) -> None:
        """Make ``self.outputs`` current (plants: from state; controllers: run a due event)."""

    def inputs(self) -> dict[str, Any]:
        values = self.values
        return {name: values[name] for name in self._input_names}

    def ensure_core(self) -> None:
        if self.core is None:
            try:
                self.core = self.make_core()
            except (ValueError, TypeError, KeyError, OSError) as err:
                self.log(f"{self.instance_name}: bad parameter: {err}", Fmi2Status.error)
                raise
            self.after_core_built()

    def after_core_built(self) -> None:
        self.outputs = dict(self.core_outputs())

    # -- FMI calls -----------------------------------------------------------------------------
    def get_real(self, vrs: list[int]) -> list[float]:
        """Real outputs in one pass: the outputs are made current once per call, not once per
        variable (a plant's 100+ recorded outputs cost one dict lookup each); any other
        variable (or a bad reference) goes through pythonfmu's generic path."""
        outputs = self._real_outputs
        try:
            names = [outputs[vr] for vr in vrs]
        except (KeyError, TypeError):
            return super().get_real(vrs)
        if not names:
            return []
        self.ensure_core()
        self.refresh_outputs()
        values = self.outputs
        return [float(values[name]) for name in names]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.core_class is not None and "variables" not in cls.__dict__:
            cls.variables = cls.declared_variables()
        for name in _FMI_ENTRY_POINTS:
            method = cls.__dict__.get(name)
            if method is not None and not getattr(method, "_fmi_guarded", False):
                setattr(cls, name, _guarded(name, method))

    def require_mode(self, call: str, *modes: str) -> None:
        """Reject an FMI call made in the wrong state (FMI 2.0 sec. 4.2.4 state machine)."""
        if self.mode not in modes:
            raise RuntimeError(f"{call} not allowed in state {self.mode!r} "
                               f"(allowed in: {', '.join(modes)})")

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        self.require_mode("fmi2SetupExperiment", "instantiated")
        if not math.isfinite(start_time):
            raise ValueError(f"start time {start_time} is not finite")
        self.start_ticks = to_ticks(start_time)

    def enter_initialization_mode(self) -> None:
        self.require_mode("fmi2EnterInitializationMode", "instantiated")
        self.initialized = False
        self.mode = "initialization"

    def exit_initialization_mode(self) -> None:
        self.require_mode("fmi2ExitInitializationMode", "initialization")
        self.ensure_core()
        self.initialized = True
        self.mode = "initialized"

    def terminate(self) -> None:
        self.require_mode("fmi2Terminate", "initialized")
        report = getattr(self.core, "diagnostics", None)
        if callable(report):  # run-dependent timings: logged once, never outputs or state
            self.log(diagnostics.message(self.instance_name, report()), Fmi2Status.ok)
        self.mode = "terminated"

    # -- FMU state: the whole core, not only registered variables -------------------------------
    def _get_fmu_state(self) -> dict[str, Any]:
        self.ensure_core()
        return {
            "fmu": self.modelName,
            "values": copy.deepcopy(self.values),
            "slave": copy.deepcopy(self.slave_state()),
            "core": self.core_state(),
            "outputs": copy.deepcopy(self.outputs),
            "executions": self.executions,
            "initialized": self.initialized,
            "mode": self.mode,
        }

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        if not isinstance(state, dict) or state.get("fmu") != self.modelName:
            raise FmuStateError(f"state does not belong to FMU {self.modelName}")
        params = [v.name for v in self.variables if v.causality == "parameter"]
        same_core = self.core is not None and all(
            self.values.get(n) == state["values"].get(n) for n in params)
        self.values = copy.deepcopy(state["values"])
        if not same_core:  # the core (DARE, sets, route, QP set-up) depends on parameters only
            self.core = None
            self.initialized = False
            self.ensure_core()
        self.core.set_state(copy.deepcopy(state["core"]))
        self.set_slave_state(copy.deepcopy(state["slave"]))
        self.outputs = copy.deepcopy(state["outputs"])
        self.executions = state["executions"]
        self.initialized = state["initialized"]
        self.mode = state.get("mode", "initialized" if self.initialized else "instantiated")

    def core_state(self) -> Any:
        """The core state an FMU state holds (a copy)."""
        return self.core.get_state()

    def slave_state(self) -> dict[str, Any]:
        return {}

    def set_slave_state(self, state: dict[str, Any]) -> None:
        pass

    @staticmethod
    def _fmu_state_to_bytes(state: dict[str, Any]) -> bytes:
        return json.dumps(_encode(state)).encode("utf-8")

    @staticmethod
    def _fmu_state_from_bytes(data: bytes) -> dict[str, Any]:
        return _decode(json.loads(bytes(data).decode("utf-8")))

    # -- modelDescription ----------------------------------------------------------------------
    def to_xml(self, model_options: dict[str, str] | None = None) -> Element:
        options = dict(model_options or {})
        options.setdefault("canGetAndSetFMUstate", "true")
        options.setdefault("canSerializeFMUstate", "true")
        root = super().to_xml(options)
        for tag in ("ModelVariables", "ModelStructure", "DefaultExperiment"):
            node = root.find(tag)
            if node is not None:
                root.remove(node)
        children = list(root)
        for child in children:
            root.remove(child)
        cosim = [c for c in children if c.tag == "CoSimulation"]
        rest = [c for c in children if c.tag != "CoSimulation"]
        for child in cosim:
            root.append(child)
        root.append(self._unit_definitions())
        for child in rest:  # LogCategories
            root.append(child)
        SubElement(root, "DefaultExperiment", {
            "startTime": "0.0",
            "stopTime": repr(float(self.default_experiment_stop_time)),
            "stepSize": repr(float(self.default_experiment_step)),
        })
        root.append(self._model_variables())
        root.append(self._model_structure())
        return root

    def _unit_definitions(self) -> Element:
        node = Element("UnitDefinitions")
        for unit in sorted({v.unit for v in self.variables if v.type is float}):
            exponents, factor = UNITS[unit]
            u = SubElement(node, "Unit", {"name": unit})
            attrib = {k: str(e) for k, e in exponents.items()}
            if factor != 1.0:
                attrib["factor"] = repr(factor)
            SubElement(u, "BaseUnit", attrib)
        return node

    def _model_variables(self) -> Element:
        node = Element("ModelVariables")
        for vr, var in enumerate(self.variables):
            attrib = {
                "name": var.name,
                "valueReference": str(vr),
                "description": var.description or var.name,
                "causality": var.causality,
                "variability": var.resolved_variability(self.output_variability),
            }
            if var.causality == "parameter":
                attrib["initial"] = "exact"
            elif var.causality == "output":
                attrib["initial"] = "calculated"
            sv = SubElement(node, "ScalarVariable", attrib)
            type_attrib: dict[str, str] = {}
            if var.type is float:
                type_attrib["unit"] = var.unit
                if var.min is not None:
                    type_attrib["min"] = repr(float(var.min))
                if var.max is not None:
                    type_attrib["max"] = repr(float(var.max))
            elif var.type is int:  # declared, so a master checks a horizon N before running
                if var.min is not None:
                    type_attrib["min"] = str(int(var.min))
                if var.max is not None:
                    type_attrib["max"] = str(int(var.max))
            if var.causality != "output":
                if var.type is bool:
                    type_attrib["start"] = str(var.start).lower()
                elif var.type is float:
                    type_attrib["start"] = repr(float(var.start))
                else:
                    type_attrib["start"] = str(var.start)
            SubElement(sv, _TYPES[var.type].__name__, type_attrib)
        return node

    def output_dependencies(self, output: Var) -> list[str]:
        """Names of the inputs an output depends on at the same instant (default: none)."""
        return []

    def _model_structure(self) -> Element:
        node = Element("ModelStructure")
        index = {v.name: i + 1 for i, v in enumerate(self.variables)}
        outputs = [v for v in self.variables if v.causality == "output"]
        if outputs:
            out_node = SubElement(node, "Outputs")
            init_node = Element("InitialUnknowns")
            for var in outputs:
                deps = " ".join(str(index[n]) for n in self.output_dependencies(var))
                SubElement(out_node, "Unknown", {"index": str(index[var.name]),
                                                 "dependencies": deps})
                # initial values may depend on any parameter/input: no dependencies attribute
                SubElement(init_node, "Unknown", {"index": str(index[var.name])})
            node.append(init_node)
        return node


class PlantSlave(CoreSlave):
    """A plant: no direct feedthrough; accepts any communication step.

    The core provides ``advance(t_ticks, h_ticks, inputs)`` (sub-steps <= max_step inside) and
    ``outputs() -> dict``.
    """

    output_variability = "continuous"

    def do_step(self, current_time: float, step_size: float) -> bool:
        self.require_mode("fmi2DoStep", "initialized")
        self.ensure_core()
        if not step_size > 0.0 or not math.isfinite(step_size):
            raise ValueError(f"doStep: step size {step_size} must be positive and finite")
        inputs = self.inputs()
        for name, value in inputs.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"input {name} = {value} is not finite")
        self.core.advance(to_ticks(current_time), to_ticks(step_size), inputs)
        self.outputs = self.core.outputs()  # a fresh dict per call (core contract)
        self.executions += 1
        return True


class SampledControllerSlave(CoreSlave):
    """A sampled (periodic or self-triggered) controller with direct feedthrough.

    Core API: ``compute(t_s, inputs) -> (outputs: dict, hold_samples: int)``. The event after
    one at tick ``k`` is at ``k + hold_samples * sample_time``; periodic controllers return 1.
    The output ``next_event_time`` (s) announces it to the master.

    Timing contract under any master (SPEC timing contract, FMI 2.0.4 sec. 4.2.2):

    * at an event instant, reading an output computes the event from the *current* inputs on a
      copy of the core state (nothing is committed): inputs set again at the same instant, as an
      iterating master does, give outputs of the new inputs; doStep commits the event computed
      from the inputs it is given (reusing the last read's result when the inputs are the same);
    * doStep must continue from the controller's own time; a step longer than the time to the
      next event executes every event inside it, as a discrete-time block does, with the
      inputs held at the step's start (logged once with fmi2Warning), so no event is ever
      dropped; with ``strict_steps`` such a doStep is refused with fmi2Error and a message
      naming the event.
    """

    output_variability = "discrete"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.now_ticks = 0
        self.next_event_ticks = 0
        self.event_done_ticks: int | None = None
        # event computed on a read, not committed: (key, outputs, hold, core state *before*);
        # the live core holds the state after it until the event is committed or undone
        self._tentative: tuple[Any, dict[str, Any], int, Any] | None = None
        # inputs set so far, and (time, that count) when the tentative event was last checked:
        # reading the N outputs one by one then costs one comparison each, not N dict builds
        self._input_serial = 0
        self._tentative_checked: tuple[int, int] | None = None
        self._tentative_shown: tuple[int, int] | None = None
        self._held_inputs_logged = False  # the message on events inside a step, said once

    @classmethod
    def declared_variables(cls) -> tuple[Var, ...]:
        return (*super().declared_variables(), *CONTROLLER_TIMING_VARS)

    def output_dependencies(self, output: Var) -> list[str]:
        return [v.name for v in self.variables if v.causality == "input"]

    def setup_experiment(self, start_time: float, stop_time=None, tolerance=None) -> None:
        super().setup_experiment(start_time, stop_time, tolerance)
        self.now_ticks = self.start_ticks
        self.next_event_ticks = self.start_ticks
        self.event_done_ticks = None
        self._tentative = None

    def sample_ticks(self) -> int:
        return to_ticks(self.values["sample_time"])

    def _event_due(self) -> bool:
        return self.now_ticks >= self.next_event_ticks and self.event_done_ticks != self.now_ticks

    def _grid_event(self) -> int:
        """The scheduled event being run at ``now`` (the sampling grid is kept if late)."""
        event, period = self.next_event_ticks, self.sample_ticks()
        while event + period <= self.now_ticks:
            event += period
        return event

    def _undo_tentative(self) -> None:
        """Put the core back to its state before an uncommitted (tentative) event."""
        if self._tentative is not None:
            saved = self._tentative[3]
            self._tentative = None
            self.core.set_state(saved)

    def on_input(self, name: str) -> None:
        super().on_input(name)
        self._input_serial += 1

    def _compute_tentative(self) -> tuple[Any, dict[str, Any], int, Any]:
        """The due event computed from the current inputs, not committed.

        The event runs on the live core after saving its state (one copy per event instead of
        computing on a copy: save, compute, save the result, restore, and restore again at
        commit); the saved state undoes it when the inputs change at the same instant, and is
        what ``getFMUstate`` reports while the event is uncommitted. Reading the N outputs one
        by one costs one comparison each while no input was set since (the input serial)."""
        checked = (self.now_ticks, self._input_serial)
        if self._tentative is not None and self._tentative_checked == checked:
            return self._tentative  # no input set since it was computed at this instant
        inputs = self.inputs()
        key = (self.now_ticks, tuple(sorted(inputs.items())))
        if self._tentative is not None:
            if self._tentative[0] == key:
                self._tentative_checked = checked
                return self._tentative
            self._undo_tentative()
        for name, value in inputs.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"input {name} = {value} is not finite")
        saved = self.core.get_state()
        try:
            outputs, hold = self.core.compute(to_seconds(self.now_ticks), inputs)
        except BaseException:
            self.core.set_state(saved)
            raise
        self._tentative = (key, dict(outputs), max(1, int(hold)), saved)
        self._tentative_checked = checked
        return self._tentative

    def core_state(self) -> Any:
        """The committed core state (without an uncommitted tentative event)."""
        if self._tentative is not None:
            return copy.deepcopy(self._tentative[3])
        return super().core_state()

    def after_core_built(self) -> None:
        self._tentative = None  # a new core: nothing computed on it yet
        super().after_core_built()
        self._show({}, self.next_event_ticks, self.executions)

    def _show(self, outputs: dict[str, Any], next_event: int, executions: int) -> None:
        self.outputs.update(outputs)
        self.outputs["next_event_time"] = to_seconds(next_event)
        self.outputs["executions"] = executions

    def refresh_outputs(self) -> None:
        if self.initialized and self._event_due():
            checked = (self.now_ticks, self._input_serial)
            if self._tentative is not None and self._tentative_shown == checked:
                return  # the outputs already show this tentative event
            _, outputs, hold, _ = self._compute_tentative()
            self._show(outputs, self._grid_event() + hold * self.sample_ticks(),
                       self.executions + 1)
            self._tentative_shown = checked

    def do_step(self, current_time: float, step_size: float) -> bool:
        self.require_mode("fmi2DoStep", "initialized")
        self.ensure_core()
        if not step_size > 0.0 or not math.isfinite(step_size):
            raise ValueError(f"doStep: step size {step_size} must be positive and finite")
        if not math.isfinite(current_time) or to_ticks(current_time) != self.now_ticks:
            raise ValueError(f"doStep at t={current_time} s, but this controller is at "
                             f"t={to_seconds(self.now_ticks)} s (a step must continue from "
                             "the end of the previous one)")
        end = to_ticks(current_time + step_size)
        while True:  # each event in [now, end): those after the first with the inputs held
            due = self._event_due()
            if due:
                _, outputs, hold, _ = self._compute_tentative()
                following = self._grid_event() + hold * self.sample_ticks()
            else:
                following = self.next_event_ticks
            if following < end and self.values.get("strict_steps", False):
                raise ValueError(
                    f"doStep from t={current_time} s to t={to_seconds(end)} s passes over "
                    f"this controller's event at t={to_seconds(following)} s (sample_time "
                    f"{self.values['sample_time']} s) and strict_steps is true: use "
                    "communication steps that end on its sample instants (at most "
                    "sample_time long)")
            if due:  # commit the event computed from the inputs of this doStep (live core)
                self.next_event_ticks = following
                self.event_done_ticks = self.now_ticks
                self.executions += 1
                self._show(outputs, following, self.executions)
                self._tentative = None
            if following >= end:
                break
            if not self._held_inputs_logged:
                self._held_inputs_logged = True
                self.log(f"{self.instance_name}: doStep from t={current_time} s to "
                         f"t={to_seconds(end)} s passes over this controller's event at "
                         f"t={to_seconds(following)} s (sample_time "
                         f"{self.values['sample_time']} s): its events inside a step are "
                         "executed with the inputs held at the step's start (said once; "
                         "strict_steps = true refuses such steps)", Fmi2Status.warning)
            self.now_ticks = following
        self.now_ticks = end
        return True

    def slave_state(self) -> dict[str, Any]:
        return {"now": self.now_ticks, "next": self.next_event_ticks,
                "done": self.event_done_ticks}

    def set_slave_state(self, state: dict[str, Any]) -> None:
        self.now_ticks = state["now"]
        self.next_event_ticks = state["next"]
        self.event_done_ticks = state["done"]
        self._tentative = None  # the core state was just set (committed state)


for _name in _FMI_ENTRY_POINTS:  # CoreSlave's own and those inherited from Fmi2Slave
    setattr(CoreSlave, _name, _guarded(_name, getattr(CoreSlave, _name)))
del _name
