"""``cosim`` command line: build, list, run, validate (and more, each its own command)."""

from __future__ import annotations

import contextlib
import inspect
import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from cosim.run import MAX_RUNS
from cosim.run.archive import LIMIT_SETTINGS, MB, ArchiveLimits

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Train plants and ATO controllers as FMUs: build, run, validate.")
console = Console(stderr=True)
out = Console()


def _fail(message: str, code: int = 2) -> None:
    console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def _did_you_mean(name: str, known: list[str]) -> str:
    """`` (did you mean 'X'?)`` for the closest of ``known`` (difflib), else ``""``."""
    import difflib

    hint = difflib.get_close_matches(name, known, n=1)
    return f" (did you mean {hint[0]!r}?)" if hint else ""


FMI_CHOICES = {"2": (2,), "3": (3,), "all": (2, 3)}


def _fmi_versions(fmi: str) -> tuple[int, ...]:
    if fmi not in FMI_CHOICES:
        _fail(f"--fmi {fmi!r}: expected one of {', '.join(FMI_CHOICES)}")
    return FMI_CHOICES[fmi]


@app.command()
def build(names: Annotated[list[str] | None, typer.Argument(
        help="FMU identifiers (default: all)")] = None,
          fmi: Annotated[str, typer.Option(
              "--fmi", help="FMI version to build: 2 (fmus/<id>.fmu), 3 (fmus/fmi3/<id>.fmu, "
              "co-simulation with Event Mode for the controllers) or all. Default all: the "
              "FMI 3 build is derived from the same FMI 2 build (same Python bundle, a C "
              "front in front of it), so both cost little more than one. With --native: "
              "fmus/native/<id>.fmu and fmus/native/fmi3/<id>.fmu")] = "all",
          native: Annotated[bool, typer.Option(
              "--native", help="build the native C FMUs (no Python needed) into fmus/native/ "
              "instead, of the FMI versions --fmi names: Linux with gcc, Windows too when "
              "x86_64-w64-mingw32-gcc is installed; the named ones or all that have a C "
              "model")] = False,
          clock: Annotated[str | None, typer.Option(
              "--clock", help="with --fmi 3, the named controllers with an input Clock "
              "activating their events instead of nextEventTime, into "
              "fmus/fmi3/<clock>/<id>.fmu: periodic (a fixed Clock of interval sample_time) "
              "or countdown (the FMU gives the time to its next event: self-triggered "
              "controllers)")] = None,
          interface: Annotated[str, typer.Option(
              "--interface", help="with --clock, the clocked build's interface: cs "
              "(Co-Simulation in Event Mode, the importer ticks the Clock) or se (Scheduled "
              "Execution: the Clock's model partition, activated by the importer at its "
              "ticks; into fmus/fmi3/se/<clock>/<id>.fmu)")] = "cs") -> None:
    """Build FMUs into fmus/ (all, or the named ones)."""
    from cosim.build.fmi3 import INTERFACES, Fmi3BuildError
    from cosim.build.python import build_clocked, build_fmus, resolve

    versions = _fmi_versions(fmi)
    if clock is not None:
        _check_clock(names, clock, fmi, native, interface)
    elif interface != "cs":
        _fail(f"--interface {interface}: an interface of a clocked build: give --clock too")
    if native:
        _build_native(names, versions)
        return
    try:
        specs = resolve(names)
    except ValueError as err:
        _fail(str(err))
    for spec in specs:
        try:
            paths = ([build_clocked(spec, clock, interface)] if clock is not None
                     else build_fmus(spec, fmi_versions=versions))
        except Fmi3BuildError as err:
            _fail(f"{spec.identifier}: {err}")
        except ValueError as err:  # a model without a clocked build (the message names it)
            _fail(str(err))
        for path in paths:
            shown = path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path
            kind = (f", {clock} Clock, {INTERFACES[interface]}" if clock is not None
                    else "")
            out.print(f"built {shown}  ({spec.description}{kind})", highlight=False,
                      markup=False)


def _check_clock(names: list[str] | None, clock: str, fmi: str, native: bool,
                 interface: str) -> None:
    from cosim.build.fmi3 import CLOCK_VARIABILITY, INTERFACES

    if clock not in CLOCK_VARIABILITY:
        _fail(f"--clock {clock!r}: expected one of {', '.join(CLOCK_VARIABILITY)}")
    if interface not in INTERFACES:
        _fail(f"--interface {interface!r}: expected one of {', '.join(INTERFACES)}")
    if fmi != "3" or native or not names:
        _fail(f"--clock {clock}: clocked builds are FMI 3 builds of named Python controllers: "
              "give --fmi 3 and the controllers' identifiers, without --native")


def _build_native(names: list[str] | None, versions: tuple[int, ...]) -> list[Path]:
    from cosim.build.native import NATIVE, CompilerMissing, build_all_natives

    built: list[Path] = []
    try:  # the models side by side, one per core
        done = build_all_natives(names or sorted(NATIVE), versions)
    except (ValueError, CompilerMissing, RuntimeError) as err:
        _fail(str(err))
    for paths in done.values():
        for version, path in zip(versions, paths):
            shown = path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path
            out.print(f"built {shown}  (native C, FMI {version}.0)", highlight=False,
                      markup=False)
        built += paths
    return built


def _built(path: Path) -> str:
    """``cosim list``'s cell for one FMU file: built, no, or corrupt (rebuilt on next use)."""
    from cosim.build.python import is_intact

    if not path.is_file():
        return "no"
    return "built" if is_intact(path) else "corrupt (rebuilt on next use)"


@app.command("list")
def list_() -> None:
    """List the FMUs, the shipped scenarios and the papers.

    A line each: the FMUs this project builds (whether their FMI 2 and FMI 3 builds are in
    fmus/), the scenarios (scenarios/ and each paper's papers/NAME/scenarios/) with their
    descriptions, and the papers reproduced (papers/NAME/entry.toml) with the alias `cosim
    reproduce` also takes."""
    from cosim.build.python import catalog
    from cosim.run.scenario import ScenarioError, read_toml, scenario_files

    table = Table(title="FMUs", show_edge=False)
    table.add_column("identifier")
    table.add_column("FMI 2")
    table.add_column("FMI 3")
    table.add_column("description")
    for spec in catalog().values():
        table.add_row(escape(spec.identifier), _built(spec.path), _built(spec.path_fmi3),
                      escape(spec.description))
    out.print(table)
    table = Table(title="Scenarios", show_edge=False)
    table.add_column("name")
    table.add_column("description")
    for path in scenario_files().values():
        try:
            desc = escape(str(read_toml(path).get("description", "")))
        except ScenarioError as err:
            desc = f"[red]{escape(str(err))}[/]"
        table.add_row(escape(path.stem), desc)
    out.print(table)
    table = Table(title="Papers (cosim reproduce NAME or ALIAS)", show_edge=False)
    table.add_column("name")
    table.add_column("alias")
    table.add_column("paper")
    for name, alias, title in paper_names():
        table.add_row(escape(name), escape(alias), escape(title))
    out.print(table)


def paper_names() -> list[tuple[str, str, str]]:
    """Each shipped reproduction entry's (file stem, alias, title): the papers a reader
    names to `cosim reproduce`."""
    from cosim.reproduce.entry import entry_aliases, entry_names, load_entry

    aliases = {stem: alias for alias, stem in entry_aliases().items()}
    return [(name, aliases.get(name, ""), load_entry(name).title) for name in entry_names()]


SUMMARY_KEYS = ("stop_error_m", "final_speed_mps", "command_switches", "speed_rmse_mps",
                "speed_mse_kmh2", "iae_kmh_s", "max_abs_speed_error_kmh", "max_abs_accel_mps2",
                "max_jerk_mps3", "ctcs3_speed_error_ok", "max_coupler_force_kn", "energy_kwh",
                "arrival_time_error_s", "qp_solves", "qp_infeasible", "qp_solve_time_median_s",
                "executions", "do_steps", "sim_time_s", "wall_time_s", "real_time_factor")


# bookkeeping of summary.json that the printed summary leaves to the file
_NOT_PRINTED = {"completed", "error", "algorithm", "warnings", "fmu_wall_time_s", "do_steps",
                "command_switch_resolution", "terminated_by", "ma_sample_time_s"}


def summary_rows(summary: dict) -> list[tuple[str, str]]:
    """(metric, value) rows of the printed summary: the usual metrics in SUMMARY_KEYS' order,
    then every further scalar metric the scenario's [summary] produced (each family's
    headline figures), dictionaries shortened; the bookkeeping stays in summary.json."""
    keys = [k for k in SUMMARY_KEYS if k in summary and k not in _NOT_PRINTED]
    keys += [k for k, v in summary.items() if k not in keys and k not in _NOT_PRINTED
             and isinstance(v, (int, float, bool, str))]
    rows = []
    for key in keys:
        value = summary[key]
        if isinstance(value, float):
            value = f"{value:.6g}"
        elif isinstance(value, dict):
            value = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                              for k, v in value.items())
        rows.append((key, str(value)))
    return rows


def print_summary(summary: dict, title: str, notes: dict[str, str] | None = None) -> None:
    """The summary as a two-column table at most 80 columns wide (long values wrap);
    ``notes``: text after a metric's value, in parentheses."""
    notes = notes or {}
    table = Table(title=escape(title), show_header=False, show_edge=False,
                  width=min(80, out.width))
    table.add_column("metric", style="bold", no_wrap=True)
    table.add_column("value", overflow="fold")
    for key, value in summary_rows(summary):
        table.add_row(key, escape(value + (f" ({notes[key]})" if key in notes else "")))
    out.print(table)


def real_time_notes(summary: dict, stepping: float | None) -> dict[str, str]:
    """The summary's real-time factor explained: it is the whole run's (loading,
    initialising and freeing the FMUs included), the progress lines' is the stepping's."""
    if summary.get("real_time_factor") is None:
        return {}
    note = "whole run: loading and initialising the FMUs included"
    if stepping is not None:
        note += f"; stepping alone {stepping:.3g}, as the progress lines"
    return {"real_time_factor": note}


@app.command()
def run(
    ctx: typer.Context,
    scenario: Annotated[str, typer.Argument(
        help="a shipped scenario's name (`cosim list`) or a path")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder "
                                                 "(default runs/<scenario>)")] = None,
    algorithm: Annotated[str | None, typer.Option(
        help=escape("event (default), fixed or jacobi; overrides [simulation] algorithm"))]
        = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="override, e.g. plant.mass=539000, controller.N=10, "
                      "simulation.stop_time=80 (repeatable)")] = None,
    fmi: Annotated[int | None, typer.Option(
        "--fmi", help=escape("2 or 3: run the FMI 2.0 or FMI 3.0 builds of catalog FMUs "
                             "(fmus/<Id>.fmu or fmus/fmi3/<Id>.fmu); overrides [simulation] "
                             "fmi_version"))] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar")] = False,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="skip the plot")] = False,
    plot_format: Annotated[str, typer.Option(
        "--format", help="plot file format: png (200 dpi), svg or pdf")] = "png",
    force: Annotated[bool, typer.Option(
        "--force", help="let partial results replace a complete earlier run in --out "
        "(otherwise they go to <out>.partial)")] = False,
    strict: Annotated[bool, typer.Option(
        "--strict", help="exit with status 1 when the run had warnings (e.g. infeasible QPs)")]
        = False,
    in_process: Annotated[bool, typer.Option(
        "--in-process", help="run the FMUs in this process (no child process: an FMU that "
        "crashes ends the command without a report)")] = False,
) -> None:
    """Run a scenario and print its summary.

    Writes results.csv, summary.json and plot.png into --out, building the FMUs it needs.
    The FMUs run in a child process: an FMU that crashes is reported (its name, the signal,
    the FMI call and the time) with summary.json "completed": false. Ctrl-C (or SIGTERM)
    stops the run at the next communication point, writes what was recorded and exits with
    status 130 (an FMU call that does not return is ended after a few seconds); a second
    one exits at once."""
    from cosim.run import interrupt, simulate
    from cosim.run.master import SimulationError
    from cosim.run.results import PLOT_FORMATS, OutputError, check_destination, locked_destination
    from cosim.run.scenario import ScenarioError, find_scenario
    from cosim.run.simulate import run_scenario

    with contextlib.ExitStack() as held, interrupt.guard(restore=False):
        if not console.is_terminal and not quiet:  # a log says what ran
            console.print(command_line(ctx), highlight=False,
                          markup=False, soft_wrap=True)
        try:
            if plot_format not in PLOT_FORMATS:
                raise OutputError(f"--format {plot_format}: one of {', '.join(PLOT_FORMATS)}")
            path = find_scenario(scenario)
            target = out_dir or Path("runs") / path.stem
            check_destination(target)
            held.enter_context(locked_destination(target))
        except (ScenarioError, OutputError) as err:
            _fail(str(err))
        overrides = [*(set_ or []),
                     *([f"simulation.fmi_version={fmi}"] if fmi is not None else [])]
        options = {"overrides": overrides, "algorithm": algorithm, "out_dir": target,
                   "plot": not no_plot, "force": force, "plot_format": plot_format}
        reporter = _ProgressReporter(path.stem, quiet)
        try:
            if in_process:
                with reporter.bar:
                    result = run_scenario(path, progress=reporter, **options)
                stepping = reporter.stepping_rtf()
            else:  # the child shows the progress and says what it saw
                result = simulate.finish_run(simulate.start_run(str(path), reporter,
                                                                  **options), target, force)
                stepping = result.stepping_rtf
        except interrupt.Interrupted as err:
            reporter.stop()
            console.print(f"[bold yellow]{escape(str(err))}[/]", highlight=False,
                          soft_wrap=True)
            raise typer.Exit(interrupt.EXIT_INTERRUPTED) from None
        except (ScenarioError, SimulationError) as err:
            reporter.stop()
            _fail(str(err))
        print_summary(result.summary, f"{path.stem} ({result.algorithm})",
                      real_time_notes(result.summary, stepping))
        out.print(f"wrote {target}/results.csv, summary.json"
                  + ("" if no_plot else f", plot.{plot_format}"),
                  highlight=False, markup=False)
        for warning in result.summary.get("warnings", []):
            console.print(f"[bold yellow]warning:[/] {escape(warning)}", highlight=False,
                          soft_wrap=True)
        if strict and result.summary.get("warnings"):
            raise typer.Exit(1)


def command_line(ctx: typer.Context) -> str:
    """The ``cosim`` command line that repeats the command of ``ctx``: its arguments, then
    every option not at its default (each value of a repeated option), shell-quoted."""
    import shlex

    parts = ["cosim", ctx.info_name or ""]
    for param in ctx.command.params:
        value = ctx.params.get(param.name or "")
        values = list(value) if isinstance(value, (list, tuple)) else [value]
        if param.param_type_name == "argument":
            parts += [str(v) for v in values if v is not None]
            continue
        if value is None or value == param.default or value in ([], ()):
            continue
        flag = max(param.opts, key=len)  # --quiet, not -q
        if getattr(param, "is_flag", False):
            parts.append(flag if value else (param.secondary_opts or [flag])[0])
        else:
            for v in values:
                parts += [flag, str(v)]
    return shlex.join(parts)


class _ProgressReporter:
    """``progress(t, total)`` for the master: a rich bar on a terminal; elsewhere (a pipe, a
    log) a plain line every ~10 % of the simulated time with the real-time factor of the
    stepping (simulated over wall-clock time from the first communication point: loading and
    initialising the FMUs are not in it)."""

    def __init__(self, label: str, quiet: bool) -> None:
        import time

        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.label, self.quiet, self.tty = label, quiet, console.is_terminal
        self._clock = time.perf_counter
        self._first: tuple[float, float] | None = None  # (t, clock) at the first call
        self._last: tuple[float, float] | None = None
        self._next_tenth = 1
        self.bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                            TextColumn("{task.fields[t]:>8.1f} / {task.total:.1f} s sim"),
                            TimeElapsedColumn(), console=console,
                            disable=quiet or not self.tty, transient=True)
        self.task = self.bar.add_task(escape(label), total=1.0, t=0.0)

    def stepping_rtf(self) -> float | None:
        """Simulated over wall-clock seconds from the first call to the last (None before a
        second call, or without wall-clock time between them)."""
        if self._first is None or self._last is None:
            return None
        wall = self._last[1] - self._first[1]
        return (self._last[0] - self._first[0]) / wall if wall > 0 else None

    def __call__(self, t: float, total: float) -> None:
        now = (t, self._clock())
        if self._first is None:
            self._first = now
        self._last = now
        if self.tty:
            self.bar.update(self.task, completed=t, total=total, t=t)
        elif not self.quiet and total > 0 and t >= self._next_tenth * total / 10:
            self._next_tenth = int(10 * t / total) + 1
            rtf = self.stepping_rtf()
            console.print(f"{self.label}: t = {t:.1f} / {total:.1f} s sim "
                          f"({100 * t / total:.0f} %), real-time factor of the stepping "
                          + ("-" if rtf is None else f"{rtf:.3g}"),
                          highlight=False, markup=False, soft_wrap=True)

    def stop(self) -> None:
        self.bar.stop()


def _native_paths(names: list[str] | None, versions: tuple[int, ...]) -> list[Path]:
    """The native builds of the identifiers ``names`` (None: every native FMU) in
    ``versions``, built where missing."""
    from cosim.build.native import NATIVE, CompilerMissing, build_natives, native_path

    paths: list[Path] = []
    for name in sorted(NATIVE) if names is None else names:
        if name not in NATIVE:
            _fail(f"no native model of {name!r}; native: {sorted(NATIVE)}"
                  + _did_you_mean(name, sorted(NATIVE)))
        missing = tuple(v for v in versions if not native_path(name, v).is_file())
        if missing:
            try:
                build_natives(name, missing)
            except (CompilerMissing, RuntimeError) as err:
                _fail(str(err))
        paths += [native_path(name, v) for v in versions]
    return paths


@app.command()
def validate(
    fmus: Annotated[list[str] | None, typer.Argument(
        help="FMU identifiers or .fmu paths (default: every FMU of the catalog)")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable report")] = False,
    fmi: Annotated[str, typer.Option(
        "--fmi", help="for our FMUs named by identifier: check the FMI 2 build (2), the FMI 3 "
        "build (3) or both (all)")] = "2",
    native: Annotated[bool, typer.Option(
        "--native", help="identifiers name the native C FMUs (fmus/native/, built when "
        "missing) instead of the Python FMUs; default: every native FMU")] = False,
    lenient: Annotated[bool, typer.Option(
        "--lenient", help="for third-party FMUs: only what FMI 2.0.4 / FMI 3.0 requires is "
        "an error; "
        "what it recommends or leaves to the FMU, and our project conventions (units "
        "everywhere, explicit output dependencies, default step size), are warnings")] = False,
    call_timeout: Annotated[float, typer.Option(
        help="CPU seconds one FMI call may use before it is reported as a hang (with the call "
        "and its arguments); set-up calls (loading, instantiate, exit initialisation) get at "
        "least --setup-call-timeout. A call that uses no CPU is a hang once the machine, at "
        "its measured speed, offered it twice its limit: a busy machine only makes the wait "
        "longer")] = 5.0,
    setup_call_timeout: Annotated[float, typer.Option(
        help="CPU seconds a set-up call may use (the FMU's imports, e.g. cvxpy, run there)")]
        = 60.0,
    timeout: Annotated[float, typer.Option(
        help="seconds of a free core the dynamic checks of one FMU may take in all (its "
        "worker restarts included); on a busy machine the wall-clock time allowed grows "
        "with the measured slowdown")] = 300.0,
    max_extracted_mb: Annotated[float, typer.Option(
        envvar=LIMIT_SETTINGS["max_extracted"][1],
        help="MiB all files of one FMU may expand to; a larger archive is refused before "
        f"extraction (environment: {LIMIT_SETTINGS['max_extracted'][1]}, which every command "
        "that opens an FMU reads)")] = ArchiveLimits.max_extracted / MB,
    max_files: Annotated[int, typer.Option(
        envvar=LIMIT_SETTINGS["max_files"][1],
        help="files one FMU archive may hold (environment: "
        f"{LIMIT_SETTINGS['max_files'][1]})")] = ArchiveLimits.max_files,
    max_model_description_mb: Annotated[float, typer.Option(
        envvar=LIMIT_SETTINGS["max_model_description"][1],
        help="MiB modelDescription.xml may have (about 1 MiB per 170,000 variables; "
        f"environment: {LIMIT_SETTINGS['max_model_description'][1]})")]
        = ArchiveLimits.max_model_description / MB,
) -> None:
    """Check FMUs against FMI 2.0 / FMI 3.0.

    The compliance checks of cosim.interop.compliance, chosen by the FMU's fmiVersion;
    non-zero exit on an error."""
    from cosim.build.python import build_fmu, catalog

    versions = _fmi_versions(fmi)
    specs = catalog()
    paths: list[Path] = []
    names = fmus or list(specs)
    if native:  # identifiers name native FMUs; .fmu paths stay paths
        paths = _native_paths([n for n in fmus if not n.endswith(".fmu")] if fmus else None,
                              versions)
        names = [n for n in fmus or [] if n.endswith(".fmu")]
    for name in names:
        if name.endswith(".fmu"):
            if not Path(name).is_file():
                folder = name[:len(name) - len(Path(name).name)]  # as written, "" or ".../"
                near = sorted(folder + p.name for p in Path(folder or ".").glob("*.fmu"))
                _fail(f"{name}: no such file" + (_did_you_mean(name, near)  # or an identifier
                                                 or _did_you_mean(Path(name).stem, list(specs))))
            paths.append(Path(name))
        elif name in specs:
            for version in versions:
                path = specs[name].path_for(version)
                if not path.is_file():
                    build_fmu(specs[name], fmi_version=version)
                paths.append(path)
        else:
            hint = _did_you_mean(name, list(specs))
            _fail(f"unknown FMU {name!r}" + (hint or f"; known: {sorted(specs)}"))
    from cosim.interop.compliance import Options, check_fmu, classify, format_report, passed

    limits = ArchiveLimits(max_extracted=int(max_extracted_mb * MB), max_files=max_files,
                           max_model_description=int(max_model_description_mb * MB))
    report: dict[str, list[dict]] = {}
    failed = False
    for path in paths:
        problems = check_fmu(path, Options(strict=not lenient, timeout=timeout,
                                           call_timeout=call_timeout,
                                           setup_call_timeout=setup_call_timeout,
                                           limits=limits))
        failed |= not passed(problems)
        report[str(path)] = [vars(p) for p in problems]
        if not as_json:
            out.print(format_report(path, problems), highlight=False, soft_wrap=True, markup=False)
            if not lenient and not passed(problems):
                hint = _lenient_hint(problems, classify(problems, False))
                if hint:
                    out.print(hint, highlight=False, soft_wrap=True, markup=False)
    if as_json:
        out.print_json(json.dumps(report))
    if failed:
        raise typer.Exit(1)


def _lenient_hint(strict: list, lenient: list) -> str:
    """``cosim validate``'s pointer to ``--lenient`` under a strict report whose errors are,
    all or in part, what FMI recommends or leaves to the FMU or a project convention ("" when
    none is)."""
    from cosim.interop.compliance import ERROR

    errors = sum(p.severity == ERROR for p in strict)
    remain = sum(p.severity == ERROR for p in lenient)
    if remain == errors:
        return ""
    if remain == 0:
        return ("  hint: every error above is something FMI recommends or leaves to the FMU, "
                "or a convention of this project; for a third-party FMU, --lenient checks only "
                "what the standard requires (it passes this one)")
    return (f"  hint: {errors - remain} of the {errors} errors above are what FMI recommends or "
            "leaves to the FMU, or conventions of this project; for a third-party FMU, "
            f"--lenient checks only what the standard requires ({remain} error(s) remain)")


@app.command()
def sweep(
    scenarios: Annotated[list[str], typer.Argument(
        help="shipped scenario name(s) (`cosim list`) or paths, e.g. seed000_stop_rmpc "
        "seed000_stop_rsmpc")],
    set_: Annotated[list[str], typer.Option(
        "--set", help="grid, e.g. controller.N=3..15 or controller.beta=1,2,4 (repeatable)")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder "
                                                 "(default runs/sweep_<scenario>)")] = None,
    workers: Annotated[int | None, typer.Option(
        min=1, help="parallel processes (default: CPUs)")] = None,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="skip sweep.png")] = False,
    resume: Annotated[bool, typer.Option(
        "--resume", help="keep the ok rows of an existing sweep.csv (perturb.csv with "
        "--perturb) made from today's inputs and run only the rest")]
        = False,
    perturb: Annotated[list[str] | None, typer.Option(
        "--perturb", help="model-mismatch study: random plant parameter per run, e.g. "
        "plant.mass=+-10% or plant.brake_delay=0.8..1.2 (repeatable)")] = None,
    samples: Annotated[int, typer.Option(help="with --perturb: draws per grid point")] = 50,
    seed: Annotated[int, typer.Option(help="with --perturb: random seed of the draws")] = 1,
    scheduler: Annotated[str | None, typer.Option(
        help="run the points on a Dask distributed cluster: its scheduler address (e.g. "
        "tcp://10.0.0.5:8786), or 'local-dask' to start a local one of --workers processes; "
        "needs the 'dask' extra (pip install 'ato-cosim\\[dask]')")] = None,
    shared_fmus: Annotated[bool, typer.Option(
        "--shared-fmus", help="with --scheduler: the workers read the FMUs at this machine's "
        "paths (a shared file system) instead of receiving uploaded copies")] = False,
    plot_format: Annotated[str, typer.Option(
        "--format", help="figure file format: png (200 dpi), svg or pdf")] = "png",
    time_limit: Annotated[float | None, typer.Option(
        "--time-limit", min=0.001, help="seconds of wall-clock time a point may "
        "run before it is stopped and marked failed (local workers)")] = None,
    max_runs: Annotated[int, typer.Option(
        "--max-runs", min=1, help="runs (grid points x scenarios, x --samples with --perturb) "
        "the sweep may start; a larger grid is refused before any work")] = MAX_RUNS,
) -> None:
    """Run scenarios over a parameter grid in parallel.

    Writes sweep.csv (a row per point as it finishes, with status and error) and sweep.png. A
    failed point does not stop the others (exit status 1 at the end); Ctrl-C keeps the finished
    rows (exit status 130). With --scheduler: the same grid on a Dask cluster. With --perturb:
    every grid point on the same seeded random plants (perturb.csv, a row per run as it
    finishes, perturb_summary.csv, perturb.png)."""
    from cosim.run import interrupt
    from cosim.run.console import fit_table
    from cosim.run.master import SimulationError
    from cosim.run.results import PLOT_FORMATS, check_destination, locked_destination
    from cosim.run.scenario import ScenarioError, find_scenario
    from cosim.run.sweep import parse_grid, run_sweep

    held = contextlib.ExitStack()
    try:
        if plot_format not in PLOT_FORMATS:
            raise ValueError(f"--format {plot_format}: one of {', '.join(PLOT_FORMATS)}")
        grid = parse_grid(set_)
        stems = [find_scenario(s).stem for s in scenarios]
        target = out_dir or Path("runs") / ("sweep_" + "_".join(stems))
        check_destination(target)
        held.enter_context(locked_destination(target))
        if shared_fmus and scheduler is None:
            raise ValueError("--shared-fmus is for --scheduler runs (local workers read the "
                             "FMUs where they are)")
        if perturb and scheduler is not None:
            raise ValueError("--perturb runs in the local process pool; --scheduler is not "
                             "supported with it")
        if perturb:
            _perturbed_sweep(scenarios, grid, perturb, samples, seed, target, workers, no_plot,
                             plot_format, max_runs, resume)
            return
        frame = run_sweep(scenarios, grid, target, workers, plot=not no_plot, resume=resume,
                          scheduler=scheduler, shared_fmus=shared_fmus,
                          plot_format=plot_format, time_limit=time_limit,
                          max_runs=max_runs)
    except interrupt.Interrupted as err:
        console.print(f"[bold yellow]{escape(str(err))}[/]; the finished rows are in "
                      f"{escape(str(target))}/{'perturb' if perturb else 'sweep'}.csv "
                      "(--resume runs the rest)", highlight=False, soft_wrap=True)
        raise typer.Exit(interrupt.EXIT_INTERRUPTED) from None
    except (ValueError, ScenarioError, SimulationError) as err:
        _fail(str(err))
    finally:
        held.close()
    columns = ["scenario", *grid, "status", "stop_error_m", "controller_executions",
               "command_switches", "qp_infeasible"]
    labels = {"stop_error_m": "stop error m", "controller_executions": "executions",
              "command_switches": "switches", "qp_infeasible": "infeasible",
              **{k: k.rpartition(".")[2] for k in grid}}
    rows = [{c: (None if row[c] is None or row[c] != row[c] else row[c]) for c in columns}
            for row in frame.to_dict("records")]
    out.print(fit_table(rows, columns, labels, keys=1 + len(grid), signed=["stop_error_m"],
                        title=_wrapped(f"sweep over {', '.join(grid)} (every column: "
                                       "sweep.csv)")),
              markup=False, highlight=False, soft_wrap=True)
    out.print(f"wrote {target}/sweep.csv" + ("" if no_plot else f", sweep.{plot_format}"),
              highlight=False, markup=False)
    failed = frame[frame["status"] != "ok"]
    for _, row in failed.iterrows():
        point = ", ".join(f"{k}={row[k]}" for k in grid)
        console.print(f"[bold red]failed:[/] {escape(row['scenario'])} {escape(point)}: "
                      f"{escape(str(row['error']))}", highlight=False, soft_wrap=True)
    if len(failed):
        raise typer.Exit(1)


def _wrapped(text: str, width: int = 80) -> str:
    """``text`` in lines of at most ``width`` characters, broken between words."""
    import textwrap

    return "\n".join(textwrap.wrap(text, width, break_on_hyphens=False))


def _check_perturbed_keys(scenarios: list[str], keys: list[str]) -> None:
    """Raise :class:`ScenarioError` for a ``--perturb`` key whose FMU is not in a scenario or
    whose variable is not in that FMU, with the closest name (difflib); builds the
    scenarios' missing FMUs to read their variables."""
    from fmpy import read_model_description

    from cosim.run.scenario import ScenarioError, load_scenario
    from cosim.run.simulate import ensure_built

    for scenario in scenarios:
        sc = load_scenario(scenario)
        for key in keys:
            comp_name, _, name = key.partition(".")
            comp = sc.components.get(comp_name)
            if comp is None:
                raise ScenarioError(
                    f"--perturb {key}: {sc.name} has no FMU named {comp_name!r}"
                    + (_did_you_mean(comp_name, list(sc.components))
                       or f"; it has {', '.join(sorted(sc.components))}"))
            if name in comp.parameters:
                continue
            ensure_built(sc)
            names = [v.name for v in read_model_description(str(comp.fmu_path)).modelVariables]
            if name not in names:
                raise ScenarioError(f"--perturb {key}: {comp_name} ({comp.fmu}) has no "
                                    f"variable {name!r}" + _did_you_mean(name, names))


def _perturbed_sweep(scenarios: list[str], grid: dict[str, list[Any]], perturb: list[str],
                     samples: int, seed: int, target: Path, workers: int | None,
                     no_plot: bool, plot_format: str = "png", max_runs: int = MAX_RUNS,
                     resume: bool = False) -> None:
    """The mismatch study of ``cosim sweep --perturb`` and its table."""
    from cosim.run.console import fit_table
    from cosim.run.grid import check_runs
    from cosim.run.perturb import run_perturbed
    from cosim.run.perturbation import parse_perturb

    perts = parse_perturb(perturb)
    check_runs(grid, len(scenarios), max_runs, samples)
    _check_perturbed_keys(scenarios, [p.key for p in perts])
    _, summary = run_perturbed(scenarios, grid, perts, samples, seed, target, workers,
                               plot=not no_plot, plot_format=plot_format, max_runs=max_runs,
                               resume=resume)
    columns = [c for c in ["scenario", *grid, "runs", "stop_error_min_m", "stop_error_median_m",
                           "stop_error_max_m", "inside_window", "executions_median",
                           "qp_infeasible_total", "qp_infeasible_max",
                           "qp_infeasible_after_stop_total", "command_min", "command_max"]
               if c in summary]
    labels = {"stop_error_min_m": "err min m", "stop_error_median_m": "err median m",
              "stop_error_max_m": "err max m", "inside_window": "in +-0.5 m",
              "executions_median": "executions", "qp_infeasible_total": "infeasible",
              "qp_infeasible_max": "infeasible max/run",
              "qp_infeasible_after_stop_total": "after stop", "command_min": "u min",
              "command_max": "u max", **{k: k.rpartition(".")[2] for k in grid}}
    out.print(fit_table(summary.to_dict("records"), columns, labels,
                        keys=1 + len([k for k in grid if k in summary]),
                        signed=[c for c in columns if c.startswith("stop_error")],
                        title=_wrapped(f"{samples} perturbed plants (seed {seed}): "
                                       + ", ".join(perturb)
                                       + " (every column: perturb_summary.csv)")),
              markup=False, highlight=False, soft_wrap=True)
    out.print(f"wrote {target}/perturb.csv, perturb_summary.csv"
              + ("" if no_plot else f", perturb.{plot_format}"), markup=False, highlight=False)


@app.command()
def export(
    scenario: Annotated[str, typer.Argument(help="scenario name or TOML path")],
    ssp: Annotated[Path, typer.Option("--ssp", help="SSP archive to write (.ssp)")],
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="override NAME.key=value (repeatable)")] = None,
) -> None:
    """Export a scenario and its FMUs as an SSP 1.0 package.

    The package holds SystemStructure.ssd (components, connections, parameter values, units,
    default experiment) and the FMUs."""
    from cosim.interop.ssp import export_notes, export_ssp
    from cosim.run.results import check_destination, locked_destination
    from cosim.run.scenario import ScenarioError, load_scenario

    try:
        check_destination(ssp, "--ssp", is_dir=False)
        with locked_destination(ssp, "--ssp", is_dir=False):
            sc = load_scenario(scenario, set_ or None)
            path = export_ssp(sc, ssp)
    except (ScenarioError, ValueError, FileNotFoundError) as err:
        _fail(str(err))
    out.print(f"wrote {path}", highlight=False, markup=False)
    for note in export_notes(sc):
        console.print(f"note: {note}", highlight=False, markup=False)


@app.command()
def reproduce(
    name: Annotated[str, typer.Argument(
        help="a paper: its entry papers/NAME/entry.toml (seed000, ...), its alias "
        "(liu2022, ...; `cosim list`) or 'all'")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder "
                                                 "(default runs/reproduce/<name>)")] = None,
    workers: Annotated[int | None, typer.Option(
        help="parallel processes (default: CPUs)", min=1)] = None,
    seeds: Annotated[int | None, typer.Option(
        help="members of each claim's ensemble: the first K report seeds (default 20)",
        min=1)] = None,
    no_rounding: Annotated[bool, typer.Option(
        "--no-rounding", help="skip the claims' rerun on the perturbed floating-point "
        "path (then no claim is marked rounding-robust)")] = False,
    scheduler: Annotated[str | None, typer.Option(
        help="run the runs on a Dask cluster: its address, or 'local-dask' for a local "
        "cluster of --workers processes")] = None,
    plot_format: Annotated[str, typer.Option(
        "--format", help="figure file format: png (200 dpi), svg or pdf")] = "png",
    redraw: Annotated[bool, typer.Option(
        "--redraw", help="no simulation: tables, claims and figures again from the "
        "folder's record (seconds)")] = False,
    resume: Annotated[bool, typer.Option(
        "--resume", help="run only the jobs the folder's record lacks (same simulation "
        "inputs, K, path and build)")] = False,
    build: Annotated[str | None, typer.Option(
        "--build", help="native: the native C builds of the FMUs that have one (the others "
        "Python); python: every FMU's Python build (default: the entry's build)")] = None,
    run_files: Annotated[str, typer.Option(
        "--run-files", help="what each table run writes into runs/<run>/: figures "
        "(summary.json; results.csv where a figure draws the run) or all (also results.csv "
        "and plot of every run, as `cosim run`)")] = "figures",
) -> None:
    """Reproduce a paper's results and test its claims.

    Runs its scenarios, keeps what they produced (record/), writes the table (ours beside the
    paper's), the sweeps and the figures, and tests its claims over K seeds (claims.csv,
    claims.md: median [95 % CI], k of K, verdict); 'all' writes one REPRODUCTION.md. With
    --redraw everything after the simulations is made again from the record."""
    from cosim.reproduce.builds import BUILDS
    from cosim.reproduce.entry import ReproduceError, entry_names, resolve_name
    from cosim.reproduce.page import redraw_entry, reproduce_all
    from cosim.reproduce.page import reproduce as reproduce_entry
    from cosim.reproduce.run import RUN_FILES
    from cosim.run import interrupt, runner
    from cosim.run.master import SimulationError
    from cosim.run.results import PLOT_FORMATS, OutputError, check_destination
    from cosim.run.scenario import ScenarioError

    try:
        if plot_format not in PLOT_FORMATS:
            raise OutputError(f"--format {plot_format}: one of {', '.join(PLOT_FORMATS)}")
        if build is not None and build not in BUILDS:
            raise ReproduceError(f"--build {build}: one of {', '.join(BUILDS)}")
        if run_files not in RUN_FILES:
            raise ReproduceError(f"--run-files {run_files}: one of {', '.join(RUN_FILES)}")
        runner.check_workers(workers, scheduler)
        if out_dir is not None:
            check_destination(out_dir)
        if redraw:
            names = entry_names() if name == "all" else [
                name if Path(name).is_file() else resolve_name(name)]
            for each in names:
                path = redraw_entry(each, out_dir if name != "all" or out_dir is None
                                    else out_dir / each, plot_format)
        elif name == "all":
            path = reproduce_all(out_dir, workers, seeds, not no_rounding, scheduler,
                                 plot_format, build, resume, run_files)
        else:
            if not Path(name).is_file():
                name = resolve_name(name)
            path = reproduce_entry(name, out_dir, workers, seeds, not no_rounding,
                                   scheduler, plot_format, resume=resume, build=build,
                                   run_files=run_files)
    except interrupt.Interrupted as err:
        console.print(f"[bold yellow]{escape(str(err))}[/]", highlight=False, soft_wrap=True)
        raise typer.Exit(interrupt.EXIT_INTERRUPTED) from None
    except (ReproduceError, ScenarioError, SimulationError, OutputError, ValueError) as err:
        _fail(str(err))
    except OSError as err:  # a folder that became unwritable during the run
        _fail(f"cannot write {err.filename or out_dir}: {err.strerror or err}")
    out.print(f"wrote {path}", highlight=False, markup=False)


@app.command()
def optimal(
    track: Annotated[str, typer.Argument(
        help="TTOBench track JSON, route TOML or bundled route name")],
    out_dir: Annotated[Path, typer.Option("--out", help="folder for the CSV and figure")],
    train: Annotated[str, typer.Option(
        help="TTOBench train JSON, or crh3 (seed 003's train)")] = "crh3",
    time: Annotated[float | None, typer.Option(
        "--time", help="running time in s (default: the route's schedule)")] = None,
    journey: Annotated[Path | None, typer.Option(
        help="TTOBench journey JSON: every section, each in its timing window")] = None,
    stops: Annotated[str, typer.Option(help="FROM:TO stop indices of a track")] = "0:-1",
    trade_off: Annotated[int, typer.Option(
        "--trade-off", help="also the energy/running-time curve at N times")] = 0,
    ds: Annotated[float, typer.Option(help="position step of the optimiser (m)")] = 50.0,
    speeds: Annotated[int, typer.Option(help="speed nodes of the optimiser")] = 600,
    closed_loop: Annotated[str | None, typer.Option(
        "--closed-loop", help="also run this tracking controller (pid) after each optimal run "
        "on the CRH3 plant FMU carrying the train, and compare: route.toml, the scenario "
        "LABEL_CONTROLLER.toml, its results in LABEL_CONTROLLER/ and closed_loop.csv")] = None,
    traction_share: Annotated[float, typer.Option(
        "--traction-share", help="share of the traction envelope planned with (crh3 only; "
        "seed 003's trackers plan with 0.9)")] = 1.0,
    max_accel: Annotated[float | None, typer.Option(
        "--max-accel", help="comfort limit on dv/dt (m/s2; default none)")] = None,
    max_decel: Annotated[float | None, typer.Option(
        "--max-decel", help="limit on -dv/dt (m/s2; default none, the train's own brake), "
        "e.g. a service braking rate")] = None,
) -> None:
    """Write the energy-optimal speed profile of a run.

    The profile is for a line, train and running time, by the regimes of optimal train control
    (Pontryagin's maximum principle). With --closed-loop a shipped tracking controller follows
    it in co-simulation: the table gives the planned and closed-loop energy and running time,
    the arrival against the schedule (+-5 s) and the stop error (+-0.5 m), seed 003's
    windows."""
    from cosim.optimal import closed_loop as loop
    from cosim.optimal import output
    from cosim.optimal.lines import load_line
    from cosim.optimal.model import Section, Train
    from cosim.optimal.pontryagin import Grid, SectionSolver
    from cosim.optimal.ttobench import JourneySection, load_journey, load_train
    from cosim.run.master import SimulationError
    from cosim.run.scenario import ScenarioError

    compared: list[loop.Comparison] = []
    try:
        if closed_loop is not None:
            loop.controller(closed_loop)  # an unknown name fails before any planning
        route, stop_list = load_line(track)
        if traction_share != 1.0 and train != "crh3":
            raise ValueError(f"--traction-share {traction_share} applies to --train crh3 only")
        vehicle = (Train.from_crh3(traction_share=traction_share) if train == "crh3"
                   else load_train(train))
        limits = {k: v for k, v in (("max_accel", max_accel), ("max_decel", max_decel))
                  if v is not None}
        if limits:
            vehicle = vehicle.with_limits(**limits)
        runs: list[tuple[str, Section, float, JourneySection | None]] = []
        if journey is not None:
            for i, sec in enumerate(load_journey(journey).sections):
                runs.append((f"section{i}", Section(route, sec.departure.position,
                                                   sec.arrival.position), sec.running_time(),
                             sec))
        else:
            a, b = (int(x) for x in stops.split(":"))
            T = time if time is not None else route.scheduled_time_s
            if T is None:
                raise ValueError("give --time or --journey (the route has no schedule)")
            runs.append(("run", Section(route, stop_list[a], stop_list[b]), T, None))
        grid = Grid(ds=ds, speeds=speeds)
        route_path = loop.write_route(route, out_dir / "route.toml") if closed_loop else None
        table = Table("run", "from (m)", "to (m)", "time (s)", "energy (kWh)", "V (km/h)")
        options = " ".join([f"--train {train}"] + [
            f"--{flag} {value:g}" for flag, value in (
                ("traction-share", traction_share), ("max-accel", max_accel),
                ("max-decel", max_decel), ("ds", ds)) if value is not None]
            + [f"--speeds {speeds}"])
        for label, section, T, sec in runs:
            solver = SectionSolver(section, vehicle, grid)
            best = solver.for_time(T)
            name = f"{route.name} {label}"
            where = (f"--journey {journey} (section {label})" if sec is not None
                     else f"--stops {stops} --time {T:.17g}")
            output.write_csv(best, vehicle, out_dir / f"{label}.csv", name,
                             command=f"cosim optimal {track} {where} {options}")
            output.figure(best, out_dir / f"{label}.png", name)
            table.add_row(label, f"{section.start:.0f}", f"{section.end:.0f}",
                          f"{best.running_time:.1f}", f"{best.energy / 3.6e6:.2f}",
                          f"{best.hold_speed * 3.6:.1f}")
            if trade_off > 1:
                import numpy as np

                t0 = solver.fastest().running_time
                times = np.linspace(t0 * 1.02, max(T, t0 * 1.02) * 1.3, trade_off)
                runs_t = [solver.for_time(float(t)) for t in times]
                output.trade_off_csv(np.array([r.running_time for r in runs_t]),
                                     np.array([r.energy for r in runs_t]),
                                     out_dir / f"{label}_trade_off.csv")
            if closed_loop is not None and route_path is not None:
                window = loop.Window(T, journey=None if sec is None else sec.window())
                compared.append(loop.run_section(label, section, best, vehicle, window,
                                                 out_dir, route_path, _run_scenario,
                                                 closed_loop, name, sec))
    except (ValueError, KeyError, OSError, ScenarioError, SimulationError, RuntimeError) as err:
        _fail(str(err))
    out.print(table)
    if compared:
        path = loop.write_table(compared, out_dir / "closed_loop.csv")
        out.print(_closed_loop_table(compared, closed_loop or ""))
        out.print(f"wrote {path}", highlight=False, markup=False)
    out.print(f"wrote {out_dir}", highlight=False, markup=False)


def _run_scenario(path: Path, where: Path) -> tuple[Any, dict[str, Any]]:
    """Run a scenario file as ``cosim run PATH --out WHERE`` does: (recorded frame, summary)."""
    from cosim.run.simulate import run_scenario

    result = run_scenario(path, out_dir=where)
    return result.frame, result.summary


def _closed_loop_table(compared: list, controller: str) -> Table:
    """Plan against closed loop, a row per section (energies in kWh)."""
    table = Table("run", "schedule (s)", "planned (s)", "closed loop (s)", "planned (kWh)",
                  "closed loop (kWh)", "stop error (m)", "verdict",
                  title=f"closed loop ({controller}) against the plan")
    for c in compared:
        time_cell = "still moving" if c.time is None else (
            f"{c.time:.1f} ({c.arrival_error:+.1f})")
        table.add_row(c.label, f"{c.window.schedule:.1f}", f"{c.planned_time:.1f}", time_cell,
                      f"{c.planned_energy / 3.6e6:.2f}",
                      f"{c.energy / 3.6e6:.2f} ({100 * (c.energy / c.planned_energy - 1):+.1f} %)",
                      f"{c.stop_error:+.3f}", escape("; ".join(c.verdict())
                                                     or "within the windows"))
    return table


def cli_reference() -> str:
    """``docs/cli.md``: every command's usage, help text and options, read from the click
    command tree typer builds (so the page says what ``--help`` says)."""
    group = typer.main.get_command(app)
    ctx = group.context_class(group, info_name="cosim")
    lines = ["# CLI reference", "",
             "Generated by `cosim docs` from the commands themselves; do not edit by hand. "
             "`cosim COMMAND --help` prints the same.", "", group.help or "", ""]
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        sub = cmd.context_class(cmd, info_name=name, parent=ctx)
        lines += [f"## cosim {name}", "", "```text", cmd.get_usage(sub).replace(
            "Usage: ", ""), "```", "", (cmd.help or "").strip(), ""]
        rows = []
        for param in cmd.params:
            if param.name == "help":
                continue
            text = getattr(param, "help", "") or ""
            if param.param_type_name == "option":
                names = ", ".join(param.opts + param.secondary_opts)
                if not getattr(param, "is_flag", False) and param.default not in (None, [], ()):
                    text += f" (default: {param.default})"
            else:
                names = (param.name or "").upper()
            rows.append(f"| `{names}` | {' '.join(text.split()).replace('|', chr(92) + '|')} |")
        if rows:
            lines += ["| argument or option | meaning |", "| --- | --- |", *rows, ""]
    return "\n".join(lines).rstrip() + "\n"


@app.command()
def docs(check: Annotated[bool, typer.Option(
        "--check", help="exit 1 if a generated page is out of date instead of writing it")
        ] = False) -> None:
    """Write the documentation site's generated pages.

    The CLI reference (docs/cli.md), the FMU reference (docs/fmus.md, from the cores'
    declarations), the benchmarks (docs/benchmarks.md, from benchmarks/results.json) and a page
    per paper (docs/papers/NAME.md, from runs/reproduce/NAME/ where it exists)."""
    from cosim.site import DOCS, generated_pages, stale, stale_papers, write

    def pages():
        yield DOCS / "cli.md", cli_reference().encode()
        yield from generated_pages()

    if check:
        old = stale(pages())
        if old:
            _fail("out of date: " + ", ".join(str(p) for p in old) + ": run `cosim docs`",
                  code=1)
        papers = stale_papers()
        if papers:
            _fail("paper pages not made from this tree:\n  " + "\n  ".join(papers), code=1)
        out.print("generated pages are up to date")
        return
    for path in write(pages()):
        out.print(f"wrote {path}", highlight=False, markup=False)
    for line in stale_papers():
        out.print(f"[yellow]stale:[/] {line}", highlight=False)


def one_line_paragraphs(text: str) -> str:
    """``text`` (a docstring) with each paragraph on one line: typer's rich help keeps a
    docstring's line breaks, which then break sentences in the middle at any terminal width;
    a one-line paragraph is wrapped by the terminal at its own width."""
    return "\n\n".join(" ".join(p.split()) for p in inspect.cleandoc(text).split("\n\n"))


for _command in app.registered_commands:  # each command's help: a short first sentence
    _command.help = one_line_paragraphs(_command.help or _command.callback.__doc__ or "")


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    app()
