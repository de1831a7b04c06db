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


_IMMUTABLE = (int, float, bool, str, bytes, type(None))


def copy_value(value: Any) -> Any:
    """An independent copy of one state value, faster than ``copy.deepcopy`` for the common
    cases (per controller event the FMU copies the whole core state up to four times):
    immutable scalars are shared, numeric numpy arrays are copied with ``ndarray.copy``
    (numpy is not imported here: this module is stdlib only), the rest is deep-copied."""
    if isinstance(value, _IMMUTABLE):
        return value
    if type(value).__module__ == "numpy" and getattr(value, "dtype", None) is not None \
            and value.dtype.hasobject is False and hasattr(value, "copy"):
        return value.copy()
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
                           else copy_value(value))
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        for name in self.state_fields:
            current = getattr(self, name, None)
            if isinstance(current, StatefulCore):
                current.set_state(state[name])
            else:
                setattr(self, name, copy_value(state[name]))
