"""Declared units are what they say: every unit name in ``cosim.fmu.declare.UNITS`` is a
Modelica-syntax unit string whose meaning (SI base exponents and factor) is the one declared
for it, every modelDescription (FMI 2 and FMI 3, Python and native builds) defines each unit
it uses by that meaning, and a grade is declared in permille (factor 0.001), so a unit-aware
tool reads a grade of 12 as 0.012."""

from __future__ import annotations

import math
import re
import uuid
import xml.etree.ElementTree as ET

import pytest

from cosim.build.python import catalog
from cosim.fmu.declare import UNITS

# The symbols the unit strings may use: SI base and derived units, and the dimensionless
# percent and permille (Modelica Language Specification, sec. 19.1: unit_symbol).
SYMBOLS: dict[str, tuple[dict[str, int], float]] = {
    "m": ({"m": 1}, 1.0), "s": ({"s": 1}, 1.0), "kg": ({"kg": 1}, 1.0),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0), "Pa": ({"kg": 1, "m": -1, "s": -2}, 1.0),
    "J": ({"kg": 1, "m": 2, "s": -2}, 1.0), "W": ({"kg": 1, "m": 2, "s": -3}, 1.0),
    "%": ({}, 0.01), "‰": ({}, 0.001),
}
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")  # FMI BaseUnit attributes
_FACTOR = re.compile(r"([^\d.()/+-]+)([+-]?\d+)?$")  # unit_operand [unit_exponent]


def _times(a: tuple[dict[str, int], float], b: tuple[dict[str, int], float],
           sign: int = 1) -> tuple[dict[str, int], float]:
    exps = dict(a[0])
    for k, e in b[0].items():
        exps[k] = exps.get(k, 0) + sign * e
    return {k: e for k, e in exps.items() if e}, a[1] * b[1] ** sign


def _split(text: str, sep: str) -> list[str]:
    """``text`` split at ``sep`` outside parentheses."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == sep and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    return parts + [text[start:]]


def parse_unit(text: str) -> tuple[dict[str, int], float]:
    """(SI base exponents, factor) of a unit string in the Modelica unit syntax: factors
    joined by ``.``, each a symbol with an optional integer exponent (``s2``), ``/`` dividing
    (left to right, as UCUM reads ``m/s2/%``), parentheses grouping, ``1`` for none. Raises
    ValueError for a string outside that syntax or with an unknown symbol."""
    if not text:
        raise ValueError("empty unit")
    quotients = _split(text, "/")
    result = _product(quotients[0])
    for denominator in quotients[1:]:
        result = _times(result, _product(denominator), -1)
    return result


def _product(text: str) -> tuple[dict[str, int], float]:
    if text.startswith("(") and text.endswith(")") and len(_split(text[1:-1], ")")) == 1:
        return parse_unit(text[1:-1])
    if text == "1":
        return {}, 1.0
    result: tuple[dict[str, int], float] = ({}, 1.0)
    for factor in _split(text, "."):
        if factor.startswith("("):
            result = _times(result, parse_unit(factor[1:-1]))
            continue
        match = _FACTOR.fullmatch(factor)
        if not match or match.group(1) not in SYMBOLS:
            raise ValueError(f"{factor!r} in {text!r}: not a known unit symbol")
        exps, scale = SYMBOLS[match.group(1)]
        power = int(match.group(2) or 1)
        result = _times(result, ({k: e * power for k, e in exps.items()}, scale ** power))
    return result


def _same(a: tuple[dict[str, int], float], b: tuple[dict[str, int], float]) -> bool:
    return a[0] == b[0] and math.isclose(a[1], b[1], rel_tol=1e-12)


@pytest.mark.parametrize("text,meaning", [
    ("m/s2", ({"m": 1, "s": -2}, 1.0)), ("N.s2/m2", ({"kg": 1, "m": -1}, 1.0)),
    ("%/(m/s2)", ({"m": -1, "s": 2}, 0.01)), ("m/s2/%", ({"m": 1, "s": -2}, 100.0)),
    ("‰", ({}, 0.001)), ("1/s", ({"s": -1}, 1.0))])
def test_the_unit_parser_reads_modelica_syntax(text, meaning):
    assert _same(parse_unit(text), meaning)


@pytest.mark.parametrize("text", ["", "m/", "m s", "permil", "km/h", "m**2", "N.", "(m"])
def test_the_unit_parser_refuses_what_is_not_a_unit(text):
    with pytest.raises(ValueError):
        parse_unit(text)


@pytest.mark.parametrize("name", sorted(UNITS))
def test_every_declared_unit_string_is_valid_and_means_its_declaration(name):
    assert _same(parse_unit(name), UNITS[name]), name


def _grades() -> list[tuple[str, str]]:
    return [(identifier, var.unit) for identifier, spec in sorted(catalog().items())
            for var in spec.load().variables
            if "grade" in var.name and var.causality == "output" and var.type is float]


def test_every_grade_output_is_declared_in_permille():
    grades = _grades()
    assert {"BrakeDelayTrain", "Crh3Train", "FreightTrain"} <= {i for i, _ in grades}
    for identifier, unit in grades:
        assert UNITS[unit] == ({}, 0.001), (identifier, unit)


def _defined_units(root: ET.Element) -> dict[str, tuple[dict[str, int], float]]:
    """Unit name -> (exponents, factor) of a modelDescription's UnitDefinitions."""
    out = {}
    for unit in root.iter("Unit"):
        [base] = unit.findall("BaseUnit")
        assert set(base.attrib) <= {*BASE_UNITS, "factor", "offset"}, base.attrib
        out[unit.get("name")] = ({k: int(base.get(k)) for k in BASE_UNITS if base.get(k)},
                                 float(base.get("factor", "1")))
    return out


def _used_units(root: ET.Element) -> set[str]:
    return {node.get("unit") for node in root.iter() if node.get("unit")}


@pytest.mark.parametrize("identifier", ["BrakeDelayTrain", "Crh3Train", "Emu3", "FreightTrain"])
def test_native_and_fmi3_descriptions_define_the_permille_grade(identifier):
    """The native builds' FMI 2 modelDescription and the FMI 3 one derived from it (what
    ``cosim build --native`` and the FMI 3 builds write) define every unit they use by its
    meaning, the grade's as permille."""
    from cosim.build import fmi3
    from cosim.build import native as native_build

    fmi2_xml = native_build.model_description(identifier, catalog()[identifier].load(), [],
                                              str(uuid.uuid4()))
    for xml in (fmi2_xml, fmi3.model_description(fmi2_xml)[0]):
        root = ET.fromstring(xml)
        defined = _defined_units(root)
        assert _used_units(root) <= set(defined)
        for name, meaning in defined.items():
            assert _same(parse_unit(name), meaning), (identifier, name)
        [grade] = [n for n in root.iter() if n.get("name") == "grade"]
        unit = (grade.get("unit") or next(c for c in grade if c.get("unit") is not None)
                .get("unit"))
        assert defined[unit] == ({}, 0.001)


def test_a_unit_aware_reader_takes_a_grade_of_12_as_0_012(built_fmus, built_fmus_fmi3):
    """fmpy reading the built Python FMUs (FMI 2 and 3): the grade's unit converts 12 to
    0.012 (SI), and every unit used is defined and means what its name says."""
    from fmpy import read_model_description

    for path in (built_fmus["Crh3Train"].path, built_fmus_fmi3["Crh3Train"].path_fmi3,
                 built_fmus["FreightTrain"].path):
        md = read_model_description(str(path))
        units = {u.name: u for u in md.unitDefinitions}
        grade = next(v for v in md.modelVariables if v.name == "grade")
        base = units[grade.unit].baseUnit
        assert 12.0 * base.factor + base.offset == pytest.approx(0.012, rel=1e-15)
        for v in md.modelVariables:
            if v.unit:
                meaning = ({k: getattr(units[v.unit].baseUnit, k) for k in BASE_UNITS
                            if getattr(units[v.unit].baseUnit, k)},
                           units[v.unit].baseUnit.factor)
                assert _same(parse_unit(v.unit), meaning), (path, v.name, v.unit)
