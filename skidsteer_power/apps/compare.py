"""FESS against the simple models a user would fit, on the user's own bags (issue 27).

The baselines (:mod:`skidsteer_power.analysis.baselines`) are fitted on the training bags' measured
motor terminal power; FESS predicts each bag as ``validate`` does (:func:`skidsteer_power.validation.
validate.predict_bag`: the estimator core fed the bag's commands, so whatever validate predicts from
by default, compare follows), with the given terrain, with the terrain calibrated on the training
bags (:func:`skidsteer_power.calibration.calibrate_bags`, by default fitted at the wheel speed set
points of the commands, as the node predicts: ``calibrate_fit_at``) and with that calibration plus the online
correction the estimator core applies (validate's ``online_prediction``). Every model is scored on
the same samples: the joint_states readings of the hold-out bags with a command in force, each
held as validate holds it.

Splits
------
* ``same_range``: hold-out bags whose commands lie inside the training bags' command envelope;
* ``extrapolation``: hold-out bags with at least :data:`OUTSIDE_SHARE` of their driving time at
  commands faster (|V|) or tighter (|yaw rate|) than anything in training, by more than
  :data:`ENVELOPE_MARGIN` (detected, and reported per bag);
* ``transfer``: bags on another terrain or with another payload and no new data to fit: the physics
  models take ``transfer_terrain`` (a terrain file or preset) or the vehicle with
  ``transfer_payload_kg`` added to its mass (then FESS calibrated keeps its calibrated terrain);
  the fitted baselines keep their coefficients; the on-line ones keep learning, as on the robot.

Per model and split: ``energy_error_pct`` (100 (E_pred - E_meas) / |E_meas|, sample-and-hold
energy over the split's samples), ``power_rmse_W`` (both sides' terminal power, per sample) and
``median_abs_segment_error_pct`` (the median over constant-command segments of |energy error|).
"""

from __future__ import annotations

import copy
import math
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from skidsteer_power.analysis.baselines import (
    CmdVelConsumer,
    IcrRlsPower,
    LinearPower,
    Samples,
    energy_J,
)
from skidsteer_power.drive.prediction_modes import CMD
from skidsteer_power.errors import InputError, SkidsteerError
from skidsteer_power.jsonout import JsonObject
from skidsteer_power.vehicle import TrackGear, WheelGear

if TYPE_CHECKING:
    from skidsteer_power.validation.validate import BagPrediction, ValidateOptions

MAX_BAGS = 16  # per list (training, hold-out, transfer)
MAX_BAG_S = 3600.0  # longest bag [s]
ENVELOPE_MARGIN = 0.05  # a command beyond the training envelope by more than this fraction is outside
OUTSIDE_SHARE = 0.1  # share of a bag's driving time outside the envelope that makes it extrapolation
SPLITS = ('same_range', 'extrapolation', 'transfer')
FESS_MODELS = ('fess', 'fess_online', 'fess_calibrated', 'fess_calibrated_online')
BASELINES = ('linear', 'gazebo_cmd_vel', 'icr_rls_online')
MODELS = (*BASELINES, *FESS_MODELS)
GOAL_MODEL = 'fess_calibrated_online'
GOAL_WITHIN_PCT = 5.0


@dataclass(frozen=True)
class CompareOptions:
    """vehicle, terrain : as for validate; train, holdout, transfer : bag paths; transfer_terrain /
    transfer_payload_kg : what changed for the transfer bags [-, kg]; work_dir : where the calibrated
    terrain and a payload vehicle file are written (None: a temporary folder); map_cache_dir : power
    map cache (None: the estimator's default); calibrate_fit : parameters calibrate fits;
    calibrate_fit_at : what calibrate solves the segments at ('cmd', as the node predicts, or
    'motion')."""

    vehicle: str
    terrain: str
    train: tuple[str, ...]
    holdout: tuple[str, ...]
    transfer: tuple[str, ...] = ()
    transfer_terrain: str | None = None
    transfer_payload_kg: float | None = None
    work_dir: str | Path | None = None
    map_cache_dir: str | Path | None = None
    calibrate_fit: str = 'auto'  # what the recordings identify, soil or rigid ground, powertrain terms
    calibrate_fit_at: str = CMD
    extra_types: Mapping[str, str] | None = None  # .msg texts by type name (--msg): types the bags lack

    def check(self) -> None:
        for label, bags in (
            ('training', self.train),
            ('--holdout', self.holdout),
            ('--transfer', self.transfer),
        ):
            if len(bags) > MAX_BAGS:
                raise InputError(f'{label}: {len(bags)} bags, at most {MAX_BAGS}')
        if not self.train:
            raise InputError('no training bag')
        if not self.holdout and not self.transfer:
            raise InputError(
                'nothing to hold out: give --holdout BAG (or two or more BAGs: the last is held out)'
            )
        if self.transfer and self.transfer_terrain is None and self.transfer_payload_kg is None:
            raise InputError('--transfer needs --transfer-terrain or --transfer-payload-kg (what changed)')
        if self.transfer_payload_kg is not None and not (
            math.isfinite(self.transfer_payload_kg) and -50.0 <= self.transfer_payload_kg <= 500.0
        ):
            raise InputError(f'--transfer-payload-kg must lie in [-50, 500], got {self.transfer_payload_kg}')
        for bag in (*self.train, *self.holdout, *self.transfer):
            if not Path(bag).exists():
                raise InputError(f'{bag}: no such file or directory')


@dataclass
class BagRun:
    """One bag: its scored samples, FESS's predictions on them [W] and its segments' sample masks."""

    path: str
    samples: Samples
    t_s: np.ndarray
    predicted_W: dict[str, np.ndarray] = field(default_factory=dict)
    segments: list[np.ndarray] = field(default_factory=list)


def _validate_options(vehicle: str, terrain: str, cache: str | Path | None) -> ValidateOptions:
    from skidsteer_power.validation.validate import ValidateOptions

    return ValidateOptions(vehicle, terrain, report_dir='.', plots=False, map_cache_dir=cache)


def _predict(
    path: str,
    vehicle: str,
    terrain: str,
    cache: str | Path | None,
    extra_types: Mapping[str, str] | None = None,
) -> BagPrediction:
    from skidsteer_power.bag_io import open_bag
    from skidsteer_power.validation.validate import predict_bag

    with open_bag(path, extra_types=extra_types) as bag:
        if bag.duration_s > MAX_BAG_S:
            raise InputError(f'{path}: {bag.duration_s:.0f} s long, at most {MAX_BAG_S:.0f} s')
        return predict_bag(bag, _validate_options(vehicle, terrain, cache))


def _held(times: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The sample of ``values`` in force at each of ``at`` (the last at or before; NaN before any)."""
    index = np.searchsorted(times, at, side='right') - 1
    out = values[np.maximum(index, 0)].astype(float)
    out[index < 0] = math.nan
    return out


def bag_run(path: str, prediction: BagPrediction, drive_radius_m: float, gear_ratio: float) -> BagRun:
    """The scored samples of a bag from validate's run over it (rows with a command in force and a
    measurement, as validate's metrics), with the command in force, the sprocket surface speeds
    (motor speed / G x r [m/s]) and the measured motion (ground truth if recorded, else odometry)."""
    from skidsteer_power.validation.validate import command_segments

    c, inputs = prediction.series.columns, prediction.inputs
    valid = (c['cmd_fresh'] > 0) & np.isfinite(c['measured_torque_left_Nm'])
    t = c['t_s'][valid]
    if t.size == 0:
        raise InputError(f'{path}: no joint_states with a command in force: no measured power to compare')
    command = np.column_stack([_held(inputs.cmd_t, inputs.cmd[:, k], t) for k in range(2)])
    omega = np.column_stack([c['measured_omega_left_rad_s'][valid], c['measured_omega_right_rad_s'][valid]])
    speed = yaw = np.full(t.size, math.nan)
    if prediction.motion is not None:
        moved = prediction.motion[1]
        speed, yaw = (_held(moved.cmd_t, moved.cmd[:, k], t) for k in range(2))
    samples = Samples(
        weight_s=np.nan_to_num(c['hold_s'][valid], nan=0.0, posinf=0.0),
        speed_cmd=command[:, 0],
        yaw_cmd=command[:, 1],
        power_W=c['measured_power_left_W'][valid] + c['measured_power_right_W'][valid],
        side_speed=omega / gear_ratio * drive_radius_m,
        speed=speed,
        yaw=yaw,
    )
    runs = command_segments(inputs.cmd_t, inputs.cmd, 1.0, 1.0, inputs.cmd_end)
    segments = [(t >= a) & (t < b) for a, b, _, _ in runs]
    return BagRun(path, samples, t, segments=[m for m in segments if m.any()])


def fess_power(prediction: BagPrediction, online: bool) -> np.ndarray:
    """FESS's predicted terminal power of both sides on the scored rows [W]; ``online``: corrected."""
    c = prediction.series.columns
    valid = (c['cmd_fresh'] > 0) & np.isfinite(c['measured_torque_left_Nm'])
    kind = 'online' if online else 'predicted'
    both: np.ndarray = (c[f'{kind}_power_left_W'] + c[f'{kind}_power_right_W'])[valid]  # numpy: Any
    return both


def concat(runs: Sequence[BagRun]) -> Samples:
    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(r.samples, name) for r in runs])

    bag = np.concatenate([np.full(r.t_s.size, i) for i, r in enumerate(runs)])
    names = ('weight_s', 'speed_cmd', 'yaw_cmd', 'power_W', 'side_speed', 'speed', 'yaw')
    return Samples(**{n: cat(n) for n in names}, bag=bag)


def scores(predicted: np.ndarray, runs: Sequence[BagRun]) -> dict[str, float]:
    """energy_error_pct, power_rmse_W, median_abs_segment_error_pct (+ the energies) of ``predicted``
    [W] (the runs' samples concatenated) against the runs' measured power."""
    s = concat(runs)
    e_pred, e_meas = energy_J(predicted, s.weight_s), energy_J(s.power_W, s.weight_s)
    segment_errors, offset = [], 0
    for run in runs:
        for mask in run.segments:
            index = np.flatnonzero(mask) + offset
            measured = energy_J(s.power_W[index], s.weight_s[index])
            if abs(measured) > 1e-9:
                segment_errors.append(
                    100.0 * abs(energy_J(predicted[index], s.weight_s[index]) / measured - 1.0)
                )
        offset += run.t_s.size
    return {
        'energy_error_pct': 100.0 * (e_pred - e_meas) / abs(e_meas) if abs(e_meas) > 1e-9 else math.nan,
        'power_rmse_W': float(np.sqrt(np.mean((predicted - s.power_W) ** 2))),
        'median_abs_segment_error_pct': float(np.median(segment_errors)) if segment_errors else math.nan,
        'energy_predicted_J': e_pred,
        'energy_measured_J': e_meas,
        'segments': len(segment_errors),
    }


def failed_scores(reason: str) -> JsonObject:
    """The scores of a model that could not predict: NaN figures and ``error`` (the reason)."""
    keys = ('energy_error_pct', 'power_rmse_W', 'median_abs_segment_error_pct')
    return {**dict.fromkeys(keys, math.nan), 'energy_predicted_J': math.nan, 'energy_measured_J': math.nan,
            'segments': 0, 'error': reason}  # fmt: skip


def envelope(samples: Samples) -> dict[str, float]:
    """Largest |V| [m/s] and |yaw rate| [rad/s] commanded while driving."""
    return {
        'max_speed_m_s': float(np.max(np.abs(samples.speed_cmd), initial=0.0)),
        'max_yaw_rate_rad_s': float(np.max(np.abs(samples.yaw_cmd), initial=0.0)),
    }


def outside_share(samples: Samples, train: dict[str, float]) -> float:
    """Share of the driving time [-] whose command is beyond the training envelope (+ the margin)."""
    moving = (samples.speed_cmd != 0) | (samples.yaw_cmd != 0)
    beyond = (np.abs(samples.speed_cmd) > train['max_speed_m_s'] * (1 + ENVELOPE_MARGIN) + 1e-9) | (
        np.abs(samples.yaw_cmd) > train['max_yaw_rate_rad_s'] * (1 + ENVELOPE_MARGIN) + 1e-9
    )
    total = float(np.sum(samples.weight_s[moving]))
    return float(np.sum(samples.weight_s[moving & beyond])) / total if total > 0 else 0.0


def payload_vehicle(vehicle: str, payload_kg: float, folder: Path) -> str:
    """A vehicle file like ``vehicle`` with ``payload_kg`` added to its mass; returns its path."""
    from skidsteer_power import resources

    data = yaml.safe_load(resources.find('vehicles', vehicle).read_text(encoding='utf-8'))
    data['mass_kg'] = float(data['mass_kg']) + payload_kg
    data['name'] = f'{data.get("name", "vehicle")}_payload_{payload_kg:g}kg'
    path = folder / f'{data["name"]}.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
    return str(path)


def calibrated_terrain(options: CompareOptions, folder: Path) -> tuple[str | None, JsonObject]:
    """Calibrate on the training bags (all their segments); (terrain file or None, report). The
    report's ``vehicle_file`` is the vehicle with its identified powertrain and drive controller
    (what ``calibrate --out-vehicle`` writes), which the calibrated models predict with."""
    from skidsteer_power.calibration import calibrate_bags, io

    try:
        result, _ = calibrate_bags(
            options.train,
            options.vehicle,
            options.terrain,
            fit=options.calibrate_fit,
            holdout=0.0,
            fit_at=options.calibrate_fit_at,
            extra_types=options.extra_types,
        )
    except SkidsteerError as err:
        return None, {'error': str(err)}
    path = io.write_terrain(
        folder / 'calibrated_terrain.yaml', result, options.train, options.terrain, 'calibrated'
    )
    vehicle_file = io.write_vehicle(
        folder / 'calibrated_vehicle.yaml', options.vehicle, result, options.train, str(path)
    )
    report = result.as_json()
    return str(path), {
        'terrain_file': str(path),
        'vehicle_file': str(vehicle_file),
        'parameters': {
            n: {k: p.get(k) for k in ('value', 'ci95', 'fitted', 'status')}
            for n, p in report['parameters'].items()
        },
        'optimizer_converged': report['optimizer_converged'],
        'fit_at': report['fit_at'],
        'at_bound': report.get('at_bound', []),
        'segments_fit': report['segments_fit'],
    }


def compare(options: CompareOptions, progress: Callable[[str], None] | None = None) -> JsonObject:
    """The whole comparison (module doc); ``progress(message)`` is told each step. Without
    ``work_dir`` the calibrated terrain lives in a temporary folder removed at the end."""
    options.check()
    if options.work_dir:
        folder = Path(options.work_dir)
        folder.mkdir(parents=True, exist_ok=True)
        return _compare(options, folder, progress)
    with tempfile.TemporaryDirectory(prefix='compare_') as tmp:
        return _compare(options, Path(tmp), progress)


def _compare(options: CompareOptions, folder: Path, progress: Callable[[str], None] | None) -> JsonObject:
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.vehicle import load_vehicle

    say = progress or (lambda message: None)
    vehicle = load_vehicle(options.vehicle)
    gear = Powertrain.for_vehicle(vehicle).gear_ratio
    cache = options.map_cache_dir
    say(f'calibrating on {len(options.train)} training bag(s)')
    cal_terrain, calibration = calibrated_terrain(options, folder)
    if cal_terrain is None:
        say(f'warning: the calibrated models fail: {calibration["error"]}')
    configs = {'fess': options.terrain, 'fess_calibrated': cal_terrain}
    cal_vehicle = str(calibration.get('vehicle_file', options.vehicle))

    def predict_runs(bags: Sequence[str], veh: str, terrains: dict[str, str | None]) -> list[BagRun]:
        runs = []
        for path in bags:
            say(f'predicting {path}')
            first: BagRun | None = None
            for key, terrain in terrains.items():
                if terrain is None:
                    continue
                # the calibrated model predicts with the calibrated vehicle (its identified powertrain),
                # unless the run's vehicle was changed (a payload transfer keeps the given powertrain)
                own = cal_vehicle if key == 'fess_calibrated' and veh == options.vehicle else veh
                prediction = _predict(path, own, terrain, cache, options.extra_types)
                if first is None:
                    first = bag_run(path, prediction, vehicle.drive_radius_m, gear)
                first.predicted_W[key] = fess_power(prediction, online=False)
                first.predicted_W[f'{key}_online'] = fess_power(prediction, online=True)
            assert first is not None
            runs.append(first)
        return runs

    train_runs = predict_runs(options.train, options.vehicle, {'fess': options.terrain})
    train = concat(train_runs)
    train_envelope = envelope(train)
    linear, gazebo = LinearPower().fit(train), CmdVelConsumer().fit(train)
    icr = IcrRlsPower(vehicle.tread_m, _contact_positions(vehicle.gear)).fit(train)

    split_runs: dict[str, list[BagRun]] = {name: [] for name in SPLITS}
    holdout_report = []
    for run in predict_runs(options.holdout, options.vehicle, configs):
        share = outside_share(run.samples, train_envelope)
        split = 'extrapolation' if share >= OUTSIDE_SHARE else 'same_range'
        split_runs[split].append(run)
        holdout_report.append(
            {'bag': run.path, 'split': split, 'outside_envelope_share': share, **envelope(run.samples)}
        )
    transfer_report: JsonObject | None = None
    if options.transfer:
        split_runs['transfer'], transfer_report = _transfer(options, folder, cal_terrain, predict_runs)
    failure = None if cal_terrain is not None else str(calibration['error'])
    splits = _score_splits(split_runs, (linear, gazebo, icr), failure)
    return {
        'vehicle': options.vehicle,
        'terrain': options.terrain,
        # what FESS predicted from: validate's default ('cmd': the commands' wheel speed set points)
        'kinematics': _validate_options(options.vehicle, options.terrain, cache).kinematics,
        'train_bags': list(options.train),
        'train_envelope': train_envelope,
        'holdout': holdout_report,
        'transfer': transfer_report,
        'calibration': calibration,
        'baselines': _baselines_json(linear, gazebo, icr),
        'splits': splits,
        'goal': goal(splits),
    }


def _contact_positions(running_gear: TrackGear | WheelGear) -> np.ndarray:
    """Fore-aft positions [m] of the contact points the ICR baseline sums over: 21 along a track,
    else the axles."""
    if isinstance(running_gear, TrackGear):
        return np.linspace(-0.5, 0.5, 21) * float(running_gear.track_length_m)
    return np.array(running_gear.axle_positions_m())


def _transfer(
    options: CompareOptions,
    folder: Path,
    cal_terrain: str | None,
    predict_runs: Callable[[Sequence[str], str, dict[str, str | None]], list[BagRun]],
) -> tuple[list[BagRun], JsonObject]:
    """The transfer bags predicted (on the transfer terrain, with the payload vehicle if one is
    given) and what the report says of them."""
    veh = options.vehicle
    if options.transfer_payload_kg is not None:
        veh = payload_vehicle(options.vehicle, options.transfer_payload_kg, folder)
    terrains = {
        'fess': options.transfer_terrain or options.terrain,
        'fess_calibrated': options.transfer_terrain or cal_terrain,
    }
    report: JsonObject = {
        'bags': list(options.transfer),
        'terrain': options.transfer_terrain,
        'payload_kg': options.transfer_payload_kg,
        'vehicle': veh,
    }
    return predict_runs(options.transfer, veh, terrains), report


def _score_splits(
    split_runs: dict[str, list[BagRun]],
    baselines: tuple[LinearPower, CmdVelConsumer, IcrRlsPower],
    failure: str | None,
) -> JsonObject:
    """Every model's scores per split; ``failure``: why the calibrated models failed (their rows
    then carry the reason), None when they ran."""
    linear, gazebo, icr = baselines
    splits: JsonObject = {}
    for name, runs in split_runs.items():
        if not runs:
            continue
        s = concat(runs)
        predicted = {
            'linear': linear.predict(s),
            'gazebo_cmd_vel': gazebo.predict(s),
            'icr_rls_online': copy.deepcopy(icr).predict(s),
        }
        for key in FESS_MODELS:
            if all(key in r.predicted_W for r in runs):
                predicted[key] = np.concatenate([r.predicted_W[key] for r in runs])
        models = {key: scores(p, runs) for key, p in predicted.items()}
        for key in FESS_MODELS:  # a model that failed is a visible row with its reason
            if key not in models and 'calibrated' in key and failure is not None:
                models[key] = failed_scores(failure)
        splits[name] = {'bags': [r.path for r in runs], 'models': models}
    return splits


def _baselines_json(linear: LinearPower, gazebo: CmdVelConsumer, icr: IcrRlsPower) -> JsonObject:
    """The fitted baselines' coefficients, named with their units."""
    return {
        'linear': dict(zip(('a_W_s_per_m', 'b_W_s_per_rad', 'c_W'), linear.coef.tolist(), strict=True)),
        'gazebo_cmd_vel': {
            'power_load_rate_x': float(gazebo.rate_speed),
            'power_load_rate_yaw': float(gazebo.rate_yaw),
            'consumer_idle_power': gazebo.idle_W,
        },
        'icr_rls_online': {'icr_y_m_after_training': icr.icr.tolist(), 'theta': icr.theta.tolist()},
    }


def goal(splits: JsonObject) -> JsonObject:
    """Issue 27's goal per split: FESS calibrated + online no worse than the best baseline on the same
    range; at most a third of its |energy error| (or within 5 %) on extrapolation and transfer."""
    out = {}
    for name, split in splits.items():
        models = split['models']
        if GOAL_MODEL not in models:
            continue
        if models[GOAL_MODEL].get('error'):
            out[name] = {
                'best_baseline': None,
                'met': False,
                'error': models[GOAL_MODEL]['error'],
                'best_baseline_abs_energy_error_pct': math.nan,
                'fess_calibrated_online_abs_energy_error_pct': math.nan,
                'limit_pct': math.nan,
            }
            continue
        best = min(BASELINES, key=lambda m: abs(models[m]['energy_error_pct']))
        best_error = abs(models[best]['energy_error_pct'])
        error = abs(models[GOAL_MODEL]['energy_error_pct'])
        limit = best_error if name == 'same_range' else max(best_error / 3.0, GOAL_WITHIN_PCT)
        out[name] = {
            'best_baseline': best,
            'best_baseline_abs_energy_error_pct': best_error,
            'fess_calibrated_online_abs_energy_error_pct': error,
            'limit_pct': limit,
            'met': bool(error <= limit),
        }
    return out


def table(result: JsonObject) -> str:
    """A plain-text table: one row per model, per split energy error / RMSE / median segment error."""
    names = list(result['splits'])
    head = f'{"model":<24}' + ''.join(f'{n + " E% / RMSE W / seg%":>36}' for n in names)
    lines = [head]
    for model in MODELS:
        cells = []
        for n in names:
            m = result['splits'][n]['models'].get(model)
            if m is None:
                cells.append('-')
                continue
            if m.get('error'):
                cells.append('failed (see below)')
                continue
            seg = m['median_abs_segment_error_pct']
            cells.append(f'{m["energy_error_pct"]:+8.1f} / {m["power_rmse_W"]:6.2f} / {seg:5.1f}')
        lines.append(f'{model:<24}' + ''.join(f'{c:>36}' for c in cells))
    every = [(m, e) for split in result['splits'].values() for m, e in split['models'].items()]
    failed = {m: e['error'] for m, e in every if e.get('error')}
    for model, reason in failed.items():
        lines.append(f'{model}: failed: {reason}')
    for n, g in result['goal'].items():
        if g.get('error'):
            lines.append(f'goal {n}: MISSED (fess_calibrated_online failed)')
            continue
        lines.append(
            f'goal {n}: fess_calibrated_online |E| {g["fess_calibrated_online_abs_energy_error_pct"]:.1f} % '
            f'vs limit {g["limit_pct"]:.1f} % (best baseline {g["best_baseline"]} '
            f'{g["best_baseline_abs_energy_error_pct"]:.1f} %): {"met" if g["met"] else "MISSED"}'
        )
    return '\n'.join(lines)


def plot(result: JsonObject, folder: str | Path) -> Path:
    """Bar charts of |energy error| [%] and power RMSE [W] per model, grouped by split; the PNG path."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    names = list(result['splits'])
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    width = 0.8 / len(MODELS)
    for k, model in enumerate(MODELS):
        for ax, key in zip(axes, ('energy_error_pct', 'power_rmse_W'), strict=True):
            values = [
                abs(result['splits'][n]['models'][model][key])
                if model in result['splits'][n]['models']
                else 0.0
                for n in names
            ]
            ax.bar(np.arange(len(names)) + (k - len(MODELS) / 2 + 0.5) * width, values, width, label=model)
    for ax, label in zip(axes, ('|energy error| [%]', 'power RMSE [W]'), strict=True):
        ax.set_xticks(np.arange(len(names)), names)
        ax.set_ylabel(label)
        ax.grid(axis='y', alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f'{result["vehicle"]}: FESS vs fitted baselines on hold-out bags')
    fig.tight_layout()
    path = out / 'compare.png'
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
