"""Figure of a calibration: measured against predicted motor torque per segment, before and after."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from skidsteer_power.calibration.fit import CalibrationResult
    from skidsteer_power.calibration.segments import SteadyWindow


def plot_segments(path: str | Path, result: CalibrationResult, segments: Sequence[SteadyWindow]) -> Path:
    """Write a PNG: per segment and side, predicted vs measured K_t i [N m]; hold-out segments filled."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    held = np.zeros(len(segments), bool)
    held[result.holdout_index] = True
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6), sharex=True, sharey=True)
    lo = float(min(result.measured_Nm.min(), result.before_Nm.min(), result.after_Nm.min()))
    hi = float(max(result.measured_Nm.max(), result.before_Nm.max(), result.after_Nm.max()))
    for ax, predicted, title in (
        (axes[0], result.before_Nm, 'before (start terrain)'),
        (axes[1], result.after_Nm, 'after (calibrated)'),
    ):
        ax.plot([lo, hi], [lo, hi], color='0.6', lw=1)
        for side, colour in ((0, 'tab:blue'), (1, 'tab:red')):
            name = ('left', 'right')[side]
            ax.scatter(
                result.measured_Nm[~held, side],
                predicted[~held, side],
                s=14,
                facecolors='none',
                edgecolors=colour,
                label=f'{name}, fit',
            )
            ax.scatter(
                result.measured_Nm[held, side],
                predicted[held, side],
                s=16,
                color=colour,
                label=f'{name}, hold-out',
            )
        ax.set_title(title)
        ax.set_xlabel('measured motor torque K_t i [N m]')
        ax.grid(alpha=0.3)
    axes[0].set_ylabel('predicted motor torque [N m]')
    axes[1].legend(loc='upper left', fontsize=8)
    fig.suptitle(
        'steady segments: hold-out torque RMSE '
        f'{result.torque_rmse_before_Nm:.3g} -> {result.torque_rmse_after_Nm:.3g} N m, '
        f'energy error {result.holdout_energy_error_before:+.1%} -> {result.holdout_energy_error_after:+.1%}'
    )
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
