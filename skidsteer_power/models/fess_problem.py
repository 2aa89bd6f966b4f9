"""The FESS problem and the equations both of its kernels evaluate (chapter 6; module doc of
:mod:`~skidsteer_power.models.fess`).

FESS runs in two layouts of the same residual (eq. 3.19): the batched one of
:mod:`~skidsteer_power.models.fess` (maps, missions: P points at once) and the one-point kernel of
:mod:`~skidsteer_power.models.fess_point` (on board, ~0.3 ms per command: there a residual call costs
its number of numpy operations). Both set up a batch with :func:`build_problem` and evaluate each
equation by the ONE function here: the shear displacement of eq. 6.6 (:func:`chord_displacement`),
the centrifugal force of eq. 3.18
(:func:`centrifugal`), the slip of eq. 2.13 (:func:`slip_ratio`) and Steeds' s0 guess of eq. 3.7
(:func:`steeds_s0`). Their formulas take a Python float or a numpy array
(:mod:`skidsteer_power.numeric`), so the kernel's floats and the batch's arrays run the same
arithmetic and give the same bits. The Newton iteration's rules are :mod:`~skidsteer_power.models.newton`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, cast

import numpy as np

from skidsteer_power.models.fess_contact import Contact, track_contact, wheel_contact
from skidsteer_power.models.loads import OperatingPoints, side_loads
from skidsteer_power.models.newton import TOLERANCE
from skidsteer_power.models.rigid_contact import rigid_contact
from skidsteer_power.numeric import Real, hypot, maximum, minimum, where
from skidsteer_power.vehicle import GRAVITY_M_S2

if TYPE_CHECKING:
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle

GUESS_FRICTION = 0.5  # [-] mu standing in for the unknown mu_t in Steeds' s0 guess (eq. 3.7)
STEEDS_S0_SCALE = 1.0 / (2.0 * GUESS_FRICTION * GRAVITY_M_S2)  # [s^2/m]: s0 = V |w_z| l x this (eq. 3.7)
DEFAULT_ELEMENTS = 40  # elements per contact (eq. 6.5); see test_fess_track.py for the n study
FORCE_TOL_N = TOLERANCE  # stopping rule of section 3.3.1: |each equation of (3.19)| < 0.001 (N, N m)
MAX_HALVINGS = 12
RETRY_ROUNDS = 3  # warm-started re-solves of failed points from converged neighbours
SLIP_LIMIT = 0.95  # |slip| beyond this: the side cannot develop the thrust (no steady state)
RIGID_MARGIN_MIN = 0.01  # rigid ground: a side within 1 % of mu x its load has no steady state
STRAIGHT_YAW = 1e-9  # [rad/s] yaw rate at which straight-running points are solved (s0 limit)

SIDE_Y_SIGN = np.array([1.0, -1.0])  # left side at y = +B/2, right side at y = -B/2


@dataclass
class Problem:
    """Everything fixed for a batch of P operating points (forward speed V >= 0)."""

    vehicle: Vehicle
    terrain: Terrain
    speed: np.ndarray  # (P,) V >= 0 [m/s]
    yaw: np.ndarray  # (P,) signed yaw rate [rad/s]; straight points carry STRAIGHT_YAW (see residual)
    loads: np.ndarray  # (P, 2) left, right [N]
    contact: Contact
    radius: float  # drive radius r [m]
    half_tread: float  # B / 2 [m]
    lateral_scale: np.ndarray  # (P,) 1, or 1 / STRAIGHT_YAW [s] for straight points
    # the slip path (rigid_contact) for the shear displacement: on rigid ground everywhere, on soil
    # past half a revolution of an element (pivot_blend; the pivot band); else eq. 6.6's chord
    path_law: bool = False

    def take(self, idx: np.ndarray) -> Problem:
        """The sub-problem of the operating points ``idx``."""
        return Problem(
            self.vehicle,
            self.terrain,
            self.speed[idx],
            self.yaw[idx],
            self.loads[idx],
            self.contact.take(idx),
            self.radius,
            self.half_tread,
            self.lateral_scale[idx],
            self.path_law,
        )

    # fixed per batch and read on every residual call: computed once (cached_property)
    @cached_property
    def turn_radius(self) -> np.ndarray:
        """(P,) signed R = V / w_z [m] (0 when spinning in place)."""
        radius: np.ndarray = self.speed / self.yaw
        return radius

    @cached_property
    def side_speed(self) -> np.ndarray:
        """(P, 2) ground speed of each side's centreline along x, V - w_z y_side [m/s]."""
        ground_speed: np.ndarray = self.speed[:, None] - self.yaw[:, None] * SIDE_Y_SIGN * self.half_tread
        return ground_speed

    @cached_property
    def rolling(self) -> np.ndarray:
        """(P, 2) compaction resistance of each side, signed against its motion over the ground [N]."""
        resistance: np.ndarray = self.contact.resistance * rolling_direction(self)
        return resistance

    @cached_property
    def side_y(self) -> np.ndarray:
        """(2,) lateral position of each side's centreline, +B/2 (left), -B/2 (right) [m]."""
        return SIDE_Y_SIGN * self.half_tread

    @cached_property
    def centre_offset(self) -> np.ndarray:
        """(P, 1, 2, 1, 1) lateral distance of each side's centreline from the turning centre O = (0, R)
        [m]; R = V / w_z is finite because straight points run at STRAIGHT_YAW, 0 spinning in place."""
        radius = self.turn_radius[:, None, None, None, None]
        offset: np.ndarray = self.side_y[None, None, :, None, None] - radius
        return offset

    @cached_property
    def half_turn_rate(self) -> np.ndarray:
        """(P, 1, 2|1, G, N) w_z xi / 2 [m rad/s]: divided by the rim speed |omega| r it is half the
        angle an element has turned since it touched down (eqs. 6.3, 6.5)."""
        rate: np.ndarray = (0.5 * self.yaw[:, None, None, None] * self.contact.xi)[:, None]
        return rate

    @cached_property
    def element_x(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each element's x now and at touch-down from the CG [m], forward (omega >= 0) and mirrored:
        (centre + fwd, centre - fwd, centre + entry, centre - entry), each (P|1, 1, 2|1, G, N|1).
        :func:`element_displacement` picks per side (the same sums, built once per batch)."""
        c = self.contact
        fwd, entry = c.fwd[:, None], c.entry[:, None]
        return c.centre + fwd, c.centre + -1.0 * fwd, c.centre + entry, c.centre + -1.0 * entry

    @cached_property
    def centrifugal_terms(self) -> tuple[np.ndarray, ...]:
        """(P, 1) V, w_z, |V|, |w_z| and -m |V w_z|, -m V w_z [N]: the parts of eq. 3.18 that do not
        depend on the trial state (:func:`centrifugal`)."""
        v, w = self.speed[:, None], self.yaw[:, None]
        mass = self.vehicle.mass_kg
        return v, w, np.abs(v), np.abs(w), -mass * np.abs(v * w), -mass * v * w

    @cached_property
    def omega_ref(self) -> np.ndarray:
        """(P,) reference wheel speed [rad/s]: the faster side's no-slip speed, at least 1 mm/s / r
        (scales the Newton steps and their trust region)."""
        reference: np.ndarray = np.maximum(np.max(np.abs(self.side_speed), axis=1), 1e-3) / self.radius
        return reference


# The pivot band's shear law on soil (``FessSolver(path_law=True)``, docs/PREDICTION.md "The pivot
# band"): an element keeps eq. 6.6's chord until it has turned half a revolution since touch-down
# (eq. 6.3: w_z t = pi, where the chord is longest), then its displacement blends linearly into its
# slip path (rigid_contact.slip_path_displacement) over the next PIVOT_BLEND_REV of a revolution.
PIVOT_BLEND_REV = 0.125


PIVOT_REST_SPEED_M_S = 1e-3


def rolling_direction(problem: Problem) -> np.ndarray:
    """(P, 2) the compaction (on rigid ground: rolling) resistance's direction factor per side [-]:
    sign(v_side) (against the motion over the ground); in the pivot law (on soil the fallback, on
    rigid ground always) clip(v_side / PIVOT_REST_SPEED_M_S, -1, 1), because a side at rest over the
    ground (a pivot's inner side, its ground speed crossing 0) holds any resistance in [-R, R], as
    static friction does, and the sign's jump left a gap of set points without a root
    (docs/PREDICTION.md, "The pivot band"; on rigid ground husky_a200 on grass, inner / outer set
    point -0.25 to -0.15, was "dug in" between two steady states)."""
    v = problem.side_speed
    if problem.path_law:
        ramp: np.ndarray = np.clip(v / PIVOT_REST_SPEED_M_S, -1.0, 1.0)
        return ramp
    direction: np.ndarray = np.sign(v)
    return direction


def pivot_blend(half: np.ndarray) -> np.ndarray:
    """The slip path's weight in an element's shear displacement (0: eq. 6.6's chord, 1: the slip
    path), from ``half`` = w_z t / 2 [rad], half the angle it turned since touch-down (eq. 6.3):
    0 up to half a revolution, 1 from 0.5 + PIVOT_BLEND_REV rev on."""
    weight: np.ndarray = np.clip((np.abs(half) - 0.5 * np.pi) / (np.pi * PIVOT_BLEND_REV), 0.0, 1.0)
    return weight


def build_problem(
    vehicle: Vehicle, terrain: Terrain, n: int, path_law: bool, speed: np.ndarray, yaw: np.ndarray
) -> Problem:
    """The batch of P operating points (V >= 0 [m/s], signed w_z [rad/s], shapes (P,)) with ``n``
    elements per contact: the side loads of eq. 6.12 (m V^2/R = m V |w_z|), the contacts, and the
    straight points' STRAIGHT_YAW (see :func:`~skidsteer_power.models.fess.residual_and_forces`).
    ``path_law``: the slip-path shear law (:class:`Problem`)."""
    inf = np.full_like(speed, np.inf)  # no turning radius: the loads need only V and |w_z|
    outer, inner = side_loads(vehicle, OperatingPoints(speed, inf, inf, np.abs(yaw), speed.shape))
    pair = np.stack((inner, outer), axis=1)  # (P, 2) left, right of a left turn (w_z >= 0)
    loads = np.where((yaw < 0)[:, None], pair[:, ::-1], pair)  # eq. 6.12: the outer side is heavier
    if terrain.is_rigid:
        contact = rigid_contact(vehicle, terrain, loads, n)
    else:
        contact = (track_contact if vehicle.is_tracked else wheel_contact)(vehicle, terrain, loads, n)
    straight = yaw == 0
    kin_yaw = np.where(straight, STRAIGHT_YAW, yaw)
    scale = np.where(straight, 1.0 / STRAIGHT_YAW, 1.0)
    return Problem(
        vehicle,
        terrain,
        speed,
        kin_yaw,
        loads,
        contact,
        vehicle.drive_radius_m,
        0.5 * vehicle.tread_m,
        scale,
        path_law,
    )


def chord_displacement(
    travel: np.ndarray, xe: np.ndarray, dy: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Shear displacement of eq. 6.6 [m], (jx, jy) along the vehicle's current x and y axes:
    J = p_k - Rot(-theta) p_e with p = (x, dy), for elements whose x moved by ``travel`` = x_k - x_e
    since touch-down, touched down at ``xe`` (relative to the turning centre), at lateral distance
    ``dy`` from the turning centre, having turned by theta = 2 ``half`` [rad] since (eq. 6.3). The
    text's phi is the yaw rate (module doc of fess.py). 1 - cos is written as 2 sin^2 (no
    cancellation). Arrays broadcast."""
    sh = np.sin(half)
    twice_sh = 2.0 * sh
    sin = twice_sh * np.cos(half)
    one_minus_cos = twice_sh * sh
    jx = travel + one_minus_cos * xe - dy * sin
    jy = dy * one_minus_cos + xe * sin
    return jx, jy


def centrifugal(terms: tuple[Real, ...], s0: Real) -> tuple[Real, Real]:
    """Centrifugal force components (x, y) on the CG [N], eq. 3.18: m V^2/R (-sin beta, -cos beta),
    beta = atan(s0 / R), from ``terms`` = (V, w_z, |V|, |w_z|, -m |V w_z|, -m V w_z) (floats or
    arrays, :attr:`Problem.centrifugal_terms`) at offset s0 [m]."""
    v, w, abs_v, abs_w, force_x, force_y = terms
    q = hypot(v, w * s0)
    safe = where(q > 0, q, 1.0)  # at q = 0 (V = 0) both forces vanish whatever beta
    return force_x * (s0 * abs_w / safe), force_y * (abs_v / safe)


def steeds_s0(speed: Real, abs_yaw: Real, length: float) -> Real:
    """Steeds' s0 = V |w_z| l / (2 mu g) (eq. 3.7, mu = GUESS_FRICTION standing in for mu_t) [m], at
    most a quarter of the contact span l [m]: the first guess of every FESS solve."""
    return minimum(speed * abs_yaw * length * STEEDS_S0_SCALE, 0.25 * length)


def slip_ratio(side_speed: Real, rim_speed: Real) -> Real:
    """Slip of eq. 2.13 [-] for either direction of travel (computed in the side's own direction),
    from each side's ground speed and rim speed omega r [m/s] (floats or arrays); in [-1, 1], NaN
    for a NaN rim speed. Driving (rim >= v): (rim - v) / rim, 0 at rim = 0; braking: (rim - v) / v,
    -1 for a side that stands on the ground while its rim turns backwards."""
    d = where(side_speed < 0, -1.0, 1.0)
    v, rim = side_speed * d, rim_speed * d
    driving, braking = rim >= v, rim < v  # both False for a NaN rim speed
    den = where(driving, where(rim != 0, rim, 1.0), where(v != 0, v, 1.0))
    ratio: Real = (rim - v) / den
    # the cast: mypy binds Real to the 0.0 (float) in both instantiations; the array one needs it
    s = cast(Real, where(driving & (rim == 0), 0.0, where(braking & (v == 0), -1.0, ratio)))  # type: ignore[redundant-cast]
    return minimum(maximum(s, -1.0), 1.0)
