"""Sweep of the freight preview's train-mean feedback (seed 002; prints figures,
asserts nothing): the whole freight_20km run, preview core on the plant core at 0.01 s.

For each ``mean_weight`` w and ``observer_correction_time`` t_c, and optionally a plant that
differs from the controller's nominal data (wagon mass, wagon resistance, coupler stiffness
and damping scaled), prints the train-mean (plain mean of the 109 vehicle speeds) and the head
speed errors against ``v_ref(s_head)`` outside the last 50 m before the stop (max |e| and
RMSE, km/h, as the metrics of ``cosim reproduce seed002``), the stop error, the observer's
error against the plant's ``m (1 + gamma)``-weighted mean speed and the command's total
variation.

    python benchmarks/freight_mean_observer_sweep.py --weights 0 0.7 --correction-times 45
        [--wagon-mass 1.05] [--wagon-resistance 1.3] [--coupler-stiffness 0.8]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from controllers.preview.preview import FreightPreview, PreviewParams  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from plants.freight import KMH, FreightParams, FreightTrain  # noqa: E402
from plants.route import load_route  # noqa: E402

STOP, WINDOW, T_END = 20000.0, 50.0, 1400.0


def run(w: float, t_c: float, plant: FreightParams) -> dict[str, float]:
    route = load_route("freight_20km")
    core = FreightPreview(PreviewParams(mean_weight=w, observer_correction_time=t_c),
                          route.reference, route)
    train = FreightTrain(plant, route)
    weights = train.m_eff / train.m_eff.sum()
    T, t, end = to_ticks(core.sample_time), 0, to_ticks(T_END)
    rows = []
    while t < end:
        out = train.outputs()
        cmd, _ = core.compute(t / 1e9, {"v": out["v"], "s": out["s"]})
        rows.append((out["s"], out["v"], cmd["v_ref"], float(train.v.mean()),
                     float(weights @ train.v), cmd["v_mean_estimate"], cmd["accel_demand"]))
        train.advance(t, T, cmd)
        t += T
    s, v, v_ref, v_mean, v_com, v_obs, u = np.array(rows).T
    keep = (s < STOP - WINDOW) & ~((v_ref <= 0.0) & (v <= 0.0))
    e_mean, e_head, e_obs = ((x - y)[keep] / KMH for x, y in
                             ((v_mean, v_ref), (v, v_ref), (v_obs, v_com)))
    return {"mean_max": np.abs(e_mean).max(), "mean_rmse": np.sqrt(np.mean(e_mean**2)),
            "head_max": np.abs(e_head).max(), "head_rmse": np.sqrt(np.mean(e_head**2)),
            "stop": s[-1] - STOP, "obs_max": np.abs(e_obs).max(),
            "obs_rms": np.sqrt(np.mean(e_obs**2)), "tv": np.abs(np.diff(u)).sum()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", type=float, nargs="+", default=[0.0, 0.7])
    ap.add_argument("--correction-times", type=float, nargs="+", default=[45.0])
    ap.add_argument("--wagon-mass", type=float, default=1.0, help="plant / nominal")
    ap.add_argument("--wagon-resistance", type=float, default=1.0, help="plant / nominal")
    ap.add_argument("--coupler-stiffness", type=float, default=1.0, help="plant / nominal")
    ap.add_argument("--coupler-damping", type=float, default=1.0, help="plant / nominal")
    a = ap.parse_args()
    base = FreightParams()
    plant = replace(base, wagon_mass=a.wagon_mass * base.wagon_mass,
                    wagon_resistance=tuple(a.wagon_resistance * c
                                           for c in base.wagon_resistance),
                    coupler_stiffness=a.coupler_stiffness * base.coupler_stiffness,
                    coupler_damping=a.coupler_damping * base.coupler_damping)
    print(f"plant/nominal: wagon mass {a.wagon_mass}, wagon resistance {a.wagon_resistance}, "
          f"coupler stiffness {a.coupler_stiffness}, damping {a.coupler_damping}")
    print("   w   t_c s | train mean max  RMSE | head max  RMSE | stop m | observer max  rms "
          "| TV(u) m/s2 | wall s")
    for t_c in a.correction_times:
        for w in a.weights:
            start = time.perf_counter()
            r = run(w, t_c, plant)
            print(f"{w:4.2f} {t_c:7.1f} | {r['mean_max']:14.3f} {r['mean_rmse']:6.4f} | "
                  f"{r['head_max']:8.3f} {r['head_rmse']:6.4f} | {r['stop']:+6.2f} | "
                  f"{r['obs_max']:12.3f} {r['obs_rms']:5.3f} | {r['tv']:10.2f} | "
                  f"{time.perf_counter() - start:5.1f}", flush=True)


if __name__ == "__main__":
    main()
