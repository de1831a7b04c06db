"""A scenario run end to end: load (and override) it, build its missing or stale FMUs, run the
master over them, compute the summary and write the results (results.csv, summary.json, the
plot); in this process (:func:`run_scenario`) or in a child process that an FMU crash cannot take
down (:func:`start_run`, :func:`finish_run`). The master (:mod:`cosim.run.master`) returns a
result and writes nothing; writing is this module's."""

from __future__ import annotations

import contextlib
import inspect
import json
import os
from pathlib import Path
from typing import Any

from cosim.build.native import build_natives, native_is_stale
from cosim.build.python import build_stale, catalog
from cosim.run import interrupt, isolation
from cosim.run.master.core import Master, ProgressFn, RunResult
from cosim.run.master.errors import SimulationError
from cosim.run.master.pool import InstancePool
from cosim.run.metrics import compute_summary
from cosim.run.results import FILES, is_complete_run, write_results
from cosim.run.scenario import Scenario, ScenarioError, catalog_path, load_scenario


def run_scenario(scenario: str | Path | Scenario, overrides: dict[str, Any] | list[str] | None
                 = None, algorithm: str | None = None, out_dir: str | Path | None = None,
                 progress: ProgressFn | None = None, build: bool = True,
                 plot: bool = True, force: bool = False, plot_format: str = "png",
                 pool: InstancePool | None = None) -> RunResult:
    """Load (and override) a scenario, build missing or stale FMUs, run it, compute the summary
    and, with ``out_dir``, write results.csv, summary.json and plot.png (see
    :func:`cosim.run.results.write_results` for ``force``); ``pool``: the FMU instances kept
    between runs (:mod:`cosim.run.master.pool`). A failure raises
    :class:`SimulationError`, SIGINT/SIGTERM :class:`cosim.run.interrupt.Interrupted`, both
    after writing the partial results."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    if build:
        ensure_built(sc)
    master = Master(sc, algorithm, progress, pool)
    # SIGINT/SIGTERM only set a flag while the FMUs run (never an exception inside their code);
    # the master stops at the next communication point and what was recorded is written
    with interrupt.guard():
        try:
            result = master.run()
        except (SimulationError, interrupt.Interrupted, KeyboardInterrupt) as err:
            partial = getattr(master, "partial", None)
            interrupted = isinstance(err, (interrupt.Interrupted, KeyboardInterrupt))
            if out_dir is None or partial is None or partial.frame.empty and not interrupted:
                raise  # a failure before anything was recorded (e.g. a rejected parameter)
            partial.summary = compute_summary(partial)
            where = write_results(partial, Path(out_dir), plot=plot, force=force,
                                  plot_format=plot_format)[0].parent
            note = (f"; partial results up to t = {partial.sim_time_s:g} s written to {where} "
                    f"(summary.json has \"completed\": false)")
            if isinstance(err, interrupt.Interrupted):
                raise interrupt.Interrupted(f"{err}{note}") from err
            if isinstance(err, KeyboardInterrupt):
                raise interrupt.Interrupted(f"{partial.error}{note}") from err
            raise SimulationError(f"{err}{note}") from err
        result.summary = compute_summary(result)
        if out_dir is not None:
            write_results(result, Path(out_dir), plot=plot, force=force,
                          plot_format=plot_format)
    return result


def ensure_built(sc: Scenario) -> list[Path]:
    """Build the scenario's catalog FMUs that are missing or older than their sources, in the
    scenario's FMI version ([simulation] fmi_version), and its native ones (build =
    "native")."""
    native = sorted({c.fmu for c in sc.components.values() if c.build == "native"})
    version = sc.simulation.fmi_version
    built: list[Path] = []
    for name in native:
        if native_is_stale(name, version):
            built += build_natives(name, (version,))
    return built + _ensure_python_built(sc)


def _ensure_python_built(sc: Scenario) -> list[Path]:
    version = sc.simulation.fmi_version
    specs = catalog()
    wanted = [specs[c.fmu] for c in sc.components.values()
              if c.fmu in specs and c.fmu_path == catalog_path(c.fmu, version)]
    if version == 2:
        return build_stale(wanted)
    if not wanted:
        return []
    if "fmi_version" not in inspect.signature(build_stale).parameters:
        raise ScenarioError(f"{sc.path}: [simulation] fmi_version = 3: this installation cannot "
                            "build FMI 3.0 FMUs (cosim.build.python has no FMI 3 builds); give "
                            "explicit .fmu paths or fmi_version = 2")
    return build_stale(wanted, fmi_version=version)


class RunOutcome:
    """What ``cosim run`` prints of a run done in a child: its summary, algorithm, and the
    real-time factor of the stepping its progress reporter saw (None without one)."""

    def __init__(self, summary: dict[str, Any], algorithm: str,
                 stepping_rtf: float | None) -> None:
        self.summary, self.algorithm, self.stepping_rtf = summary, algorithm, stepping_rtf


def _run_scenario(path: str, options: dict[str, Any], progress: Any = None) -> RunOutcome:
    """In the child: :func:`run_scenario` writing into ``out_dir``, its
    progress shown by ``progress`` (``cosim run``'s reporter: ``progress(t, total)``,
    ``progress.bar`` the display held open meanwhile, ``progress.stepping_rtf()``)."""
    with progress.bar if progress is not None else contextlib.nullcontext():
        result = run_scenario(path, progress=progress, **options)
    return RunOutcome(result.summary, result.algorithm,
                      None if progress is None else progress.stepping_rtf())


def start_run(path: str, progress: Any = None, **options: Any) -> isolation.Child:
    """:func:`run_scenario` (``options``: its keywords, with ``out_dir``)
    started in a child process, showing its progress with ``progress`` (see
    :func:`_run_scenario`; forked, the child writes to the same terminal; a spawned child
    shows none); :func:`finish_run` waits for it."""
    shown = progress if isolation.FORK else None
    return isolation.Child(first=(_run_scenario, (str(path), options, shown), {}))


def finish_run(child: isolation.Child, out_dir: Path, force: bool = False) -> RunOutcome:
    """The outcome of :func:`start_run`'s child; a crash (or a hang stopped) is a
    :class:`cosim.run.master.errors.SimulationError` (``Interrupted``) saying so, after
    :func:`record_crash` wrote what is known of it."""
    try:
        return isolation.supervise(child)
    except isolation.ChildFailed as err:
        where = record_crash(out_dir, str(err), force)
        raise SimulationError(f"{err}; nothing this run recorded could be kept: "
                              f"{where} says so (\"completed\": false)") from None
    except interrupt.Interrupted as err:
        if "SIGKILL" not in str(err):
            raise
        where = record_crash(out_dir, str(err), force)
        raise interrupt.Interrupted(f"{err} ({where} says so)") from None
    finally:
        child.close()


def record_crash(out_dir: Path, message: str, force: bool = False) -> Path:
    """A run that ended without results: ``summary.json`` with ``"completed": false`` and
    ``error`` = ``message``, in ``out_dir``, or in ``<out_dir>.partial`` when ``out_dir``
    holds a complete earlier run (unless ``force``), as :func:`cosim.run.results.write_results`
    places partial results; the results and plots of an earlier run in that folder are
    removed, so none is taken for this run's. Returns the summary's path."""
    out_dir = Path(out_dir)
    if not force and is_complete_run(out_dir):
        out_dir = out_dir.with_name(out_dir.name + ".partial")
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        (out_dir / name).unlink(missing_ok=True)
    summary = out_dir / "summary.json"
    tmp = summary.with_name(".summary.json.writing")
    tmp.write_text(json.dumps({"completed": False, "error": message}, indent=2) + "\n")
    os.replace(tmp, summary)
    return summary
