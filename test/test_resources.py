"""The one resolver of shipped files (skidsteer_power.resources): source tree, ament index, errors.

The colcon-installed case end to end is test/test_colcon_install.py; here an ament prefix is laid
out by hand (the marker file colcon installs plus share/skidsteer_power/config) and found through the
real ament_index_python.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from skidsteer_power import resources
from skidsteer_power.errors import ConfigError
from skidsteer_power.powertrain.config import load_preset
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import available_vehicles, load_vehicle

SOURCE_CONFIG = Path(__file__).resolve().parents[1] / 'config'


def test_source_tree_resolves_every_shipped_file() -> None:
    for kind in ('vehicles', 'terrains', 'powertrains', 'batteries', 'joints'):
        names = {p.stem for p in (SOURCE_CONFIG / kind).glob('*.yaml')}
        assert names and set(resources.shipped(kind)) >= names, kind
    assert resources.params_file('estimator.yaml') == SOURCE_CONFIG / 'estimator.yaml'
    assert resources.find('foxglove', 'operator_layout', ('.json',)).name == 'operator_layout.json'


def test_errors_list_what_is_shipped() -> None:
    with pytest.raises(ConfigError, match=r'no such file or shipped vehicle \(shipped: .*test_robot_track'):
        load_vehicle('no_such_robot')
    with pytest.raises(ConfigError, match=r'shipped: .*dry_sand.*example_terrain'):
        load_terrain('mud')
    with pytest.raises(ConfigError, match=r'powertrain .*shipped: .*test_robot'):
        load_preset('powertrains', 'nope')


def test_shipped_terrain_file_by_name() -> None:
    terrain = load_terrain('example_terrain')
    assert terrain.name == load_terrain(SOURCE_CONFIG / 'terrains' / 'example_terrain.yaml').name


@pytest.fixture
def ament_prefix(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An install prefix as colcon lays it out, with the source tree hidden from the resolver."""
    prefix = tmp_path / 'install'
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'skidsteer_power'
    marker.parent.mkdir(parents=True)
    marker.write_text('')
    config = prefix / 'share' / 'skidsteer_power' / 'config'
    (config / 'vehicles').mkdir(parents=True)
    source = SOURCE_CONFIG / 'vehicles' / 'test_robot_track.yaml'
    shutil.copy(source, config / 'vehicles' / 'installed_only.yaml')
    shutil.copytree(SOURCE_CONFIG / 'powertrains', config / 'powertrains')
    shutil.copytree(SOURCE_CONFIG / 'batteries', config / 'batteries')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    monkeypatch.setattr(resources, '_SOURCE_CONFIG', tmp_path / 'no_source_tree')
    return config


def test_colcon_share_directory_is_found_through_the_ament_index(ament_prefix: Path) -> None:
    assert resources.ament_share_dir() == ament_prefix.parent
    assert resources.config_roots()[0] == ament_prefix
    assert available_vehicles() == ['installed_only']
    vehicle = load_vehicle('installed_only')
    assert vehicle.mass_kg > 0 and vehicle.source
    with pytest.raises(ConfigError, match=r"vehicle 'test_robot_4wheel'.*shipped: installed_only\)"):
        load_vehicle('test_robot_4wheel')


def test_no_ament_index_and_no_source_tree_says_where_it_looked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    monkeypatch.setattr(resources, '_SOURCE_CONFIG', tmp_path / 'no_source_tree')
    monkeypatch.setattr(sys, 'prefix', str(tmp_path))  # the module resources reads sys.prefix from
    assert resources.ament_share_dir() is None
    with pytest.raises(ConfigError, match=r'shipped: none \(searched no config folder found\)'):
        load_vehicle('test_robot_track')
