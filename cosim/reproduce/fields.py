"""The fields of the entry's dataclasses as TOML keys: their documentation, and a table checked
against them (unknown keys with the nearest known name, missing keys, types).

A field is declared with :func:`doc`: its meaning (``doc``), its TOML key when it is not the
field's name (``toml``; ``toml=False``: not a key, set by the loader), its default (absent:
required) and, for a key that applies to some kinds of a table only, those kinds (``kinds``).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import types
import typing
from collections.abc import Iterator
from typing import Any

REQUIRED: Any = dataclasses.MISSING


class ReproduceError(ValueError):
    """A reproduction entry that cannot be used (the message names the file, key and value)."""


def doc(text: str, *, toml: str | bool | None = None, default: Any = REQUIRED,
        kinds: tuple[str, ...] | None = None) -> Any:
    """A dataclass field documented by ``text``, read from TOML key ``toml`` (default: the
    field's name; False: not a TOML key), with ``default`` (a list, dict or dataclass is
    copied for each instance; absent: the key is required), applying to ``kinds`` only."""
    meta = {"doc": text, "toml": toml, "kinds": kinds}
    if default is REQUIRED:
        return dataclasses.field(metadata=meta)
    if isinstance(default, (list, dict)) or dataclasses.is_dataclass(default):
        return dataclasses.field(default_factory=lambda: copy.deepcopy(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def toml_key(f: dataclasses.Field[Any]) -> str | None:
    """The TOML key of field ``f`` (None: not read from TOML)."""
    key = f.metadata.get("toml")
    if key is False:
        return None
    return key if isinstance(key, str) else f.name


def keys_of(cls: type, kind: str | None = None) -> Iterator[tuple[str, dataclasses.Field[Any]]]:
    """(TOML key, field) of every field of ``cls`` read from TOML that applies to ``kind``."""
    for f in dataclasses.fields(cls):
        key = toml_key(f)
        kinds = f.metadata.get("kinds")
        if key is not None and (kind is None or kinds is None or kind in kinds):
            yield key, f


def required(f: dataclasses.Field[Any]) -> bool:
    """Whether the field has no default (its key must be given)."""
    return f.default is REQUIRED and f.default_factory is REQUIRED


def type_hints(cls: type) -> dict[str, Any]:
    """The fields' types of ``cls``, resolved."""
    import sys

    return typing.get_type_hints(cls, vars(sys.modules[cls.__module__]))


def _is(value: Any, tp: Any) -> bool:
    """Whether the TOML value ``value`` is of type ``tp`` (an int is a float; a bool is
    neither)."""
    if tp is Any:
        return True
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return any(_is(value, a) for a in typing.get_args(tp))
    if tp is type(None):
        return value is None
    if tp is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if origin is list:
        (item,) = typing.get_args(tp)
        return isinstance(value, list) and all(_is(v, item) for v in value)
    if origin is dict:
        key, item = typing.get_args(tp)
        return isinstance(value, dict) and all(_is(k, key) and _is(v, item)
                                               for k, v in value.items())
    return isinstance(value, tp)


def type_text(tp: Any) -> str:
    """The type ``tp`` in words (the schema page and the errors)."""
    names = {str: "a string", int: "an integer", float: "a number", bool: "true or false",
             Any: "any value"}
    if tp in names:
        return names[tp]
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(type_text(a) for a in typing.get_args(tp) if a is not type(None))
    if origin is list:
        (item,) = typing.get_args(tp)
        kinds = typing.get_args(item) if typing.get_origin(item) in (
            typing.Union, types.UnionType) else (item,)
        return "a list of " + " and ".join(_plural(type_text(k)) for k in kinds)
    if origin is dict:
        key, item = typing.get_args(tp)
        return "a table" if item is Any else f"a table of {type_text(item).split(' ', 1)[1]}s"
    return getattr(tp, "__name__", str(tp))


def _plural(text: str) -> str:
    """``a number`` -> ``numbers``."""
    return text.split(" ", 1)[1] + "s" if text.startswith(("a ", "an ")) else text


def unknown_text(unknown: list[str], known: list[str], context: str = "") -> str:
    """``unknown key 'scenaro' (did you mean 'scenario'?)``, or the known keys where none is
    near; ``context`` follows the keys (`` for kind 'panels'``)."""
    parts = []
    for key in unknown:
        near = difflib.get_close_matches(key, known, n=1)
        parts.append(f"{key!r} (did you mean {near[0]!r}?)" if near else repr(key))
    text = f"unknown key{'s' if len(unknown) > 1 else ''} " + ", ".join(parts) + context
    if not any("did you mean" in p for p in parts):
        text += f" (known: {', '.join(sorted(known))})"
    return text


def check_keys(where: str, data: Any, known: list[str]) -> None:
    """Refuse ``data`` unless it is a table whose keys are all ``known``."""
    if not isinstance(data, dict):
        raise ReproduceError(f"{where}: {data!r}: expected a table")
    unknown = [k for k in data if k not in known]
    if unknown:
        raise ReproduceError(f"{where}: {unknown_text(unknown, known)}")


def check_table(cls: type, where: str, data: Any, *, kind: str | None = None,
                skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """``data`` (a TOML table) checked against the fields of ``cls`` that apply to ``kind``:
    the constructor's arguments by field name, defaults filled; the keys in ``skip`` are
    the caller's to read (neither checked nor returned)."""
    if not isinstance(data, dict):
        raise ReproduceError(f"{where}: {data!r}: expected a table")
    fields = dict(keys_of(cls, kind))
    unknown = [k for k in data if k not in fields and k not in skip]
    if unknown:
        context = f" for kind {kind!r}" if kind is not None else ""
        known = list(dict.fromkeys([*fields, *skip]))
        raise ReproduceError(f"{where}: {unknown_text(unknown, known, context)}")
    missing = [k for k, f in fields.items() if required(f) and k not in data]
    if missing:
        raise ReproduceError(f"{where}: missing key(s) {missing}")
    hints = type_hints(cls)
    out: dict[str, Any] = {}
    for key, f in fields.items():
        if key in skip:
            continue
        if key not in data:
            if not required(f):
                out[f.name] = (f.default_factory() if f.default_factory is not REQUIRED
                               else f.default)
            continue
        value = data[key]
        if not _is(value, hints[f.name]):
            raise ReproduceError(f"{where}: {key} = {value!r}: expected "
                                 f"{type_text(hints[f.name])}")
        out[f.name] = value
    return out


def build(cls: type, where: str, data: Any, extra: dict[str, Any] | None = None,
          kind: str | None = None) -> Any:
    """An instance of ``cls`` from the TOML table ``data`` (:func:`check_table`) and the
    fields the loader sets (``extra``)."""
    return cls(**check_table(cls, where, data, kind=kind), **(extra or {}))


def span_error(value: list[Any], labelled: bool = False) -> str | None:
    """Why ``value`` is not ``[low, high]`` with low < high (with ``labelled`` also
    ``[low, high, label]``), or None."""
    span = value[:2]
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in span)
    size = len(value) in (2, 3) if labelled else len(value) == 2
    if len(span) == 2 and numbers and span[0] < span[1] and size:
        return None
    return "expected [low, high]" + (" or [low, high, label]" if labelled else "") + \
        " with low < high"
