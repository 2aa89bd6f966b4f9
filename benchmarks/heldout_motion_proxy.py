"""A PROXY of issue 36's held-out check, "a real Husky you don't have, calibrated with ``calibrate
--fit auto`` on the first half of its drive, then ``predict --commands`` on the second half: yaw
rate MAE <= 0.08 rad/s and vx MAE <= 0.07 m/s from the command, better than every fitted model".
The whole path a Husky user takes, through the real command line, with the shipped
``--vehicle husky_a200``. It is no real robot: the recordings come from the project's dynamic twin
(``skidsteer-power simulate``: its own contact laws, motor dynamics, drive controller and sensor
noise, never FESS or the maps), rewritten into what a Husky records: joint_states of its four
ros2_control wheel joints at the wheel (position and velocity, no effort; config/joints/
ros2_control_4wheel.yaml), cmd_vel and the body motion on ``ground_truth/odom`` (standing in for
lidar scan matching or motion capture); the battery topic is dropped (no current, as most motion
recordings).

Per case: two command files of the held-out check's kind (holds of 1-8 s; spins up to 3 rad/s and
speeds up to 1.5 m/s, beyond what the Husky's controller lets its wheels reach, so the drive
controller decides the motion); one simulated bag each; ``calibrate --fit auto --motion-topic
ground_truth/odom --out-vehicle --out-terrain`` on the first; ``predict --commands`` of the second
bag's held commands with the written files. Compared per steady window (each held command after
:data:`SETTLE_S`, at least :data:`MIN_WINDOW_S`): the mean ground-truth forward speed and yaw rate.
The simplest alternatives: the no-slip kinematics (the command itself) and a linear fit per output
(v = a v_cmd + b, w_z = c w_cmd + d) fitted to the first bag's windows.

Rigid ground (asphalt, concrete, flooring) is left out: the twin's contact is a soil law and
diverges there under these commands (docs/TWIN.md, "Rigid ground is still a soil to the twin").
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.heldout_proxy import Case, Command, cli, teleop_commands
from skidsteer_power.bag_io import open_bag
from skidsteer_power.bag_io.writer import BagWriter

VEHICLE = 'husky_a200'
GEAR_RATIO = 79.0  # the twin's joint_states are at the motor (husky_a200 powertrain, config/powertrains)
WHEEL_JOINTS = (
    ('front_left_wheel_joint', 'rear_left_wheel_joint'),
    ('front_right_wheel_joint', 'rear_right_wheel_joint'),
)  # config/joints/ros2_control_4wheel.yaml (husky_description's names)
SETTLE_S = 1.5  # a held command's first seconds left out of its window [s] (calibrate's default)
MIN_WINDOW_S = 0.5  # shortest window compared [s]
MOTION_TOPIC = '/ground_truth/odom'
GOAL_YAW_RAD_S = 0.08  # issue 36
GOAL_VX_M_S = 0.07  # issue 36


@dataclass(frozen=True)
class MotionOutcome:
    """MAE of the second half's steady windows, forward speed [m/s] and yaw rate [rad/s], per model."""

    case: Case
    windows_fit: int
    windows_check: int
    mae: dict[str, tuple[float, float]]  # model -> (vx, yaw)
    fitted: str
    limited: int  # windows predict flagged limited (calibrated)


def _motion_mix(rng: random.Random) -> Command:
    """Stops, straights to 1.5 m/s, turns to 2 rad/s, near-pivot spins to 3 rad/s, reversing."""
    kind = rng.random()
    if kind < 0.1:
        return 0.0, 0.0
    if kind < 0.3:
        return rng.uniform(0.2, 1.5), 0.0
    if kind < 0.6:
        return rng.uniform(0.1, 1.2), rng.uniform(-2.0, 2.0)
    if kind < 0.85:
        return rng.uniform(-0.05, 0.05), rng.choice((-1.0, 1.0)) * rng.uniform(0.3, 3.0)
    return -rng.uniform(0.1, 0.8), rng.uniform(-0.5, 0.5)


def commands(path: Path, seconds: float, seed: int) -> Path:
    """A command CSV of the held-out check's kind (:func:`teleop_commands` of :func:`_motion_mix`)."""
    return teleop_commands(path, seconds, seed, _motion_mix)


def as_husky_recording(twin_bag: Path, out: Path) -> Path:
    """The twin's bag as a Husky records it: its two motor joints become the four wheel joints at the
    wheel (velocity / gear ratio, each side's two joints alike), no effort, no battery topic."""
    with open_bag(twin_bag) as bag, BagWriter(out) as writer:
        topics = {
            n: writer.add_topic(n, i.msgtype) for n, i in bag.topics.items() if n != '/battery/measured'
        }
        for message in bag.messages():
            if message.topic not in topics:
                continue
            data = message.data
            if message.topic == '/joint_states':
                msg = bag.deserialize(message)
                msg.name = [*WHEEL_JOINTS[0], *WHEEL_JOINTS[1]]
                msg.position = np.repeat(np.asarray(msg.position, dtype=float) / GEAR_RATIO, 2)
                msg.velocity = np.repeat(np.asarray(msg.velocity, dtype=float) / GEAR_RATIO, 2)
                msg.effort = np.zeros(0)
                data = bag.typestore.serialize_cdr(msg, message.msgtype)
            writer.write(topics[message.topic], message.timestamp_ns, data)
    return out


def steady_windows(path: Path) -> np.ndarray:
    """(n, 4): commanded v [m/s], w [rad/s], mean measured forward speed [m/s] and yaw rate [rad/s]
    of every moving held command after :data:`SETTLE_S` (ground truth odometry)."""
    cmd, truth = [], []
    with open_bag(path) as bag:
        for message in bag.messages():
            if message.topic == '/cmd_vel':
                msg = bag.deserialize(message)
                cmd.append((message.timestamp_ns * 1e-9, msg.linear.x, msg.angular.z))
            elif message.topic == MOTION_TOPIC:
                twist = bag.deserialize(message).twist.twist
                truth.append((message.timestamp_ns * 1e-9, twist.linear.x, twist.angular.z))
    c, o = np.array(cmd), np.array(truth)
    change = np.flatnonzero(np.any(np.abs(np.diff(c[:, 1:], axis=0)) > 1e-6, axis=1)) + 1
    out = []
    for s, e in zip(np.r_[0, change], np.r_[change, len(c)], strict=True):
        t0, t1 = c[s, 0] + SETTLE_S, c[e - 1, 0]
        inside = (o[:, 0] >= t0) & (o[:, 0] <= t1)
        if t1 - t0 < MIN_WINDOW_S or not np.any(c[s, 1:]) or np.count_nonzero(inside) < 3:
            continue
        out.append((c[s, 1], c[s, 2], o[inside, 1].mean(), o[inside, 2].mean()))
    return np.array(out).reshape(-1, 4)


def predicted(folder: Path, windows: np.ndarray, vehicle: str, terrain: str) -> tuple[np.ndarray, int]:
    """``predict --commands`` of the windows' commands: ((n, 2) speed, yaw rate; limited count)."""
    csv = folder / 'check_commands.csv'
    np.savetxt(csv, windows[:, :2], delimiter=',', header='speed_m_s,yaw_rate_rad_s', comments='')
    rows = json.loads(
        cli('predict', '--vehicle', vehicle, '--terrain', terrain, '--commands', str(csv), '--json')
    )
    motion = np.array([[r['speed_m_s'], r['yaw_rate_rad_s']] for r in rows], dtype=float)
    return motion, sum(bool(r['limited']) for r in rows)


def linear_motion(fit: np.ndarray, check: np.ndarray) -> np.ndarray:
    """v = a v_cmd + b and w_z = c w_cmd + d, least squares on ``fit``, at ``check``'s commands."""
    out = []
    for k in (0, 1):
        design = np.column_stack([fit[:, k], np.ones(len(fit))])
        coef, *_ = np.linalg.lstsq(design, fit[:, 2 + k], rcond=None)
        out.append(coef[0] * check[:, k] + coef[1])
    return np.column_stack(out)


def mae(motion: np.ndarray, windows: np.ndarray) -> tuple[float, float]:
    err = np.abs(motion - windows[:, 2:4])
    return float(err[:, 0].mean()), float(err[:, 1].mean())


def simulate(folder: Path, case: Case, half: int) -> Path:
    seed = case.seed * 10 + half
    csv = commands(folder / f'cmd{half}.csv', case.seconds, seed)
    twin = folder / f'twin{half}.mcap'
    cli('simulate', '--vehicle', VEHICLE, '--terrain', case.terrain, '--commands', str(csv),
        '--seed', str(seed), '-o', str(twin), '--json')  # fmt: skip
    return as_husky_recording(twin, folder / f'husky{half}.mcap')


def run_case(case: Case, folder: Path) -> MotionOutcome:
    folder.mkdir(parents=True, exist_ok=True)
    first, second = simulate(folder, case, 1), simulate(folder, case, 2)
    out_vehicle, out_terrain = folder / 'calibrated_vehicle.yaml', folder / 'calibrated_terrain.yaml'
    report = json.loads(
        cli(
            'calibrate',
            str(first),
            '--vehicle',
            VEHICLE,
            '--terrain',
            case.terrain,
            '--fit',
            'auto',
            '--motion-topic',
            MOTION_TOPIC.lstrip('/'),
            '--out-vehicle',
            str(out_vehicle),
            '--out-terrain',
            str(out_terrain),
            '--json',
        )
    )
    fitted = ', '.join(n for n, p in report['parameters'].items() if p.get('fitted')) or 'nothing'
    fit, check = steady_windows(first), steady_windows(second)
    preset, _ = predicted(folder, check, VEHICLE, case.terrain)
    calibrated, limited = predicted(folder, check, str(out_vehicle), str(out_terrain))
    models = {
        'no-slip kinematics': check[:, :2],
        'linear fit': linear_motion(fit, check),
        'FESS preset': preset,
        'FESS calibrated': calibrated,
    }
    return MotionOutcome(
        case, len(fit), len(check), {k: mae(v, check) for k, v in models.items()}, fitted, limited
    )
