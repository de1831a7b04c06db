"""The master against the bare C loop on the same native FMUs (the EMU and the freight train).

Each scenario (default seed001_emu_pid and seed002_freight_pid) runs with every FMU's native C
build (``NAME.build = "native"``) twice, alternately, ``repeat`` times each:

* through the event-driven master in this process (``Master.run``, no files): its loop's wall
  and CPU time (``Master.loop_wall_time``, ``loop_cpu_time``: the communication points alone);
* through ``benchmarks/c_loop.c``, compiled here with gcc and the native builds' flags against
  fmpy's FMI 2.0 headers: the same FMUs' shared libraries loaded with dlopen, the same start
  values (``raw_loop.start_values``), connections in the same order
  (``raw_loop.connection_groups``), step and stop time, one fmi2GetReal / fmi2SetReal per
  connection group and one fmi2DoStep per FMU and step, no recording: its loop's wall and CPU
  time, measured inside the C program.

Reports the medians, the ratios C / master (the share of the C loop's speed the master reaches,
target >= 0.5) and master / C, and whether the final position (the scenario's ``[summary]
position``) is the same in both, to all 17 printed digits. Asserts nothing.
``benchmarks/run_all.py --only c_limit`` records the figures.

    python benchmarks/bench_c_limit.py [SCENARIO ...] [--repeat N]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE)]

import fmpy  # noqa: E402
from fmpy import extract, read_model_description  # noqa: E402
from raw_loop import connection_groups, start_values  # noqa: E402

from cosim.build.native import CC_FLAGS, LINUX_CC, build_natives, native_path  # noqa: E402
from cosim.run.master import Master  # noqa: E402
from cosim.run.scenario import Scenario, find_scenario, load_scenario  # noqa: E402

SCENARIOS = {"EMU": "seed001_emu_pid", "freight": "seed002_freight_pid"}
TARGET = 0.5  # the master's share of the C loop's speed (C loop wall / master loop wall)
SOURCE = HERE / "c_loop.c"


def native_scenario(scenario: str) -> Scenario:
    """``scenario`` with every component on its native C build (built when missing)."""
    sc = load_scenario(find_scenario(scenario))
    for comp in sc.components.values():
        if not native_path(comp.fmu, 2).is_file():
            build_natives(comp.fmu, (2,))
    return load_scenario(find_scenario(scenario),
                         {f"{name}.build": "native" for name in sc.components})


def compile_c_loop(folder: Path) -> Path:
    """``c_loop.c`` compiled into ``folder`` with gcc (the native builds' flags)."""
    cc = shutil.which(LINUX_CC)
    if cc is None:
        raise SystemExit(f"the bare C loop needs the C compiler {LINUX_CC!r} on PATH")
    exe = folder / "c_loop"
    headers = Path(fmpy.__file__).parent / "c-code"  # fmi2Functions.h, as the native builds
    done = subprocess.run([cc, *CC_FLAGS, f"-I{headers}", "-o", str(exe), str(SOURCE), "-ldl"],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{cc} failed on {SOURCE}:\n{done.stderr[-3000:]}")
    return exe


def plan_text(sc: Scenario, unzipped: dict[str, str]) -> str:
    """The C loop's plan (the line format of ``c_loop.c``) for ``sc``'s FMUs extracted into
    ``unzipped`` (component -> folder)."""
    names = list(sc.components)
    lines, variables, feedthrough = [], {}, {}
    for name, comp in sc.components.items():
        md = read_model_description(str(comp.fmu_path))
        mid = md.coSimulation.modelIdentifier
        library = (Path(unzipped[name]) / "binaries" / fmpy.platform
                   / f"{mid}{fmpy.sharedLibraryExtension}")
        resources = (Path(unzipped[name]) / "resources").as_uri()
        lines.append(f"fmu {library} {mid} {md.guid} {resources} {name}")
        variables[name] = {v.name: v for v in md.modelVariables}
        feedthrough[name] = any(o.dependencies for o in md.outputs)
    for name, comp in sc.components.items():
        for var, value in start_values(comp, variables[name]):
            text = repr(value) if var.type == "Real" else str(int(value)) \
                if var.type in ("Integer", "Boolean") else value
            lines.append(f"set {var.type[0].lower()} {names.index(name)} "
                         f"{var.valueReference} {text}")
    for src, s_refs, dst, d_refs in connection_groups(sc, variables, feedthrough):
        lines.append(f"link {names.index(src)} {names.index(dst)} {len(s_refs)} "
                     + " ".join(map(str, [*s_refs, *d_refs])))
    step = float(sc.simulation.base_step)
    steps = int(round((sc.simulation.stop_time - sc.simulation.start_time) / step))
    lines.append(f"run {sc.simulation.start_time!r} {step!r} {steps}")
    comp, var = sc.summary["position"].split(".", 1)
    lines.append(f"final {names.index(comp)} {variables[comp][var].valueReference}")
    return "\n".join(lines) + "\n"


def prepare_c_loop(sc: Scenario, folder: Path) -> tuple[Path, str]:
    """The C loop compiled into ``folder``, and its plan for ``sc``'s FMUs (extracted there)."""
    unzipped = {name: extract(str(comp.fmu_path), unzipdir=str(folder / name))
                for name, comp in sc.components.items()}
    return compile_c_loop(folder), plan_text(sc, unzipped)


def c_run(exe: Path, plan: str) -> dict[str, float]:
    """Run the C loop on ``plan``: {final, loop_wall_s, loop_cpu_s}."""
    done = subprocess.run([str(exe)], input=plan, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{exe} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout)


def master_run(sc: Scenario) -> dict[str, float]:
    """Run ``sc`` through the master: {final (the summary's position), loop_wall_s,
    loop_cpu_s}."""
    master = Master(sc)
    result = master.run()
    comp, var = sc.summary["position"].split(".", 1)
    return {"final": result.final_outputs[comp][var], "loop_wall_s": master.loop_wall_time,
            "loop_cpu_s": master.loop_cpu_time}


def master_vs_c(scenario: str, repeat: int = 3) -> dict:
    """Medians over ``repeat`` alternating pairs (after one warm-up of both): loop wall and
    CPU seconds of the master and the C loop, their ratios, the final positions."""
    sc = native_scenario(scenario)
    with tempfile.TemporaryDirectory() as tmp:
        exe, plan = prepare_c_loop(sc, Path(tmp))
        master_run(sc)
        c_run(exe, plan)
        pairs = [(master_run(sc), c_run(exe, plan)) for _ in range(repeat)]
    master, c = pairs[-1]
    med = [{key: statistics.median(p[i][key] for p in pairs)
            for key in ("loop_wall_s", "loop_cpu_s")} for i in (0, 1)]  # master, C
    return {"master_loop_s": med[0]["loop_wall_s"], "master_loop_cpu_s": med[0]["loop_cpu_s"],
            "c_loop_s": med[1]["loop_wall_s"], "c_loop_cpu_s": med[1]["loop_cpu_s"],
            "c_over_master": statistics.median(p[1]["loop_wall_s"] / p[0]["loop_wall_s"]
                                               for p in pairs),
            "c_over_master_cpu": statistics.median(p[1]["loop_cpu_s"] / p[0]["loop_cpu_s"]
                                                   for p in pairs),
            "master_final_position": master["final"], "c_final_position": c["final"],
            "same_final_position": f"{master['final']:.17g}" == f"{c['final']:.17g}",
            "steps": int(round((sc.simulation.stop_time - sc.simulation.start_time)
                               / float(sc.simulation.base_step))),
            "load_average": os.getloadavg()[0]}


def summary_line(scenario: str, r: dict) -> str:
    """One line of :func:`master_vs_c`'s figures."""
    return (f"{scenario}: master loop {r['master_loop_s']:.3f} s ({r['master_loop_cpu_s']:.3f} "
            f"s CPU), C loop {r['c_loop_s']:.3f} s ({r['c_loop_cpu_s']:.3f} s CPU); C / master "
            f"{r['c_over_master']:.3f} wall, {r['c_over_master_cpu']:.3f} CPU (target >= "
            f"{TARGET:g}); final position {r['master_final_position']:.17g} (master), "
            f"{r['c_final_position']:.17g} (C): same {r['same_final_position']}; load "
            f"{r['load_average']:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="*", default=list(SCENARIOS.values()),
                        help="scenarios whose FMUs all have native builds")
    parser.add_argument("--repeat", type=int, default=3, help="alternating pairs")
    args = parser.parse_args()
    for scenario in args.scenarios:
        print(summary_line(scenario, master_vs_c(scenario, args.repeat)), flush=True)

if __name__ == "__main__":
    main()
