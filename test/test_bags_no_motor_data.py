"""Recordings without motor data, and other recorders' MCAP files (issue 29): real MCAP files written
with the mcap library from the bundled twin recordings.

The bundled bags/*.mcap are twin recordings with cmd_vel, joint_states, odometry, ground truth and
the battery. A copy with joint_states and the battery stripped is what most real bags look like; a
prediction from the measured motion must not depend on whether the motor data are there.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from skidsteer_power.bag_io import open_bag
from skidsteer_power.errors import InputError
from skidsteer_power.estimator import MapPredictor, factory
from skidsteer_power.maps import PowerMap
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.validation.cmd_timing import command_timing
from skidsteer_power.validation.report import MIN_TURN_RAD, flagged_spans, is_turn
from skidsteer_power.validation.validate import TraceSegment, ValidateOptions, validate
from skidsteer_power.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
TWIN_BAG = ROOT / 'bags' / 'test_robot_6wheel_sand_bin.mcap'
VEHICLE, TERRAIN = 'test_robot_6wheel', 'sand_bin'


def copy_mcap(src: Path, dst: Path, drop: tuple[str, ...] = (), profile: str | None = None) -> None:
    """Copy an MCAP file record by record, without the topics ``drop``, optionally with another
    header ``profile``."""
    with src.open('rb') as f, dst.open('wb') as g:
        reader = make_reader(f)
        header = reader.get_header()
        writer = Writer(g)
        writer.start(profile=header.profile if profile is None else profile, library='test copy')
        summary = reader.get_summary()
        assert summary is not None
        schemas = {s.id: writer.register_schema(s.name, s.encoding, s.data) for s in summary.schemas.values()}
        channels = {
            c.id: writer.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], c.metadata)
            for c in summary.channels.values()
            if c.topic not in drop
        }
        for _, channel, msg in reader.iter_messages():
            if channel.id in channels:
                out = channels[channel.id]
                writer.add_message(out, msg.log_time, msg.data, msg.publish_time, msg.sequence)
        writer.finish()


@pytest.fixture(scope='module')
def predictor() -> MapPredictor:
    """A real FESS map of the 6-wheel test robot on the sand bin, on a coarse grid (fast)."""
    vehicle = load_vehicle(VEHICLE)
    power_map = PowerMap.build(vehicle, factory.check_terrain(TERRAIN), shape=(6, 9))
    return MapPredictor(power_map, Powertrain.for_vehicle(vehicle), description='coarse test map')


@pytest.mark.parametrize('kinematics', ['odom', 'ground_truth'])
def test_motion_prediction_does_not_depend_on_motor_data(
    tmp_path: Path, predictor: MapPredictor, kinematics: str
) -> None:
    """Predicted terminal energy from the measured twist: the twin bag with and without joint_states
    and battery agree (before: each 10 Hz odometry row held for the 0.5 s command hold, ~5x)."""
    stripped = tmp_path / 'stripped.mcap'
    copy_mcap(TWIN_BAG, stripped, drop=('/joint_states', '/battery/measured'))
    energy = {}
    for name, path in (('full', TWIN_BAG), ('stripped', stripped)):
        options = ValidateOptions(
            vehicle=VEHICLE, terrain=TERRAIN, report_dir=tmp_path / name, kinematics=kinematics, plots=False
        )
        with open_bag(path) as bag:
            summary = validate(bag, options, predictor).as_json()
        energy[name] = summary['metrics']['energy_predicted_J']
    assert summary['has_motor_data'] is False
    assert energy['stripped'] == pytest.approx(energy['full'], rel=0.02)
    # the report agrees with itself: the battery gives the terminal energy plus the amplifiers' loss
    # (bus power = terminal power / efficiency while driving), so no less (was 475.5 against 1207 J)
    assert summary['battery']['energy_predicted_J'] >= energy['stripped']


def test_foreign_profile_with_ros2_schemas_is_read_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    copy = tmp_path / 'empty_profile.mcap'
    copy_mcap(TWIN_BAG, copy, profile='')
    with caplog.at_level(logging.WARNING), open_bag(copy) as bag:
        odom = sum(1 for _ in bag.messages(['/odom']))
        assert bag.complete and not bag.damage
    with open_bag(TWIN_BAG) as original:
        assert odom == original.topics['/odom'].count
        assert set(bag.topics) == set(original.topics)
    assert "profile is ''" in caplog.text


def test_foreign_profile_with_other_encodings_is_one_clear_error(tmp_path: Path) -> None:
    path = tmp_path / 'json.mcap'
    with path.open('wb') as g:
        writer = Writer(g)
        writer.start(profile='', library='test')
        schema = writer.register_schema('Point', 'jsonschema', b'{}')
        channel = writer.register_channel('/p', 'json', schema)
        writer.add_message(channel, 1, b'{"x": 1}', 1)
        writer.finish()
    with pytest.raises(InputError, match='not a ROS 2 bag'):
        open_bag(path)


def test_on_change_period_is_that_of_distinct_commands() -> None:
    """An on-change publisher sends a stop and the new command 0.27 ms apart every 5 s: the period
    of distinct commands is 5 s (before: the median of 0.27 ms and 5 s intervals)."""
    t, cmd = [], []
    for k in range(6):
        t += [5.0 * k, 5.0 * k + 0.00027]
        cmd += [(0.0, 0.0), (0.1 * (k + 1), 0.05 * (-1) ** k)]
    timing = command_timing(np.array(t), np.array(cmd))
    assert timing.mode == 'on_change'
    assert timing.period_s == pytest.approx(5.0)


def _segment(radius_m: float, speed_m_s: float, duration_s: float) -> TraceSegment:
    return TraceSegment(0.0, duration_s, speed_m_s, 0.0, math.inf, 30, radius_m, 0.0, 0.0, 0.001, speed_m_s)


def test_circles_are_drawn_only_for_turns() -> None:
    # 0.1 m/s for 3 s on Table 7.3's 1 m circle: 0.3 rad swept (a turn)
    assert is_turn(_segment(1.0, 0.1, 3.0))
    # 0.2 m/s for 10 s, fitted radius 300 m: 2 m / 300 m = 0.0067 rad (a straight run)
    assert not is_turn(_segment(300.0, 0.2, 10.0))
    assert not is_turn(_segment(math.inf, 0.2, 10.0))
    assert 2.0 / 300.0 < MIN_TURN_RAD < 0.3


def test_clamped_time_spans() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    flag = np.array([False, True, True, False, True])
    hold = np.array([1.0, 1.0, 0.5, 1.0, np.nan])
    # rows 1 (1..2 s) and 2 (2..2.5 s) merge; row 4 holds until the next row: none, so to itself
    assert flagged_spans(t, flag, hold) == [(1.0, 2.5), (4.0, 4.0)]
    # a 1.5 s gap (2.5 .. 4.0 s) is merged when gaps up to 2 s are to be drawn as one span
    assert flagged_spans(t, flag, hold, min_gap_s=2.0) == [(1.0, 4.0)]
