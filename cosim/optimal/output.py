"""The optimal run as a CSV (units in the header; readable as a speed-distance reference by
:func:`plants.route.load_reference`, whose first two columns it has) and as a figure: speed
against position with the speed limit and the grade."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from cosim.optimal.model import Train
from cosim.optimal.regimes import REGIME_NAMES, OptimalRun

COMMAND_PREFIX = "# command: "  # header line naming the command that wrote the file
COLUMNS = ("position_m", "speed_mps", "time_s", "speed_limit_mps", "grade_permil",
           "force_N", "regime")


def write_csv(run: OptimalRun, train: Train, path: str | Path, title: str = "",
              command: str = "") -> Path:
    """One row per grid node; the step quantities (limit, grade, force, regime) of the step
    that starts at the node (the last node: the step that ends there). ``command``: the
    command that regenerates the file, written as a header line (``# command: ...``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = run.s.size
    step = np.minimum(np.arange(n), n - 2)
    with open(path, "w", newline="") as f:
        f.write(f"# energy-optimal run{': ' + title if title else ''}; train {train.name}\n")
        if command:
            f.write(f"{COMMAND_PREFIX}{command}\n")
        f.write(f"# running time {run.running_time:.3f} s; energy (traction / eta_t - eta_r "
                f"regenerated) {run.energy:.6e} J; traction work {run.traction_work:.6e} J; "
                f"regenerative braking work {run.regen_work:.6e} J\n")
        f.write(f"# time multiplier lambda {run.multiplier:.6e} J/kg/s (dJ/dT = -lambda "
                f"m_eff); cruising speed V {run.hold_speed:.4f} m/s; braking cruise speed W "
                f"{run.brake_hold_speed:.4f} m/s\n")
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for i in range(n):
            k = int(step[i])
            w.writerow([f"{run.s[i]:.3f}", f"{run.v[i]:.6f}", f"{run.t[i]:.4f}",
                        f"{run.speed_limit[k]:.6f}", f"{run.grade[k]:.4f}",
                        f"{run.force[k]:.1f}", REGIME_NAMES.get(int(run.regime[k]), "")])
    return path


def figure(run: OptimalRun, path: str | Path, title: str = "") -> Path:
    """Speed (km/h) against position (km) with the speed limit, and the grade (permille,
    equivalent grade of curves included) below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    km = run.s / 1000.0
    fig, (ax, axg) = plt.subplots(2, 1, figsize=(7.0, 4.2), sharex=True,
                                  gridspec_kw={"height_ratios": [3, 1]})
    edges = np.repeat(km, 2)[1:-1]
    ax.plot(edges, np.repeat(run.speed_limit * 3.6, 2), color="0.4", linestyle="--",
            linewidth=1.0, label="speed limit")
    ax.plot(km, run.v * 3.6, color="C0", linewidth=1.5, label="optimal speed")
    ax.set_ylabel("speed (km/h)")
    ax.set_ylim(bottom=0)
    ax.legend(loc="lower center", frameon=False, fontsize=8, ncol=2)
    if title:
        ax.set_title(title, fontsize=10)
    axg.fill_between(edges, np.repeat(run.grade, 2), step=None, color="C2", alpha=0.5,
                     linewidth=0)
    axg.axhline(0.0, color="0.3", linewidth=0.5)
    axg.set_ylabel("grade (‰)")
    axg.set_xlabel("position (km)")
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path


def trade_off_csv(times: np.ndarray, energies: np.ndarray, path: str | Path) -> Path:
    """The energy / running-time trade-off curve: running time (s) and energy (J)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["running_time_s", "energy_J"])
        for t, e in zip(times, energies):
            w.writerow([f"{t:.4f}", f"{e:.6e}"])
    return path
