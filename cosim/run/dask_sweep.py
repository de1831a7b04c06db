"""Sweep points on a Dask distributed cluster (``cosim sweep --scheduler ADDRESS``).

The client (this process) loads and overrides each point's scenario, so a bad value fails its
row exactly as in the local pool, and submits one task per point; a worker runs it with the
same code as a local pool worker (:func:`cosim.run.sweep._run_point`), so the rows are the same
(timings aside). The FMUs travel as files, one of two ways:

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
import logging
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cosim.run import interrupt

LOCAL = "local-dask"
EXTRA = "dask"
_POLL_S = 0.1


def check_available() -> None:
    """Raise ``ValueError`` naming the extra to install when Dask distributed is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError as err:
        raise ValueError(f"--scheduler needs Dask distributed, an optional extra: pip install "
                         f"'ato-cosim[{EXTRA}]' (or pip install -e \".[{EXTRA}]\" in a checkout)"
                         f" ({err})") from None


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


def run_point(scenario: Any, point: dict[str, Any],
              fmus: dict[str, tuple[str, bytes]] | None) -> dict[str, Any]:
    """A Dask task: one grid point of a loaded scenario; ``fmus``: client FMU path ->
    (sha256, file content), or None to use the paths as they are (shared)."""
    from cosim.run.sweep import _run_point, worker_setup

    if not getattr(run_point, "ready", False):  # once per worker process
        worker_setup()
        run_point.ready = True  # type: ignore[attr-defined]
    if fmus is not None:
        scenario = copy.deepcopy(scenario)
        for comp in scenario.components.values():
            digest, data = fmus[str(comp.fmu_path)]
            comp.fmu_path = _local_copy(digest, data)
    return _run_point(scenario, point)


def execute(jobs: list[tuple[str, dict[str, Any]]], scheduler: str, workers: int | None,
            finished: Callable[[dict[str, Any]], None], shared_fmus: bool = False) -> None:
    """Run ``jobs`` (scenario path, grid point) on the cluster at ``scheduler`` (or a new
    local one), handing each row to ``finished`` as it arrives."""
    from distributed import Client, LocalCluster

    from cosim.run.scenario import ScenarioError, load_scenario
    from cosim.run.sweep import pool_size

    if not jobs:
        return
    loaded: list[tuple[str, dict[str, Any], Any]] = []
    for path, point in jobs:  # a bad value fails its row here, as in a local worker
        try:
            loaded.append((path, point, load_scenario(path, dict(point))))
        except (ScenarioError, ValueError, OSError) as err:
            finished({"scenario": Path(path).stem, **point, "status": "failed",
                      "error": str(err)})
    if not loaded:
        return
    cluster = None
    if scheduler == LOCAL:
        cluster = LocalCluster(n_workers=pool_size(workers, len(loaded)), threads_per_worker=1,
                               processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    try:
        with Client(cluster if cluster is not None else scheduler) as client:
            files = None
            if not shared_fmus:
                fmu_paths = sorted({str(c.fmu_path) for _, _, sc_ in loaded
                                    for c in sc_.components.values()})
                blobs = {p: (_digest(Path(p)), Path(p).read_bytes()) for p in fmu_paths}
                [files] = client.scatter([blobs], broadcast=True)
            futures = {client.submit(run_point, sc_, point, files, pure=False): (path, point)
                       for path, point, sc_ in loaded}
            _collect(client, futures, finished)
    finally:
        if cluster is not None:
            cluster.close()


def _collect(client: Any, futures: dict[Any, tuple[str, dict[str, Any]]],
             finished: Callable[[dict[str, Any]], None]) -> None:
    """Rows as the tasks finish; on a signal, cancel the rest and raise Interrupted."""
    pending = set(futures)
    while pending:
        done = {f for f in pending if f.done()}
        for future in done:
            path, point = futures[future]
            try:
                finished(future.result())
            except Exception as err:  # noqa: BLE001 - a lost worker fails its point only
                finished({"scenario": Path(path).stem, **point, "status": "failed",
                          "error": f"Dask task failed: {type(err).__name__}: {err}"})
        pending -= done
        if pending and interrupt.requested():
            client.cancel(list(pending))
            break
        if not done:
            time.sleep(_POLL_S)
    interrupt.check_between("the sweep")
