"""Per-event solve time of the seed 004 hybrid MPCs, and DAQP against SCIP (prints only).

1. Closed loop of the cores (plant :class:`plants.emu.Emu`, controller
   :class:`controllers.hybrid.hybrid_mpc.HybridMpc` / ``MoveBlockingMpc`` /
   :class:`controllers.hybrid.explicit_mpc.ExplicitMpc`) over the 800 s seed 004 run:
   per-event wall and CPU time of the controller (MIQP, or the region lookup of EMPC: median,
   p99, total), branch and bound nodes, for GMPC, MB-MPC and EMPC at N = 10 (blocks 3:4:3 for
   MB-MPC and EMPC) and at N = 3 (MB-MPC 1:2; EMPC unblocked, region data
   ``seed004_empc_crh3_3car_n3``).
   EMPC's lookup runs compiled (numba) where numba is installed; ``--lookup`` also times the
   compiled point location against its numpy reference per lookup on random parameters.
2. Solver comparison on the MIQPs of that run (every ``--every``-th event and the
   ``--hardest`` with the most branch-and-bound nodes): DAQP (as the controller calls it)
   against SCIP through pyscipopt (convex quadratic objective as a constraint on an epigraph
   variable, gap 0), objective values and times. pyscipopt is not a dependency: give its
   location with ``--scip-path`` (e.g. after ``pip install --target /tmp/scipenv
   pyscipopt``); without it the comparison is skipped.

    python benchmarks/bench_hybrid.py [--every 200] [--hardest 5] [--scip-path DIR] [--lookup]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.hybrid.explicit_mpc import ExplicitMpc, regions_path  # noqa: E402
from controllers.hybrid.hybrid_mpc import HybridMpc, MoveBlockingMpc  # noqa: E402
from controllers.hybrid.miqp import _BINARY, _INF  # noqa: E402
from controllers.hybrid.model import KN, Limits  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from plants.emu import Emu, emu_config  # noqa: E402
from plants.route import load_reference, load_route  # noqa: E402

STOP = 800
MEASURED = ([f"v[{i}]" for i in (1, 2, 3)] + ["s", "coupler_force[1]", "coupler_force[2]"]
            + [f"traction_limit[{i}]" for i in (1, 2, 3)]
            + [f"brake_limit[{i}]" for i in (1, 2, 3)])


def closed_loop(cls: type, regions: str | None = None, **params
                ) -> tuple[HybridMpc, list[tuple[float, dict]], list]:
    """Run the cores for 800 s; returns the controller, the (t, inputs) of every event and
    per-event (wall s, cpu s, nodes)."""
    extra = {} if regions is None else {"regions": regions_path(regions)}
    ctl = cls(dataclasses.replace(cls.default_params, **params),
              load_reference("seed004_crh3_reference"), **extra)
    plant = Emu(emu_config("crh3_3car"), load_route("seed004_level"))
    events, stats = [], []
    for k in range(STOP + 1):
        o = plant.outputs()
        inputs = {n: o[n] for n in MEASURED}
        events.append((float(k), inputs))
        nodes = ctl.nodes
        cpu = ctl.timing.cpu_total
        out, _ = ctl.compute(float(k), inputs)
        stats.append((ctl.timing.recent[-1], ctl.timing.cpu_total - cpu, ctl.nodes - nodes))
        if k < STOP:
            plant.advance(to_ticks(k), to_ticks(1.0),
                          {f"force[{i}]": out[f"force[{i}]"] for i in (1, 2, 3)})
    return ctl, events, stats


def report(name: str, ctl: HybridMpc, stats: list) -> None:
    wall = np.array([s[0] for s in stats]) * 1e3
    cpu = np.array([s[1] for s in stats]) * 1e3
    nodes = np.array([s[2] for s in stats])
    print(f"{name:<22} wall ms median {np.median(wall):6.2f} p99 {np.percentile(wall, 99):6.2f}"
          f" total {wall.sum() / 1e3:6.2f} s | cpu ms median {np.median(cpu):6.2f} p99 "
          f"{np.percentile(cpu, 99):6.2f} total {cpu.sum() / 1e3:6.2f} s | nodes median "
          f"{np.median(nodes):.0f} max {nodes.max()} | infeasible {ctl.qp_infeasible}")


def problem(ctl: HybridMpc, t: float, inputs: dict) -> tuple:
    """The MIQP data of one event: (H, f, A, lo, hi, binary mask)."""
    q, n = ctl.miqp, ctl.n
    x0 = ctl.state_vector(inputs)
    lim = Limits(np.array([inputs[f"traction_limit[{i}]"] for i in range(1, n + 1)]) / KN,
                 np.array([inputs[f"brake_limit[{i}]"] for i in range(1, n + 1)]) / KN,
                 coupler=ctl.p.coupler_force_max / KN, speed=ctl.p.speed_max)
    delta = ctl.schedule(t, float(ctl.model.c @ x0))
    ref = ctl.references(t, float(inputs["s"]))
    f, const = q.linear_term(x0, ref)
    lo, hi, sense, free = q.bounds(x0, lim, delta)
    binary = (sense[:q.nV] == _BINARY) & (lo[:q.nV] < hi[:q.nV])
    return q.H, f, const, q.A, lo, hi, binary, (x0, ref, lim, delta), free


def solve_scip(H, f, A, lo, hi, binary, nV) -> tuple[float, float, float]:
    """(objective, SCIP solving time, total time incl. model build) at gap 0."""
    from pyscipopt import Model, quicksum

    t0 = time.perf_counter()
    m = Model()
    m.hideOutput()
    m.setParam("limits/gap", 0.0)
    big = 1e20
    x = []
    for i in range(nV):
        lb = None if lo[i] <= -_INF else lo[i]
        ub = None if hi[i] >= _INF else hi[i]
        vtype = "B" if binary[i] else "C"
        x.append(m.addVar(lb=lb if lb is not None else -big, ub=ub if ub is not None else big,
                          vtype=vtype))
    for r in range(A.shape[0]):
        lo_r, hi_r = lo[nV + r], hi[nV + r]
        if lo_r <= -_INF and hi_r >= _INF:
            continue
        nz = np.nonzero(np.abs(A[r]) > 0)[0]
        expr = quicksum(float(A[r, j]) * x[j] for j in nz)
        if lo_r == hi_r:
            m.addCons(expr == float(lo_r))
            continue
        if lo_r > -_INF:
            m.addCons(expr >= float(lo_r))
        if hi_r < _INF:
            m.addCons(expr <= float(hi_r))
    epi = m.addVar(lb=-big, ub=big)
    iu, ju = np.nonzero(np.triu(H))
    quad = quicksum(float(H[i, j] if i == j else 2 * H[i, j]) * 0.5 * x[i] * x[j]
                    for i, j in zip(iu, ju, strict=True))
    m.addCons(quad + quicksum(float(f[i]) * x[i] for i in range(nV)) <= epi)
    m.setObjective(epi, "minimize")
    m.optimize()
    total = time.perf_counter() - t0
    return float(m.getObjVal()), float(m.getSolvingTime()), total


def compare(ctl: HybridMpc, events: list, stats: list, every: int, hardest: int) -> None:
    nodes = np.array([s[2] for s in stats])
    chosen = sorted(set(range(0, len(events), every)) | set(np.argsort(-nodes)[:hardest].tolist()))
    daqp_t, scip_t, scip_total, gaps = [], [], [], []
    for k in chosen:
        t, inputs = events[k]
        H, f, const, A, lo, hi, binary, args, nfree = problem(ctl, t, inputs)
        t0 = time.perf_counter()
        res = ctl.miqp.solve(*args)
        daqp_t.append(time.perf_counter() - t0)
        obj, st, tot = solve_scip(H, f, A, lo, hi, binary, ctl.miqp.nV)
        scip_t.append(st)
        scip_total.append(tot)
        gaps.append(abs((obj + const) - res.cost) / max(1.0, abs(res.cost)))
    ms = 1e3
    print(f"  {len(chosen)} MIQPs: DAQP median {np.median(daqp_t) * ms:.2f} ms (max "
          f"{np.max(daqp_t) * ms:.2f}); SCIP solving median {np.median(scip_t) * ms:.1f} ms "
          f"(max {np.max(scip_t) * ms:.1f}), with model build {np.median(scip_total) * ms:.1f} "
          f"ms; largest relative objective difference {max(gaps):.1e}")


def lookups(count: int = 2000) -> None:
    """Median time (us) of one point location, compiled and numpy, per region set of the
    seed 004 EMPC, on ``count`` random parameters over each set's box."""
    from controllers.hybrid.explicit import ExplicitLaw

    law = ExplicitLaw.load(regions_path("seed004_empc_crh3_3car"))
    rng = np.random.default_rng(1)
    print("EMPC point location, median us per lookup: compiled (numba) / numpy reference")
    for key, rs in sorted(law.sets.items()):
        box = law.boxes[key]
        thetas = box[:, 0] + rng.random((count, box.shape[0])) * (box[:, 1] - box[:, 0])
        times = {}
        for label, locate in (("compiled", rs.locate), ("numpy", rs.locate_reference)):
            if label == "compiled" and not rs.compiled:
                continue
            locate(thetas[0])
            ts = []
            for theta in thetas:
                t0 = time.perf_counter()
                locate(theta)
                ts.append(time.perf_counter() - t0)
            times[label] = 1e6 * float(np.median(ts))
        print(f"  mode {key[0]} segment {key[1]} ({rs.count} regions): "
              + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lookup", action="store_true", help="time the EMPC point location only")
    ap.add_argument("--every", type=int, default=200, help="compare every n-th event")
    ap.add_argument("--hardest", type=int, default=5,
                    help="also compare the events with the most nodes")
    ap.add_argument("--scip-path", default="", help="directory holding pyscipopt")
    args = ap.parse_args()
    if args.lookup:
        lookups()
        return
    if args.scip_path:
        sys.path.insert(0, args.scip_path)
    runs = [("GMPC N=10", HybridMpc, {}), ("MB-MPC 3:4:3 N=10", MoveBlockingMpc, {}),
            ("EMPC 3:4:3 N=10", ExplicitMpc, {}),
            ("GMPC N=3", HybridMpc, {"horizon": 3}),
            ("MB-MPC 1:2 N=3", MoveBlockingMpc, {"horizon": 3, "move_blocks": "1:2"}),
            ("EMPC N=3", ExplicitMpc, {"horizon": 3, "move_blocks": "",
                                       "regions": "seed004_empc_crh3_3car_n3"})]
    kept = {}
    for name, cls, params in runs:
        ctl, events, stats = closed_loop(cls, **params)
        report(name, ctl, stats)
        kept[name] = (ctl, events, stats)
    try:
        import pyscipopt  # noqa: F401
    except ImportError:
        print("pyscipopt not importable: DAQP/SCIP comparison skipped (see --scip-path)")
        return
    for name in ("GMPC N=10", "GMPC N=3"):
        print(f"DAQP vs SCIP on {name}:")
        ctl, events, stats = kept[name]
        compare(ctl, events, stats, args.every, args.hardest)


if __name__ == "__main__":
    main()
