"""``cosim`` command line: build, list, run, validate (and more, each its own command)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Train plants and ATO controllers as FMUs: build, run, validate.")
console = Console(stderr=True)
out = Console()


def _fail(message: str, code: int = 2) -> None:
    from rich.markup import escape

    # escaped: scenario keys such as [fmus.plant] are not rich markup
    console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


@app.command()
def build(names: Annotated[list[str] | None, typer.Argument(
        help="FMU identifiers (default: all)")] = None) -> None:
    """Build FMUs into fmus/ (all, or the named ones)."""
    from cosim.fmu.build import build_fmu, resolve

    try:
        specs = resolve(names)
    except ValueError as err:
        _fail(str(err))
    for spec in specs:
        path = build_fmu(spec)
        shown = path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path
        out.print(f"built {shown}  ({spec.description})", highlight=False)


@app.command("list")
def list_() -> None:
    """List the FMUs this project builds and the shipped scenarios, a line each."""
    from cosim.fmu.build import catalog
    from cosim.run.scenario import SCENARIO_DIR

    table = Table(title="FMUs", show_edge=False)
    table.add_column("identifier")
    table.add_column("built")
    table.add_column("description")
    for spec in catalog().values():
        table.add_row(spec.identifier, "yes" if spec.path.is_file() else "no", spec.description)
    out.print(table)
    table = Table(title="Scenarios", show_edge=False)
    table.add_column("name")
    table.add_column("description")
    for path in sorted(SCENARIO_DIR.glob("*.toml")):
        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            import tomli as tomllib  # type: ignore[no-redef]
        try:
            desc = tomllib.loads(path.read_text()).get("description", "")
        except tomllib.TOMLDecodeError as err:
            desc = f"[red]invalid TOML: {err}[/]"
        table.add_row(path.stem, desc)
    out.print(table)


SUMMARY_KEYS = ("stop_error_m", "final_speed_mps", "command_switches", "speed_rmse_mps",
                "speed_mse_kmh2", "iae_kmh_s", "max_abs_speed_error_kmh", "max_abs_accel_mps2",
                "max_jerk_mps3", "ctcs3_speed_error_ok", "max_coupler_force_kn", "energy_kwh",
                "arrival_time_error_s", "qp_solves", "qp_infeasible", "qp_solve_time_median_s",
                "executions", "do_steps", "sim_time_s", "wall_time_s", "real_time_factor")


def print_summary(summary: dict, title: str) -> None:
    table = Table(title=title, show_header=False, show_edge=False)
    table.add_column("metric", style="bold")
    table.add_column("value")
    for key in SUMMARY_KEYS:
        if key in summary:
            value = summary[key]
            if isinstance(value, float):
                value = f"{value:.6g}"
            elif isinstance(value, dict):
                value = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                  for k, v in value.items())
            table.add_row(key, str(value))
    out.print(table)


@app.command()
def run(
    scenario: Annotated[str, typer.Argument(help="scenario name in scenarios/ or a path")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder "
                                                 "(default runs/<scenario>)")] = None,
    algorithm: Annotated[str | None, typer.Option(
        help="event (default), fixed or jacobi; overrides [simulation] algorithm")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="override, e.g. plant.mass=539000, controller.N=10, "
                      "simulation.stop_time=80 (repeatable)")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bar")] = False,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="skip plot.png")] = False,
) -> None:
    """Run a scenario; write results.csv, summary.json and plot.png; print the summary."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from cosim.run.master import SimulationError, run_scenario
    from cosim.run.scenario import ScenarioError, find_scenario

    try:
        path = find_scenario(scenario)
    except ScenarioError as err:
        _fail(str(err))
    target = out_dir or Path("runs") / path.stem
    show = not quiet and sys.stderr.isatty()
    progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                        TextColumn("{task.fields[t]:>8.1f} / {task.total:.1f} s sim"),
                        TimeElapsedColumn(), console=console, disable=not show, transient=True)
    with progress:
        task = progress.add_task(path.stem, total=1.0, t=0.0)

        def on_progress(t: float, total: float) -> None:
            progress.update(task, completed=t, total=total, t=t)

        try:
            result = run_scenario(path, overrides=set_ or [], algorithm=algorithm,
                                  out_dir=target, progress=on_progress, plot=not no_plot)
        except (ScenarioError, SimulationError) as err:
            progress.stop()
            _fail(str(err))
    print_summary(result.summary, f"{path.stem} ({result.algorithm})")
    out.print(f"wrote {target}/results.csv, summary.json" + ("" if no_plot else ", plot.png"))


@app.command()
def validate(
    fmus: Annotated[list[str] | None, typer.Argument(
        help="FMU identifiers or .fmu paths (default: every FMU of the catalog)")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="machine-readable report")] = False,
    lenient: Annotated[bool, typer.Option(
        "--lenient", help="for third-party FMUs: only what FMI 2.0.4 requires is an error; "
        "what it recommends or leaves to the FMU, and our project conventions (units "
        "everywhere, explicit output dependencies, default step size), are warnings")] = False,
    call_timeout: Annotated[float, typer.Option(
        help="seconds one FMI call may take before it is reported as a hang (with the call "
        "and its arguments)")] = 5.0,
    timeout: Annotated[float, typer.Option(
        help="seconds one FMU's whole check may take (a backstop for hangs the per-call "
        "watchdog misses)")] = 120.0,
) -> None:
    """FMI 2.0 compliance checks (cosim.interop.compliance) on FMUs; non-zero exit on an error."""
    from cosim.fmu.build import build_fmu, catalog

    specs = catalog()
    paths: list[Path] = []
    for name in fmus or list(specs):
        if name.endswith(".fmu"):
            if not Path(name).is_file():
                _fail(f"{name}: no such file")
            paths.append(Path(name))
        elif name in specs:
            if not specs[name].path.is_file():
                build_fmu(specs[name])
            paths.append(specs[name].path)
        else:
            _fail(f"unknown FMU {name!r}; known: {sorted(specs)}")
    from cosim.interop.compliance import Options, check_fmu, format_report, passed

    report: dict[str, list[dict]] = {}
    failed = False
    for path in paths:
        problems = check_fmu(path, Options(strict=not lenient, timeout=timeout,
                                           call_timeout=call_timeout))
        failed |= not passed(problems)
        report[str(path)] = [vars(p) for p in problems]
        if not as_json:
            out.print(format_report(path, problems), highlight=False, soft_wrap=True)
    if as_json:
        out.print_json(json.dumps(report))
    if failed:
        raise typer.Exit(1)


@app.command()
def sweep(
    scenarios: Annotated[list[str], typer.Argument(
        help="scenario name(s) in scenarios/ or paths, e.g. seed000_stop_rmpc seed000_stop_rsmpc")],
    set_: Annotated[list[str], typer.Option(
        "--set", help="grid, e.g. controller.N=3..15 or controller.beta=1,2,4 (repeatable)")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder "
                                                 "(default runs/sweep_<scenario>)")] = None,
    workers: Annotated[int | None, typer.Option(help="parallel processes (default: CPUs)")] = None,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="skip sweep.png")] = False,
) -> None:
    """Run scenarios over a parameter grid in parallel; write sweep.csv and sweep.png."""
    from cosim.run.master import SimulationError
    from cosim.run.scenario import ScenarioError, find_scenario
    from cosim.run.sweep import parse_grid, run_sweep

    try:
        grid = parse_grid(set_)
        stems = [find_scenario(s).stem for s in scenarios]
        target = out_dir or Path("runs") / ("sweep_" + "_".join(stems))
        frame = run_sweep(scenarios, grid, target, workers, plot=not no_plot)
    except (ValueError, ScenarioError, SimulationError) as err:
        _fail(str(err))
    table = Table(title=f"sweep over {', '.join(grid)}")
    columns = ["scenario", *grid, "stop_error_m", "controller_executions", "command_switches",
               "qp_infeasible"]
    labels = {"stop_error_m": "stop error m", "controller_executions": "executions",
              "command_switches": "switches", "qp_infeasible": "infeasible"}
    for col in columns:
        table.add_column(labels.get(col, col.rpartition(".")[2]),
                         justify="left" if col == "scenario" else "right")
    for _, row in frame.iterrows():
        table.add_row(*[f"{row[c]:+.3f}" if c == "stop_error_m" else str(row[c])
                        for c in columns])
    out.print(table)
    out.print(f"wrote {target}/sweep.csv" + ("" if no_plot else ", sweep.png"))


@app.command()
def export(
    scenario: Annotated[str, typer.Argument(help="scenario name or TOML path")],
    ssp: Annotated[Path, typer.Option("--ssp", help="SSP archive to write (.ssp)")],
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="override NAME.key=value (repeatable)")] = None,
) -> None:
    """Export a scenario and its FMUs as an SSP 1.0 package (SystemStructure.ssd + FMUs)."""
    from cosim.interop.ssp import export_ssp
    from cosim.run.scenario import ScenarioError

    try:
        path = export_ssp(scenario, ssp, overrides=set_ or None)
    except (ScenarioError, ValueError, FileNotFoundError) as err:
        _fail(str(err))
    out.print(f"wrote {path}")


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    app()
