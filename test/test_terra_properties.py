"""Property tests (hypothesis) over plausible terrain and running-gear parameters.

Ranges span the presets of Tables 2.1-2.3, 7.2, 8.2 and 8.3 (n 0.5-1.1, kc 0-102 kN/m^(n+1),
kphi 0.69-5.3 MN/m^(n+2), c 0-4.1 kPa, phi 13-31 deg, K 5-25 mm) with some margin. Where a wheel
cannot carry the load even sunk to its radius, the property is that ConvergenceError says so.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from skidsteer_power.errors import ConvergenceError
from skidsteer_power.terramechanics import Terrain
from skidsteer_power.terramechanics.track import single_track
from skidsteer_power.terramechanics.wheel import sinkage_at_slip, wheel_at_slip, wheel_forces

terrains = st.builds(
    Terrain,
    name=st.just('random'),
    n=st.floats(0.4, 1.3),
    kc=st.floats(0.0, 2e5),
    kphi=st.floats(6e5, 8e6),
    c=st.floats(0.0, 6000.0),
    phi=st.floats(math.radians(10), math.radians(40)),
    K=st.floats(0.003, 0.05),
)
loads = st.floats(10.0, 300.0)
slips = st.floats(-1.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(terrain=terrains, load=loads, slip=slips, width=st.floats(0.03, 0.2), length=st.floats(0.2, 1.0))
def test_track_outputs_finite_and_sinkage_monotonic(
    terrain: Terrain, load: float, slip: float, width: float, length: float
) -> None:
    state = single_track(terrain, [load, 1.5 * load], width, length, slip)
    for value in (
        state.sinkage_m,
        state.compaction_resistance_N,
        state.tractive_effort_N,
        state.drawbar_pull_N,
    ):
        assert np.all(np.isfinite(value))
    assert state.sinkage_m[1] > state.sinkage_m[0] > 0
    assert state.compaction_resistance_N[1] > state.compaction_resistance_N[0] >= 0
    # the tractive effort never exceeds the shear strength of the contact (eq. 2.11)
    f_max = width * length * terrain.c + np.array([load, 1.5 * load]) * math.tan(terrain.phi)
    assert np.all(np.abs(state.tractive_effort_N) <= f_max * (1 + 1e-12))


@settings(max_examples=40, deadline=None)
@given(terrain=terrains, load=st.floats(10.0, 150.0), slip=slips)
def test_wheel_outputs_finite_and_sinkage_monotonic(terrain: Terrain, load: float, slip: float) -> None:
    r, b = 0.1, 0.07
    try:
        state = wheel_at_slip(terrain, [load, 1.5 * load], slip, r, b)
    except ConvergenceError as err:
        assert 'deeper than its radius' in str(err)
        assert float(wheel_forces(terrain, r, slip, r, b).Fz_N) < 1.5 * load
        return
    for value in (state.sinkage_m, state.Fx_N, state.Fz_N, state.My_Nm, state.theta_f, state.theta_r):
        assert np.all(np.isfinite(value))
    assert state.sinkage_m[1] > state.sinkage_m[0] > 0
    np.testing.assert_allclose(state.Fz_N, [load, 1.5 * load], atol=1e-3)


@settings(max_examples=25, deadline=None)
@given(terrain=terrains, slip=st.floats(0.05, 1.0))
def test_wheel_sinkage_monotonic_over_load_grid(terrain: Terrain, slip: float) -> None:
    loads = np.linspace(10.0, 150.0, 8)
    capacity = float(wheel_forces(terrain, 0.1, slip, 0.1, 0.07).Fz_N)
    z = sinkage_at_slip(terrain, loads[loads < capacity], slip, 0.1, 0.07)
    assert np.all(np.diff(z) > 0)
