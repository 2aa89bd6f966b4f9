"""Power and energy of a vehicle driving a route (ch. 8.1, 8.2).

Every segment is a steady state (V, R, payload): the skid-steer model gives each side's axle torque
and speed, the powertrain adds its internal resistance (eqs. 7.1-7.4) and turns it into motor,
amplifier and battery power. The unique states of a route are solved in one batched model call per
payload state (``source='direct'``), or read from the vehicle's FESS power map (``source='map'``,
the default, see :mod:`skidsteer_power.maps`), so a route of hundreds of segments costs little.

Energies (SI, J) follow the dissertation's split (Figures 8.5, 8.11):
    terrain  = sum over sides of  T_axle w_axle  x time   (vehicle-terrain interaction)
    internal = sum over sides of  T_int w_motor  x time   (eqs. 7.2-7.4, >= 0)
    total    = terrain + internal                          (the "power consumption" of ch. 7-8)
and, beyond the dissertation, the battery energy: the amplifiers' DC bus power (motor copper loss,
amplifier efficiency, regeneration at an efficiency; see powertrain.motor) x time.
Energies are exact sums of constant segment powers times durations, so they equal the time integral
of the piecewise-constant power trace.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from skidsteer_power.commands import Segment
from skidsteer_power.drive import DriveController, controller_for_vehicle
from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.missions.mobility import max_drawbar_pull
from skidsteer_power.missions.routes import Route
from skidsteer_power.numeric import distinct_rows
from skidsteer_power.powertrain import Powertrain
from skidsteer_power.powertrain.power_flow import SIDES
from skidsteer_power.seams import ArrayPowerMapLike, PowertrainLike

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject
    from skidsteer_power.terramechanics.terrain import Terrain
    from skidsteer_power.vehicle import Vehicle


@dataclass
class MissionResult:
    """Per-segment powers [W] and the mission's energies [J] and mobility.

    Per-segment arrays (one entry per route segment): ``power_W`` (terrain + internal),
    ``power_terrain_W``, ``power_internal_W``, ``power_battery_W`` (DC bus), ``sinkage_m``,
    ``traction_margin``, ``power_left_W``, ``power_right_W`` (mechanical, per side), and the map's
    flags (:class:`~skidsteer_power.maps.MapQuery`): ``clamped`` (the command lies outside the map's
    envelope) and ``limited`` (a physics limit: a turn tighter than the map's limit radius, or a cell
    at the traction limit or failing the map's accuracy check). A direct solve flags neither.
    ``slowed``: the drive controller could not carry out the segment's twist, so the robot drove its
    path slower (:func:`driven_route`; ``route`` is the route as driven).
    """

    route: Route
    vehicle_name: str
    terrain_name: str
    model: str
    power_W: np.ndarray
    power_terrain_W: np.ndarray
    power_internal_W: np.ndarray
    power_battery_W: np.ndarray
    power_left_W: np.ndarray
    power_right_W: np.ndarray
    sinkage_m: np.ndarray
    traction_margin: np.ndarray
    clamped: np.ndarray
    limited: np.ndarray
    drawbar_pull_by_payload: dict[float, float] = field(default_factory=dict)
    weight_by_payload: dict[float, float] = field(default_factory=dict)
    setpoint_rad_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    drive_radius_m: float = math.nan
    tread_m: float = math.nan
    slowed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def commands(self) -> list[dict[str, float]]:
        """Per route segment, the wheel speed set points that produce its (V, R) (each side's axle
        speed in FESS's steady state of that motion: the amplifiers hold these, issue 25) and the
        command (V, yaw rate) the driver turns into them (des/kinematics.py, inverted)."""
        a = self.route.arrays()
        out = []
        for k, (left, right) in enumerate(self.setpoint_rad_s.tolist()):
            out.append(
                {
                    'speed_m_s': float(a['speed_m_s'][k]),
                    'turn_radius_m': float(a['turn_radius_m'][k]),
                    'setpoint_left_rad_s': left,
                    'setpoint_right_rad_s': right,
                    'speed_cmd_m_s': 0.5 * (left + right) * self.drive_radius_m,
                    'yaw_rate_cmd_rad_s': (right - left) * self.drive_radius_m / self.tread_m,
                }
            )
        return out

    @property
    def duration_s(self) -> np.ndarray:
        return self.route.arrays()['duration_s']

    @property
    def turning(self) -> np.ndarray:
        turning: np.ndarray = np.isfinite(self.route.arrays()['turn_radius_m'])
        return turning

    def _energy(self, power: np.ndarray, mask: np.ndarray | None = None) -> float:
        dt = self.duration_s
        return float(np.sum((power * dt)[mask] if mask is not None else power * dt))

    @property
    def energy_J(self) -> float:
        return self._energy(self.power_W)

    @property
    def energy_terrain_J(self) -> float:
        return self._energy(self.power_terrain_W)

    @property
    def energy_internal_J(self) -> float:
        return self._energy(self.power_internal_W)

    @property
    def energy_battery_J(self) -> float:
        return self._energy(self.power_battery_W)

    def mean_power(self, turning: bool) -> float:
        """Time-weighted mean total power [W] over the turning or the straight segments (nan if none)."""
        mask = self.turning if turning else ~self.turning
        time = float(np.sum(self.duration_s[mask]))
        return self._energy(self.power_W, mask) / time if time > 0 else math.nan

    @property
    def max_drawbar_pull_N(self) -> float:
        """The mobility-limiting (smallest) maximum drawbar pull over the route's payload states [N]."""
        return min(self.drawbar_pull_by_payload.values())

    @property
    def drawbar_pull_ratio(self) -> float:
        """Smallest maximum drawbar pull / weight over the payload states [-] (ch. 8.2's mobility index)."""
        return min(dp / self.weight_by_payload[p] for p, dp in self.drawbar_pull_by_payload.items())

    def legs(self) -> list[dict[str, float]]:
        """Per payload state: energy, max sinkage, max drawbar pull and its ratio to the weight."""
        payload = self.route.arrays()['payload_kg']
        out = []
        for p in sorted(self.drawbar_pull_by_payload):
            mask = payload == p
            out.append(
                {
                    'payload_kg': p,
                    'distance_m': float(np.sum(self.route.arrays()['length_m'][mask])),
                    'energy_J': self._energy(self.power_W, mask),
                    'max_sinkage_m': float(np.max(self.sinkage_m[mask])),
                    'max_drawbar_pull_N': self.drawbar_pull_by_payload[p],
                    'drawbar_pull_ratio': self.drawbar_pull_by_payload[p] / self.weight_by_payload[p],
                }
            )
        return out

    def summary(self) -> JsonObject:
        """The DESIGN.md ``mission --json`` keys, plus a few more (SI units)."""
        return {
            'energy_J': self.energy_J,
            'energy_internal_J': self.energy_internal_J,
            'energy_terrain_J': self.energy_terrain_J,
            'power_straight_W': self.mean_power(turning=False),
            'power_turning_W': self.mean_power(turning=True),
            'max_sinkage_m': float(np.max(self.sinkage_m)),
            'max_drawbar_pull_N': self.max_drawbar_pull_N,
            'drawbar_pull_ratio': self.drawbar_pull_ratio,
            'energy_battery_J': self.energy_battery_J,
            'clamped_segments': int(np.sum(self.clamped)),
            'limited_segments': int(np.sum(self.limited)),
            'slowed_segments': int(np.sum(self.slowed)),
            'internal_fraction': self.energy_internal_J / self.energy_J,
            'distance_m': self.route.length_m,
            'duration_s': self.route.duration_s,
            'turning_distance_m': self.route.turning_length_m,
            'route': self.route.name,
            'synthetic_route': self.route.synthetic,
            'vehicle': self.vehicle_name,
            'terrain': self.terrain_name,
            'model': self.model,
            'legs': self.legs(),
            'commands': self.commands(),
        }

    def trace(self, samples_per_segment: int = 2) -> dict[str, np.ndarray]:
        """Time, distance, power and cumulative energy along the route, for plots and checks.

        Each segment contributes its start and end (and optional interior) points at its constant
        power, so the trapezoidal integral of power over time reproduces the energy exactly.
        """
        dt = self.duration_s
        ds = self.route.arrays()['length_m']
        t0 = np.r_[0.0, np.cumsum(dt)[:-1]]
        s0 = np.r_[0.0, np.cumsum(ds)[:-1]]
        frac = np.linspace(0.0, 1.0, max(samples_per_segment, 2))
        t = (t0[:, None] + dt[:, None] * frac).ravel()
        s = (s0[:, None] + ds[:, None] * frac).ravel()
        out = {'time_s': t, 'distance_m': s}
        for name in ('power_W', 'power_terrain_W', 'power_internal_W', 'power_battery_W'):
            p = np.repeat(getattr(self, name), frac.size)
            out[name] = p
            e_seg = getattr(self, name) * dt
            e0 = np.r_[0.0, np.cumsum(e_seg)[:-1]]
            out[name.replace('power', 'energy').replace('_W', '_J')] = (
                e0[:, None] + e_seg[:, None] * frac
            ).ravel()
        return out


def with_payload(vehicle: Vehicle, payload_kg: float) -> Vehicle:
    """The vehicle carrying ``payload_kg`` [kg] more, at its CG (ch. 8.2: only the weight changes)."""
    if payload_kg == 0:
        return vehicle
    return dataclasses.replace(vehicle, mass_kg=vehicle.mass_kg + payload_kg)


SOURCES = ('map', 'direct')


def run_mission(
    vehicle: Vehicle,
    terrain: Terrain,
    route: Route,
    *,
    source: str = 'map',
    model: str = 'fess',
    powertrain: Powertrain | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    controller: DriveController | None = None,
) -> MissionResult:
    """Evaluate ``route`` for ``vehicle`` on ``terrain`` (see module doc), driven as the robot's drive
    ``controller`` (default: the vehicle file's) carries it out: :func:`driven_route`.

    ``source='map'`` (default) queries the FESS power map of the vehicle (one per payload state) from
    :mod:`skidsteer_power.maps`: built in memory, or loaded from / saved to ``cache_dir``. The map
    handles turns tighter than it can solve by its small-radius limit (see maps.power_map).
    ``source='direct'`` solves ``model`` at the route's unique states in one batched call per
    payload and raises ConvergenceError naming the first (V, R) it cannot solve.
    """
    if source not in SOURCES:
        raise InputError(f'source must be one of {", ".join(SOURCES)}, not {source!r}')
    if source == 'map' and model != 'fess':
        raise InputError(f"power maps are built with FESS; use source='direct' for model {model!r}")
    pt = powertrain or Powertrain.for_vehicle(vehicle)
    route, slowed = driven_route(route, controller or controller_for_vehicle(vehicle, pt), pt)
    a = route.arrays()
    n = len(route.segments)
    fields_ = {k: np.zeros(n) for k in ('P', 'Pt', 'Pi', 'Pb', 'Pl', 'Pr', 'z', 'tm', 'wl', 'wr')}
    clamped = np.zeros(n, dtype=bool)
    limited = np.zeros(n, dtype=bool)
    dp: dict[float, float] = {}
    weight: dict[float, float] = {}
    for payload in np.unique(a['payload_kg']):
        in_group = a['payload_kg'] == payload
        loaded = with_payload(vehicle, float(payload))
        states, inv = distinct_rows(np.column_stack([a['speed_m_s'], a['turn_radius_m']])[in_group])
        if source == 'map':
            axle = _map_states(loaded, terrain, states[:, 0], states[:, 1], cache_dir)
        else:
            axle = _axle_states(loaded, terrain, states[:, 0], states[:, 1], model)
        powers = state_powers(pt, axle)
        rows = np.flatnonzero(in_group)
        for key, name in (('Pl', 'left_W'), ('Pr', 'right_W'), ('P', 'mechanical_W')):
            fields_[key][rows] = powers[name][inv]
        for key, name in (('Pt', 'terrain_W'), ('Pi', 'internal_W'), ('Pb', 'battery_W')):
            fields_[key][rows] = powers[name][inv]
        fields_['wl'][rows] = axle['omega_left'][inv]  # the side speeds of the motion: its set points
        fields_['wr'][rows] = axle['omega_right'][inv]
        fields_['z'][rows] = axle['sinkage'][inv]
        fields_['tm'][rows] = axle['traction_margin'][inv]
        clamped[rows] = axle['clamped'][inv]
        limited[rows] = axle['limited'][inv]
        dp[float(payload)] = float(max_drawbar_pull([loaded], terrain)[0])
        weight[float(payload)] = float(loaded.weight_N)
    return MissionResult(
        route=route,
        vehicle_name=vehicle.name,
        terrain_name=getattr(terrain, 'name', str(terrain)),
        model=f'{model} ({source})',
        power_W=fields_['P'],
        power_terrain_W=fields_['Pt'],
        power_internal_W=fields_['Pi'],
        power_battery_W=fields_['Pb'],
        power_left_W=fields_['Pl'],
        power_right_W=fields_['Pr'],
        sinkage_m=fields_['z'],
        traction_margin=fields_['tm'],
        clamped=clamped,
        limited=limited,
        drawbar_pull_by_payload=dp,
        weight_by_payload=weight,
        setpoint_rad_s=np.column_stack([fields_['wl'], fields_['wr']]),
        drive_radius_m=float(vehicle.drive_radius_m),
        tread_m=float(vehicle.tread_m),
        slowed=slowed,
    )


def driven_route(
    route: Route, controller: DriveController, powertrain: Powertrain
) -> tuple[Route, np.ndarray]:
    """(``route`` as the robot drives it, slowed (n,) bool): a segment whose twist the drive
    ``controller`` cannot carry out (a velocity limit, the wheel speed ceiling or the motors' no-load
    speed, :func:`~skidsteer_power.models.predict.max_axle_speed`) is driven on the same path
    (curvature, length, turned angle) at the highest speed it can: V and yaw rate times
    :meth:`~skidsteer_power.drive.DriveController.path_scale` s < 1, the duration divided by s."""
    from skidsteer_power.models.predict import max_axle_speed

    speed = np.array([s.speed_m_s for s in route.segments])
    yaw_rate = np.array([s.yaw_rate_rad_s for s in route.segments])
    scale = controller.path_scale(speed, yaw_rate, ceiling_rad_s=max_axle_speed(powertrain))
    slowed = scale < 1.0
    if not np.any(slowed):
        return route, slowed
    driven = tuple(
        Segment(s.speed_m_s * k, s.yaw_rate_rad_s * k, s.duration_s / k, s.payload_kg) if k < 1.0 else s
        for s, k in zip(route.segments, scale.tolist(), strict=True)
    )
    return dataclasses.replace(route, segments=driven), slowed


def yaw_rate_of(speed: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Yaw rate V / R [rad/s] of forward speeds [m/s] on signed turn radii [m] (0 for R = inf)."""
    straight = np.isinf(radius)
    return np.where(straight, 0.0, speed / np.where(straight, 1.0, radius))


def _map_states(
    vehicle: Vehicle,
    terrain: Terrain,
    speed: np.ndarray,
    radius: np.ndarray,
    cache_dir: str | os.PathLike[str] | None,
) -> dict[str, np.ndarray]:
    from skidsteer_power.maps import PowerMap, load_or_build

    if cache_dir is None:
        power_map = PowerMap.build(vehicle, terrain)
    else:
        power_map, _built = load_or_build(vehicle, terrain, cache_dir)
    envelope = float(power_map.meta.get('max_speed_m_s', np.inf))
    if np.any(np.abs(speed) > envelope):
        raise InputError(
            f'speed {float(np.max(np.abs(speed))):g} m/s is beyond the power map of {vehicle.name} '
            f'(up to {envelope:g} m/s): it would be clamped; solve directly with --direct'
        )
    return map_axle_states(power_map, speed, radius)


def map_axle_states(
    power_map: ArrayPowerMapLike, speed: np.ndarray, radius: np.ndarray
) -> dict[str, np.ndarray]:
    """Per-side axle torque [N m] and speed [rad/s], sinkage [m], traction margin and the clamped and
    limited flags from a :class:`~skidsteer_power.maps.PowerMap` at forward speeds [m/s] and signed
    radii [m]."""
    q = power_map.query(speed, yaw_rate_of(speed, radius))
    return {
        'torque_left': np.asarray(q.torque_left_Nm, dtype=float),
        'torque_right': np.asarray(q.torque_right_Nm, dtype=float),
        'omega_left': np.asarray(q.omega_left_rad_s, dtype=float),
        'omega_right': np.asarray(q.omega_right_rad_s, dtype=float),
        'sinkage': np.asarray(q.sinkage_m, dtype=float),
        'traction_margin': np.asarray(q.traction_margin, dtype=float),
        'clamped': np.asarray(q.clamped, dtype=bool),
        'limited': np.asarray(q.limited, dtype=bool),
    }


def state_powers(powertrain: PowertrainLike, axle: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Powers [W] at each steady state from its per-side axle torque and speed (:func:`map_axle_states`).

    ``left_W``, ``right_W`` and ``mechanical_W`` (their sum): motor shaft T_m w_m = terrain +
    internal; ``terrain_W`` (T_a w_a), ``internal_W`` (eqs. 7.1-7.4), ``battery_W`` (DC bus, motor and
    amplifier losses included; see powertrain.motor). Shared by missions and the robot's path energy.
    """
    left, right = (powertrain.motor_side(s, axle[f'torque_{s}'], axle[f'omega_{s}']) for s in SIDES)
    return {
        'left_W': left.mechanical_power_W,
        'right_W': right.mechanical_power_W,
        'mechanical_W': left.mechanical_power_W + right.mechanical_power_W,
        'terrain_W': left.terrain_power_W + right.terrain_power_W,
        'internal_W': left.internal_power_W + right.internal_power_W,
        'battery_W': left.electrical_power_W + right.electrical_power_W,
    }


def route_energy_on_map(
    route: Route, power_map: ArrayPowerMapLike, powertrain: PowertrainLike
) -> dict[str, float]:
    """Energies [J] of driving ``route`` with the loads a ready ``power_map`` holds (the robot's own,
    no payload changes): the same state grouping, map query and powertrain as :func:`run_mission`.

    Returns energy_J (terrain + internal), energy_terrain_J, energy_internal_J, energy_battery_J and
    clamped_segments and limited_segments (segments whose map query was flagged so). See
    :func:`energy_on_map`.
    """
    a = route.arrays()
    return energy_on_map(a['speed_m_s'], a['turn_radius_m'], a['duration_s'], power_map, powertrain)


def energy_on_map(
    speed_m_s: np.ndarray,
    turn_radius_m: np.ndarray,
    duration_s: np.ndarray,
    power_map: ArrayPowerMapLike,
    powertrain: PowertrainLike,
    terrain_scale: float = 1.0,
) -> dict[str, float]:
    """:func:`route_energy_on_map` of segments given as arrays: forward speed [m/s], signed turn radius
    [m] (inf: straight) and duration [s] each. ``terrain_scale`` [-] multiplies the map's axle torques
    before the powertrain (the estimator's online terrain correction; 1: the map as built)."""
    return MapLoads.of(speed_m_s, turn_radius_m, duration_s, power_map).energy(powertrain, terrain_scale)


@dataclass(frozen=True)
class MapLoads:
    """What a map says about a set of segments, ready for any powertrain and terrain scale: the axle
    states (:func:`map_axle_states`) at their distinct (V, R) states, the time spent in each
    (``seconds`` [s]) and the segments the map flagged clamped or limited. The robot's path energy
    keeps these while only the online terrain scale moves (estimator/path_energy.py)."""

    axle: dict[str, np.ndarray]
    seconds: np.ndarray
    clamped_segments: int
    limited_segments: int

    @classmethod
    def of(
        cls,
        speed_m_s: np.ndarray,
        turn_radius_m: np.ndarray,
        duration_s: np.ndarray,
        power_map: ArrayPowerMapLike,
    ) -> MapLoads:
        """Segments as arrays: forward speed [m/s], signed turn radius [m] (inf: straight), duration [s]."""
        states, inverse = distinct_rows(np.column_stack([speed_m_s, turn_radius_m]).astype(float))
        axle = map_axle_states(power_map, states[:, 0], states[:, 1])
        return cls(
            axle,
            np.bincount(inverse, weights=duration_s, minlength=len(states)),
            int(np.sum(axle['clamped'][inverse])),
            int(np.sum(axle['limited'][inverse])),
        )

    def energy(self, powertrain: PowertrainLike, terrain_scale: float = 1.0) -> dict[str, float]:
        """Energies [J] (:func:`route_energy_on_map`) with the axle torques times ``terrain_scale`` [-]."""
        axle = self.axle
        if terrain_scale != 1.0:
            scaled = {f'torque_{s}': axle[f'torque_{s}'] * terrain_scale for s in SIDES}
            axle = {**axle, **scaled}
        powers = state_powers(powertrain, axle)
        return {
            'energy_J': float(np.dot(powers['mechanical_W'], self.seconds)),
            'energy_terrain_J': float(np.dot(powers['terrain_W'], self.seconds)),
            'energy_internal_J': float(np.dot(powers['internal_W'], self.seconds)),
            'energy_battery_J': float(np.dot(powers['battery_W'], self.seconds)),
            'clamped_segments': self.clamped_segments,
            'limited_segments': self.limited_segments,
        }


def _axle_states(
    vehicle: Vehicle, terrain: Terrain, speed: np.ndarray, radius: np.ndarray, model: str
) -> dict[str, np.ndarray]:
    """Per-side axle torque [N m] and speed [rad/s], sinkage [m] and traction margin at (V, R)."""
    from skidsteer_power.models import solve

    state = solve(vehicle, terrain, speed, radius, model=model, raise_on_failure=False)
    converged = np.asarray(state.converged, dtype=bool)
    if not np.all(converged):
        k = int(np.flatnonzero(~converged)[0])
        raise ConvergenceError(
            f'{model} did not converge for {vehicle.name} ({vehicle.mass_kg:g} kg) at V = {speed[k]:g} m/s, '
            f'R = {radius[k]:g} m ({int(np.sum(~converged))} of {converged.size} route states failed); '
            'the map source handles tight turns'
        )
    return {
        'torque_left': state.side('torque', 'left'),
        'torque_right': state.side('torque', 'right'),
        'omega_left': state.side('omega', 'left'),
        'omega_right': state.side('omega', 'right'),
        'sinkage': np.asarray(state.sinkage_m, dtype=float),
        'traction_margin': np.asarray(state.traction_margin, dtype=float),
        'clamped': np.zeros(speed.shape, dtype=bool),
        'limited': np.zeros(speed.shape, dtype=bool),
    }
