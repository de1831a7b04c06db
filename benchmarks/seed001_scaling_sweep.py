"""Seed 001: the data scaling of the FFDL laws, measured on direct core loops.

Every FFDL law (MFAC, ISMC, ISMPC) works on ``y_i = c_y v_i`` and ``u_i = c_u F_i / m``
(``output_scale``, ``input_scale`` of the controller FMUs; default km/h and m/s2). The
paper's ``Phi(1) = 0.5 I``, ``mu = 1``, ``beta = 0.05``, ``delta = 1`` only mean something for
a given scaling. This script runs the Emu core (CRH380A, Jinan West - Xuzhou East, 3600 s)
in closed loop with each controller core for a list of scalings and prints Table 2's indices
(eqs. 87-89) per scaling, disturbance and seed, plus the estimator's input gain (strong
singular value of Phi_2) at 100 s, 1000 s and the end, and the median / 90th percentile of
``||dH||^2`` (the estimator's step is ``lambda ||dH||^2 / (mu + ||dH||^2)``).

The FFDL laws start from the laws' own defaults (the paper's values; ours declared for km/h
and m/s2). With ``--keep-meaning`` ours (Delta, b, theta, the estimator's reset threshold,
excitation gate and pinv eps) keep their physical meaning under the new scaling, as in the
FMUs (the core converts them with :func:`controllers.datadriven.emu_control.rescaled`; the
FMUs' defaults are ``--scale 1,1 --keep-meaning --sample-time 1``); without it they keep
their numbers in the new units. GPC runs its FMU defaults (km/h, m/s2) unless
``--gpc-too``.

    python benchmarks/seed001_scaling_sweep.py --scale 3.6,1 --scale 1,0.4 [--white]
        [--seeds 1] [--laws ISMPC,ISMC,MFAC,GPC] [--workers 2] [--keep-meaning] [--gpc-too]
        [--sample-time 0.2]   (the default 0.2 s keeps the commands of the earlier notes)
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from controllers.datadriven.emu_control import (  # noqa: E402
    DriveParams,
    EmuGpc,
    EmuIsmc,
    EmuIsmpc,
    EmuMfac,
    rescaled,
)
from controllers.datadriven.laws import IsmcParams, IsmpcParams, MfacParams  # noqa: E402
from cosim.fmu.state import to_ticks  # noqa: E402
from cosim.papers import paper_metrics  # noqa: E402
from plants.emu import Emu, emu_config  # noqa: E402
from plants.route import load_reference, load_route  # noqa: E402

unit_indices = paper_metrics("seed001").unit_indices  # papers/seed001/metrics.py

CONTROLLERS = {"ISMPC": EmuIsmpc, "ISMC": EmuIsmc, "MFAC": EmuMfac, "GPC": EmuGpc}
LAWS = {"ISMPC": IsmpcParams, "ISMC": IsmcParams, "MFAC": MfacParams}  # set for km/h, m/s2
T = 0.2
STOP = 3600.0


def disturbance(white: bool, seed: int) -> dict:
    if white:  # the scenarios as shipped
        return dict(disturbance_accel_std=0.05, disturbance_interval=0.2, disturbance_seed=seed)
    return dict(disturbance_accel_std=0.03, disturbance_interval=0.2, disturbance_seed=seed,
                disturbance_smooth=True, disturbance_correlation_time=10.0)


def closed_loop(ctl, white: bool, seed: int, T: float, each=None) -> tuple[np.ndarray, ...]:
    """``ctl`` (a seed-001 controller core) sampled every ``T`` in closed loop with the Emu
    core over ``STOP`` s; ``each(k)`` after sample ``k``. Returns the units' speeds, the
    reference and the train's acceleration at the samples (m/s, m/s, m/s2)."""
    emu = Emu(emu_config("crh380a_3unit", **disturbance(white, seed)),
              load_route("jinan_xuzhou_east"))
    steps = int(round(STOP / T))
    v = np.zeros((steps + 1, 3))
    ref = np.zeros(steps + 1)
    acc = np.zeros(steps + 1)
    for k in range(steps + 1):
        meas = emu.outputs()
        out, _ = ctl.compute(k * T, meas)
        v[k] = [meas[f"v[{i}]"] for i in (1, 2, 3)]
        acc[k] = meas["a"]  # the train's (the summary's max_abs_accel_mps2)
        ref[k] = out["v_ref"]
        if each is not None:
            each(k)
        if k < steps:
            emu.advance(to_ticks(k * T), to_ticks(T), out)
    return v, ref, acc


def run(args: tuple) -> dict:
    name, cy, cu, white, seed, keep, gpc_too, T = args
    cls = CONTROLLERS[name]
    params = cls.params_class()
    params = dataclasses.replace(params, drive=dataclasses.replace(params.drive, sample_time=T))
    drive = DriveParams(output_scale=cy, input_scale=cu, sample_time=T)
    if name in LAWS:
        law = LAWS[name]()  # the laws' own defaults: the paper's values, ours for km/h, m/s2
        if not keep:  # the core converts ours (rescaled); undo it: ours as numbers in y, u
            law = rescaled(law, 3.6 / cy, 1.0 / cu)
        params = cls.params_class(drive=drive, law=law)
    elif gpc_too:
        params = dataclasses.replace(params, drive=drive)
    ctl = cls(params, load_reference("jinan_xuzhou_east_reference"), 3)
    gain = {}
    dh2, dys, dus = [], [], []
    steps = int(round(STOP / T))

    def each(k: int) -> None:
        est = getattr(ctl.law, "est", None)
        if est is not None:
            dh2.append(float(est.dH_prev @ est.dH_prev))
            dys.append(est.dH_prev[:3] / cy)  # physical: m/s per sample
            dus.append(est.dH_prev[-3:] / cu)  # m/s2 per sample
            if k in (round(100 / T), round(1000 / T), steps):
                gain[k * T] = float(np.linalg.svd(est.input_block, compute_uv=False)[0])

    v, ref, acc = closed_loop(ctl, white, seed, T, each)
    est = getattr(ctl.law, "est", None)
    t = np.arange(steps + 1) * T
    m = unit_indices(t, v, ref, 1.0)
    m["max_abs_speed_error_kmh"] = float(np.abs(v - ref[:, None]).max() * 3.6)
    m["max_abs_unit_accel"] = float(np.abs(acc).max())
    m["phi2_sv"] = gain
    m["dh2_median"] = float(np.median(dh2)) if dh2 else float("nan")
    m["dh2_p90"] = float(np.percentile(dh2, 90)) if dh2 else float("nan")
    m["rms_dv"] = float(np.sqrt(np.mean(np.square(dys)))) if dys else float("nan")
    m["rms_du"] = float(np.sqrt(np.mean(np.square(dus)))) if dus else float("nan")
    m["resets"] = int(ctl.law.est.resets) if est is not None else 0
    return dict(name=name, cy=cy, cu=cu, white=white, seed=seed, keep=keep, **m)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", action="append", default=[],
                    help="c_y,c_u (repeatable; default 3.6,1)")
    ap.add_argument("--white", action="store_true", help="white noise (the shipped scenarios)")
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--laws", default="ISMPC,ISMC,MFAC,GPC")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sample-time", type=float, default=T, help="controller sample time, s")
    ap.add_argument("--keep-meaning", action="store_true")
    ap.add_argument("--gpc-too", action="store_true",
                    help="GPC on the same scalings too (a diagnostic; its default is km/h, m/s2)")
    a = ap.parse_args()
    scales = [tuple(float(x) for x in s.split(",")) for s in (a.scale or ["3.6,1"])]
    jobs = []
    for seed in (int(s) for s in a.seeds.split(",")):
        for cy, cu in scales:
            for name in a.laws.split(","):
                if name == "GPC" and (cy, cu) != scales[0] and not a.gpc_too:
                    continue  # GPC keeps its own scaling: one row per seed
                jobs.append((name, cy, cu, a.white, seed, a.keep_meaning, a.gpc_too,
                             a.sample_time))
    print(f"# {'white' if a.white else 'smooth'}, keep_meaning={a.keep_meaning}, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'law':<6} {'c_y':>6} {'c_u':>6} {'seed':>4} {'MSE':>9} {'IAE':>7} {'MA':>5} "
          f"{'max|e|':>6} {'max|a|':>6} {'Phi2 sv 100/1000/end':>20} {'dH2 med':>8} "
          f"{'dH2 p90':>8} {'resets':>6} {'rms dv':>8} {'rms du':>8}")
    with ProcessPoolExecutor(a.workers) as pool:
        for r in pool.map(run, jobs):
            sv = "/".join(f"{x:.2f}" for x in r["phi2_sv"].values()) or "-"
            print(f"{r['name']:<6} {r['cy']:>6.3g} {r['cu']:>6.3g} {r['seed']:>4} "
                  f"{r['unit_mse_kmh2']:>9.3e} {r['unit_iae_kmh_s']:>7.3g} "
                  f"{r['unit_ma_mps_per_sample']:>5.2f} {r['max_abs_speed_error_kmh']:>6.3f} "
                  f"{r['max_abs_unit_accel']:>6.2f} {sv:>20} {r['dh2_median']:>8.2e} "
                  f"{r['dh2_p90']:>8.2e} {r['resets']:>6} {r['rms_dv']:>8.2e} {r['rms_du']:>8.2e}",
                  flush=True)


if __name__ == "__main__":
    main()
