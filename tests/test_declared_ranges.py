"""Declared ranges are enforced where cores are built: every declared bound, choice and
integrality of every parameter dataclass in ``plants`` and ``controllers`` rejects a value just
outside it with an error naming the parameter (``cosim.fmu.declare.check_declared``)."""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
from dataclasses import dataclass

import pytest

import controllers
import plants
from cosim.fmu.declare import Checked, check_declared, param

SPEC = "atocosim_declaration"


def _declared_dataclasses() -> list[type]:
    found: dict[str, type] = {}
    for package in (plants, controllers):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.endswith("_fmu"):
                continue
            module = importlib.import_module(info.name)
            for value in vars(module).values():
                if (isinstance(value, type) and dataclasses.is_dataclass(value)
                        and value.__module__ == module.__name__
                        and any(SPEC in f.metadata for f in dataclasses.fields(value))):
                    found[f"{value.__module__}.{value.__qualname__}"] = value
    return [found[k] for k in sorted(found)]


DECLARED = _declared_dataclasses()


def _default(cls: type):
    if cls.__qualname__ == "EmuParams":  # per-configuration data: a named train
        from plants.emu import emu_config
        return emu_config("crh380a_3unit")
    if cls.__qualname__ == "Davis":  # coefficients of a named train
        return cls.from_kn_kmh(5.4, 0.0098, 0.00163)
    return cls()


def _outside(spec, value):
    """Values just outside each declared bound (relative step well above rounding)."""
    step = lambda bound: max(abs(bound), 1.0) * 1e-6  # noqa: E731
    out = []
    if spec.min is not None:
        out.append(spec.min - step(spec.min))
    if spec.above is not None:
        out.append(spec.above)
    if spec.max is not None:
        out.append(spec.max + step(spec.max))
    if spec.below is not None:
        out.append(spec.below)
    if spec.integer and isinstance(value, (int, float)):
        out.append(float(value) + 0.5)
    if spec.choices is not None:
        out.append("not-a-choice")
    if isinstance(value, float) and not isinstance(value, bool):
        out.append(float("nan"))
    return [type(value)(v) if isinstance(value, float) and isinstance(v, int) else v
            for v in out]


def test_there_are_declared_parameter_classes() -> None:
    assert len(DECLARED) >= 15


@pytest.mark.parametrize("cls", DECLARED, ids=lambda c: c.__qualname__)
def test_every_declared_class_checks_its_declarations(cls: type) -> None:
    assert issubclass(cls, Checked), f"{cls.__qualname__}: derive from Checked"
    base = _default(cls)
    base.check()
    for f in dataclasses.fields(cls):
        spec = f.metadata.get(SPEC)
        if spec is None:
            continue
        value = getattr(base, f.name)
        for bad in _outside(spec, value):
            broken = dataclasses.replace(base, **{f.name: bad})
            with pytest.raises(ValueError, match=rf"\b{f.name}\b|{spec.name or f.name}"):
                check_declared(broken)


@dataclass(frozen=True)
class _Example(Checked):
    gain: float = param(1.0, "1", "a gain", above=0.0)
    share: float = param(0.5, "1", "a share", min=0.0, max=1.0)
    steps: int = param(3, "1", "a count", min=1, integer=True, name="M")
    mode: str = param("zoh", description="a mode", choices=("zoh", "euler"))
    weights: tuple[float, ...] = param((1.0, 2.0), "1", "weights", min=0.0)

    def check_relations(self) -> None:
        if self.share > self.gain:
            raise ValueError(f"share = {self.share} must be <= gain = {self.gain}")


@pytest.mark.parametrize("change, message", [
    ({"gain": 0.0}, r"gain = 0.0: must be greater than 0.0"),
    ({"share": 1.5}, r"share = 1.5: must be at most 1.0"),
    ({"share": -0.1}, r"share = -0.1: must be at least 0.0"),
    ({"steps": 2.5}, r"M \(steps\) = 2.5: must be an integer"),
    ({"steps": 0}, r"M \(steps\) = 0: must be at least 1"),
    ({"mode": "rk4"}, r"mode = 'rk4': must be one of 'zoh', 'euler'"),
    ({"weights": (1.0, -2.0)}, r"weights = \[1.0, -2.0\]: entry -2.0: must be at least 0.0"),
    ({"gain": float("inf")}, r"gain = inf: must be a finite number"),
    ({"gain": 0.25}, r"share = 0.5 must be <= gain = 0.25"),
])
def test_messages_name_parameter_value_and_bound(change: dict, message: str) -> None:
    dataclasses.replace(_Example()).check()
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(_Example(), **change).check()


def test_exclusive_bounds_are_written_as_the_model_description_bounds() -> None:
    from cosim.fmu.declare import parameters
    declared = {v.name: v for v in parameters(_Example())}
    assert (declared["gain"].min, declared["gain"].max) == (0.0, None)
    assert (declared["share"].min, declared["share"].max) == (0.0, 1.0)
