"""One name, one idea in the config files (issue 38): the vehicle file's joint mapping is ``joints:``
(it was ``drivetrain:``, which also named the powertrain's lumped part, now ``lumped``). Files of
earlier rounds still load, to the same vehicle and powertrain, and say the new name once.

Reference: the shipped config/vehicles/husky_a200.yaml and config/powertrains/husky_a200.yaml,
re-spelled with the earlier names by the test itself."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from skidsteer_power.cli.main import main
from skidsteer_power.errors import ConfigError
from skidsteer_power.powertrain.internal import LUMPED, side_from_config
from skidsteer_power.resources import find
from skidsteer_power.vehicle import load_vehicle, vehicle_from_dict


def _husky() -> dict[str, object]:
    data = yaml.safe_load(find('vehicles', 'husky_a200').read_text(encoding='utf-8'))
    assert isinstance(data, dict) and 'joints' in data and 'drivetrain' not in data
    return data


def test_an_earlier_vehicle_file_loads_to_the_same_vehicle() -> None:
    new = _husky()
    old = {('drivetrain' if k == 'joints' else k): v for k, v in new.items()}
    with pytest.warns(FutureWarning, match="'drivetrain:' is now spelled 'joints:'"):
        earlier = vehicle_from_dict(old, origin='old.yaml')
    assert earlier == vehicle_from_dict(new) and earlier.joints == new['joints']
    with pytest.raises(ConfigError, match="give 'joints' only"):
        vehicle_from_dict({**new, 'drivetrain': new['joints']}, origin='both.yaml')


def test_the_lumped_internal_resistance_reads_its_earlier_name() -> None:
    """One viscous + Coulomb term per side at the motor shaft (config/powertrains/husky_a200.yaml)."""
    coefficients = {'viscous_Nm_s': 0.0001, 'coulomb_Nm': 0.046}
    now = side_from_config({LUMPED: coefficients}, 0.05, 'wheel')
    with pytest.warns(FutureWarning, match="'drivetrain' is now spelled 'lumped'"):
        before = side_from_config({'drivetrain': coefficients}, 0.05, 'wheel')
    assert LUMPED == 'lumped' and list(before.components) == [LUMPED]
    assert before.components == now.components


def test_the_command_line_says_the_new_name_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    old = tmp_path / 'old_husky.yaml'
    old.write_text(
        find('vehicles', 'husky_a200').read_text(encoding='utf-8').replace('\njoints:', '\ndrivetrain:')
    )
    argv = ['--vehicle', str(old), '--terrain', 'asphalt', '--speed', '0.5', '--yaw-rate', '0', '--direct']
    assert main(['predict', *argv]) == 0
    out, err = capsys.readouterr()
    assert err.strip().splitlines() == [
        f"note: {old}: 'drivetrain:' is now spelled 'joints:' (the old name still works)"
    ]
    assert main(['predict', *argv[:1], 'husky_a200', *argv[2:]]) == 0
    assert capsys.readouterr().out == out  # the same prediction as from the shipped file
    assert load_vehicle('husky_a200').joints['preset'] == 'ros2_control_4wheel'
