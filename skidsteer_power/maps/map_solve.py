"""Building a power map's grid: FESS solved ring by ring with the small-radius limit, right turns
mirrored from left ones, failures filled from converged neighbours, and the build-time check of each
cell's centre against FESS (split from :mod:`skidsteer_power.maps.power_map`, whose module doc
describes the grid; :meth:`PowerMap.build` drives these)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol, TypeAlias

import numpy as np

from skidsteer_power.jsonout import JsonObject
from skidsteer_power.maps.grid_angles import _angle_coordinate, _angle_from_coordinate

if TYPE_CHECKING:
    from skidsteer_power.models.fess import FessSolver

SLIP_LIMIT = 0.7  # slip ratio from which a node counts as at the traction limit (module doc) [-]
Ring: TypeAlias = dict[str, np.ndarray]
"""One ring of solved points by quantity (:func:`_solve_row`: torque, slip, omega (P, 2); s0, sinkage,
margin, slip_ratio, converged, limited (P,))."""


class PowerAnswer(Protocol):
    """What :func:`_check_cells` reads of a map's answer
    (:class:`~skidsteer_power.maps.power_map.MapQuery`)."""

    @property
    def total_power_W(self) -> float | np.ndarray: ...  # [W]


class GridMap(Protocol):
    """What :func:`_check_cells` reads of a :class:`~skidsteer_power.maps.power_map.PowerMap` (named
    here, so that this module does not import power_map.py, which calls it)."""

    radial: np.ndarray  # (Ns,) command magnitude [m/s]
    angles: np.ndarray  # (Npsi,) turn angle [rad]
    length_m: float  # L [m]
    values: dict[str, np.ndarray]
    meta: JsonObject

    def query(self, speed: np.ndarray, yaw_rate: np.ndarray) -> PowerAnswer: ...


def _solve_row(solver: FessSolver, v: np.ndarray, w: np.ndarray, r_min: float) -> Ring:
    """One ring of points (V, w_z): FESS at (V_eff, w_z), V_eff = max(V, r_min |w_z|) (the
    small-radius limit), each from FESS's own first guess (:meth:`PowerMap.build` re-solves failures)."""
    veh = solver.vehicle
    r = veh.drive_radius_m
    v_eff = np.maximum(v, r_min * np.abs(w))
    limited = v_eff > v
    sol = solver.solve_twist(v_eff, w)
    half = 0.5 * veh.tread_m
    ys = np.array([half, -half])
    side_v = v[:, None] - w[:, None] * ys  # actual ground speed of each side [m/s]
    side_v_eff = v_eff[:, None] - w[:, None] * ys
    slip = r * sol.omega - side_v_eff  # each side keeps its slip speed (module doc)
    torque, slip, s0 = _spin_symmetric(sol.torque, slip, sol.s0, v, v_eff)
    return {
        'torque': torque,
        'slip': slip,
        'omega': (side_v + slip) / r,
        's0': s0,
        'sinkage': sol.sinkage,
        'margin': sol.traction_margin,
        'slip_ratio': np.max(
            np.abs(slip) / np.maximum(np.maximum(np.abs(side_v + slip), np.abs(side_v)), 1e-12), axis=1
        ),
        'converged': sol.converged,
        'limited': limited,
    }


def _spin_symmetric(
    torque: np.ndarray, slip: np.ndarray, s0: np.ndarray, v: np.ndarray, v_eff: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Torques (P, 2) [N m], slip speeds (P, 2) [m/s] and s0 (P,) [m] of points solved at the
    small-radius limit, blended with their spin mirror image so that a spin in place is symmetric.

    A laterally and fore-aft symmetric vehicle spinning in place at w_z looks the same after a half
    turn about the vertical: left and right swap and every forward quantity changes sign, so
    T_left = -T_right, slip_left = -slip_right, s0 = 0 (module doc of fess.py). The limit answer (the
    turn at R = min_radius) is not: its outer side keeps a driving, its inner side a braking state.
    Each limited point (|V| < V_eff = min_radius |w_z|) takes (1 - lam) x its answer + lam x the
    mirrored answer (sides swapped, signs changed), lam = (1 - V / V_eff) / 2: exactly symmetric at
    V = 0 (lam = 1/2), the limit answer itself at R = min_radius (lam = 0), continuous between."""
    with np.errstate(invalid='ignore', divide='ignore'):
        lam = np.where(v_eff > v, 0.5 * (1.0 - v / np.where(v_eff > 0, v_eff, 1.0)), 0.0)
    keep = (1.0 - lam)[:, None]
    mirror = lam[:, None]
    torque_sym = keep * torque - mirror * torque[:, ::-1]
    slip_sym = keep * slip - mirror * slip[:, ::-1]
    return torque_sym, slip_sym, (1.0 - 2.0 * lam) * s0


def _check_cells(
    power_map: GridMap, solver: FessSolver, r_min: float, ring_done: Callable[[int], None] | None = None
) -> np.ndarray:
    """The build-time accuracy check (module doc): the relative total-power error [-] of the map at
    the centre of every cell a query could answer unflagged, against FESS solved there (with the
    small-radius limit, as the nodes). (Ns - 1, Npsi - 1); nan for cells every query flags anyway
    (wholly tighter than the limit radius or outside the envelope, or with a corner at the traction
    limit), inf where FESS finds no steady state at the centre. Left turns are checked, right turns
    mirrored. ``ring_done(k)`` is called after the cells of ring k (0-based)."""
    m = power_map
    u = _angle_coordinate(m.angles)
    psi_c = _angle_from_coordinate(0.5 * (u[1:] + u[:-1]))  # centre in the grid coordinate
    s_c = 0.5 * (m.radial[1:] + m.radial[:-1])
    suspect = m.values['suspect'] > 0
    corner = suspect[:-1, :-1] | suspect[1:, :-1] | suspect[:-1, 1:] | suspect[1:, 1:]
    tight = m.angles[:-1] >= math.atan2(m.length_m, r_min)  # the whole cell has R <= min_radius
    # the whole cell is outside the envelope (clamped): its smallest V or L w_z beyond the edge
    v_max = float(m.meta['max_speed_m_s'])
    outside = (m.radial[:-1, None] * np.cos(m.angles[None, 1:]) > v_max) | (
        m.radial[:-1, None] * np.sin(m.angles[None, :-1]) > v_max  # L w_max = v_max
    )
    check = (psi_c > 0)[None, :] & ~tight[None, :] & ~corner & ~outside
    out = np.full(check.shape, np.nan)
    for k, s in enumerate(s_c):  # ring by ring: bounded memory, neighbours for FESS's retries
        cols = np.flatnonzero(check[k])
        if cols.size:
            v, w = s * np.cos(psi_c[cols]), s * np.sin(psi_c[cols]) / m.length_m
            row = _solve_row(solver, v, w, r_min)
            side = row['torque'] * row['omega']  # FESS side powers [W]
            q = m.query(v, w)
            with np.errstate(invalid='ignore', divide='ignore'):
                err = np.abs(q.total_power_W - side.sum(axis=1)) / np.abs(side).sum(axis=1)
            out[k, cols] = np.where(row['converged'] & np.isfinite(err), err, np.inf)
        if ring_done is not None:
            ring_done(k)
    mirrored = psi_c < 0  # the right turn at -psi is the left turn at psi (cells are symmetric)
    out[:, mirrored] = out[:, ::-1][:, mirrored]
    return out


def _mirror(row: Ring, n_psi: int) -> Ring:
    """Extend a ring solved for psi >= 0 to all ``n_psi`` angles: the right turn at -psi is the
    left turn at psi with left and right swapped (s0, sinkage and margin unchanged)."""
    m = len(row['converged'])
    take = np.concatenate([np.arange(m - 1, m - 1 - (n_psi - m), -1), np.arange(m)])  # mirror indices
    right = np.arange(n_psi) < n_psi - m
    out = {}
    for key, arr in row.items():
        full = np.asarray(arr)[take]
        if full.ndim == 2 and full.shape[1] == 2 and key in ('torque', 'slip', 'omega'):
            full = np.where(right[:, None], full[:, ::-1], full)
        out[key] = full
    return out


def _assemble(rows: list[Ring]) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    torque = np.stack([r['torque'] for r in rows])  # (Nv, Nw, 2)
    slip = np.stack([r['slip'] for r in rows])
    converged = np.stack([r['converged'] for r in rows])
    limited = np.stack([r['limited'] for r in rows])
    values = {
        'torque_left_Nm': torque[..., 0],
        'torque_right_Nm': torque[..., 1],
        'slip_left_m_s': slip[..., 0],
        'slip_right_m_s': slip[..., 1],
        's0_m': np.stack([r['s0'] for r in rows]),
        'sinkage_m': np.stack([r['sinkage'] for r in rows]),
        'traction_margin': np.stack([r['margin'] for r in rows]),
        'suspect': (~converged).astype(float),
    }
    steep = np.stack([r['slip_ratio'] for r in rows]) >= SLIP_LIMIT
    steep[0] = False  # ring 0 is the s -> 0 limit: slip over a vanishing ground speed means nothing
    values['suspect'] = (~converged | steep).astype(float)
    if np.any(~converged) and np.any(converged):
        _fill_nearest(values, converged)
    return values, converged, limited


def _fill_nearest(values: dict[str, np.ndarray], converged: np.ndarray) -> None:
    """Replace non-converged cells by their nearest converged cell (grid-index distance)."""
    good = np.argwhere(converged)
    for i, j in np.argwhere(~converged):
        k = good[np.argmin(np.sum((good - (i, j)) ** 2, axis=1))]
        for name, arr in values.items():
            if name != 'suspect':
                arr[i, j] = arr[k[0], k[1]]
        # no steady state found (typically a side's thrust saturated): no traction margin left
        values['traction_margin'][i, j] = min(values['traction_margin'][i, j], 0.0)
