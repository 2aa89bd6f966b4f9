"""Vehicle descriptions: shipped files, validation errors naming the field, fingerprint."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import yaml

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.vehicle import (
    FIELD_NAMES,
    GRAVITY_M_S2,
    TRACK_FIELDS,
    WHEEL_FIELDS,
    TrackGear,
    Vehicle,
    WheelGear,
    available_vehicles,
    load_vehicle,
    vehicle_dirs,
    vehicle_fingerprint,
    vehicle_from_dict,
)

SHIPPED = (
    'chapter3_track',
    'chapter4_4wheel',
    'test_robot_track',
    'test_robot_4wheel',
    'test_robot_6wheel',
    'packbot_track',
    'packbot_4wheel',
    'packbot_6wheel',
)


def test_every_design_file_is_shipped_and_loads() -> None:
    assert set(SHIPPED) <= set(available_vehicles())
    for name in SHIPPED:
        vehicle = load_vehicle(name)
        assert vehicle.name == name
        assert vehicle.source  # where the numbers came from
        assert vehicle.weight_N == pytest.approx(vehicle.mass_kg * GRAVITY_M_S2)


def test_chapter3_track_is_table_3_3() -> None:
    # Table 3.3: m 30 kg, l 0.7 m, b 0.07 m, B 0.4 m, r 0.1 m, h 0.15 m
    v = load_vehicle('chapter3_track')
    assert (v.running_gear, v.mass_kg, v.tracks().track_length_m, v.tracks().track_width_m) == (
        'track',
        30.0,
        0.7,
        0.07,
    )
    assert (v.tread_m, v.tracks().sprocket_radius_m, v.cg_height_m, v.drive_radius_m) == (0.4, 0.1, 0.15, 0.1)


def test_chapter4_wheels_are_section_4_2() -> None:
    # Section 4.2: Table 3.3 with four wheels, r = 0.1 m, b = 0.074 m, wb = 0.45 m
    v = load_vehicle('chapter4_4wheel')
    assert v.running_gear == 'wheel'
    assert v.gear == WheelGear(n_wheels=4, wheel_radius_m=0.1, wheel_width_m=0.074, wheelbase_m=0.45)
    assert (v.mass_kg, v.tread_m, v.cg_height_m) == (30.0, 0.4, 0.15)
    assert v.axle_positions_m() == (0.225, -0.225)


def test_packbots_share_table_8_1_chassis() -> None:
    # Table 8.1: 15.8 kg, h 0.08 m, B 0.4 m; track 0.7 x 0.074, r 0.1; wheels 0.074 x r 0.1; 4-wheel wb 0.7
    track, four, six = (load_vehicle(f'packbot_{k}') for k in ('track', '4wheel', '6wheel'))
    for v in (track, four, six):
        assert (v.mass_kg, v.cg_height_m, v.tread_m, v.drive_radius_m, v.contact_width_m) == (
            15.8,
            0.08,
            0.4,
            0.1,
            0.074,
        )
    assert track.tracks().track_length_m == 0.7
    assert four.wheels().wheelbase_m == 0.7 and four.wheels().n_wheels == 4
    # Table 8.1 "Wheel Base (6-Wheel) 0.35" read as the adjacent-axle spacing (flagged in the file)
    assert six.wheels().n_wheels == 6 and six.axle_positions_m() == (0.35, 0.0, -0.35)
    assert 'INTERPRETED' in six.source


def test_test_robot_section_7_1_and_flags() -> None:
    # Section 7.1.1: about 30 kg, 650 mm x 500 mm, two motors, 12:1; silent dimensions flagged ASSUMED
    for name in ('test_robot_track', 'test_robot_4wheel', 'test_robot_6wheel'):
        v = load_vehicle(name)
        assert v.mass_kg == 30.0
        assert v.powertrain == {'preset': 'test_robot'}
        assert 'ASSUMED' in v.source
        # the running gear fits in the 650 mm x 500 mm outline
        span = v.gear.track_length_m if isinstance(v.gear, TrackGear) else v.gear.wheelbase_m
        length = span + 2 * v.drive_radius_m
        assert length <= 0.650 + 1e-9
        assert v.tread_m + v.contact_width_m <= 0.500 + 1e-9


def test_load_by_path_and_passthrough(tmp_path: Path) -> None:
    src = vehicle_dirs()[0] / 'chapter3_track.yaml'
    copy = tmp_path / 'mine.yaml'
    copy.write_text(src.read_text())
    v = load_vehicle(copy)
    assert v == load_vehicle('chapter3_track')
    assert load_vehicle(v) is v


def _write(tmp_path: Path, data: object) -> Path:
    path = tmp_path / 'v.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


BASE = yaml.safe_load((vehicle_dirs()[0] / 'chapter4_4wheel.yaml').read_text())


@pytest.mark.parametrize(
    ('change', 'message'),
    [
        ({'mass_kg': -3.0}, 'mass_kg'),
        ({'mass_kg': 'heavy'}, 'mass_kg'),
        ({'tread_m': float('nan')}, 'tread_m'),
        ({'n_wheels': 5}, 'n_wheels'),
        ({'running_gear': 'legs'}, 'running_gear'),
        ({'wheel_radius_m': None}, 'wheel_radius_m'),
        ({'track_length_m': 0.5}, 'track_length_m'),
        ({'wheelbase_m': 0.15}, 'wheelbase_m'),
        ({'tread_m': 0.05}, 'tread_m'),
        ({'colour': 'red'}, 'colour'),
        ({'powertrain': [1, 2]}, 'powertrain'),
    ],
)
def test_bad_field_is_named(tmp_path: Path, change: dict[str, object], message: str) -> None:
    data = {**BASE, **change}
    with pytest.raises(ConfigError, match=message):
        load_vehicle(_write(tmp_path, data))


def test_missing_field_is_named(tmp_path: Path) -> None:
    data = dict(BASE)
    del data['cg_height_m']
    with pytest.raises(ConfigError, match='cg_height_m'):
        load_vehicle(_write(tmp_path, data))


def test_unreadable_inputs(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='no such file or shipped vehicle'):
        load_vehicle('no_such_vehicle')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('name: [unclosed\n')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_vehicle(bad)
    with pytest.raises(ConfigError, match='mapping'):
        load_vehicle(_write(tmp_path, [1, 2, 3]))


def test_direct_construction_is_validated() -> None:
    with pytest.raises(ConfigError, match='sprocket_radius_m'):
        TrackGear(track_length_m=0.7, track_width_m=0.07, sprocket_radius_m=-0.1)
    with pytest.raises(ConfigError, match='n_wheels'):
        WheelGear(n_wheels=5, wheel_radius_m=0.1, wheel_width_m=0.074, wheelbase_m=0.45)
    tracks = TrackGear(track_length_m=0.7, track_width_m=0.07, sprocket_radius_m=0.1)
    with pytest.raises(ConfigError, match="vehicle 'x': tread_m"):
        Vehicle('x', tracks, mass_kg=30.0, cg_height_m=0.15, tread_m=0.05)  # narrower than the track
    with pytest.raises(ConfigError, match='gear must be'):
        Vehicle('x', 'track', mass_kg=30.0, cg_height_m=0.15, tread_m=0.4)  # type: ignore[arg-type]


def test_running_gear_is_one_field_narrowed_by_its_kind() -> None:
    track, wheels = load_vehicle('test_robot_track'), load_vehicle('test_robot_6wheel')
    assert track.tracks() is track.gear and wheels.wheels() is wheels.gear
    with pytest.raises(InputError, match="'test_robot_6wheel' has wheels"):
        wheels.tracks()
    with pytest.raises(InputError, match="'test_robot_track' has tracks"):
        track.wheels()
    assert (track.wheels_per_side, track.axle_positions_m()) == (0, ())
    assert (wheels.wheels_per_side, wheels.axle_positions_m()) == (3, (0.225, 0.0, -0.225))


@pytest.mark.parametrize('name', SHIPPED)
def test_flat_fields_round_trip(name: str) -> None:
    v = load_vehicle(name)
    flat = v.as_dict()
    assert tuple(flat) == FIELD_NAMES
    assert vehicle_from_dict(flat) == v
    other = WHEEL_FIELDS if v.is_tracked else TRACK_FIELDS
    assert all(flat[k] is None for k in other)


def test_fingerprints_are_those_of_the_flat_file_format() -> None:
    # digests of the flat vehicle fields, computed before the running gear became one field (commit
    # 616625a): maps and fast-model tables cached under them stay valid
    assert vehicle_fingerprint(load_vehicle('chapter3_track')) == '43f114b48237ba58'
    assert vehicle_fingerprint(load_vehicle('test_robot_6wheel')) == '4e1816fb6141d3c4'
    assert vehicle_fingerprint(load_vehicle('test_robot_track')) == '8d337fbebe307fe3'  # K_x / K = 4


def test_fingerprint_is_stable_and_physical() -> None:
    v = load_vehicle('chapter3_track')
    assert vehicle_fingerprint(v) == vehicle_fingerprint(load_vehicle('chapter3_track'))
    renamed = dataclasses.replace(v, name='other', source='elsewhere')
    assert vehicle_fingerprint(renamed) == vehicle_fingerprint(v)  # name and source do not matter
    heavier = dataclasses.replace(v, mass_kg=math.nextafter(30.0, 31.0))
    assert vehicle_fingerprint(heavier) != vehicle_fingerprint(v)
    geared = dataclasses.replace(v, powertrain={'preset': 'test_robot'})
    assert vehicle_fingerprint(geared) != vehicle_fingerprint(v)
    assert len({vehicle_fingerprint(load_vehicle(n)) for n in SHIPPED}) == len(SHIPPED)


def test_track_longitudinal_shear_ratio_is_a_track_parameter_with_a_neutral_default() -> None:
    # default 1 (Wong's inextensible belt) leaves the fingerprint as it was, so maps built before
    # the field existed stay valid; any other value is new physics (a new fingerprint)
    v = load_vehicle('chapter3_track')
    tracks = v.tracks()
    assert tracks.track_longitudinal_shear_ratio == 1.0
    text = vehicle_fingerprint(v)
    for ratio, same in ((1, True), (4.0, False)):
        belt = dataclasses.replace(v, gear=dataclasses.replace(tracks, track_longitudinal_shear_ratio=ratio))
        assert (vehicle_fingerprint(belt) == text) is same
    assert load_vehicle('test_robot_track').tracks().track_longitudinal_shear_ratio == 4.0  # fitted, shipped
    with pytest.raises(ConfigError, match='track_longitudinal_shear_ratio'):
        dataclasses.replace(tracks, track_longitudinal_shear_ratio=0.5)  # a belt only adds compliance
    six = load_vehicle('test_robot_6wheel').as_dict()
    with pytest.raises(ConfigError, match='track_longitudinal_shear_ratio does not apply'):
        vehicle_from_dict({**six, 'track_longitudinal_shear_ratio': 4.0})
