"""Integer-tick time and complete, copyable core state (bundled into every FMU; stdlib only)."""

from __future__ import annotations

import copy
from typing import Any, ClassVar

TICKS_PER_SECOND = 1_000_000_000


def to_ticks(seconds: float) -> int:
    """Seconds -> integer nanoseconds (rounded, so ``0.2 * k`` lands on the tick grid)."""
    return int(round(seconds * TICKS_PER_SECOND))


def to_seconds(ticks: int) -> float:
    """Integer nanoseconds -> seconds."""
    return ticks / TICKS_PER_SECOND


_IMMUTABLE = (float, int, bool, str, bytes, type(None))


def _copy(value: Any) -> Any:
    """A deep copy of a state value (a tree: lists, dicts, numeric arrays, scalars); immutable
    scalars as they are, numeric arrays by ``ndarray.copy`` (what ``copy.deepcopy`` does for
    them, without its per-call dispatch); anything else by ``copy.deepcopy``."""
    if isinstance(value, _IMMUTABLE):
        return value
    kind = type(value)
    if kind is list:  # e.g. command histories [[tick, value], ...]
        return [_copy(v) for v in value]
    if kind is dict:
        return {k: _copy(v) for k, v in value.items()}
    if kind.__name__ == "ndarray" and value.dtype.hasobject is False:
        return value.copy(order="K")
    return copy.deepcopy(value)


class StatefulCore:
    """Mixin for numerical cores: ``get_state``/``set_state`` over ``state_fields``.

    Subclasses list every attribute that changes during a run in ``state_fields``; the FMU
    wrapper saves and restores exactly those (deep copies), which makes FMU state complete.
    A field holding another ``StatefulCore`` (a sub-controller) is saved through its own
    ``get_state``/``set_state``.
    """

    state_fields: ClassVar[tuple[str, ...]] = ()

    def get_state(self) -> dict[str, Any]:
        state: dict[str, Any] = {}
        for name in self.state_fields:
            value = getattr(self, name)
            state[name] = (value.get_state() if isinstance(value, StatefulCore)
                           else _copy(value))
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        for name in self.state_fields:
            current = getattr(self, name, None)
            if isinstance(current, StatefulCore):
                current.set_state(state[name])
            else:
                setattr(self, name, _copy(state[name]))
