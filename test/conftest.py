"""Shared test set-up.

Every pytest process gets its own ROS domain (unless ROS_DOMAIN_ID is already set) and DDS discovery
is confined to this host, so parallel test runs on one machine never see each other's topics.
"""

from __future__ import annotations

import os
import random
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(1, 100)))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import pytest

if TYPE_CHECKING:
    from rclpy.context import Context
    from test_nodes_estimator import Rig

    from skidsteer_power.estimator.prediction import Predictor

SHARED_DIR = Path(__file__).resolve().parents[1].parent / 'shared'
"""``../shared`` beside the repository: the dissertation text and real recordings made by others."""
REQUIRE_SHARED_ENV = 'SKIDSTEER_REQUIRE_SHARED'
"""Set to 1 (CI's .ci/run does) to make a missing ``../shared`` a failure instead of a skip."""


def shared_path(*parts: str) -> Path:
    """``../shared/<parts>``; if it is missing, skip the test with the reason (a user's clone without
    the shared folder), or fail it when ``SKIDSTEER_REQUIRE_SHARED=1`` (CI: never silently skipped)."""
    path = SHARED_DIR.joinpath(*parts)
    if not path.exists():
        reason = f'{path} is missing (the shared folder beside the repository)'
        if os.environ.get(REQUIRE_SHARED_ENV) == '1':
            pytest.fail(f'{reason}; {REQUIRE_SHARED_ENV}=1 requires it', pytrace=False)
        pytest.skip(reason)
    return path


@pytest.fixture
def shared_dir() -> Path:
    """The ``../shared`` folder (skip, or fail in CI, when missing)."""
    return shared_path()


@pytest.fixture
def neato_bag() -> Path:
    """``../shared/realbags/neato-teleop``: a real sqlite3 teleop recording (skip, or fail in CI)."""
    return shared_path('realbags', 'neato-teleop')


@pytest.fixture
def ros_context() -> Iterator[Context]:
    """An initialised rclpy context of its own, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def rig_factory(ros_context: Context, tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """Makes power_estimator rigs (test_nodes_estimator.Rig: the node and a probe over real DDS),
    closed after the test."""
    from test_nodes_estimator import Rig

    rigs: list[Rig] = []

    def make(predictor: Predictor | None = None, **params: object) -> Rig:
        rigs.append(Rig(ros_context, tmp_path, predictor, **params))
        return rigs[-1]

    yield make
    for rig in rigs:
        rig.close()


@pytest.fixture
def strong_motor_vehicle(tmp_path: Path) -> Path:
    """test_robot_track with its powertrain's motor overridden to K_t = 0.228 N m/A (2 x the EC-45's
    0.114, Appendix B line 12) and a max. speed of 5000 rpm = 523.6 rad/s (half the EC-45's 10 000,
    line 23, as a doubled K_t halves the speed constant): a vehicle file whose motor differs from the
    built-in one."""
    from skidsteer_power import resources

    base = resources.find('vehicles', 'test_robot_track').read_text(encoding='utf-8')
    vehicle = tmp_path / 'strong_motor.yaml'
    vehicle.write_text(
        base.replace(
            'powertrain: {preset: test_robot}',
            'powertrain: {preset: test_robot, motor: {preset: EC45, torque_constant_Nm_A: 0.228,'
            ' max_speed_rad_s: 523.5987755982989}}',
        ),
        encoding='utf-8',
    )
    return vehicle
