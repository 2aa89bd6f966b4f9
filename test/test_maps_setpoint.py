"""The set-point map (skidsteer_power.maps.setpoint_map): the direct set-point solve, tabulated.

Reference: CommandPredictor.predict (the direct FESS solve at the set points, test_fess_setpoint.py);
at a node the map must give exactly the direct answer, between nodes a bilinear blend of them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from skidsteer_power.errors import InputError
from skidsteer_power.maps.identity import map_identity
from skidsteer_power.maps.setpoint_map import SetpointMap, SetpointQuery, cache_path, load_or_build
from skidsteer_power.terramechanics.terrain import load_terrain
from skidsteer_power.vehicle import load_vehicle


@pytest.fixture(scope='module')
def track_map() -> SetpointMap:
    return SetpointMap.build(load_vehicle('test_robot_track'), load_terrain('sand_bin'), nodes=(7, 7))


def _node_command(smap: SetpointMap, i: int, j: int) -> tuple[float, float]:
    veh = smap.predictor.vehicle
    m, d = smap.grid.axis0.values[i], smap.grid.axis1.values[j]
    return float(m * veh.drive_radius_m), float(2 * d * veh.drive_radius_m / veh.tread_m)


def test_at_a_node_the_map_is_the_direct_solve(track_map: SetpointMap) -> None:
    v, w = _node_command(track_map, 2, 1)
    q = track_map.query(v, w)
    direct = track_map.predictor.predict(v, w)
    assert not q.limited and not direct.limited[0]
    assert q.speed_m_s == pytest.approx(direct.speed[0], rel=1e-9)
    assert q.yaw_rate_rad_s == pytest.approx(direct.yaw_rate[0], rel=1e-9)
    assert [q.torque_left_Nm, q.torque_right_Nm] == pytest.approx(direct.torque[0], rel=1e-9)
    assert [q.current_left_A, q.current_right_A] == pytest.approx(direct.current[0], rel=1e-9)
    assert q.battery_power_W == pytest.approx(direct.battery_power[0], rel=1e-9)


@pytest.mark.parametrize('sv, sw', [(1, 1), (1, -1), (-1, 1), (-1, -1)])
def test_every_quadrant_is_the_direct_solve_at_a_node(track_map: SetpointMap, sv: int, sw: int) -> None:
    v, w = _node_command(track_map, 3, 2)
    q = track_map.query(sv * v, sw * w)
    direct = track_map.predictor.predict(sv * v, sw * w)
    assert q.speed_m_s == pytest.approx(direct.speed[0], rel=1e-6)
    assert q.yaw_rate_rad_s == pytest.approx(direct.yaw_rate[0], rel=1e-6)
    assert [q.torque_left_Nm, q.torque_right_Nm] == pytest.approx(direct.torque[0], rel=1e-6)
    assert [q.slip_left, q.slip_right] == pytest.approx(direct.slip[0], rel=1e-6, abs=1e-12)


def test_between_nodes_it_is_close_to_the_direct_solve(track_map: SetpointMap) -> None:
    q = track_map.query(0.4, 0.3)
    direct = track_map.predictor.predict(0.4, 0.3)
    assert q.speed_m_s == pytest.approx(direct.speed[0], rel=0.02)
    assert q.yaw_rate_rad_s == pytest.approx(direct.yaw_rate[0], rel=0.05)


def test_clamped_outside_the_envelope_and_bad_input(track_map: SetpointMap) -> None:
    veh = track_map.predictor.vehicle
    assert track_map.query(2 * veh.max_speed_m_s, 0.0).clamped
    assert not track_map.query(0.5 * veh.max_speed_m_s, 0.0).clamped
    with pytest.raises(InputError):
        track_map.query(math.nan, 0.0)


def test_current_limit_holds_in_every_query(track_map: SetpointMap) -> None:
    rng = np.random.default_rng(3)
    veh = track_map.predictor.vehicle
    for v, w in zip(rng.uniform(-2, 2, 200) * veh.max_speed_m_s, rng.uniform(-2, 2, 200) * 2.0, strict=True):
        q = track_map.query(float(v), float(w))
        assert abs(q.current_left_A) <= 10.0 + 1e-9 and abs(q.current_right_A) <= 10.0 + 1e-9


def test_pivot_band_agrees_with_the_direct_solve(track_map: SetpointMap) -> None:
    """A command whose inner element turns past half a revolution in the contact (set points
    0.375 / 3.545 rad/s; models/setpoint.py's element_turn_rev) is solved by the pivot law
    (docs/PREDICTION.md, "The pivot band"): the map answers it as the direct solve does, unflagged,
    and the wide turn at the same speed is an ordinary answer too. The map solves it with the pivot
    law at once, warm-started from its interpolated state, the direct solve after eq. 6.6's chord
    failed, from the no-slip guess: the same root within the stopping rule |F| < 1e-3 N (section
    3.3.1), here to about 2e-7 relative, not bit for bit (rel=1e-5 below)."""
    query = track_map.query(0.196, 0.744)
    direct = track_map.predictor.predict([0.196], [0.744])
    assert not query.limited and not direct.limited[0] and query.reason == direct.reason[0] == ''
    assert query.speed_m_s == pytest.approx(float(direct.speed[0]), rel=1e-5)
    assert query.yaw_rate_rad_s == pytest.approx(float(direct.yaw_rate[0]), rel=1e-5)
    assert query.torque_left_Nm == pytest.approx(float(direct.torque[0, 0]), rel=1e-5)
    assert query.torque_right_Nm == pytest.approx(float(direct.torque[0, 1]), rel=1e-5)
    assert query.yaw_rate_rad_s > 0 and query.setpoint_left_rad_s < 0.15 * query.setpoint_right_rad_s
    sol = track_map.predictor.solver.solve(
        np.array([[query.setpoint_left_rad_s, query.setpoint_right_rad_s]])
    )
    assert sol.element_turn[0] > 0.5 and sol.shear_path[0]  # in the band, by the pivot law
    wide = track_map.query(0.196, 0.2)  # the same speed on a wide turn: an ordinary answer
    assert not wide.limited and wide.reason == ''


def test_many_queries_answer_as_one_query_each(track_map: SetpointMap) -> None:
    """query_many solves the commands of exact cells in one batch: the same answers as query."""
    rng = np.random.default_rng(5)
    veh = track_map.predictor.vehicle
    v = rng.uniform(-1.0, 1.0, 60) * veh.max_speed_m_s
    w = rng.uniform(-1.0, 1.0, 60) * veh.max_yaw_rate_rad_s
    many = track_map.query_many(v.tolist(), w.tolist())
    one = [track_map.query(float(a), float(b)) for a, b in zip(v, w, strict=True)]
    exact_cells = 0
    for a, b in zip(many, one, strict=True):
        assert a.limited == b.limited and a.reason == b.reason and a.clamped == b.clamped
        for name in ('speed_m_s', 'yaw_rate_rad_s', 'torque_left_Nm', 'torque_right_Nm', 'battery_power_W'):
            assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-9, abs=1e-12)
    for speed, yaw_rate in zip(v, w, strict=True):
        exact_cells += not isinstance(track_map._locate(float(speed), float(yaw_rate)), SetpointQuery)
    assert exact_cells > 0  # the batch path was taken (7 x 7 nodes: the pivot band is exact)
    assert track_map.query_many([], []) == []


def test_cached_map_is_checked_like_a_power_map(tmp_path: Path) -> None:
    """The set-point cache keeps the power map's contract (maps/identity.py): the file says what it
    was built for, and a file for another vehicle or older physics code is rebuilt, never used."""
    vehicle, terrain = load_vehicle('test_robot_track'), load_terrain('sand_bin')
    _first, built = load_or_build(vehicle, terrain, nodes=(5, 5), cache_dir=tmp_path)
    assert built
    path = cache_path(vehicle, terrain, (5, 5), tmp_path)
    with np.load(path, allow_pickle=False) as data:
        stored = json.loads(str(data['meta']))
        arrays = {k: np.array(data[k]) for k in data.files if k != 'meta'}
    assert stored['vehicle'] == 'test_robot_track' and stored['model_version'].startswith('setpoint-')
    _again, built = load_or_build(vehicle, terrain, nodes=(5, 5), cache_dir=tmp_path)
    assert not built  # its own file is used
    other = load_vehicle('packbot_4wheel')
    np.savez(path, meta=np.array(json.dumps(map_identity(other, terrain, 'setpoint'))), **arrays)  # type: ignore[arg-type]
    _fresh, built = load_or_build(vehicle, terrain, nodes=(5, 5), cache_dir=tmp_path)
    assert built  # the same bytes, another vehicle's identity: rebuilt
    np.savez(path, **arrays)  # type: ignore[arg-type]  # a file of the code before: no identity
    _fresh, built = load_or_build(vehicle, terrain, nodes=(5, 5), cache_dir=tmp_path)
    assert built


def test_refined_cells_interpolate_their_sub_grid_and_match_the_direct_solve(track_map: SetpointMap) -> None:
    """Every exact cell is refined 4 x 4 (maps/setpoint_map.py, module doc): at a sub-grid node the
    answer is the direct solve (its node), and a command inside an interpolated sub-cell is within
    the map's goals of the direct solve (1 % battery power, 5 mm/s, issue 36)."""
    assert len(track_map.refined.cells) == int(track_map.exact.sum()) > 0
    assert track_map.exact_fraction < track_map.exact.mean()  # part of the exact area interpolated
    veh = track_map.predictor.vehicle
    r, half_tread = veh.drive_radius_m, 0.5 * veh.tread_m
    checked = 0
    for sub in track_map._sub.values():
        grid, flags = sub.grid, sub.flags
        for i, j in np.argwhere(~flags.exact)[:2]:
            m = 0.5 * (grid.axis0.values[i] + grid.axis0.values[i + 1])
            d = 0.5 * (grid.axis1.values[j] + grid.axis1.values[j + 1])
            v, w = float(m * r), float(d * r / half_tread)  # the sub-cell's centre as a command
            q = track_map.query(v, w)
            direct = track_map.predictor.predict(v, w)
            assert q.limited == bool(direct.limited[0])
            p_direct = float(direct.battery_power[0])
            assert abs(q.battery_power_W - p_direct) <= 0.01 * max(abs(p_direct), 1.0)
            assert abs(q.speed_m_s - float(direct.speed[0])) <= 0.005
            checked += 1
    assert checked > 0, f'no interpolated sub-cell in {len(track_map._sub)} refined cells'


def test_a_cached_map_keeps_its_refinements(tmp_path: Path) -> None:
    """The cache stores the sub-grids: the loaded map answers as the built one, bit for bit, in a
    refined cell too; ``refine=1`` builds none, and a refinement outside 1...MAX_REFINE is refused."""
    vehicle, terrain = load_vehicle('test_robot_track'), load_terrain('sand_bin')
    built_map, built = load_or_build(vehicle, terrain, nodes=(7, 7), cache_dir=tmp_path)
    loaded_map, again = load_or_build(vehicle, terrain, nodes=(7, 7), cache_dir=tmp_path)
    assert built and not again and len(loaded_map.refined.cells) > 0
    cell = int(loaded_map.refined.cells[0])
    i, j = divmod(cell, len(loaded_map.grid.axis1.values) - 1)
    mean, diff = loaded_map.grid.axis0.values, loaded_map.grid.axis1.values
    m, d = 0.3 * mean[i] + 0.7 * mean[i + 1], 0.6 * diff[j] + 0.4 * diff[j + 1]
    v, w = float(m * vehicle.drive_radius_m), float(2 * d * vehicle.drive_radius_m / vehicle.tread_m)
    assert loaded_map.query(v, w) == built_map.query(v, w)
    plain = SetpointMap.build(vehicle, terrain, nodes=(7, 7), refine=1)
    assert len(plain.refined.cells) == 0 and plain.exact_fraction == plain.exact.mean()
    with pytest.raises(InputError, match='refine'):
        SetpointMap.build(vehicle, terrain, nodes=(7, 7), refine=0)
