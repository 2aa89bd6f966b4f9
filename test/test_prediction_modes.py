"""One name for "predict a command at its wheel speed set points" (issue 38): ``cmd`` in the estimator's
``kinematics`` parameter, ``validate --kinematics`` and ``calibrate --fit-at``; the spellings of
earlier rounds (``setpoint``, ``setpoints``) still work and say the new name once.

Reference: skidsteer_power/drive/prediction_modes.py (the names) and DESIGN.md
(``validate --kinematics cmd|twist|odom|ground_truth``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from test_nodes_estimator import Rig

from skidsteer_power.cli.main import main
from skidsteer_power.drive.prediction_modes import CMD, FIT_AT, VALIDATE_KINEMATICS, prediction_mode
from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator.factory import KINEMATICS, map_predictor
from skidsteer_power.estimator.prediction import SetpointPredictor
from skidsteer_power.vehicle import load_vehicle


def test_every_option_spells_it_cmd() -> None:
    assert CMD in KINEMATICS and CMD in FIT_AT and CMD in VALIDATE_KINEMATICS
    assert prediction_mode('cmd', 'kinematics', KINEMATICS) == ('cmd', '')
    assert prediction_mode('twist', 'kinematics', KINEMATICS) == ('twist', '')


@pytest.mark.parametrize(
    ('old', 'option', 'choices'),
    [('setpoint', 'kinematics', KINEMATICS), ('setpoints', '--fit-at', FIT_AT)],
)
def test_the_old_spellings_still_work_and_say_the_new_name(
    old: str, option: str, choices: tuple[str, ...]
) -> None:
    name, note = prediction_mode(old, option, choices)
    assert name == 'cmd'
    assert option in note and repr(old) in note and "'cmd'" in note and '\n' not in note


def test_an_unknown_mode_names_the_choices() -> None:
    with pytest.raises(InputError, match='cmd, motion'):
        prediction_mode('setpont', '--fit-at', FIT_AT)
    with pytest.raises(InputError):  # 'setpoints' means cmd, and cmd is not a choice here
        prediction_mode('setpoints', 'mode', ('twist',))


def test_calibrate_refuses_an_unknown_fit_at_in_one_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bag = str(tmp_path / 'none.mcap')
    argv = ['calibrate', bag, '--vehicle', 'test_robot_track', '--terrain', 'dry_sand']
    with pytest.raises(SystemExit) as stop:
        main([*argv, '--fit-at', 'bogus', '--out-terrain', str(tmp_path / 't.yaml')])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert 'cmd, motion' in err and 'Traceback' not in err


def test_the_factory_takes_the_old_kinematics_with_a_warning(tmp_path: Path) -> None:
    vehicle = load_vehicle('test_robot_track')
    with pytest.warns(FutureWarning, match="'cmd'"):
        predictor, _, _ = map_predictor(vehicle, 'dry_sand', tmp_path, 'setpoint')
    assert isinstance(predictor, SetpointPredictor)
    with pytest.raises(ConfigError, match='cmd, twist'):
        map_predictor(vehicle, 'dry_sand', tmp_path, 'setpont')


def test_the_estimator_node_takes_the_old_kinematics(rig_factory: Callable[..., Rig], tmp_path: Path) -> None:
    """Real rclpy: a parameter file of an earlier round (``kinematics: setpoint``) still starts the
    node, predicting at the set points."""
    rig = rig_factory(kinematics='setpoint', map_cache_dir=str(tmp_path / 'maps'))
    assert rig.node.kinematics == 'cmd'
    assert isinstance(rig.node.core.predictor, SetpointPredictor)
