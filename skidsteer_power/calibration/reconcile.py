"""Step 6 of a calibration with battery-side power: the powertrain's battery terms fitted to every sample.

The steady-window fit (:mod:`.fit`) sees only held commands after they settled. What a user checks
is the energy of a whole drive: its starts, stops, turns into and out of a spin and the time the robot
stands still, which the steady windows leave out (on the twin's Husky the starts and stops drew 2.2 kJ
of 8.0 kJ, predicted 13 % low). The simplest alternative, P = a|v| + b|w| + c, is fitted to every
sample; so is this step, with the physics in front of it.

With the ground fixed at its calibrated values, the drive is replayed through the estimator
(:func:`skidsteer_power.validation.validate.predict_bag`: the set points, the drive controller, the map),
every sample's predicted axle torque and speed per side kept. Two battery-side terms
(:data:`RECONCILED`: the amplifier efficiency, which scales every motoring watt, and the idle power,
every second) are then fitted to the measured battery power of the sides together, each sample
weighted by the time it is in force (a fit of energy, not of message counts), inside their physical
ranges (``scipy.optimize.least_squares``, trust-region reflective; the physics is
:meth:`~skidsteer_power.powertrain.Powertrain.motor_side`, eqs. 7.1-7.4, its one implementation).
The loss terms b, c and k_cu stay as the steady windows fitted them: they are what the command mix
changes, and refitting them to every sample overfit the first drive's mix on the twin.

Honesty: the drive is cut into :data:`BLOCK_S` blocks; fitted without every :data:`CHECK_EVERY`-th
block, the two terms must predict those blocks' energy no worse than the steady-window result
(:data:`~.fit.ENERGY_WORSE`), or the steady-window result is kept and the result says why. Kept, they
are fitted again on every sample. They then carry what the steady windows could not see (the average
cost of accelerating the robot), so they are effective values: the result's warnings say so.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from skidsteer_power.calibration.fit import (
    ENERGY_WORSE,
    PARAMS,
    CalibrationResult,
    Model,
)
from skidsteer_power.calibration.segments import SegmentOptions
from skidsteer_power.powertrain import Powertrain

BLOCK_S = 10.0
"""The drive is cut into blocks this long [s]; every :data:`CHECK_EVERY`-th is the check (module doc)."""
CHECK_EVERY = 3
EFFICIENCY = 'amplifier_efficiency'
RECONCILED = (EFFICIENCY, 'idle_power_W')
"""What this step fits: the amplifier efficiency (every motoring watt) and the idle power (every
second), the idle power only where the calibration was allowed to fit it. Two terms to thousands of
samples: on eight twin drives (five grounds) these two predicted the other drive better than the
same step with the loss terms b, c and k_cu too in 7 of 8 (those follow the first drive's command
mix; docs/CALIBRATION.md step 6)."""
MIN_SAMPLES = 20
"""Fewer samples with a measured battery power: no reconciliation [-]."""


@dataclass(frozen=True)
class PowerSamples:
    """Every sample of the replayed drive(s) with a measured battery power: predicted axle torque
    (n, 2) [N m] and axle speed (n, 2) [rad/s] per side, the measured battery power of both sides
    together (n,) [W] and how long each sample is in force (n,) [s]; ``t_s`` (n,) [s] orders them
    in time (drives one after the other)."""

    axle_torque_Nm: np.ndarray
    axle_omega_rad_s: np.ndarray
    measured_W: np.ndarray
    hold_s: np.ndarray
    t_s: np.ndarray

    def __post_init__(self) -> None:
        keep = (
            np.all(np.isfinite(self.axle_torque_Nm), axis=1)
            & np.all(np.isfinite(self.axle_omega_rad_s), axis=1)
            & np.isfinite(self.measured_W)
            & np.isfinite(self.hold_s)
            & (self.hold_s > 0)
        )
        for name in ('axle_torque_Nm', 'axle_omega_rad_s', 'measured_W', 'hold_s', 't_s'):
            object.__setattr__(self, name, np.asarray(getattr(self, name))[keep])

    def __len__(self) -> int:
        return int(self.measured_W.size)

    def subset(self, index: np.ndarray) -> PowerSamples:
        return PowerSamples(
            self.axle_torque_Nm[index],
            self.axle_omega_rad_s[index],
            self.measured_W[index],
            self.hold_s[index],
            self.t_s[index],
        )


def predicted_W(powertrain: Powertrain, samples: PowerSamples) -> np.ndarray:
    """(n,) predicted battery power of both sides [W] (eqs. 7.1-7.4 through ``motor_side``)."""
    total: np.ndarray = np.zeros(len(samples))
    for k, side in enumerate(('left', 'right')):
        point = powertrain.motor_side(side, samples.axle_torque_Nm[:, k], samples.axle_omega_rad_s[:, k])
        total = total + np.asarray(point.electrical_power_W, dtype=float)
    return total


def energy_error(powertrain: Powertrain, samples: PowerSamples) -> float:
    """Signed relative energy error of ``samples`` [-] (predicted / measured - 1; NaN: no energy)."""
    measured = float(samples.measured_W @ samples.hold_s)
    if len(samples) == 0 or measured == 0:
        return math.nan
    return float(predicted_W(powertrain, samples) @ samples.hold_s) / measured - 1.0


def fit_terms(model: Model, names: Sequence[str], samples: PowerSamples) -> dict[str, float]:
    """Values of ``names`` (parameter units) minimizing the time-weighted squared battery-power
    error of ``samples``, inside their physical ranges, from the model's values."""
    names = list(names)
    lower = np.array([PARAMS[n].bounds[0] for n in names])
    upper = np.array([PARAMS[n].bounds[1] for n in names])
    x0 = np.clip([model.start_value(n) for n in names], lower, upper)
    weight = np.sqrt(samples.hold_s)
    scale = max(1.0, float(np.sqrt(np.mean(samples.measured_W**2))))

    def residuals(x: np.ndarray) -> np.ndarray:
        _, powertrain = model.with_values({n: float(v) for n, v in zip(names, x, strict=True)})
        out: np.ndarray = weight * (predicted_W(powertrain, samples) - samples.measured_W) / scale
        return out

    sol = optimize.least_squares(residuals, x0, bounds=(lower, upper), method='trf', x_scale='jac')
    return {n: float(v) for n, v in zip(names, sol.x, strict=True)}


@dataclass(frozen=True)
class Reconciliation:
    """What step 6 did: the terms fitted (empty: none), their values, the energy errors of the
    checked part before / after, of every sample before / after, and why it kept the steady fit."""

    names: list[str]
    values: dict[str, float]
    check_before: float
    check_after: float
    all_before: float
    all_after: float
    samples: int
    kept: str = ''

    def as_json(self) -> dict[str, object]:
        return {
            'parameters': self.names,
            'values': dict(self.values),
            'check_energy_error_before': self.check_before,
            'check_energy_error_after': self.check_after,
            'energy_error_before': self.all_before,
            'energy_error_after': self.all_after,
            'samples': self.samples,
            'kept_steady_fit': self.kept or None,
        }


def reconcile(model: Model, samples: PowerSamples, allowed: Collection[str]) -> Reconciliation:
    """Fit :data:`RECONCILED` to every sample (module doc): the efficiency always, the others where
    ``allowed`` (the calibration's candidates) names them; ``model`` carries the calibrated terrain
    and powertrain (:meth:`Model.with_values` applies the terms)."""
    names = [n for n in RECONCILED if n == EFFICIENCY or n in allowed]
    none = Reconciliation([], {}, math.nan, math.nan, math.nan, math.nan, len(samples))
    if len(samples) < MIN_SAMPLES:
        return dataclasses.replace(none, kept=f'only {len(samples)} samples with a measured battery power')
    order = np.argsort(samples.t_s, kind='stable')
    ordered = samples.subset(order)
    block = np.floor((ordered.t_s - ordered.t_s[0]) / BLOCK_S).astype(int)
    checked = block % CHECK_EVERY == CHECK_EVERY - 1
    fit_part, check_part = ordered.subset(np.flatnonzero(~checked)), ordered.subset(np.flatnonzero(checked))
    before_check = energy_error(model.powertrain, check_part)
    before_all = energy_error(model.powertrain, ordered)
    trial = fit_terms(model, names, fit_part)
    after_check = energy_error(model.with_values(trial)[1], check_part)
    base = dataclasses.replace(
        none, check_before=before_check, check_after=after_check, all_before=before_all
    )
    if not math.isfinite(after_check) or abs(after_check) > abs(before_check) + ENERGY_WORSE:
        why = (
            f'fitted to the drive without every {CHECK_EVERY}rd {BLOCK_S:g} s, the battery terms '
            f'predicted those worse (energy error {before_check:+.1%} -> {after_check:+.1%}): '
            'the steady-window fit is kept'
        )
        return dataclasses.replace(base, kept=why, all_after=before_all)
    values = fit_terms(model, names, ordered)
    after_all = energy_error(model.with_values(values)[1], ordered)
    return dataclasses.replace(base, names=names, values=values, all_after=after_all)


def replay_samples(
    bags: Sequence[str],
    vehicle: str,
    result: CalibrationResult,
    options: SegmentOptions,
    start_name: str,
    gear_ratio: float,
) -> PowerSamples:
    """Every sample with a measured battery power of ``bags``, predicted from its command by the
    estimator with ``result``'s terrain and powertrain (written to a scratch vehicle and terrain file
    first: the same files ``calibrate --out-vehicle`` writes and ``validate`` reads). Bags follow
    each other in ``t_s``."""
    import tempfile
    from pathlib import Path

    from skidsteer_power.bag_io.reader import open_bag
    from skidsteer_power.calibration import io
    from skidsteer_power.validation.series import ValidateOptions
    from skidsteer_power.validation.validate import predict_bag

    parts: list[PowerSamples] = []
    offset = 0.0
    with tempfile.TemporaryDirectory(prefix='reconcile_') as tmp:
        folder = Path(tmp)
        terrain_file = io.write_terrain(folder / 'terrain.yaml', result, bags, start_name, 'calibrated')
        vehicle_file = io.write_vehicle(folder / 'vehicle.yaml', vehicle, result, bags, str(terrain_file))
        replay = ValidateOptions(
            vehicle=str(vehicle_file),
            terrain=str(terrain_file),
            report_dir=folder,
            plots=False,
            cmd_vel_topic=options.cmd_vel_topic or '/cmd_vel',
            joint_states_topic=options.joint_states_topic or '/joint_states',
        )
        for bag in bags:
            with open_bag(Path(bag), extra_types=options.extra_types) as reader:
                run = predict_bag(reader, replay)
            columns = run.series.columns
            if not run.core.settings.joint_map.measures_battery or columns['t_s'].size == 0:
                continue
            t = columns['t_s']
            parts.append(
                PowerSamples(
                    np.column_stack(
                        [columns['predicted_axle_torque_left_Nm'], columns['predicted_axle_torque_right_Nm']]
                    ),
                    np.column_stack(
                        [columns['predicted_omega_left_rad_s'], columns['predicted_omega_right_rad_s']]
                    )
                    / gear_ratio,
                    columns['measured_battery_W'],
                    columns['hold_s'],
                    t - t[0] + offset,
                )
            )
            offset += float(t[-1] - t[0]) + 1.0
    if not parts:
        empty = np.zeros((0, 2))
        return PowerSamples(empty, empty, np.zeros(0), np.zeros(0), np.zeros(0))
    return PowerSamples(
        *(
            np.concatenate([getattr(p, name) for p in parts])
            for name in ('axle_torque_Nm', 'axle_omega_rad_s', 'measured_W', 'hold_s', 't_s')
        )
    )


def apply(result: CalibrationResult, model: Model, found: Reconciliation) -> None:
    """Write ``found`` into ``result``: its report, and where terms were fitted their values, the
    powertrain with them and a warning that they are effective values."""
    result.reconciliation = found.as_json()
    if not found.names:
        if found.kept:
            result.correlations_warnings.append(found.kept)
        return
    _, result.powertrain = model.with_values(found.values)
    for name, value in found.values.items():
        result.start.setdefault(name, model.start_value(name))
        result.values[name] = value
        result.ci95[name] = None  # the steady windows' interval is not this value's
    result.reconciled = dict(found.values)
    listed = ', '.join(f'{n} {v:.4g} {PARAMS[n].unit}' for n, v in found.values.items())
    result.correlations_warnings.append(
        f'battery terms fitted again to every sample of the drive ({found.samples} samples; energy error '
        f'{found.all_before:+.1%} -> {found.all_after:+.1%}; checked on every {CHECK_EVERY}rd {BLOCK_S:g} s: '
        f'{found.check_before:+.1%} -> {found.check_after:+.1%}): {listed}. They are effective values: '
        'they carry the starts, stops and transients the steady windows leave out'
    )
