"""The seed-002 freight laws' tuned gains: the picks of one tuning protocol
(``papers/seed002/tuning.py``), read from the generated :data:`TUNING_FILE`.

Each table of the file is a law as the reproduction runs it (``[SMC]``, ``["SMC, boundary
layer"]``, ...); its keys are the law's parameter names as its FMU declares them (``kp``,
``lambda``, ``mean_weight``, ...). The four laws' FMUs take their table as their parameters'
defaults (:func:`tuned_param`); a row of the reproduction that runs a law another way (a
boundary layer, a feedforward) names its own table with the entry's ``[[runs]] tuned`` key.
Nothing in the file is typed by hand.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from cosim.fmu.declare import param

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

#: written by ``papers/seed002/tuning.py`` (one protocol for every law), not by hand
TUNING_FILE = Path(__file__).with_name("freight_tuning.toml")


@cache
def _picks() -> dict[str, dict[str, Any]]:
    return tomllib.loads(TUNING_FILE.read_text())


def tuned(law: str, key: str) -> float:
    """The pick of parameter ``key`` for ``law`` in :data:`TUNING_FILE`
    (``[<law>] <key> = value``)."""
    try:
        return _picks()[law][key]
    except KeyError:
        raise KeyError(f"{TUNING_FILE}: no [{law}] {key} (rerun papers/seed002/tuning.py)"
                       ) from None


def tuned_param(law: str, name: str, unit: str, description: str, **range_: Any) -> Any:
    """A parameter declared as ``name`` whose default is ``law``'s pick of it
    (:func:`cosim.fmu.declare.param`; ``range_`` its ``min``, ``max``, ``integer``)."""
    value = tuned(law, name)
    return param(int(value) if range_.get("integer") else float(value), unit,
                 f"{description} (default: tuned, {TUNING_FILE.name} [{law}])", name=name,
                 **range_)
