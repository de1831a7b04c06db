"""The optimum of cosim.optimal against the convex oracle of tests/optimal_oracle.py on
TTOBench lines and a steep test line, and against seed 003's optimal profile on its line.

    python benchmarks/optimal_vs_oracle.py [--seed003]

on TTOBench's instances shipped in cosim_data/ttobench (or ``$TTOBENCH_DIR``).

Prints one row per line: running time, theory energy, oracle energy, their difference and the
error estimates from the two grids of each method, whose sum is the tolerance
(tests/test_optimal_control.py); the oracle on grids of 12.5 and 6.25 m."""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.optimal import ttobench as tb  # noqa: E402
from cosim.optimal.model import Section, Train  # noqa: E402
from cosim.optimal.pontryagin import Grid, SectionSolver  # noqa: E402
from tests import optimal_oracle  # noqa: E402
from tests.test_optimal_control import STEEP, WEAK, _at, oracle_error  # noqa: E402

GRID = Grid(50.0, 400)
ORACLE_DS = 12.5  # m: the oracle's grid (and half of it for its error estimate)


def compare(label: str, section: Section, train: Train, T: float | None = None,
            stretch: float = 1.15) -> None:
    t0 = time.time()
    coarse = SectionSolver(section, train, GRID)
    if T is None:
        T = stretch * coarse.fastest().running_time
    th_c = coarse.for_time(T)
    th_f = SectionSolver(section, train, GRID.finer()).for_time(T)
    T = th_f.running_time
    m = train.effective_mass
    or_c = optimal_oracle.solve(section, train, T, ORACLE_DS)
    or_f = optimal_oracle.solve(section, train, T, ORACLE_DS / 2)
    te = abs(_at(th_c, T, m) - th_f.energy)
    oe = oracle_error(or_c, or_f, T, th_f.multiplier * m)
    gap = th_f.energy - or_f.energy
    pct = 100.0 / or_f.energy
    print(f"| {label} | {section.length:.0f} | {T:.2f} | {th_f.running_time:.4f} | "
          f"{th_f.energy / 3.6e6:.4f} | {or_f.energy / 3.6e6:.4f} | {pct * gap:+.4f} % | "
          f"{pct * te:.4f} % | {pct * oe:.4f} % | {'yes' if abs(gap) <= te + oe else 'NO'} "
          f"| {time.time() - t0:.0f} s |", flush=True)


def seed003() -> None:
    from controllers.common import speed_profiles as sp
    from plants.crh3 import Crh3Params
    from plants.route import load_route

    route = load_route("seed003_crh3")
    opt = sp.generate("fixed_family", route)
    T = opt.arrival_time
    e_sp = sp.net_energy(opt, route)
    section = Section(route, 0.0, route.length_m)
    grid = Grid(100.0, 600)
    same = Train.from_crh3(Crh3Params(), traction_share=0.9, max_accel=1.0, max_decel=0.5)
    own = Train.from_crh3(Crh3Params())
    for label, train in (("planning limits of speed_profiles (0.9 envelope, a <= 1, "
                          "brake 0.5 m/s2)", same), ("the plant's own envelope and brake", own)):
        run = SectionSolver(section, train, grid).for_time(T)
        e = _at(run, T, train.effective_mass)
        print(f"| seed 003, {label} | {T:.1f} | {e_sp / 1e6:.1f} | {run.energy / 1e6:.1f} "
              f"(at {run.running_time:.1f} s) | {e / 1e6:.1f} | {100 * (e - e_sp) / e_sp:+.2f} % |",
              flush=True)


def main() -> None:
    if "--seed003" in sys.argv:
        print("| line | T (s) | speed_profiles optimal (MJ) | cosim.optimal (MJ) | at T (MJ) | "
              "difference |\n|---|---|---|---|---|---|")
        seed003()
        return
    print("| line, train | length (m) | T (s) | theory's running time (s) | theory (kWh) | "
          "oracle (kWh) | difference | theory's error estimate | oracle's error estimate | "
          "within | time |\n|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    compare("steep test line (-20, +15 permille), 500 t test train", STEEP, WEAK,
            stretch=1.25)
    flirt = tb.load_train(tb.instance("trains", "CH_Stadler_FLIRT_TPF"))
    ref = tb.load_track(tb.instance("tracks", "00_reference"))
    compare("00_reference stop 0-1, FLIRT TPF", ref.section(0, 1), flirt)
    cn = tb.load_track(tb.instance("tracks", "CN_Songjiazhuang_Yizhuang"))
    subway = tb.load_train(tb.instance("trains", "CN_Beijing_Subway"))
    compare("CN_Songjiazhuang_Yizhuang stop 0-1, Beijing Subway", cn.section(0, 1), subway)
    sg = tb.load_track(tb.instance("tracks", "CH_StGallen_Wil"))
    kiss = tb.load_train(tb.instance("trains", "CH_Stadler_KISS_SBB"))
    j = tb.load_journey(tb.instance("journeys", "CH_StGallen_Wil_Journey_01")).sections[0]
    compare("CH_StGallen_Wil journey 01 section 0, KISS SBB",
            Section(sg.route, j.departure.position, j.arrival.position), kiss,
            T=j.running_time())


if __name__ == "__main__":
    main()
