"""Offline calibration: terrain (and drivetrain) parameters fitted to the user's own recordings.

:func:`calibrate_bags` is the whole pipeline: read bags (:mod:`.segments`), fit (:mod:`.fit`); the
CLI (``skidsteer-power calibrate``) writes the result with :mod:`.io`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from skidsteer_power.calibration.drive_limits import identify_drive
from skidsteer_power.calibration.fit import (
    DEFAULT_FIT,
    FIT_TO,
    CalibrationResult,
    auto_fit_names,
    calibrate,
    parse_fit_list,
)
from skidsteer_power.calibration.segments import (
    Recording,
    SegmentOptions,
    SteadyWindow,
    find_segments,
    read_recording,
)
from skidsteer_power.drive import controller_for_vehicle
from skidsteer_power.drive.prediction_modes import CMD, FIT_AT
from skidsteer_power.errors import InputError

if TYPE_CHECKING:
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.vehicle import Vehicle

__all__ = [
    'DEFAULT_FIT',
    'FIT_AT',
    'FIT_TO',
    'CalibrationResult',
    'SegmentOptions',
    'SteadyWindow',
    'auto_fit_names',
    'calibrate',
    'calibrate_bags',
    'find_segments',
    'parse_fit_list',
    'read_recording',
]


def calibrate_bags(
    bags: Sequence[str],
    vehicle: str,
    terrain: str,
    *,
    fit: str | Sequence[str] = DEFAULT_FIT,
    holdout: float = 0.3,
    seed: int = 0,
    settle_s: float = 1.5,
    min_segment_s: float = 1.0,
    topics: tuple[str, str, str] = ('/cmd_vel', '/joint_states', ''),
    extra_types: Mapping[str, str] | None = None,
    fit_at: str = CMD,
    options: SegmentOptions | None = None,
    fit_to: str | None = None,
    every_sample: bool = True,
) -> tuple[CalibrationResult, list[SteadyWindow]]:
    """Read ``bags``, cut steady segments and fit ``fit`` starting from ``terrain``, solved at
    ``fit_at`` (:data:`FIT_AT`; see fit.py). ``fit`` 'auto' (or ['auto']): what the recordings
    identify (:func:`auto_fit_names`), fitted to the torque and the measured motion together where
    both are recorded. ``options`` (when given) overrides settle_s, min_segment_s, topics and
    extra_types. ``fit_to`` (:data:`FIT_TO`; None: 'torque', or by the recordings with 'auto').
    ``every_sample``: where the bags measured battery-side power, fit its terms again to every sample
    (:mod:`.reconcile`)."""
    import dataclasses

    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    names = parse_fit_list(fit) if isinstance(fit, str) else list(fit)
    veh = load_vehicle(vehicle)
    start = load_terrain(terrain)
    powertrain = Powertrain.for_vehicle(veh)
    base = SegmentOptions(
        settle_s=settle_s,
        min_s=min_segment_s,
        cmd_vel_topic=topics[0],
        joint_states_topic=topics[1],
        odom_topic=topics[2],
        extra_types=extra_types,
    )
    options = options or base
    if options.extra_types is None and extra_types is not None:
        options = dataclasses.replace(options, extra_types=extra_types)
    motion_allowed = names == ['auto'] or fit_to == 'motion'  # else the fit needs the joints' torque
    recordings, segments, dropped = read_segments(
        bags, veh, powertrain, options, need_joints=not motion_allowed
    )
    left_fixed: dict[str, str] = {}
    drive = None
    if names == ['auto']:  # the drive controller's limits too: commanded against measured wheel speeds
        prior = controller_for_vehicle(veh, powertrain)
        drive = identify_drive(recordings, prior, powertrain.gear_ratio)
        names, left_fixed = auto_fit_names(segments, start)
        fit_to = fit_to or _what_to_fit(segments)
    result = calibrate(
        veh,
        start,
        powertrain,
        segments,
        names,
        holdout=holdout,
        seed=seed,
        dropped=dropped,
        fit_at=fit_at,
        fit_to=fit_to or 'torque',
        left_fixed=left_fixed,
    )
    result.drive = drive
    if every_sample and any(math.isfinite(sum(s.battery_W)) for s in segments):  # V x I measured
        reconcile_battery_terms(result, bags, vehicle, veh, options, terrain, powertrain.gear_ratio)
    return result, segments


def read_segments(
    bags: Sequence[str],
    veh: Vehicle,
    powertrain: Powertrain,
    options: SegmentOptions,
    *,
    need_joints: bool = False,
) -> tuple[list[Recording], list[SteadyWindow], dict[str, int]]:
    """Step 1 of :func:`calibrate_bags`: every bag read (its joints through the vehicle's own motor
    and driver limits) and cut into steady segments. Returns (recordings, segments, windows dropped
    by reason); InputError when fewer than 3 segments remain."""
    from skidsteer_power.estimator import factory
    from skidsteer_power.estimator.inputs import InputLimits, JointReader

    segments: list[SteadyWindow] = []
    recordings: list[Recording] = []
    dropped: dict[str, int] = {}
    for bag in bags:
        reader = JointReader(
            factory.joint_map_for(veh),
            powertrain.gear_ratio,
            powertrain.motor.torque_constant_Nm_A,
            InputLimits.for_powertrain(powertrain),  # the vehicle's own motor and driver (issue 35)
        )  # one per bag: a position-differentiated speed must not span two bags; a battery-side
        # V x I reading stays the power [W]: the fit compares it with the predicted P_bus
        recordings.append(read_recording(bag, options, reader, need_joints=need_joints))
        found, why = find_segments(recordings[-1], options, powertrain.motor)
        segments.extend(found)
        for key, count in why.items():
            dropped[key] = dropped.get(key, 0) + count
    if len(segments) < 3:
        raise InputError(
            f'only {len(segments)} steady segment(s) in {len(bags)} bag(s) (dropped: {dropped}); '
            'calibration needs constant commands held for longer than --settle-s + --min-segment-s '
            '(or a looser --settle-tol / --cmd-tol)'
        )
    return recordings, segments, dropped


def reconcile_battery_terms(
    result: CalibrationResult,
    bags: Sequence[str],
    vehicle: str,
    veh: Vehicle,
    options: SegmentOptions,
    terrain: str,
    gear_ratio: float,
) -> None:
    """Step 6 (:mod:`.reconcile`): the battery-side terms fitted to every sample of ``bags``."""
    import numpy as np

    from skidsteer_power.calibration import reconcile
    from skidsteer_power.calibration.fit import Model

    samples = reconcile.replay_samples(bags, vehicle, result, options, terrain, gear_ratio)
    model = Model(veh, result.terrain, result.powertrain, np.zeros(0), np.zeros(0))
    reconcile.apply(result, model, reconcile.reconcile(model, samples, result.start))


def _what_to_fit(segments: Sequence[SteadyWindow]) -> str:
    """'both', 'torque' or 'motion': what the segments measured (torque and / or a body motion)."""
    # a battery-side V x I is power evidence too: the torque residuals carry it (fit.FitData)
    torque = any(math.isfinite(sum(s.motor_torque_Nm)) or math.isfinite(sum(s.battery_W)) for s in segments)
    motion = any(s.motion_source != 'command' for s in segments)
    if torque and motion:
        return 'both'
    if motion:
        return 'motion'
    if torque:
        return 'torque'
    raise InputError(
        'the recordings carry neither a motor torque / current nor a body motion: nothing to fit'
    )
