"""One parallel runner for every batch of runs (``cosim sweep``, ``cosim reproduce`` and its
claims' ensembles, ``--perturb`` studies).

:func:`run_tasks` runs :class:`Task` s (a module-level function and its arguments) and hands
each result to a callback as it arrives:

* ``workers`` processes of a local pool (default: the CPU count; one worker without an
  environment change runs in this process), each with one BLAS thread for good
  (:func:`worker_setup`) and reused for many tasks; on Linux they are forked after
  ``warm_up`` ran here (the imports and FMU extractions done once), or spawned when the tasks
  need an environment of their own (``env``, e.g. the plants' reference path);
* or a Dask distributed cluster (``scheduler``: its address, or ``"local-dask"`` for a
  ``LocalCluster`` of ``workers`` processes with one thread each); ``broadcast`` data are sent
  to the cluster once and passed to every task as the keyword ``broadcast``;
* SIGINT/SIGTERM (:mod:`cosim.run.interrupt`): no new task starts, running local tasks are
  signalled (a run stops at its next communication point), what finished is handed on, then
  :class:`cosim.run.interrupt.Interrupted` is raised;
* progress on stderr: runs done / total, elapsed, ETA (one line every ~2 s, and the last).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable, Hashable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from cosim.run import interrupt

LOCAL_DASK = "local-dask"
DASK_EXTRA = "dask"
_POLL_S = 0.2


@dataclass(frozen=True)
class Task:
    """One run: ``function(*args)`` (module-level, so that it reaches a worker process);
    ``key`` names it to the callbacks."""

    key: Hashable
    function: Callable[..., Any]
    args: tuple[Any, ...] = field(default_factory=tuple)


class Progress:
    """``<label>: runs done / total, elapsed, ETA`` lines on ``stream`` (stderr), one every
    ``every`` seconds and the last; silent with ``quiet``."""

    def __init__(self, total: int, label: str, quiet: bool = False, every: float = 2.0,
                 stream: Any = None) -> None:
        self.total, self.label, self.quiet, self.every = total, label, quiet, every
        self.stream = stream
        self.done = 0
        self.start = self.last = time.monotonic()

    def line(self) -> str:
        elapsed = time.monotonic() - self.start
        eta = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        return (f"{self.label}: {self.done}/{self.total} runs, {_duration(elapsed)} elapsed, "
                f"ETA {_duration(eta)}")

    def step(self) -> None:
        self.done += 1
        now = time.monotonic()
        if self.quiet or (now - self.last < self.every and self.done < self.total):
            return
        self.last = now
        print(self.line(), file=self.stream or sys.stderr, flush=True)


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``; ``?`` when unknown."""
    if seconds != seconds:  # NaN: nothing finished yet
        return "?"
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


def check_dask() -> None:
    """Raise ``ValueError`` naming the extra to install when Dask distributed is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError as err:
        raise ValueError(f"--scheduler needs Dask distributed, an optional extra: pip install "
                         f"'ato-cosim[{DASK_EXTRA}]' (or pip install -e \".[{DASK_EXTRA}]\" in a "
                         f"checkout) ({err})") from None


def check_workers(workers: int | None, scheduler: str | None) -> None:
    """Refuse ``--workers`` below 1, and with a cluster that is not started here."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers {workers}: must be at least 1")
    if scheduler is not None:
        check_dask()
        if workers is not None and scheduler != LOCAL_DASK:
            raise ValueError(f"--workers {workers} with --scheduler {scheduler}: a cluster's "
                             "workers are its own (--workers sizes the local pool or "
                             f"--scheduler {LOCAL_DASK})")


def pool_size(workers: int | None, tasks: int) -> int:
    """Processes for ``tasks`` runs: ``workers`` (default: CPU count), at most one a run."""
    return max(1, min(workers or os.cpu_count() or 1, tasks))


def worker_setup(env: dict[str, str] | None = None) -> None:
    """A worker process, once: ``env`` set, one BLAS thread for good, and the master's
    imports done before the first run."""
    os.environ.update(env or {})
    import cosim.run.master  # noqa: F401 - fmpy, numpy, the scenario code
    import cosim.run.metrics  # noqa: F401
    from cosim.run.threads import limit_blas_for_process

    limit_blas_for_process()


def _pool_worker_init(env: dict[str, str] | None) -> None:
    """A local pool worker, once: ignore SIGINT/SIGTERM between runs (a Ctrl-C reaches the
    whole process group; during a run :func:`cosim.run.interrupt.guard` handles them and the
    run stops; a forked worker starts with the parent's guard state, which is cleared), then
    :func:`worker_setup`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    interrupt.reset()
    worker_setup(env)


@contextmanager
def _environment(env: dict[str, str] | None) -> Iterator[None]:
    """``env`` set in this process for the duration (inherited by processes started in it)."""
    old = {k: os.environ.get(k) for k in env or {}}
    os.environ.update(env or {})
    try:
        yield
    finally:
        for key, value in old.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def run_tasks(tasks: Sequence[Task], finished: Callable[[Task, Any], None],
              failed: Callable[[Task, BaseException], None], workers: int | None = None,
              scheduler: str | None = None, label: str = "runs",
              env: dict[str, str] | None = None, warm_up: Callable[[], None] | None = None,
              broadcast: Any = None, quiet: bool = False, what: str = "the runs",
              progress: Progress | None = None) -> None:
    """Run ``tasks``; ``finished(task, result)`` or ``failed(task, error)`` as each ends
    (a task's exception, or its lost worker, fails that task only). Local tasks start in the
    given order; a signal stops them (see the module doc) and raises ``Interrupted`` ("<what>
    interrupted"). ``progress``: a :class:`Progress` shared by several calls (default: one
    over these tasks, labelled ``label``)."""
    if not tasks:
        return
    progress = progress or Progress(len(tasks), label, quiet)

    def done(task: Task, result: Any) -> None:
        finished(task, result)
        progress.step()

    def lost(task: Task, err: BaseException) -> None:
        failed(task, err)
        progress.step()

    with interrupt.guard():
        if scheduler is not None:
            _run_dask(tasks, done, lost, scheduler, workers, env, broadcast, warm_up)
        elif pool_size(workers, len(tasks)) == 1 and not env:
            for task in tasks:
                interrupt.check_between(what)
                _call(task, broadcast, done, lost)
        else:
            _run_pool(tasks, done, lost, pool_size(workers, len(tasks)), env, warm_up,
                      broadcast)
        interrupt.check_between(what)


def _call(task: Task, broadcast: Any, done: Callable[[Task, Any], None],
          lost: Callable[[Task, BaseException], None]) -> None:
    kwargs = {} if broadcast is None else {"broadcast": broadcast}
    try:
        result = task.function(*task.args, **kwargs)
    except interrupt.Interrupted:
        raise
    except Exception as err:  # noqa: BLE001 - a failing run fails its task only
        lost(task, err)
        return
    done(task, result)


def _run_pool(tasks: Sequence[Task], done: Callable[[Task, Any], None],
              lost: Callable[[Task, BaseException], None], workers: int,
              env: dict[str, str] | None, warm_up: Callable[[], None] | None,
              broadcast: Any) -> None:
    """A local process pool: forked after ``warm_up`` on Linux, spawned (inheriting ``env``)
    where an environment is given or fork is not available."""
    fork = (not env and sys.platform == "linux"
            and "fork" in multiprocessing.get_all_start_methods())
    if fork and warm_up is not None:
        import cosim.run.master  # noqa: F401 - the imports, here, once
        import cosim.run.metrics  # noqa: F401

        warm_up()
    ctx = multiprocessing.get_context("fork" if fork else "spawn")
    kwargs = {} if broadcast is None else {"broadcast": broadcast}
    with _environment(env), ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                                initializer=_pool_worker_init,
                                                initargs=(env,)) as pool:
        task_of = {pool.submit(t.function, *t.args, **kwargs): t for t in tasks}
        pending = set(task_of)
        stopping = False
        while pending:
            ready, pending = wait(pending, timeout=_POLL_S, return_when=FIRST_COMPLETED)
            for future in ready:
                if future.cancelled():
                    continue
                try:
                    result = future.result()
                except Exception as err:  # noqa: BLE001 - a crashed worker fails its task
                    lost(task_of[future], err)
                else:
                    done(task_of[future], result)
            if interrupt.requested() and not stopping:
                stopping = True
                for future in pending:
                    future.cancel()
                for proc in list(getattr(pool, "_processes", {}).values()):
                    try:  # the running tasks stop at their next communication point
                        os.kill(proc.pid, signal.SIGINT)
                    except OSError:
                        pass
                pending = {f for f in pending if not f.cancelled()}


def _run_dask(tasks: Sequence[Task], done: Callable[[Task, Any], None],
              lost: Callable[[Task, BaseException], None], scheduler: str,
              workers: int | None, env: dict[str, str] | None, broadcast: Any,
              warm_up: Callable[[], None] | None = None) -> None:
    """The tasks on the cluster at ``scheduler`` (or a LocalCluster started here, inheriting
    ``env``, its workers warmed up by ``warm_up`` before the first task, as a forked pool is);
    results are taken as they complete; on a signal the unfinished tasks are cancelled."""
    from distributed import Client, LocalCluster, wait
    from distributed import TimeoutError as DaskTimeout

    check_dask()
    cluster = None
    with _environment(env):
        if scheduler == LOCAL_DASK:
            cluster = LocalCluster(n_workers=pool_size(workers, len(tasks)),
                                   threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
        try:
            with Client(cluster if cluster is not None else scheduler) as client:
                client.run(worker_setup, env)
                if cluster is not None and warm_up is not None:  # its paths are this machine's
                    client.run(warm_up)
                kwargs: dict[str, Any] = {}
                if broadcast is not None:
                    [kwargs["broadcast"]] = client.scatter([broadcast], broadcast=True)
                task_of = {client.submit(t.function, *t.args, pure=False, **kwargs): t
                           for t in tasks}
                pending = set(task_of)
                while pending:
                    try:
                        wait(list(pending), timeout=_POLL_S, return_when="FIRST_COMPLETED")
                    except (DaskTimeout, TimeoutError):
                        pass
                    ready = {f for f in pending if f.done()}
                    for future in ready:
                        try:
                            result = future.result()
                        except Exception as err:  # noqa: BLE001 - a lost worker: its task
                            lost(task_of[future], err)
                        else:
                            done(task_of[future], result)
                    pending -= ready
                    if pending and interrupt.requested():
                        client.cancel(list(pending))
                        break
        finally:
            if cluster is not None:
                cluster.close()
