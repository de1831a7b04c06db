"""Metrics that belong to one paper, registered by name.

The generic summary (:func:`cosim.run.metrics.compute_summary`) knows no paper. A scenario names
the paper metrics it wants in ``[summary] metrics = ["ctcs3", "unit_indices"]``; each name is a
function registered here, in the metrics module of the paper that defines it (its plug-in
``papers/NAME/metrics.py``: ``papers/seed001/metrics.py`` and so on), with the ``[summary]`` keys
it reads::

    from cosim.papers import RunRecord, metric

    @metric("unit_indices", keys=("unit_speeds", "ma_sample_time"),
            description="Table 2's indices over the power units",
            outputs={"unit_mse_kmh2": ("speed MSE of the units, eq. 87", "(km/h)^2")})
    def unit_indices(run: RunRecord) -> dict[str, Any]:
        cols = run.columns("unit_speeds")
        ...
        return {"unit_mse_kmh2": ...}

A metric function takes the run's :class:`RunRecord` and returns the entries it adds to
``summary.json`` (an empty dict when the recording lacks what it needs), each one declared in
``outputs`` with its description and unit (a key it does not declare is an error; the list in
docs/scenarios.md is generated from these declarations by ``cosim docs``). Every paper's
``papers/*/metrics.py`` is loaded by path when the registry is first consulted (module name
``papers.NAME.metrics``; nothing imports a paper's folder, this package knows no paper), so a
new paper's metrics or a new function needs no other registration (:func:`paper_metrics`
gives a paper's module to a script or test that calls its functions). A key a metric declares
is a valid ``[summary]`` key only in a scenario that names the metric.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from cosim.run.metrics import matching_columns
from cosim.run.scenario import PAPERS_DIR  # papers/NAME/: a paper's folder


@dataclass(frozen=True)
class RunRecord:
    """What a paper metric sees of one run.

    ``frame``: the recorded results (``time`` and ``FMU.variable`` columns); ``summary``: the
    scenario's ``[summary]`` table (parameter references resolved); ``metrics``: the generic
    summary computed so far (read it, do not change it); ``time`` (s), ``position`` (m),
    ``speed`` (m/s) and ``reference_speed`` (m/s, the stopping curve where ``reference_decel``
    gives one) as the generic summary resolved them, None when not recorded; ``arrival_index``:
    the first sample of the final standstill (None: still moving at the end)."""

    frame: Any
    summary: Mapping[str, Any]
    metrics: Mapping[str, Any] = field(default_factory=dict)
    time: np.ndarray | None = None
    position: np.ndarray | None = None
    speed: np.ndarray | None = None
    reference_speed: np.ndarray | None = None
    arrival_index: int | None = None

    def series(self, key: str) -> np.ndarray | None:
        """The recorded column the ``[summary]`` key ``key`` names (None: key or column
        absent)."""
        ref = self.summary.get(key)
        if isinstance(ref, str) and ref in self.frame.columns and len(self.frame):
            return self.frame[ref].to_numpy(dtype=float)
        return None

    def columns(self, key: str) -> list[str]:
        """The recorded columns the ``[summary]`` key ``key`` names (a name, a
        ``"plant.v[*]"`` pattern or a list of those)."""
        return matching_columns(self.frame, self.summary.get(key))


MetricFunction = Callable[[RunRecord], dict[str, Any]]


@dataclass(frozen=True)
class Metric:
    """A registered metric: its name, the ``[summary]`` keys it reads, its function, the
    module (paper) that defines it, what it measures and the ``summary.json`` entries it adds
    (key -> (description, unit))."""

    name: str
    keys: tuple[str, ...]
    function: MetricFunction
    module: str
    description: str
    outputs: Mapping[str, tuple[str, str]]


_REGISTRY: dict[str, Metric] = {}
_loaded: list[bool] = []


def metric(name: str, keys: tuple[str, ...] = (), *, description: str,
           outputs: Mapping[str, tuple[str, str]]
           ) -> Callable[[MetricFunction], MetricFunction]:
    """Register the decorated function as the metric ``name`` reading the ``[summary]``
    ``keys``, measuring ``description`` and adding the entries ``outputs`` (key ->
    (description, unit); unit ``"1"`` for a count or ratio, ``"-"`` for a yes/no). A name is
    registered once (a second registration is an error)."""
    if not description or not outputs:
        raise ValueError(f"metric {name!r}: a description and its outputs are declared")
    for key, declared in outputs.items():
        if len(declared) != 2 or not all(declared):
            raise ValueError(f"metric {name!r}: output {key!r} = {declared!r} must be "
                             "(description, unit)")

    def register(function: MetricFunction) -> MetricFunction:
        known = _REGISTRY.get(name)
        if known is not None and known.function is not function:
            raise ValueError(f"metric {name!r} registered twice ({known.module} and "
                             f"{function.__module__})")
        _REGISTRY[name] = Metric(name, tuple(keys), function, function.__module__,
                                 description, dict(outputs))
        return function

    return register


def paper_metrics(name: str) -> ModuleType:
    """The metrics module of paper ``name`` (``papers/NAME/metrics.py``), loaded once by path
    under the module name ``papers.NAME.metrics`` (its functions register their metrics);
    ``KeyError`` when that paper has no metrics module."""
    module_name = f"papers.{name}.metrics"
    if module_name in sys.modules:
        return sys.modules[module_name]
    path = PAPERS_DIR / name / "metrics.py"
    if not path.is_file():
        raise KeyError(f"paper {name!r} has no metrics module ({path})")
    spec = importlib.util.spec_from_file_location(module_name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def registry() -> dict[str, Metric]:
    """Every registered metric by name (every paper's ``papers/*/metrics.py`` loaded once)."""
    if not _loaded:
        for path in sorted(PAPERS_DIR.glob("*/metrics.py")):
            paper_metrics(path.parent.name)
        _loaded.append(True)
    return dict(_REGISTRY)


def lookup(name: str) -> Metric:
    """The metric ``name``; ``KeyError`` naming the registered ones when there is none."""
    found = registry().get(name)
    if found is None:
        raise KeyError(f"no metric {name!r}; registered: {', '.join(sorted(registry()))}")
    return found


def declared_keys() -> dict[str, list[str]]:
    """``[summary]`` key -> the metrics that read it, over every registered metric."""
    out: dict[str, list[str]] = {}
    for m in registry().values():
        for key in m.keys:
            out.setdefault(key, []).append(m.name)
    return out


def compute(names: list[str], run: RunRecord) -> dict[str, Any]:
    """The entries the metrics ``names`` add, in that order; ``ValueError`` for an entry a
    metric does not declare in its ``outputs``."""
    out: dict[str, Any] = {}
    for name in names:
        found = lookup(name)
        added = found.function(run)
        undeclared = sorted(set(added) - set(found.outputs))
        if undeclared:
            raise ValueError(f"metric {name!r} ({found.module}) returned {undeclared}, which "
                             f"its outputs do not declare ({sorted(found.outputs)})")
        out.update(added)
    return out


def reference_markdown() -> str:
    """The registered metrics as markdown (for docs/scenarios.md, ``cosim docs``): per metric
    its name, module, the ``[summary]`` keys it reads, what it measures, and a table of the
    entries it adds with their descriptions and units."""
    lines: list[str] = []
    for m in sorted(registry().values(), key=lambda m: (m.module, m.name)):
        keys = ", ".join(f"`{k}`" for k in m.keys) or "no [summary] key"
        lines += ["", f"**`{m.name}`** (`{m.module.replace('.', '/')}.py`; reads {keys}): "
                  f"{m.description}.", "", "| entry | meaning | unit |", "| --- | --- | --- |"]
        lines += ["| " + " | ".join((f"`{key}`", text.replace("|", "\\|"), unit)) + " |"
                  for key, (text, unit) in m.outputs.items()]
    return "\n".join(lines) + "\n"
