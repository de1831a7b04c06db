"""The minimal hand-written fmpy loop a master is measured against (no master, no results).

For scenarios of periodic FMUs on one communication step (``base_step``): instantiate every
component with its parameters (and ``sample_time``), then per step set each FMU's inputs from
its sources in dependency order (plants first: their outputs do not depend on their inputs),
read the recorded variables (one getReal per FMU), and doStep every FMU. One FMI call per FMU
and direction: the floor of what a master costs on these FMUs. ``wall_s`` is the loop alone,
``total_s`` also reading the modelDescriptions, instantiating, initialising and terminating
(extraction excluded: the master extracts an FMU once per process).
"""

from __future__ import annotations

import re
import shutil
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from cosim.run.scenario import Component, Scenario, find_scenario, load_scenario  # noqa: E402

CASTS = {"Real": float, "Integer": int, "Boolean": bool, "String": str}  # FMI type -> Python


def start_values(comp: Component, variables: dict[str, Any]) -> list[tuple[Any, Any]]:
    """(model variable, value) of what ``comp`` starts with: its parameters (and its
    ``sample_time`` where the FMU has that parameter) and its inputs' start values, each cast
    to its variable's FMI type (``variables``: name -> fmpy ScalarVariable)."""
    params = dict(comp.parameters)
    if comp.sample_time is not None and "sample_time" in variables:
        params.setdefault("sample_time", comp.sample_time)
    return [(variables[key], CASTS[variables[key].type](value))
            for key, value in {**params, **comp.inputs}.items()]


def connection_groups(sc: Scenario, variables: dict[str, dict[str, Any]],
                      feedthrough: dict[str, bool]) -> list[tuple[str, list[int], str, list[int]]]:
    """The connections as (source, its value references, destination, theirs), one group per
    source and destination, in the order a step passes them on: the inputs of FMUs with direct
    feedthrough (``feedthrough``: controllers) first, from their sources (plants, whose outputs
    do not depend on their inputs), then the plants' inputs (``variables``: component -> name
    -> fmpy ScalarVariable)."""
    groups = []
    for name in sorted(variables, key=lambda n: not feedthrough[n]):
        links = [c for c in sc.connections if c.dst == name]
        for src in dict.fromkeys(c.src for c in links):
            mine = [c for c in links if c.src == src]
            groups.append((src, [variables[src][c.src_var].valueReference for c in mine],
                           name, [variables[name][c.dst_var].valueReference for c in mine]))
    return groups


def raw_fmpy_loop(scenario: str, split: bool = False) -> dict:
    """Run ``scenario`` in the minimal loop: {wall_s, cpu_s, sim_s, final values of the
    records}; ``split``: also the CPU time of each FMI call kind per FMU (``split_cpu_s``;
    the timers add a little to ``wall_s``)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    sc = load_scenario(find_scenario(scenario))
    step = float(sc.simulation.base_step)
    units: dict[str, dict] = {}
    unzipped_dirs = {name: extract(str(comp.fmu_path)) for name, comp in sc.components.items()}
    setup_start = time.perf_counter()
    try:
        for name, comp in sc.components.items():
            md = read_model_description(str(comp.fmu_path))
            unzipped = unzipped_dirs[name]
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, instanceName=name,
                            modelIdentifier=md.coSimulation.modelIdentifier)
            units[name] = {"fmu": fmu, "dir": unzipped,
                           "vars": {v.name: v for v in md.modelVariables},
                           "feedthrough": any(o.dependencies for o in md.outputs)}
            fmu.instantiate()
            fmu.setupExperiment(startTime=sc.simulation.start_time)
            fmu.enterInitializationMode()
            for var, value in start_values(comp, units[name]["vars"]):
                setter = {"Real": fmu.setReal, "Integer": fmu.setInteger,
                          "Boolean": fmu.setBoolean, "String": fmu.setString}[var.type]
                setter([var.valueReference], [value])
            fmu.exitInitializationMode()
        groups = connection_groups(sc, {n: u["vars"] for n, u in units.items()},
                                   {n: u["feedthrough"] for n, u in units.items()})
        plan = [(units[src]["fmu"], s_refs, units[dst]["fmu"], d_refs)
                for src, s_refs, dst, d_refs in groups]
        plan_names = [(src, dst) for src, _, dst, _ in groups]
        records = {}
        for ref in sc.record or []:
            comp, var = ref.split(".", 1)
            pattern = re.compile(re.escape(var).replace(r"\*", ".*") + "$")
            names = [n for n in units[comp]["vars"] if pattern.match(n)]
            records.setdefault(comp, []).extend(units[comp]["vars"][n].valueReference
                                                for n in names)
        record_calls = [(c, units[c]["fmu"], refs) for c, refs in records.items()]
        fmus = [(name, u["fmu"]) for name, u in units.items()]
        plan = [(src, s_refs, dst, d_refs, names[0], names[1])
                for (src, s_refs, dst, d_refs), names in zip(plan, plan_names)]
        n_steps = int(round((sc.simulation.stop_time - sc.simulation.start_time) / step))
        t = sc.simulation.start_time
        parts: dict[str, float] = {}
        clock = time.thread_time  # CPU time of this thread (the FMUs run in it)

        def timed(key: str, call, *args, **kwargs):
            t_start = clock()
            out = call(*args, **kwargs)
            parts[key] = parts.get(key, 0.0) + clock() - t_start
            return out

        t0, cpu0 = time.perf_counter(), time.process_time()
        for k in range(n_steps):
            t = sc.simulation.start_time + k * step
            if split:
                for src, src_refs, dst, dst_refs, s_name, d_name in plan:
                    values = timed(f"getReal {s_name} (inputs of {d_name})", src.getReal,
                                   src_refs)
                    timed(f"setReal {d_name}", dst.setReal, dst_refs, values)
                for name, fmu, refs in record_calls:
                    timed(f"getReal {name} (record)", fmu.getReal, refs)
                for name, fmu in fmus:
                    timed(f"doStep {name}", fmu.doStep, currentCommunicationPoint=t,
                          communicationStepSize=step)
                continue
            for src, src_refs, dst, dst_refs, _, _ in plan:
                dst.setReal(dst_refs, src.getReal(src_refs))
            for _, fmu, refs in record_calls:
                fmu.getReal(refs)
            for _, fmu in fmus:
                fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        final = {f"{c}.{v}": units[c]["fmu"].getReal([units[c]["vars"][v].valueReference])[0]
                 for c, v in (r.split(".", 1) for r in (sc.record or [])[:2])}
        for u in units.values():
            u["fmu"].terminate()
            u["fmu"].freeInstance()
        total = time.perf_counter() - setup_start
        units.clear()
        out = {"wall_s": wall, "cpu_s": cpu, "total_s": total, "sim_s": n_steps * step, **final}
        if split:
            out["split_cpu_s"] = parts
        return out
    finally:
        for u in units.values():
            try:
                u["fmu"].terminate()
                u["fmu"].freeInstance()
            except Exception:  # noqa: BLE001 - already failing
                pass
        for unzipped in unzipped_dirs.values():
            shutil.rmtree(unzipped, ignore_errors=True)


if __name__ == "__main__":
    print(raw_fmpy_loop(sys.argv[1] if len(sys.argv) > 1 else "seed000_stop_pid"))
