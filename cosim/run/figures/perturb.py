"""The figure of a perturbation study (``perturb.png`` of ``cosim sweep --perturb``,
:func:`plot_perturbed`): box plots of the stop error (with the +-50 cm window) and of the
controller executions, one box per scenario and grid point."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from cosim.run.figures import save_figure
from cosim.run.figures.run import fit_band
from cosim.run.metrics import STOP_WINDOW_M


def plot_perturbed(frame: pd.DataFrame, keys: list[str], path: str | Path) -> None:
    """Box plots of stop error (cm, with the +-50 cm window) and controller executions, one box
    per scenario and grid point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(frame.groupby(["scenario", *keys], sort=False))
    labels = []
    prefix = os.path.commonprefix([str(s) for s in frame["scenario"].unique()])
    prefix = prefix[: prefix.rfind("_") + 1]  # the scenarios' shared words, not half a word
    for label, _ in groups:
        label = label if isinstance(label, tuple) else (label,)
        name = str(label[0])[len(prefix):] or str(label[0])
        labels.append("\n".join([name] + [f"{k.rpartition('.')[2]}={v}"
                                          for k, v in zip(keys, label[1:], strict=True)]))
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(max(6.0, 1.1 * len(groups) + 2), 7),
                                   sharex=True, layout="constrained")
    errors_cm = [100.0 * g["stop_error_m"].astype(float) for _, g in groups]
    ax1.boxplot(errors_cm, showfliers=True)
    # the window drawn; the axis on the boxes when they lie far inside it
    fit_band(ax1, pd.concat(errors_cm), -100 * STOP_WINDOW_M, 100 * STOP_WINDOW_M)
    ax1.ticklabel_format(useOffset=False, style="plain", axis="y")
    ax1.set_ylabel("stop error (cm)")
    ax1.set_title(f"Stop error under plant mismatch ({len(groups[0][1])} samples per box)")
    ax1.grid(True, alpha=0.3)
    ax2.boxplot([g["controller_executions"].astype(float) for _, g in groups])
    ax2.set_ylabel("controller executions")
    ax2.set_xticks(range(1, len(groups) + 1), labels, fontsize=8)
    ax2.grid(True, alpha=0.3)
    save_figure(fig, Path(path))
