"""Declarations: one place for each parameter, input and output of a core (no FMI in here).

A core's parameters are the fields of its frozen ``*Params`` dataclass, each made with
:func:`param` (default, unit, description, range); a field that is itself a declared dataclass
is a :func:`group` whose fields appear flattened under a prefix (``davis`` -> ``davis_a``...).
Inputs and outputs are :class:`Var` tuples the core owns (``Var.input`` / ``Var.output``).
Everything else is derived: the FMU's variables and modelDescription (``cosim.fmu.slave``), the
scenario's type and range checks (which read the modelDescription), ``cosim list`` and
``docs/fmus.md`` (``cosim docs``).

    @dataclass(frozen=True)
    class StopPidParams:
        kp: float = param(60.0, "%.s/m", "proportional gain on v - v_ref")
        ...

    parameters(StopPidParams())          # -> (Var("kp", "parameter", 60.0, "%.s/m", ...), ...)
    build(StopPidParams, {"kp": 50.0})   # -> StopPidParams(kp=50.0, ...)

Bundled into every FMU: standard library only.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

# FMI unit name -> (SI base-unit exponents, factor): a value v in the unit is v * factor in
# the SI base units (so 12 permille = 0.012). Every unit a declaration may use is here; names
# follow the Modelica unit syntax ("." multiplies, a trailing integer is the exponent).
UNITS: dict[str, tuple[dict[str, int], float]] = {
    "1": ({}, 1.0),
    "%": ({}, 0.01),
    "‰": ({}, 0.001),  # permille: a railway grade (m of rise per km)
    "s": ({"s": 1}, 1.0),
    "m": ({"m": 1}, 1.0),
    "kg": ({"kg": 1}, 1.0),
    "m/s": ({"m": 1, "s": -1}, 1.0),
    "m/s2": ({"m": 1, "s": -2}, 1.0),
    "m/s3": ({"m": 1, "s": -3}, 1.0),
    "1/s": ({"s": -1}, 1.0),
    "1/s2": ({"s": -2}, 1.0),
    "s/m": ({"m": -1, "s": 1}, 1.0),
    "s2/m": ({"m": -1, "s": 2}, 1.0),
    "s3/m": ({"m": -1, "s": 3}, 1.0),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0),
    "N.s/m": ({"kg": 1, "s": -1}, 1.0),
    "N.s2/m2": ({"kg": 1, "m": -1}, 1.0),
    "N/m": ({"kg": 1, "s": -2}, 1.0),
    "Pa": ({"kg": 1, "m": -1, "s": -2}, 1.0),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0),
    "J": ({"kg": 1, "m": 2, "s": -2}, 1.0),
    "m/s2/%": ({"m": 1, "s": -2}, 100.0),
    "%.s/m": ({"m": -1, "s": 1}, 0.01),
    "%/m": ({"m": -1}, 0.01),
    "%/(m/s2)": ({"m": -1, "s": 2}, 0.01),
    "1/m2": ({"m": -2}, 1.0),
    "s2/m2": ({"m": -2, "s": 2}, 1.0),
}

KEEP = -1.0  # start value of a per-configuration parameter: keep the configuration's value

_SPEC = "atocosim_declaration"
_GROUP = "atocosim_group"



def out_of_range(value: Any, lo: Any, hi: Any) -> str:
    """``value`` and the bound it breaks, in words: ``5 outside [0, 2]`` when both bounds are
    declared, ``0.5: must be at least 1.0`` (or ``at most``) when only one is."""
    if lo is not None and hi is not None:
        return f"{value} outside [{lo}, {hi}]"
    if lo is not None:
        return f"{value}: must be at least {lo}"
    return f"{value}: must be at most {hi}"

@dataclass(frozen=True)
class Var:
    """One declared scalar: a parameter, an input or an output.

    ``causality`` is ``parameter``, ``input`` or ``output``; the type is that of ``start``
    (float, int, bool or str). Parameters are fixed after initialisation.
    """

    name: str
    causality: str
    start: float | int | bool | str = 0.0
    unit: str = "1"
    description: str = ""
    min: float | None = None
    max: float | None = None
    variability: str | None = None

    def __post_init__(self) -> None:
        if self.causality not in ("parameter", "input", "output"):
            raise ValueError(f"{self.name}: causality {self.causality!r}")
        if self.unit not in UNITS:
            raise ValueError(f"{self.name}: unit {self.unit!r} is not declared in UNITS")

    @classmethod
    def input(cls, name: str, unit: str = "1", description: str = "", start: Any = 0.0,
              **kw: Any) -> Var:
        return cls(name, "input", start, unit, description, **kw)

    @classmethod
    def output(cls, name: str, unit: str = "1", description: str = "", start: Any = 0.0,
               **kw: Any) -> Var:
        return cls(name, "output", start, unit, description, **kw)

    @property
    def type(self) -> type:
        return type(self.start)

    def resolved_variability(self, default_output: str) -> str:
        if self.variability:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        if self.causality == "output":
            return default_output
        return "continuous" if self.type is float else "discrete"


@dataclass(frozen=True)
class _Spec:
    unit: str
    description: str
    min: float | None
    max: float | None
    per_configuration: bool
    name: str | None
    above: float | None = None
    below: float | None = None
    choices: tuple[Any, ...] | None = None
    integer: bool = False

    @property
    def declared_min(self) -> float | None:
        """The bound written to the modelDescription's ``min`` (inclusive there)."""
        return self.min if self.min is not None else self.above

    @property
    def declared_max(self) -> float | None:
        return self.max if self.max is not None else self.below

    def violation(self, value: Any) -> str | None:
        """Why ``value`` breaks this declaration, or None when it keeps it."""
        if self.choices is not None:
            return None if value in self.choices else (
                f"{value!r}: must be one of {', '.join(repr(c) for c in self.choices)}")
        if isinstance(value, (tuple, list)):
            for item in value:
                why = self.violation(item)
                if why is not None:
                    return f"{list(value)}: entry {why}"
            return None
        if isinstance(value, (str, bool)):
            return None
        if not math.isfinite(value):
            return f"{value}: must be a finite number"
        if self.integer and int(value) != value:
            return f"{value}: must be an integer"
        if self.min is not None and not value >= self.min:
            return f"{value}: must be at least {self.min}"
        if self.above is not None and not value > self.above:
            return f"{value}: must be greater than {self.above}"
        if self.max is not None and not value <= self.max:
            return f"{value}: must be at most {self.max}"
        if self.below is not None and not value < self.below:
            return f"{value}: must be less than {self.below}"
        return None


def param(default: Any = dataclasses.MISSING, unit: str = "1", description: str = "", *,
          min: float | None = None, max: float | None = None,
          above: float | None = None, below: float | None = None,
          choices: tuple[Any, ...] | None = None, integer: bool = False,
          per_configuration: bool = False, name: str | None = None) -> Any:
    """A dataclass field declared as a parameter, named as the field unless ``name`` gives the
    paper's symbol (e.g. field ``horizon`` is parameter ``N``).

    Its range: ``min`` / ``max`` inclusive, ``above`` / ``below`` exclusive (written to the
    modelDescription as its min / max), ``choices`` the admitted values of a string or flag,
    ``integer`` a whole number; :func:`check_declared` enforces them where a core is built,
    entry by entry for a tuple value.

    ``per_configuration``: the value comes from a named configuration (e.g. an EMU's train
    data); the FMU parameter starts at :data:`KEEP` (-1), which keeps it.
    """
    if unit not in UNITS:
        raise ValueError(f"unit {unit!r} is not declared in UNITS")
    meta = {_SPEC: _Spec(unit, description, min, max, per_configuration, name, above, below,
                         tuple(choices) if choices is not None else None, integer)}
    return dataclasses.field(default=default, metadata=meta)


def group(default: Any, prefix: str) -> Any:
    """A field holding another declared dataclass; its parameters appear as ``prefix + name``
    (e.g. the Davis terms ``davis_a``, ``davis_b``, ``davis_c``)."""
    return dataclasses.field(default=default, metadata={_GROUP: prefix})


def _declared_name(f: dataclasses.Field, prefix: str) -> str:
    spec: _Spec | None = f.metadata.get(_SPEC)
    return prefix + (spec.name if spec is not None and spec.name else f.name)


def parameters(instance: Any, prefix: str = "", exclude: tuple[str, ...] = ()
               ) -> tuple[Var, ...]:
    """Parameter declarations of a declared dataclass instance (its values are the starts),
    leaving out the parameter names in ``exclude``."""
    out: list[Var] = []
    for f in dataclasses.fields(instance):
        value = getattr(instance, f.name)
        if _GROUP in f.metadata:
            out += parameters(value, prefix + f.metadata[_GROUP], exclude)
            continue
        spec: _Spec | None = f.metadata.get(_SPEC)
        name = _declared_name(f, prefix)
        if spec is None or name in exclude:
            continue
        if spec.per_configuration:
            out.append(Var(name, "parameter", KEEP, spec.unit,
                           f"{spec.description} (-1: configuration value)"))
        else:
            out.append(Var(name, "parameter", value, spec.unit, spec.description,
                           spec.declared_min, spec.declared_max))
    return tuple(out)


def build(base: Any, values: Mapping[str, Any], prefix: str = "") -> Any:
    """``base`` (a declared dataclass instance, or the class for its defaults) with every
    declared parameter found in ``values`` replaced; the inverse of :func:`parameters`."""
    if isinstance(base, type):
        base = base()
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(base):
        name = _declared_name(f, prefix)
        if _GROUP in f.metadata:
            changes[f.name] = build(getattr(base, f.name), values, prefix + f.metadata[_GROUP])
            continue
        spec: _Spec | None = f.metadata.get(_SPEC)
        if spec is None or name not in values:
            continue
        value = values[name]
        if spec.per_configuration and value == KEEP:
            continue
        if spec.per_configuration and value < 0:
            raise ValueError(f"{name} = {value} must be >= 0 (or -1: configuration value)")
        changes[f.name] = value
    return dataclasses.replace(base, **changes)


def check_declared(instance: Any, prefix: str = "") -> None:
    """Raise ValueError naming the first declared parameter of ``instance`` (groups included)
    whose value breaks its declared range, choices or integrality (see :func:`param`)."""
    for f in dataclasses.fields(instance):
        value = getattr(instance, f.name)
        if _GROUP in f.metadata:
            check_declared(value, prefix + f.metadata[_GROUP])
            continue
        spec: _Spec | None = f.metadata.get(_SPEC)
        if spec is None:
            continue
        why = spec.violation(value)
        if why is not None:
            name = _declared_name(f, prefix)
            label = name if name == prefix + f.name else f"{name} ({f.name})"
            raise ValueError(f"{label} = {why}")


class Checked:
    """Mixin of a declared ``*Params`` dataclass: :meth:`check` enforces every declaration
    (:func:`check_declared`, groups included), then :meth:`check_relations` of every group and
    of the class, the conditions between parameters that no single range states (e.g.
    ``u_min < u_max``)."""

    def check(self) -> None:
        check_declared(self)
        self._relations()

    def _relations(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if _GROUP in f.metadata and isinstance(value, Checked):
                value._relations()
        self.check_relations()

    def check_relations(self) -> None:
        """Conditions between parameters; none unless a class states them."""


def field_default(cls: type, name: str) -> Any:
    """The declared default of field ``name`` of dataclass ``cls`` (to share one default)."""
    return next(f.default for f in dataclasses.fields(cls) if f.name == name)


class Declared:
    """Mixin of a core whose FMU variables are its declarations.

    ``params_class``: its declared ``*Params`` dataclass (defaults are the FMU starts);
    ``setup_vars``: parameters that are constructor arguments (initial state, route...);
    ``input_vars`` / ``output_vars``: its inputs and outputs. Cores whose interface depends on
    a size (``units``) override :meth:`declarations`. ``from_parameters`` builds the core from
    the flat values of those declarations.
    """

    params_class: ClassVar[type | None] = None
    params_exclude: ClassVar[tuple[str, ...]] = ()
    setup_vars: ClassVar[tuple[Var, ...]] = ()
    input_vars: ClassVar[tuple[Var, ...]] = ()
    output_vars: ClassVar[tuple[Var, ...]] = ()

    @classmethod
    def declarations(cls, **options: Any) -> tuple[Var, ...]:
        declared = (parameters(cls.params_class(), exclude=cls.params_exclude)
                    if cls.params_class else ())
        return (*declared, *cls.setup_vars, *cls.input_vars, *cls.output_vars)

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any], data_dir: Any, t0: float = 0.0,
                        **options: Any) -> Any:
        raise NotImplementedError(f"{cls.__name__}.from_parameters")


def sample_time(default: float) -> Any:
    """The sample time T of a sampled controller (shared declaration)."""
    return param(default, "s", "sample time T", min=1e-6)
