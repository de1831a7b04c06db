"""Sweep points on a Dask distributed cluster (``cosim sweep --scheduler ADDRESS``).

The client (this process) loads and overrides each point's scenario, so a bad value fails its
row exactly as in the local pool, and submits one task per point; a worker runs it with the
same code as a local pool worker (:func:`cosim.run.sweep.run_point`), so the rows are the same
(timings aside); the cluster, progress and interrupts are :mod:`cosim.run.runner`'s. The FMUs
travel as files, one of two ways:

* uploaded (default): each FMU file is sent to the cluster once (``scatter``), and a worker
  writes it once into ``<tmp>/ato-cosim-fmus/<sha256>.fmu``, then extracts and imports it
  once per worker process (:func:`cosim.run.master.extract_once`), for any number of points;
* shared (``shared_fmus``): the workers open the FMUs at the client's paths, which must be
  the same files on a shared file system (NFS, a container volume).

The workers need this package installed (the same version). ``--scheduler local-dask`` starts
a ``LocalCluster`` of ``workers`` processes with one thread each, for trying it out.
Interrupt (Ctrl-C): the points not finished are cancelled, the finished rows are kept.
"""

from __future__ import annotations

import copy
import hashlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cosim.run import runner
from cosim.run.scenario import ScenarioError, load_scenario

LOCAL = runner.LOCAL_DASK
check_available = runner.check_dask
# one grid point of a loaded scenario -> its sweep row (cosim.run.sweep.run_point)
PointRun = Callable[[Any, dict[str, Any]], dict[str, Any]]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _local_copy(digest: str, data: bytes) -> Path:
    """The worker's copy of an uploaded FMU, written once (atomically) per machine."""
    folder = Path(tempfile.gettempdir()) / "ato-cosim-fmus"
    target = folder / f"{digest}.fmu"
    if not target.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        part = folder / f".{digest}.{os.getpid()}.part"
        part.write_bytes(data)
        os.replace(part, target)
    return target


def run_point(point_run: PointRun, scenario: Any, point: dict[str, Any],
              broadcast: dict[str, tuple[str, bytes]] | None = None) -> dict[str, Any]:
    """A Dask task: ``point_run`` (:func:`cosim.run.sweep.run_point`) on one grid point of a
    loaded scenario; ``broadcast``: client FMU path -> (sha256, file content), or None to use
    the paths as they are (shared)."""
    if broadcast is not None:
        scenario = copy.deepcopy(scenario)
        for comp in scenario.components.values():
            digest, data = broadcast[str(comp.fmu_path)]
            comp.fmu_path = _local_copy(digest, data)
    return point_run(scenario, point)


def tasks(jobs: list[tuple[str, dict[str, Any]]], finished: Callable[[dict[str, Any]], None],
          point_run: PointRun, shared_fmus: bool = False
          ) -> tuple[list[runner.Task], dict[str, tuple[str, bytes]] | None]:
    """The runner's tasks for ``jobs`` (scenario path, grid point), each running ``point_run``
    (:func:`cosim.run.sweep.run_point`, passed in: the sweep imports this module), each
    scenario loaded and
    overridden here (a bad value fails its row through ``finished``), and the FMU files to
    send to the cluster once (None with ``shared_fmus``)."""
    out: list[runner.Task] = []
    for path, point in jobs:
        try:
            loaded = load_scenario(path, dict(point))
        except (ScenarioError, ValueError, OSError) as err:
            finished({"scenario": Path(path).stem, **point, "status": "failed",
                      "error": str(err)})
            continue
        out.append(runner.Task((path, point), run_point, (point_run, loaded, point)))
    if shared_fmus or not out:
        return out, None
    fmu_paths = sorted({str(c.fmu_path) for t in out for c in t.args[1].components.values()})
    return out, {p: (_digest(Path(p)), Path(p).read_bytes()) for p in fmu_paths}
