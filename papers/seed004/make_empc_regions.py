"""Regenerate the EMPC region data of seed 004 (``controllers/hybrid/data/*.npz``) with PPOPT.

Offline only: needs the optional extra (``pip install -e ".[empc-offline]"``, which pulls PPOPT;
PPOPT declares gurobipy as a dependency, but only its free DAQP backend is used here: the
``Solver`` below names GLPK (through cvxopt, also in the extra) for LPs and DAQP for QPs, and
gurobipy is made unimportable before PPOPT is imported). For each mode (traction, braking) and
PWA segment, the mp-QP of :func:`controllers.hybrid.explicit.parametric_qp` is solved by
PPOPT's combinatorial algorithm; each region keeps the first move's law, its inequalities and a
bounding box (2 LPs per parameter, scipy's HiGHS). Prints the regions and solve times.

    python papers/seed004/make_empc_regions.py [--blocks 3:4:3] [--out PATH]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linprog

# gurobipy (a hard dependency of PPOPT) is hidden: importing it then fails, so no code path can
# reach the proprietary solver, whatever PPOPT's defaults are
sys.modules["gurobipy"] = None  # type: ignore[assignment]
ROOT = Path(__file__).resolve().parents[2]  # papers/NAME/ -> the repository
sys.path.insert(0, str(ROOT))

from controllers.hybrid.explicit import (  # noqa: E402
    DATA_DIR,
    PARAM_NAMES,
    ExplicitLaw,
    RegionSet,
    parametric_qp,
)
from controllers.hybrid.explicit_mpc import ExplicitMpc  # noqa: E402
from controllers.hybrid.hybrid_mpc import chain_model  # noqa: E402
from controllers.hybrid.miqp import parse_blocks  # noqa: E402
from plants.emu import emu_config  # noqa: E402


def free_backends_only() -> None:
    """Route PPOPT's Gurobi entry points to the free solvers: some internal calls (e.g. the
    full-dimension check of a critical region) use ``deterministic_solver='gurobi'`` as a
    default whatever ``Solver`` says; with gurobipy hidden they would fail, so they go to GLPK
    (LP) and DAQP (QP) instead; a mixed-integer call raises."""
    import importlib
    import pkgutil

    import ppopt
    from ppopt.solver_interface import cvxopt_interface, daqp_solver_interface

    def no_mip(*args, **kwargs):
        raise RuntimeError("a mixed-integer subproblem was requested: not expected for mp-QP")

    swap = {"solve_lp_gurobi": cvxopt_interface.solve_lp_cvxopt,
            "solve_qp_gurobi": daqp_solver_interface.solve_qp_daqp,
            "solve_milp_gurobi": no_mip, "solve_miqp_gurobi": no_mip}
    for info in pkgutil.walk_packages(ppopt.__path__, "ppopt."):
        try:
            mod = importlib.import_module(info.name)
        except Exception:  # noqa: BLE001 - optional plotting modules etc.
            continue
        for name, func in swap.items():
            if hasattr(mod, name):
                setattr(mod, name, func)


def solve_one(qp, algorithm: str):
    """PPOPT's mp-QP solution with GLPK (through cvxopt) for LPs and DAQP for QPs."""
    from ppopt.mp_solvers.solve_mpqp import mpqp_algorithm, solve_mpqp
    from ppopt.mpqp_program import MPQP_Program
    from ppopt.solver import Solver

    solver = Solver({"lp": "glpk", "qp": "daqp", "milp": "glpk", "miqp": "daqp"})
    prog = MPQP_Program(qp.G, qp.w.reshape(-1, 1), qp.cp.reshape(-1, 1), qp.Hp, qp.Qp,
                        qp.At, qp.bt.reshape(-1, 1), qp.S, solver=solver)
    return solve_mpqp(prog, getattr(mpqp_algorithm, algorithm))


def bounding_box(E: np.ndarray, e: np.ndarray, box: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of ``{E theta <= e} & box`` (PPOPT may leave the parameter box out of a
    region's rows; the controller clips theta into the box before the lookup)."""
    nth = E.shape[1]
    lo, hi = np.empty(nth), np.empty(nth)
    for d in range(nth):
        c = np.zeros(nth)
        c[d] = 1.0
        for sign, out in ((1.0, lo), (-1.0, hi)):
            r = linprog(sign * c, A_ub=E, b_ub=e, bounds=[tuple(b) for b in box],
                        method="highs")
            if r.status != 0:
                raise RuntimeError(f"bounding box LP failed: {r.message}")
            out[d] = r.x[d]
    return lo, hi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blocks", default=None, help="move blocks of the EMPC (default: the "
                    "ExplicitMpc default)")
    ap.add_argument("--horizon", type=int, default=None)
    ap.add_argument("--segments", default="0,1,2")
    ap.add_argument("--modes", default="1,0")
    ap.add_argument("--algorithm", default="combinatorial")
    ap.add_argument("--out", default=str(DATA_DIR / "seed004_empc_crh3_3car.npz"))
    args = ap.parse_args()
    p = ExplicitMpc.default_params
    if args.horizon is not None:
        p = dataclasses.replace(p, horizon=args.horizon)
    if args.blocks is not None:
        p = dataclasses.replace(p, move_blocks=args.blocks)
    train = emu_config(p.configuration)
    model = chain_model(train, p)
    N = int(p.horizon)
    blocks = parse_blocks(p.move_blocks, N)
    q = [p.q_speed] * model.n + [p.q_position] * model.n
    sets, boxes = {}, {}
    free_backends_only()
    t_all = time.perf_counter()
    for mode in (int(x) for x in args.modes.split(",")):
        for seg in (int(x) for x in args.segments.split(",")):
            box = ExplicitMpc.parameter_box(model, train, mode, seg)
            ratio = ExplicitMpc.limit_ratio(train, mode)
            qp = parametric_qp(model, N, blocks, q, p.r_force, mode, seg, box, ratio)
            t0 = time.perf_counter()
            sol = solve_one(qp, args.algorithm)
            t_mp = time.perf_counter() - t0
            regs = sol.critical_regions
            E_all, e_all, rows, F, f, lo, hi = [], [], [0], [], [], [], []
            for cr in regs:
                E, e = np.asarray(cr.E), np.asarray(cr.f).ravel()
                blo, bhi = bounding_box(E, e, box)
                E_all.append(E)
                e_all.append(e)
                rows.append(rows[-1] + E.shape[0])
                F.append(np.asarray(cr.A)[:qp.n_first])
                f.append(np.asarray(cr.b).ravel()[:qp.n_first])
                lo.append(blo)
                hi.append(bhi)
            t_box = time.perf_counter() - t0 - t_mp
            sets[mode, seg] = RegionSet(np.vstack(E_all), np.concatenate(e_all),
                                        np.array(rows), np.array(F), np.array(f),
                                        np.array(lo), np.array(hi))
            boxes[mode, seg] = box
            print(f"mode {mode} segment {seg}: {len(regs)} regions, {qp.Qp.shape[0]} variables,"
                  f" {qp.G.shape[0]} constraints, mp-QP {t_mp:.1f} s, boxes {t_box:.1f} s, "
                  f"tree depth {sets[mode, seg].tree.depth}", flush=True)
    meta = ExplicitMpc.design_meta(p)
    law = ExplicitLaw(sets, boxes, meta)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    law.save(out)
    total = sum(s.count for s in sets.values())
    print(f"{total} regions in all, {time.perf_counter() - t_all:.1f} s; parameters "
          f"{', '.join(PARAM_NAMES)}; wrote {out} ({out.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
