"""One parallel runner for every batch of runs (``cosim sweep``, ``cosim reproduce`` and its
claims' ensembles, ``--perturb`` studies).

:func:`run_tasks` runs :class:`Task` s (a module-level function and its arguments) and hands
each result to a callback as it arrives:

* ``workers`` child processes (default: the CPU count; :class:`cosim.run.isolation.Child`:
  in a process group of their own, dying with this process), each with one BLAS thread for
  good (:func:`worker_setup`) and reused for many tasks; on Linux they are forked after
  ``warm_up`` ran here (the imports and FMU extractions done once), or spawned when the tasks
  need an environment of their own (``env``, e.g. the plants' reference path); a worker that
  crashes, or passes a task's ``time_limit``, fails that task (naming the signal and the FMU
  call) and is replaced;
* or a Dask distributed cluster (``scheduler``: its address, or ``"local-dask"`` for a
  ``LocalCluster`` of ``workers`` processes with one thread each); ``broadcast`` data are sent
  to the cluster once and passed to every task as the keyword ``broadcast``;
* SIGINT/SIGTERM (:mod:`cosim.run.interrupt`): no new task starts, running local tasks are
  signalled once (a run stops at its next communication point; a worker whose FMU call does
  not return is ended), what finished is handed on, then
  :class:`cosim.run.interrupt.Interrupted` is raised; a second signal ends the workers and
  this process at once;
* progress on stderr: runs done / total, elapsed, ETA (one line every ~2 s, and the last).
"""

from __future__ import annotations

import functools
import logging
import os
import sys
import time
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import cosim.run.master  # noqa: F401 - fmpy, numpy, the scenario code: a worker has them
import cosim.run.metrics  # noqa: F401
from cosim.run import interrupt, isolation
from cosim.run.threads import limit_blas_for_process

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
    """A worker process, once: ``env`` set and one BLAS thread for good (the master's imports
    are this module's, done before the first run)."""
    os.environ.update(env or {})
    limit_blas_for_process()


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
              progress: Progress | None = None, time_limit: float | None = None) -> None:
    """Run ``tasks``; ``finished(task, result)`` or ``failed(task, error)`` as each ends
    (a task's exception, its worker's crash (:class:`cosim.run.isolation.ChildFailed`, naming
    the signal and the FMU call) or its ``time_limit`` (s, wall clock, local workers;
    :class:`TimeLimitExceeded`) fails that task only). Local tasks start in the given order; a
    signal stops them (see the module doc) and raises ``Interrupted`` ("<what>
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
        else:
            _run_local(tasks, done, lost, pool_size(workers, len(tasks)), env, warm_up,
                       broadcast, time_limit)
        interrupt.check_between(what)


class TimeLimitExceeded(Exception):  # noqa: N818 - the user's words
    """A task ran longer than its time limit and was stopped; the message says where."""


def _run_local(tasks: Sequence[Task], done: Callable[[Task, Any], None],
               lost: Callable[[Task, BaseException], None], workers: int,
               env: dict[str, str] | None, warm_up: Callable[[], None] | None,
               broadcast: Any, time_limit: float | None) -> None:
    """``workers`` child processes (:class:`cosim.run.isolation.Child`), each reused for
    many tasks: forked after ``warm_up`` on Linux, spawned (inheriting ``env``) where an
    environment is given or fork is not available. A child that crashes or passes
    ``time_limit`` fails its task and is replaced; on a signal no new task starts, the
    running ones are passed the signal once (an FMU call that does not return ends its
    child, :func:`cosim.run.isolation.hung`)."""
    spawn = bool(env) or not isolation.FORK
    if not spawn and warm_up is not None:
        warm_up()
    kwargs = {} if broadcast is None else {"broadcast": broadcast}
    queue = list(tasks)
    idle: list[isolation.Child] = []
    running: dict[isolation.Child, Task] = {}
    with _environment(env):
        try:
            while queue or running:
                name = interrupt.requested()
                while queue and name is None and len(running) < workers:
                    child = idle.pop() if idle else isolation.Child(
                        functools.partial(worker_setup, env), spawn=spawn)
                    task = queue.pop(0)
                    running[child.submit(task.function, task.args, kwargs)] = task
                isolation.wait(list(running), _POLL_S)
                name = interrupt.requested()
                for child, task in list(running.items()):
                    stopped = None if child.poll() else _stopped(child, name, time_limit)
                    if stopped is not None:
                        child.kill()
                    elif child.busy and child.process.is_alive():
                        continue
                    del running[child]
                    try:
                        if stopped is not None:
                            raise stopped
                        result = child.result()
                    except Exception as err:  # noqa: BLE001 - it fails its task only
                        lost(task, err)
                    else:
                        done(task, result)
                    if child.process.is_alive():
                        idle.append(child)
                if interrupt.requested() is not None:
                    queue.clear()
        finally:
            for child in idle:
                child.close()
            for child in running:
                child.kill()


def _stopped(child: isolation.Child, signal_name: str | None,
             time_limit: float | None) -> BaseException | None:
    """Why ``child``'s task is to be stopped now (its time limit, or an FMU call that did
    not return after a signal), else None; a signal is passed on to it once."""
    if signal_name is not None and child.stuck_since is None:
        child.interrupt(signal_name)
    where = child.in_call()
    if time_limit is not None and time.monotonic() - child.started > time_limit:
        return TimeLimitExceeded(f"stopped after its time limit of {time_limit:g} s"
                                 + ("" if where is None else
                                    ": " + where.replace("|", " in ", 1)))
    stuck = isolation.hung(child)
    return None if stuck is None else isolation.ChildFailed(f"{stuck} after {signal_name}")


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
