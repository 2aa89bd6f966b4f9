"""The BorealTC Husky recordings (../shared/realdata/borealtc-husky, MIT, README there) as
:class:`~skidsteer_power.calibration.series.Series`, and the experiments of the ``real_motion`` and
``real`` benches on them.

Units and signs, worked out from the data (and marked where ASSUMED):
- ``velL``, ``velR``: per-side wheel speed in steps of 1/127 (a signed byte of the Husky's 1 m/s
  range), read as m/s at the tread (the Husky's hardware max_speed is 1.0 m/s): the axle set point is
  vel / r with r = 0.1651 m (husky_a200.yaml). No command is recorded: the controller holds wheel
  speeds, so these are the set points.
- ``curL``, ``curR``: per-side current [A], magnitudes only (never negative). They are the MOTOR
  (armature) currents, not the drivers' battery-side input: on steady straight holds the current does
  not grow with speed (ASPHALT 0.236 / 0.472 / 0.787 m/s: 4.9 / 4.6 / 3.9 A both sides; SANDY_LOAM
  0.236 / 0.394 / 0.551 / 0.630 m/s: 8.1 / 7.8 / 7.4 / 7.9 A), nor on spot turns over a 3.6 x range of
  wheel speed (SANDY_LOAM 0.055 - 0.197 m/s: 22.2 - 22.6 A), where a battery-side current would grow
  about in proportion to speed (the mechanical power T w does) and the 1 A drawn at standstill rules
  out an idle draw that could hide it. A current that follows torque, not power, is the armature
  current (the MDL-BDC24 / Jaguar senses the armature current for its current loop). A BRAKING side
  reads about 0 A (the inner side of gentle turns on asphalt and flooring: 0 - 0.6 A while the outer
  side draws 10 - 15 A): the sensor reads the motoring current only (ASSUMED from that observation).
  So (:func:`run_segments`) a steady window's motor torque is K_t |I| in the direction of its set
  point, a reading below :data:`FLOOR_A` says only "braking or unloaded" and is left out of the fit,
  and the quantity the benches compare is what the sensor shows: 24 V x |I| (the issue's "V x I",
  the measured figures unchanged), predicted as 24 V x the predicted motoring current (a braking side
  reads 0, :func:`reading_W`). It is an upper bound of the battery power (the drivers' PWM duty is
  below 1), not the battery power itself; V = 24 V nominal bus (ASSUMED: no voltage recorded).
- ``wz``: the IMU's gyro yaw rate [rad/s], REP 103 (positive turns left): its sign agrees with
  velR - velL in the data.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skidsteer_power.calibration.series import Series, SeriesSegment, steady_segments

ROOT = Path(__file__).resolve().parents[1] / '..' / 'shared' / 'realdata' / 'borealtc-husky'
VEHICLE = 'husky_a200'
WHEEL_RADIUS_M = 0.1651  # husky_a200.yaml (husky_description URDF)
BUS_V = 24.0  # ASSUMED: the Husky's nominal bus; BorealTC records no voltage
STEP_M_S = 1.0 / 127.0  # the wheel speeds' resolution [m/s]
SURFACE_TERRAIN = {  # start terrain of each surface (presets; config/terrains/)
    'ASPHALT': 'asphalt',
    'FLOORING': 'flooring',
    'ICE': 'ice',
    'SANDY_LOAM': 'sandy_loam',
    'SNOW': 'packed_snow',
}
MIN_RUNS = 7  # surfaces with at least this many runs are benchmarked (issue 35)
FLOOR_A = 0.5  # a steady window's mean |I| below this reads "braking or unloaded": no torque [A]


def root() -> Path:
    return ROOT.resolve()


def surfaces() -> list[str]:
    """The surfaces with at least :data:`MIN_RUNS` runs and a start terrain."""
    out = []
    for name in SURFACE_TERRAIN:
        if len(runs(name)) >= MIN_RUNS:
            out.append(name)
    return out


def runs(surface: str) -> list[int]:
    """Run numbers of ``surface`` that have both files."""
    folder = root() / surface
    numbers = sorted(int(p.stem.split('_')[1]) for p in folder.glob('pro_*.csv'))
    return [n for n in numbers if (folder / f'imu_{n:02d}.csv').exists()]


def load_run(surface: str, run: int) -> Series:
    """One run as a :class:`Series` (module doc for the units)."""
    folder = root() / surface
    pro = np.genfromtxt(folder / f'pro_{run:02d}.csv', delimiter=',', names=True)
    imu = np.genfromtxt(folder / f'imu_{run:02d}.csv', delimiter=',', names=True)
    t = np.asarray(pro['time'], dtype=float)
    keep = np.r_[True, np.diff(t) > 0]  # a repeated time stamp: keep the first
    vel = np.column_stack([pro['velL'], pro['velR']])[keep]
    cur = np.column_stack([pro['curL'], pro['curR']])[keep]
    return Series(
        source=f'{surface}/pro_{run:02d}.csv',
        t_s=t[keep],
        setpoint_rad_s=vel / WHEEL_RADIUS_M,
        power_W=BUS_V * np.abs(cur),
        gyro_t_s=np.asarray(imu['time'], dtype=float),
        yaw_rate_rad_s=np.asarray(imu['wz'], dtype=float),
    )


def run_segments(surface: str, numbers: list[int]) -> list[SeriesSegment]:
    """Steady segments of runs ``numbers``: holds within one wheel speed step (1/127 m/s), each with
    its measured motor torque K_t |I| in its set point's direction (module doc; NaN below
    :data:`FLOOR_A`) and no battery-side power (the current is the motor's)."""
    from skidsteer_power.drive import controller_for_vehicle
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.vehicle import load_vehicle

    vehicle = load_vehicle(VEHICLE)
    powertrain = Powertrain.for_vehicle(vehicle)
    kt, ratio = powertrain.motor.torque_constant_Nm_A, powertrain.gear_ratio
    controller = controller_for_vehicle(vehicle)
    out: list[SeriesSegment] = []
    for n in numbers:
        found, _ = steady_segments(
            load_run(surface, n), controller.twist_of, tol_rad_s=1.01 * STEP_M_S / WHEEL_RADIUS_M
        )
        for item in found:
            current = np.asarray(item.power_W) / BUS_V
            sign = np.sign(item.setpoint_rad_s)
            torque = np.where((current >= FLOOR_A) & (sign != 0), kt * current * sign, np.nan)
            segment = dataclasses.replace(
                item.segment,
                motor_torque_Nm=(float(torque[0]), float(torque[1])),
                motor_omega_rad_s=(ratio * item.setpoint_rad_s[0], ratio * item.setpoint_rad_s[1]),
                battery_W=(math.nan, math.nan),
            )
            out.append(SeriesSegment(segment, item.power_W, item.setpoint_rad_s))
    return out


def reading_W(current_A: np.ndarray, setpoint_rad_s: np.ndarray) -> np.ndarray:
    """What BorealTC's sensors would show for predicted motor currents (P, 2) [A] at set points
    (P, 2) [rad/s]: 24 V x the motoring current per side, a braking side reading 0 (module doc),
    summed over the sides (P,) [W]."""
    motoring = np.maximum(np.asarray(current_A) * np.sign(setpoint_rad_s), 0.0)
    out: np.ndarray = BUS_V * motoring.sum(axis=1)
    return out


@dataclass(frozen=True)
class MotionRow:
    """Yaw-rate MAE [rad/s] on the held-out segments of one surface, per model."""

    surface: str
    segments_fit: int
    segments_check: int
    no_slip: float
    icr: float
    preset: float
    calibrated: float
    status: str


def yaw_mae(predicted: np.ndarray, measured: np.ndarray) -> float:
    return float(np.mean(np.abs(predicted - measured)))


def icr_fit(setpoints: np.ndarray, yaw: np.ndarray) -> float:
    """The ICR model's effective tread B [m] (yaw = r (w_R - w_L) / B, chapter 3.4's ICR spacing)
    by least squares through the origin on the fit segments."""
    x = WHEEL_RADIUS_M * (setpoints[:, 1] - setpoints[:, 0])
    denominator = float(x @ yaw)
    return float(x @ x) / denominator if abs(denominator) > 1e-12 else math.inf


def motion_row(surface: str, fit_runs: list[int], check_runs: list[int]) -> MotionRow:
    """Calibrate the ground's slip on ``fit_runs`` (``fit_to='motion'``: the gyro against FESS at the
    set points), predict ``check_runs``' yaw rate from their set points; beside the no-slip kinematics
    and an ICR fit on the same segments."""
    from skidsteer_power.calibration import auto_fit_names, calibrate
    from skidsteer_power.calibration.series import segments_of
    from skidsteer_power.models.predict import CommandPredictor
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    vehicle = load_vehicle(VEHICLE)
    powertrain = Powertrain.for_vehicle(vehicle)
    start = load_terrain(SURFACE_TERRAIN[surface])
    fit, check = run_segments(surface, fit_runs), run_segments(surface, check_runs)
    fit_sp = np.array([s.setpoint_rad_s for s in fit])
    fit_yaw = np.array([s.segment.yaw_rate_rad_s for s in fit])
    sp = np.array([s.setpoint_rad_s for s in check])
    yaw = np.array([s.segment.yaw_rate_rad_s for s in check])
    commands = np.array([s.segment.command for s in check])
    no_slip = WHEEL_RADIUS_M * (sp[:, 1] - sp[:, 0]) / float(vehicle.tread_m)
    icr = WHEEL_RADIUS_M * (sp[:, 1] - sp[:, 0]) / icr_fit(fit_sp, fit_yaw)
    preset = CommandPredictor(vehicle, start, powertrain).predict(commands[:, 0], commands[:, 1]).yaw_rate
    segments = segments_of(fit)
    names, fixed = auto_fit_names(segments, start)
    result = calibrate(
        vehicle, start, powertrain, segments, names, holdout=0.0, fit_to='motion', left_fixed=fixed
    )
    after = CommandPredictor(vehicle, result.terrain, powertrain).predict(commands[:, 0], commands[:, 1])
    fitted = [n for n in result.names if result.status(n) == 'fitted']
    pinned = [f'{n} at its {side} bound' for n, side in result.at_bound.items()]
    status = result.kept_start or '; '.join(
        [f'fitted {", ".join(fitted)}' if fitted else 'nothing fitted inside its range', *pinned]
    )
    return MotionRow(
        surface,
        len(fit),
        len(check),
        yaw_mae(no_slip, yaw),
        yaw_mae(icr, yaw),
        yaw_mae(preset, yaw),
        yaw_mae(after.yaw_rate, yaw),
        status,
    )


@dataclass(frozen=True)
class EnergyRow:
    """Energy errors [%] of one split of one surface: measured V x I energy of the check runs against
    the preset, the calibrated FESS and the linear fit P = a|v| + b|w| + c (fitted on the fit runs)."""

    surface: str
    split: str
    runs_fit: list[int]
    runs_check: list[int]
    measured_J: float
    preset_pct: float
    calibrated_pct: float
    linear_pct: float
    status: str
    by_motion: dict[str, MotionShare] = dataclasses.field(default_factory=dict)  # MOTION_KINDS


@dataclass(frozen=True)
class MotionShare:
    """One kind of motion in the check runs (:data:`MOTION_KINDS`): time [s] and measured,
    calibrated and linear-fit energy [J]."""

    seconds: float
    measured_J: float
    calibrated_J: float
    linear_J: float


MOTION_KINDS = ('standing', 'straight', 'turning', 'spinning')
"""Where a check run's energy goes, by command: standing |v| < 0.02 m/s and |w| < 0.1 rad/s,
straight |v| >= 0.02 and |w| < 0.1, turning |w| >= 0.1 and |v| >= 0.1, spinning |w| >= 0.1 and
|v| < 0.1 (thresholds of this breakdown only)."""


def motion_kinds(commands: np.ndarray) -> dict[str, np.ndarray]:
    """(n,) masks of :data:`MOTION_KINDS` for commands (n, 2) [m/s, rad/s]."""
    v, w = np.abs(commands[:, 0]), np.abs(commands[:, 1])
    turning = w >= 0.1
    return {
        'standing': ~turning & (v < 0.02),
        'straight': ~turning & (v >= 0.02),
        'turning': turning & (v >= 0.1),
        'spinning': turning & (v < 0.1),
    }


def _samples(surface: str, numbers: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(commands (n, 2) [m/s, rad/s], measured battery power (n,) [W], hold time (n,) [s]) of every
    sample of runs ``numbers``: the set points' twist through the drive controller, sample-and-hold."""
    from skidsteer_power.drive import controller_for_vehicle
    from skidsteer_power.vehicle import load_vehicle

    controller = controller_for_vehicle(load_vehicle(VEHICLE))
    commands, power, hold = [], [], []
    for n in numbers:
        series = load_run(surface, n)
        v, w = controller.twist_of(series.setpoint_rad_s)
        dt = np.diff(series.t_s, append=series.t_s[-1] + float(np.median(np.diff(series.t_s))))
        commands.append(np.column_stack([v, w]))
        assert series.power_W is not None
        power.append(series.power_W.sum(axis=1))
        hold.append(dt)
    return np.concatenate(commands), np.concatenate(power), np.concatenate(hold)


def linear_fit(commands: np.ndarray, power: np.ndarray) -> np.ndarray:
    """(a, b, c) of P = a|v| + b|w| + c by least squares [W s/m, W s/rad, W]."""
    design = np.column_stack([np.abs(commands[:, 0]), np.abs(commands[:, 1]), np.ones(len(commands))])
    coef, *_ = np.linalg.lstsq(design, power, rcond=None)
    return np.asarray(coef)


def energy_pct(predicted_W: np.ndarray, measured_W: np.ndarray, hold_s: np.ndarray) -> float:
    measured = float(measured_W @ hold_s)
    return 100.0 * (float(predicted_W @ hold_s) - measured) / measured


def energy_row(surface: str, split: str, fit_runs: list[int], check_runs: list[int]) -> EnergyRow:
    """Calibrate (``--fit auto``: ground, internal resistance and idle power, to the V x I power and
    the gyro's yaw rate together) on the steady segments of ``fit_runs``; predict every sample of
    ``check_runs`` from its set points (sample-and-hold energy)."""
    from skidsteer_power.calibration import auto_fit_names, calibrate
    from skidsteer_power.calibration.series import segments_of
    from skidsteer_power.models.predict import CommandPredictor
    from skidsteer_power.powertrain import Powertrain
    from skidsteer_power.terramechanics.terrain import load_terrain
    from skidsteer_power.vehicle import load_vehicle

    vehicle = load_vehicle(VEHICLE)
    powertrain = Powertrain.for_vehicle(vehicle)
    start = load_terrain(SURFACE_TERRAIN[surface])
    segments = segments_of(run_segments(surface, fit_runs))
    names, fixed = auto_fit_names(segments, start)
    result = calibrate(
        vehicle, start, powertrain, segments, names, holdout=0.0, fit_to='both', left_fixed=fixed
    )
    fit_cmd, fit_p, _ = _samples(surface, fit_runs)
    cmd, measured, hold = _samples(surface, check_runs)
    before = CommandPredictor(vehicle, start, powertrain).predict(cmd[:, 0], cmd[:, 1])
    after = CommandPredictor(vehicle, result.terrain, result.powertrain).predict(cmd[:, 0], cmd[:, 1])
    a, b, c = linear_fit(fit_cmd, fit_p)
    linear = a * np.abs(cmd[:, 0]) + b * np.abs(cmd[:, 1]) + c
    calibrated = reading_W(after.current, after.setpoint)
    by_motion = {
        kind: MotionShare(
            float(hold[m].sum()),
            float(measured[m] @ hold[m]),
            float(calibrated[m] @ hold[m]),
            float(linear[m] @ hold[m]),
        )
        for kind, m in motion_kinds(cmd).items()
    }
    fitted = [n for n in result.names if result.status(n) == 'fitted']
    pinned = [f'{n} at its {side} bound' for n, side in result.at_bound.items()]
    status = result.kept_start or '; '.join(
        [f'fitted {", ".join(fitted)}' if fitted else 'nothing fitted inside its range', *pinned]
    )
    return EnergyRow(
        surface,
        split,
        fit_runs,
        check_runs,
        float(measured @ hold),
        energy_pct(reading_W(before.current, before.setpoint), measured, hold),
        energy_pct(calibrated, measured, hold),
        energy_pct(linear, measured, hold),
        status,
        by_motion,
    )


def speed_split(surface: str) -> tuple[list[int], list[int]]:
    """(runs below the median mean |speed|, runs above): the transfer split of issue 35."""
    numbers = runs(surface)
    mean_speed = []
    for n in numbers:
        series = load_run(surface, n)
        mean_speed.append(float(np.mean(np.abs(series.setpoint_rad_s.mean(axis=1))) * WHEEL_RADIUS_M))
    median = float(np.median(mean_speed))
    below = [n for n, s in zip(numbers, mean_speed, strict=True) if s <= median]
    above = [n for n, s in zip(numbers, mean_speed, strict=True) if s > median]
    return below, above
