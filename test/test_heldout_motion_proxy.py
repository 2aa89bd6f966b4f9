"""The path a Husky user takes to predict motion (issue 36's held-out check, as the proxy of
benchmarks/heldout_motion_proxy.py): a twin bag rewritten into a Husky's own recording layout (four
ros2_control wheel joints at the wheel, no effort, body motion on ground_truth/odom) ->
`calibrate --fit auto --motion-topic --out-vehicle --out-terrain` with the shipped husky_a200 ->
`predict --commands` of another bag's held commands, through the real command line. The figures are
the bench's (`python -m benchmarks.run heldout`); this checks the path holds and means something."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from benchmarks.heldout_motion_proxy import run_case, simulate, steady_windows
from benchmarks.heldout_proxy import Case
from skidsteer_power.bag_io import open_bag


def test_a_husky_recording_calibrates_motion_and_predicts_the_other_half(tmp_path: Path) -> None:
    outcome = run_case(Case('grass', 5, seconds=40.0), tmp_path)
    assert outcome.windows_fit >= 4 and outcome.windows_check >= 4
    for vx, yaw in outcome.mae.values():
        assert math.isfinite(vx) and math.isfinite(yaw)
    vx, yaw = outcome.mae['FESS calibrated']
    preset_vx, preset_yaw = outcome.mae['FESS preset']
    # calibrated on the first bag, the second bag's motion is no worse than the preset's (the 150 s
    # bench: 0.004 m/s, 0.006 rad/s against 0.030, 0.080) and within issue 36's goals
    assert yaw <= preset_yaw and vx <= preset_vx + 0.005
    assert yaw <= 0.08 and vx <= 0.07
    written = yaml.safe_load((tmp_path / 'calibrated_vehicle.yaml').read_text())
    assert written['joints']['preset'] == 'ros2_control_4wheel'  # the user's vehicle, rewritten


def test_the_rewritten_recording_is_the_husky_layout(tmp_path: Path) -> None:
    """as_husky_recording: four wheel joints at the wheel (motor speed / 79), no effort; the windows
    read the ground truth's hull-frame twist."""
    husky = simulate(tmp_path, Case('grass', 7, seconds=12.0), 1)
    with open_bag(tmp_path / 'twin1.mcap') as twin, open_bag(husky) as bag:
        assert '/battery/measured' in twin.topics and '/battery/measured' not in bag.topics
        motor = [twin.deserialize(m) for m in twin.messages() if m.topic == '/joint_states']
        wheel = [bag.deserialize(m) for m in bag.messages() if m.topic == '/joint_states']
    assert len(motor) == len(wheel)
    last_motor, last_wheel = motor[len(motor) // 2], wheel[len(wheel) // 2]
    assert list(last_wheel.name) == [
        'front_left_wheel_joint',
        'rear_left_wheel_joint',
        'front_right_wheel_joint',
        'rear_right_wheel_joint',
    ]
    assert len(last_wheel.effort) == 0
    left, right = last_motor.velocity
    np.testing.assert_allclose(last_wheel.velocity, [left / 79, left / 79, right / 79, right / 79])
    windows = steady_windows(husky)
    assert len(windows) >= 1 and windows.shape[1] == 4 and np.all(np.isfinite(windows))
