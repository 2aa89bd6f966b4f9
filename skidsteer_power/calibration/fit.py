"""Fit terrain (and drivetrain) parameters to steady segments of the user's own recordings.

The model of a segment is what the estimator predicts for it (``fit_at``, :data:`FIT_AT`):

* ``cmd`` (default, issue 27; ``setpoints`` before, still accepted): FESS driven by the wheel speed
  set points of the segment's COMMAND (:class:`~skidsteer_power.models.predict.CommandPredictor`,
  issue 25: the driver's kinematics, the body motion FESS finds for them, the amplifiers' current
  limit), as power_estimator and ``validate --kinematics cmd`` predict. Fitting what the node
  predicts is what makes calibrating improve the prediction from the command: a terrain fitted at
  the measured motion can make it worse (on the twin's wheeled robot FESS turns far more at the set
  points than the robot does, so the terrain that matches the torques at the measured motion
  over-predicts them from the command);
* ``motion``: FESS solved directly at the segment's measured forward speed V [m/s] and yaw rate
  [rad/s] (the terrain as a terramechanics description of the ground; needs a pose topic).

All segments are solved in one batched Newton solve per parameter vector (no map is rebuilt), followed
by the powertrain (eqs. 7.1-7.4: axle torque / G + internal resistance at the motor shaft). Residuals
are predicted minus measured motor torque K_t i [N m], both sides of every fit segment, and with
``fit_to`` 'motion' / 'both' predicted minus measured body motion (V, yaw rate) at the set points: the
ground's slip behaviour, learned from odometry or a gyro without any motor torque.

:func:`calibrate` is a sequence of named steps (as pvlib's ``fit_desoto_sandia``):
:func:`prepare` -> :func:`screen` -> :func:`optimize_z` -> :func:`uncertainty` (and a refit without
the parameters whose interval leaves their range) -> :func:`assess` -> :class:`CalibrationResult`.

Method
------
* Parameters are searched in bounded, equally scaled coordinates z in [0, 1]: z = (u - u_lo) /
  (u_hi - u_lo) with u = ln(value) for the strictly positive moduli (kphi, kc, c, K) and u = value
  for n, phi [deg] and the internal-resistance coefficients; [lo, hi] is the parameter's physical
  range (:data:`PARAMS`). Every map back clips z to [0, 1] first, so no trial, difference quotient or
  interval can overflow (``exp`` of at most ln(hi)). ``scipy.optimize.least_squares`` (trust-region
  reflective) with the box [0, 1], ``soft_l1`` loss (a robust loss: a segment spoiled by a stall or a
  bump cannot dominate) and forward differences of 0.2 % in z.
* Residuals (:class:`FitData`): predicted minus measured motor torque over its noise scale
  (:data:`TORQUE_SCALE_SHARE` of the RMS measured torque), and with ``fit_to`` 'motion' or 'both'
  predicted minus measured forward speed and yaw rate over :data:`SPEED_SCALE_M_S`,
  :data:`YAW_SCALE_RAD_S` (ASSUMED noise scales of steady-window means). A segment without a torque
  (no effort recorded) or without a measured motion contributes only what it has.
* Identifiability: before fitting, the change of the prediction under a 10 % change (for a linear
  parameter at least 1 % of its range) of every candidate (kc always included, so the report shows
  it) is computed at the start, and the parameters are ranked by orthogonalization
  (:func:`select_identifiable`): a parameter whose change, after removing what the parameters ranked
  above it can explain, moves the scaled residuals by less than ``ident_tol`` (RMS) cannot be seen in
  the data: it is reported as non-identifiable and kept fixed at its starting value. For small robots
  this is k_c: it enters only through kc / b + kphi (eq. 2.1) with b ~ 0.1 m, so it matters ~1 % as
  much as kphi. For a track, kphi and n act only through the compaction resistance (eq. 2.10), one
  number per load, so only one of them is identifiable; the other is fixed.
* Uncertainty: covariance of z = s^2 (J^T J)^-1 at the optimum (J the Jacobian of the scaled
  residuals, s^2 = sum r^2 / (m - p)); 95 % intervals z +- t(0.975, m - p) sigma_z mapped back to the
  parameter (asymmetric for log parameters); covariance in the parameter's own units by the delta
  method; the correlation matrix; a warning for every pair with |rho| > 0.95.
* Honesty: a fitted parameter whose 95 % interval leaves its physical range (z outside [0, 1]) is
  "not identifiable" (the data do not fix it): the one with the widest interval is put back at its
  start value and the others are fitted again without it, until every interval stays in its range.
  A parameter that ends at a bound is "at_bound" (no estimate, no interval).
  When the fitted values predict the hold-out segments worse than the start (a scaled residual RMS
  grown by more than :data:`COST_WORSE`, or, where power is measured, an |energy error| grown by more
  than :data:`ENERGY_WORSE`), the start is kept and the result says why.
* ``fit='auto'`` (:func:`auto_fit_names`): the ground's parameters of the terrain's kind, and the
  internal resistance where the recordings carry a torque; the screen above then keeps what the data
  see; ``left_fixed`` names every candidate left at its start and why.
* Validation: the segments are split into fit and hold-out sets by segment (never by sample, so the
  hold-out is not a neighbour of a fitted sample); the hold-out torque RMSE and energy error are
  reported before (starting terrain) and after (fitted).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy import optimize, stats

from skidsteer_power.calibration.segments import SteadyWindow
from skidsteer_power.drive import DriveIdentification
from skidsteer_power.drive.prediction_modes import CMD, FIT_AT, prediction_mode
from skidsteer_power.errors import ConfigError, ConvergenceError, InputError
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.powertrain.internal import Resistance, SideResistance
from skidsteer_power.powertrain.motor import MotorConstants, terminal_power
from skidsteer_power.powertrain.power_flow import Powertrain
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import Vehicle

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

RHO_WARN = 0.95
SOLVE_TOL_N = 1e-6  # FESS equilibrium tolerance during the fit [N, N m]
DIFF_STEP = 2e-3  # forward-difference step in z (relative, scipy's diff_step)
FAILED_RESIDUAL_NM = 1.0  # residual given to a segment where FESS has no steady state [N m]
TORQUE_SCALE_SHARE = 0.05  # noise scale of a segment's mean torque: share of the RMS measured [-]
SPEED_SCALE_M_S = 0.02  # noise scale of a steady window's mean forward speed [m/s] (ASSUMED)
YAW_SCALE_RAD_S = 0.02  # noise scale of a steady window's mean yaw rate [rad/s] (ASSUMED)
ENERGY_WORSE = 0.01  # a hold-out |energy error| grown by more than this is worse [-] (1 point)
COST_WORSE = 0.01  # a hold-out scaled residual RMS grown by more than this share is worse [-]
IDENT_TOL = 0.04  # a 10 % change moving the scaled residuals by less (RMS) is invisible [-]
FIT_TO = ('torque', 'motion', 'both')  # what the residuals compare (module doc)


@dataclass(frozen=True)
class FitParameter:
    """A fittable parameter: ``field`` of Terrain (or an internal coefficient), unit, log search,
    bounds in the parameter's own (reported) unit, and the factor from that unit to SI."""

    unit: str
    log: bool
    bounds: tuple[float, float]
    to_si: float = 1.0


TERRAIN_PARAMS: dict[str, FitParameter] = {
    'kphi': FitParameter('N/m^(n+2)', True, (1e3, 1e9)),
    'kc': FitParameter('N/m^(n+1)', True, (1.0, 1e7)),
    'n': FitParameter('-', False, (0.2, 2.0)),
    'c': FitParameter('Pa', True, (1.0, 5e4)),
    'phi': FitParameter('deg', False, (5.0, 50.0), math.pi / 180.0),
    'K': FitParameter('m', True, (1e-4, 0.2)),
    # rigid ground (contact: rigid; ranges.py RIGID_FIELD_RANGES); mu_longitudinal is tan(phi)
    'mu_longitudinal': FitParameter('-', False, (0.02, 2.0)),
    'mu_lateral': FitParameter('-', False, (0.02, 2.0)),
    'rolling_resistance': FitParameter('-', False, (0.0, 0.5)),
}
SOIL_PARAMS = ('kphi', 'kc', 'n', 'c', 'phi', 'K')
RIGID_PARAMS = ('mu_longitudinal', 'mu_lateral', 'rolling_resistance', 'K')
INTERNAL_PARAMS: dict[str, FitParameter] = {
    # at the motor shaft, or at the axle for an effective powertrain (gear ratio 1): the ranges hold
    # both (a 56 kg Husky's effective axle Coulomb loss is ~15 N m, issue 35)
    'left_b': FitParameter('N m s/rad', False, (0.0, 2.0)),
    'left_c': FitParameter('N m', False, (0.0, 50.0)),
    'right_b': FitParameter('N m s/rad', False, (0.0, 2.0)),
    'right_c': FitParameter('N m', False, (0.0, 50.0)),
}
TIED_INTERNAL_PARAMS: dict[str, FitParameter] = {
    # one b, c for both sides: what a whole-robot battery total (measured_power: total) can see; the
    # sides' sum is all it measures, so per-side terms would be collinear
    'sides_b': INTERNAL_PARAMS['left_b'],
    'sides_c': INTERNAL_PARAMS['left_c'],
}
BATTERY_PARAMS: dict[str, FitParameter] = {  # terms only a battery-side (V x I) measurement sees
    'idle_power_W': FitParameter('W', False, (0.0, 1000.0)),  # the drive electronics, both sides
    # copper loss k_cu T_m^2 = R i^2 (Powertrain.copper_loss_W_per_Nm2); log: it spans decades between
    # a motor's shaft (the Husky's ASSUMED 167) and an effective powertrain's axle (~0.1)
    'copper_loss_W_per_Nm2': FitParameter('W/(N m)^2', True, (1e-4, 1e4)),
}
EFFICIENCY_PARAMS: dict[str, FitParameter] = {
    # the amplifier's (the drive's) efficiency, bus power = terminal power / eta when motoring: scales
    # every motoring watt, so the steady windows cannot tell it from the loss terms; only the
    # reconciliation with every sample fits it (reconcile.py). 0.3: a drive losing more is broken
    'amplifier_efficiency': FitParameter('-', False, (0.3, 1.0)),
}
PARAMS = {**TERRAIN_PARAMS, **INTERNAL_PARAMS, **TIED_INTERNAL_PARAMS, **BATTERY_PARAMS, **EFFICIENCY_PARAMS}
DEFAULT_FIT = ('kphi', 'n', 'c', 'phi', 'K')


def parse_fit_list(text: str) -> list[str]:
    """Comma-separated names; ``internal`` expands to the four per-side b, c; ``auto`` alone is
    returned as ``['auto']`` (:func:`auto_fit_names` resolves it). InputError if unknown."""
    if text.strip() == 'auto':
        return ['auto']
    names: list[str] = []
    for raw in text.split(','):
        name = raw.strip()
        if not name:
            continue
        expanded = (
            list(INTERNAL_PARAMS)
            if name == 'internal'
            else ['idle_power_W']
            if name == 'idle'
            else ['copper_loss_W_per_Nm2']
            if name == 'copper'
            else [name]
        )
        for item in expanded:
            if item not in PARAMS:
                known = ', '.join([*TERRAIN_PARAMS, 'internal', 'idle', 'copper', 'auto'])
                raise InputError(f'--fit: unknown parameter {name!r} (known: {known})')
            if item not in names:
                names.append(item)
    if not names:
        raise InputError('--fit: no parameter named')
    return names


def terrain_params(terrain: Terrain) -> tuple[str, ...]:
    """The fittable parameters of ``terrain``'s kind: Bekker / Mohr-Coulomb / Janosi for a soil;
    friction coefficients, rolling resistance and K for rigid ground."""
    return RIGID_PARAMS if terrain.is_rigid else SOIL_PARAMS


def auto_fit_names(
    segments: Sequence[SteadyWindow], terrain: Terrain | None = None
) -> tuple[list[str], dict[str, str]]:
    """(candidates, {name: why left fixed}) of ``--fit auto`` for ``segments``: the ground's
    parameters (of ``terrain``'s kind) always; the internal resistance only where the segments carry
    a measured torque."""
    if terrain is not None and terrain.is_rigid:
        names, fixed = list(RIGID_PARAMS), {}
    else:
        names = list(DEFAULT_FIT)
        fixed = {'kc': 'enters only as kc / b beside kphi (eq. 2.1): rarely visible, left at its start'}
    torque = any(math.isfinite(sum(s.motor_torque_Nm)) for s in segments)
    power = any(math.isfinite(sum(s.battery_W)) for s in segments)
    per_side = torque or any(math.isfinite(sum(s.battery_W)) and not s.battery_total for s in segments)
    if per_side:
        names += list(INTERNAL_PARAMS)
    elif power:  # only a whole-robot total: one b, c for both sides
        names += list(TIED_INTERNAL_PARAMS)
        tied = 'a whole-robot battery total: one b, c for both sides (sides_b, sides_c)'
        fixed.update(dict.fromkeys(INTERNAL_PARAMS, tied))
    else:
        fixed.update({n: 'no measured torque, current or power in the recordings' for n in INTERNAL_PARAMS})
    if power:
        names += list(BATTERY_PARAMS)
    else:
        fixed.update(
            {
                n: 'no battery-side power (V x I) in the recordings: the motor current cannot see it'
                for n in BATTERY_PARAMS
            }
        )
    return names, fixed


@dataclass(frozen=True)
class Evaluation:
    """One parameter vector's predictions of every segment (S segments): motor torque (S, 2) [N m],
    motor speed (S, 2) [rad/s], solved (S,), body speed (S,) [m/s], yaw rate (S,) [rad/s] and
    battery-side electrical power per side (S, 2) [W]."""

    torque: np.ndarray
    omega: np.ndarray
    ok: np.ndarray
    speed: np.ndarray
    yaw: np.ndarray
    power: np.ndarray


@dataclass
class Model:
    """Predicted motor torque, speed and body motion of every segment for a set of parameter values."""

    vehicle: Vehicle
    terrain: Terrain
    powertrain: Powertrain
    speed: np.ndarray  # (S,) [m/s]: the measured motion, or the command with fit_at 'cmd'
    yaw: np.ndarray  # (S,) [rad/s]
    fit_at: str = 'motion'
    _warm: np.ndarray | None = field(default=None, init=False)

    def start_value(self, name: str) -> float:
        """Value of ``name`` in the starting terrain / powertrain, in the parameter's unit."""
        if name in TERRAIN_PARAMS:  # (mu_longitudinal: Terrain's property tan(phi))
            return float(getattr(self.terrain, name)) / TERRAIN_PARAMS[name].to_si
        if name == 'copper_loss_W_per_Nm2':  # a neutral 0 starts at the range's floor (0.04 W at 20 N m)
            return max(self.powertrain.copper_loss_W_per_Nm2, BATTERY_PARAMS[name].bounds[0])
        if name in BATTERY_PARAMS:
            return float(getattr(self.powertrain, name, 0.0))
        if name == 'amplifier_efficiency':
            return float(self.powertrain.amplifier.efficiency)
        side, kind = name.split('_')
        sides = ('left', 'right') if side == 'sides' else (side,)
        totals = [self.powertrain.resistance(s).total for s in sides]
        return float(np.mean([t.viscous_Nm_s if kind == 'b' else t.coulomb_Nm for t in totals]))

    def with_values(self, values: dict[str, float]) -> tuple[Terrain, Powertrain]:
        """(terrain, powertrain) with ``values`` (parameter units) substituted."""
        # the keys are Terrain's float fields named in TERRAIN_PARAMS
        terrain_fields: dict[str, float] = {
            k: v * TERRAIN_PARAMS[k].to_si for k, v in values.items() if k in TERRAIN_PARAMS
        }
        if 'mu_longitudinal' in terrain_fields:  # rigid ground stores it as phi = atan(mu)
            terrain_fields['phi'] = math.atan(terrain_fields.pop('mu_longitudinal'))
        terrain = self.terrain
        if terrain_fields:  # only float fields of Terrain: mypy sees every field's type in **kwargs
            terrain = dataclasses.replace(terrain, **terrain_fields)  # type: ignore[arg-type]
        powertrain = self.powertrain

        def side_with_values(side: str) -> SideResistance:
            b = values.get(f'{side}_b', values.get('sides_b'))
            c = values.get(f'{side}_c', values.get('sides_c'))
            current = powertrain.resistance(side)
            return current if b is None and c is None else scaled_side(current, b, c)

        left, right = side_with_values('left'), side_with_values('right')
        if left is not powertrain.left or right is not powertrain.right:
            powertrain = dataclasses.replace(powertrain, left=left, right=right)
        if 'idle_power_W' in values:
            powertrain = dataclasses.replace(powertrain, idle_power_W=values['idle_power_W'])
        if 'amplifier_efficiency' in values:
            amplifier = dataclasses.replace(powertrain.amplifier, efficiency=values['amplifier_efficiency'])
            powertrain = dataclasses.replace(powertrain, amplifier=amplifier)
        if 'copper_loss_W_per_Nm2' in values:  # k_cu = R / K_t^2: the motor's R carries it
            kt = powertrain.motor.torque_constant_Nm_A
            motor = dataclasses.replace(
                powertrain.motor, terminal_resistance_ohm=values['copper_loss_W_per_Nm2'] * kt**2
            )
            powertrain = dataclasses.replace(powertrain, motor=motor)
        return terrain, powertrain

    def predict(self, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(motor torque (S, 2) [N m], motor speed (S, 2) [rad/s], converged (S,)) for ``values``."""
        ev = self.evaluate(values)
        return ev.torque, ev.omega, ev.ok

    def evaluate(self, values: dict[str, float]) -> Evaluation:
        """Every prediction of the segments for ``values`` (an unsolvable trial: NaN, not solved)."""
        try:
            terrain, powertrain = self.with_values(values)
        except ConfigError:  # a trial outside the terrain's validity (e.g. rigid ground's K range)
            return self._failed()
        try:
            if self.fit_at == CMD:
                return self._predict_setpoints(terrain, powertrain)
            return self._predict_motion(terrain, powertrain)
        except ConvergenceError:  # a trial terrain where FESS's contact has no solution at all
            return self._failed()

    def _failed(self) -> Evaluation:
        nan = np.full((len(self.speed), 2), np.nan)
        none = np.full(len(self.speed), np.nan)
        return Evaluation(
            nan, nan.copy(), np.zeros(len(self.speed), dtype=bool), none, none.copy(), nan.copy()
        )

    def _predict_motion(self, terrain: Terrain, powertrain: Powertrain) -> Evaluation:
        """As :meth:`evaluate`, FESS solved at the measured motion (``speed``, ``yaw``)."""
        sol = FessSolver(self.vehicle, terrain).solve_twist(
            self.speed, self.yaw, x0=self._warm, tol=SOLVE_TOL_N
        )
        if np.all(sol.converged):
            self._warm = sol.state
        torque, omega, power = motor_points(powertrain, sol.torque, sol.omega)
        ok = np.asarray(sol.converged)
        return Evaluation(torque, omega, ok, self.speed.copy(), self.yaw.copy(), power)

    def _predict_setpoints(self, terrain: Terrain, powertrain: Powertrain) -> Evaluation:
        """As :meth:`evaluate` for commands (``speed``, ``yaw``) at their wheel speed set points, as
        :class:`CommandPredictor` predicts them (its dug-in answer where FESS has no steady state is
        the node's prediction too, so every segment counts as solved)."""
        from skidsteer_power.models.predict import CommandPredictor

        predictor = CommandPredictor(self.vehicle, terrain, powertrain)
        setpoints, _ = predictor.setpoints(self.speed, self.yaw)
        sol = predictor.solver.solve(setpoints, x0=self._warm, tol=SOLVE_TOL_N)
        self._warm = np.where(sol.limited[:, None], np.nan, sol.state)  # dug in: start from no slip
        axle_torque, *_ = predictor.electrical(sol.torque, setpoints)
        torque, omega, power = motor_points(powertrain, axle_torque, setpoints)
        ok = np.ones(len(torque), dtype=bool)
        return Evaluation(torque, omega, ok, np.asarray(sol.speed), np.asarray(sol.yaw_rate), power)


def motor_points(
    powertrain: Powertrain, axle_torque_Nm: np.ndarray, axle_omega_rad_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(motor torque, motor speed, battery-side power), each (S, 2) [N m, rad/s, W], of axle torques
    and speeds (S, 2) [N m, rad/s], left and right (:meth:`Powertrain.motor_side`)."""
    torque, omega = np.empty_like(axle_torque_Nm), np.empty_like(axle_torque_Nm)
    power = np.empty_like(axle_torque_Nm)
    for i, side in enumerate(('left', 'right')):
        point = powertrain.motor_side(side, axle_torque_Nm[:, i], axle_omega_rad_s[:, i])
        torque[:, i], omega[:, i] = point.motor_torque_Nm, point.motor_omega_rad_s
        power[:, i] = point.electrical_power_W
    return torque, omega, power


def scaled_side(side: SideResistance, b: float | None, c: float | None) -> SideResistance:
    """``side`` with total viscous ``b`` [N m s/rad] and Coulomb ``c`` [N m] (None: unchanged),
    spread over the components in their original proportions (eqs. 7.3, 7.4 keep their meaning)."""
    total = side.total
    parts = {}
    for name, part in side.components.items():
        pb = _share(part.viscous_Nm_s, total.viscous_Nm_s, b, len(side.components))
        pc = _share(part.coulomb_Nm, total.coulomb_Nm, c, len(side.components))
        parts[name] = Resistance(pb, pc)
    return SideResistance(parts)


def _share(part: float, total: float, new_total: float | None, count: int) -> float:
    if new_total is None:
        return part
    return new_total * (part / total if total > 0 else 1.0 / count)


@dataclass
class CalibrationResult:
    """Everything ``calibrate`` reports (see :meth:`as_json`) and writes."""

    names: list[str]  # fitted parameters, in order
    values: dict[str, float]  # every reported parameter (fitted and fixed), parameter units
    start: dict[str, float]
    ci95: dict[str, tuple[float, float] | None]
    sensitivity_Nm: dict[str, float]
    identifiable: dict[str, bool]
    covariance: np.ndarray  # (p, p) in parameter units
    correlation: np.ndarray
    correlations_warnings: list[str]
    segments_fit: int
    segments_holdout: int
    torque_rmse_before_Nm: float
    torque_rmse_after_Nm: float
    holdout_energy_error_before: float
    holdout_energy_error_after: float
    residual_rms_Nm: float
    seconds: float
    terrain: Terrain
    powertrain: Powertrain
    dropped: dict[str, int] = field(default_factory=dict)
    converged: bool = True
    measured_Nm: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (S, 2) per segment
    before_Nm: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # predicted at the start
    after_Nm: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # predicted when fitted
    holdout_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    at_bound: dict[str, str] = field(default_factory=dict)  # fitted name -> 'lower' | 'upper'
    jacobian_z: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # residual Jacobian in z
    z: np.ndarray = field(default_factory=lambda: np.zeros(0))  # fitted values in search coordinates
    residual_variance: float = math.nan  # s^2 of the scaled residuals [-]
    from_cmd: dict[str, float] = field(default_factory=dict)  # the fit predicting from each command
    fit_at: str = 'motion'
    fit_to: str = 'torque'
    not_identifiable: dict[str, str] = field(default_factory=dict)  # name -> why (interval, screen)
    left_fixed: dict[str, str] = field(default_factory=dict)  # candidate -> why it was not fitted
    kept_start: str = ''  # why the start was kept (empty: the fit was kept)
    motion: dict[str, float] = field(default_factory=dict)  # hold-out motion errors before / after
    drive: DriveIdentification | None = None  # the drive controller's limits (--fit auto), docs/DRIVE.md
    # battery-side terms fitted again to every sample of the drive (reconcile.py), parameter units
    reconciled: dict[str, float] = field(default_factory=dict)
    reconciliation: JsonObject = field(default_factory=dict)  # its report (Reconciliation.as_json)

    def status(self, name: str) -> str:
        """'fitted', 'fixed', 'fixed: not identifiable', 'not identifiable', 'at_bound (lower|upper)'
        'kept start' (the fit made the hold-out worse), 'fitted (every sample)' or 'at_bound (lower|upper),
        every sample' (reconcile.py)."""
        if name in self.reconciled:
            lo, hi = PARAMS[name].bounds
            value, edge = self.reconciled[name], 1e-6 * (hi - lo)
            side = 'lower' if value <= lo + edge else 'upper' if value >= hi - edge else ''
            return f'at_bound ({side}), every sample' if side else 'fitted (every sample)'
        if self.kept_start and name in self.names:
            return 'kept start'
        if name in self.at_bound:
            return f'at_bound ({self.at_bound[name]})'
        if name in self.not_identifiable:
            return 'not identifiable'
        if name not in self.names:
            return 'fixed' if self.identifiable.get(name, True) else 'fixed: not identifiable'
        return 'fitted'

    def as_json(self) -> JsonObject:
        parameters = {}
        for name in self.values:
            ci = self.ci95.get(name)
            parameters[name] = {
                'value': self.values[name],
                'ci95': list(ci) if ci is not None else None,
                'status': self.status(name),
                'at_bound': name in self.at_bound,
                'unit': PARAMS[name].unit,
                'range': list(PARAMS[name].bounds),
                'fitted': (name in self.names and not self.kept_start)
                or self.status(name) == 'fitted (every sample)',
                'identifiable': self.identifiable.get(name, True) and name not in self.not_identifiable,
                'start': self.start[name],
                'sensitivity_Nm': self.sensitivity_Nm.get(name),
                'why': self.not_identifiable.get(name) or self.left_fixed.get(name),
            }
        return {
            'parameters': parameters,
            'correlations_warnings': self.correlations_warnings,
            'segments_fit': self.segments_fit,
            'segments_holdout': self.segments_holdout,
            'torque_rmse_before_Nm': self.torque_rmse_before_Nm,
            'torque_rmse_after_Nm': self.torque_rmse_after_Nm,
            'holdout_energy_error_before': self.holdout_energy_error_before,
            'holdout_energy_error_after': self.holdout_energy_error_after,
            'seconds': self.seconds,
            'residual_rms_Nm': self.residual_rms_Nm,
            'correlation': {'parameters': self.names, 'matrix': self.correlation.tolist()},
            'segments_dropped': self.dropped,
            # the optimizer stopped by its tolerances; with a parameter at a bound that is a constrained
            # optimum, not the unconstrained one: at_bound names them and a warning says so
            'optimizer_converged': self.converged,
            'at_bound': sorted(self.at_bound),
            'converged_inside_bounds': self.converged and not self.at_bound,
            'fit_at': self.fit_at,
            'fit_to': self.fit_to,
            'not_identifiable': dict(self.not_identifiable),
            'left_fixed': dict(self.left_fixed),
            'kept_start': self.kept_start or None,
            'motion': dict(self.motion),
            'from_cmd': self.from_cmd,
            'drive_controller': self.drive.as_json() if self.drive is not None else None,
            'reconciliation': dict(self.reconciliation) or None,
        }


def _u_bounds(name: str) -> tuple[float, float]:
    lo, hi = PARAMS[name].bounds
    return (math.log(lo), math.log(hi)) if PARAMS[name].log else (lo, hi)


def _to_z(name: str, value: float) -> float:
    """Search coordinate z in [0, 1] of ``value`` (parameter units; clipped to its range)."""
    lo, hi = PARAMS[name].bounds
    v = min(max(value, lo), hi)
    u_lo, u_hi = _u_bounds(name)
    u = math.log(v) if PARAMS[name].log else v
    return (u - u_lo) / (u_hi - u_lo)


def _from_z(name: str, z: float) -> float:
    """Parameter value of search coordinate ``z`` (clipped to [0, 1] first: never beyond the range,
    never an overflow)."""
    u_lo, u_hi = _u_bounds(name)
    zc = min(max(float(z), 0.0), 1.0) if math.isfinite(z) else (1.0 if z > 0 else 0.0)
    u = u_lo + zc * (u_hi - u_lo)
    lo, hi = PARAMS[name].bounds
    return min(max(math.exp(u) if PARAMS[name].log else u, lo), hi)  # exactly inside (exp's rounding)


def _dvalue_dz(name: str, value: float) -> float:
    """d value / d z at ``value`` [parameter unit per z unit] (the delta method's factor)."""
    u_lo, u_hi = _u_bounds(name)
    return (u_hi - u_lo) * (value if PARAMS[name].log else 1.0)


def _values(names: Sequence[str], z: np.ndarray) -> dict[str, float]:
    return {n: _from_z(n, float(v)) for n, v in zip(names, z, strict=True)}


def select_identifiable(
    columns: dict[str, np.ndarray], fit: Sequence[str], tol: float
) -> tuple[list[str], dict[str, float]]:
    """Which of ``fit`` the data can see, by orthogonalization (Yao et al. 2003).

    ``columns`` maps every candidate to the residual change (all observations) of a 10 % change of
    it. Greedily pick the ``fit`` parameter whose change is largest after removing what the already
    picked ones can explain (least-squares projection); stop when the largest unexplained RMS is below
    ``tol``. Returns (picked names in ``fit`` order, unexplained RMS of every candidate against the
    picked set: for a picked one, against the others picked before it).
    """
    picked: list[str] = []
    basis = np.zeros((next(iter(columns.values())).size, 0))
    unexplained: dict[str, float] = {}

    def rest(col: np.ndarray) -> np.ndarray:
        if basis.shape[1] == 0:
            return col
        coef, *_ = np.linalg.lstsq(basis, col, rcond=None)
        remainder: np.ndarray = col - basis @ coef
        return remainder

    pool = [n for n in fit if n in columns]
    while pool:
        scores = {n: _rmse(rest(columns[n])) for n in pool}
        best = max(scores, key=scores.__getitem__)
        if scores[best] < tol:
            break
        unexplained[best] = scores[best]
        picked.append(best)
        pool.remove(best)
        basis = np.column_stack([basis, columns[best]])
    for name, col in columns.items():
        unexplained.setdefault(name, _rmse(rest(col)))
    return [n for n in fit if n in picked], unexplained


BOUND_TOL_Z = 1e-4  # a fitted z this close to 0 or 1 is at its bound


def bound_hits(names: Sequence[str], z: np.ndarray) -> dict[str, str]:
    """Fitted parameters whose search coordinate ended within :data:`BOUND_TOL_Z` of 0 or 1."""
    hits = {}
    for name, value in zip(names, z, strict=True):
        if value <= BOUND_TOL_Z:
            hits[name] = 'lower'
        elif value >= 1.0 - BOUND_TOL_Z:
            hits[name] = 'upper'
    return hits


def split_holdout(count: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (fit, hold-out) of ``count`` segments; hold-out ~ ``fraction`` of them, by segment."""
    if not 0 <= fraction < 1:
        raise InputError(f'--holdout must lie in [0, 1), got {fraction}')
    order = np.random.default_rng(seed).permutation(count)
    n_hold = round(fraction * count)
    if fraction > 0 and count >= 3:
        n_hold = max(1, n_hold)
    return np.sort(order[n_hold:]), np.sort(order[:n_hold])


def _energy_error(
    segments: Sequence[SteadyWindow], idx: np.ndarray, ev: Evaluation, motor: MotorConstants
) -> float:
    """Signed relative error of the summed energy of segments ``idx`` [-] (predicted vs measured):
    the battery-side energy where the segments measured it (V x I), else the motor terminal energy
    (K_t i); NaN where no segment of ``idx`` measured either."""
    if idx.size == 0:
        return math.nan
    battery = np.array([sum(segments[i].battery_W) for i in idx])
    if np.any(np.isfinite(battery)):
        measured_w, predicted_w = battery, np.sum(ev.power[idx], axis=1)
    else:
        measured_w = np.array([sum(segments[i].terminal_W) for i in idx])
        predicted_w = np.sum(np.asarray(terminal_power(motor, ev.torque[idx], ev.omega[idx])), axis=1)
    keep = np.isfinite(measured_w)
    if not np.any(keep):
        return math.nan
    duration = np.array([segments[i].duration_s for i in idx])[keep]
    measured = measured_w[keep] @ duration
    predicted = predicted_w[keep] @ duration
    return float((predicted - measured) / measured) if measured != 0 else math.nan


def _rmse(err: np.ndarray) -> float:
    err = err[np.isfinite(err)] if err.size else err
    return float(np.sqrt(np.mean(err**2))) if err.size else math.nan


@dataclass
class FitData:
    """The measurements of a calibration and their noise scales (module doc, "Residuals")."""

    segments: list[SteadyWindow]
    model: Model
    fit_idx: np.ndarray
    hold_idx: np.ndarray
    measured: np.ndarray  # (S, 2) motor torque [N m] (NaN: none recorded)
    motion: np.ndarray  # (S, 2) measured V [m/s], yaw rate [rad/s] (NaN: none measured)
    fit_to: str
    torque_scale_Nm: float
    start: dict[str, float]
    candidates: list[str]
    battery: np.ndarray  # (S, 2) measured battery-side power per side [W] (NaN: not measured)
    power_scale_W: float = 1.0
    battery_total: np.ndarray | None = None  # (S,) True: only the sides' sum is measured (a total)
    notes: list[str] = field(default_factory=list)  # what a step changed, for the result's warnings

    def residuals(self, ev: Evaluation, idx: np.ndarray) -> np.ndarray:
        """Scaled residuals of segments ``idx`` (fixed length; a missing measurement gives 0)."""
        parts = []
        if self.fit_to in ('torque', 'both'):
            err = (ev.torque[idx] - self.measured[idx]) / self.torque_scale_Nm
            failed = ~ev.ok[idx][:, None] | ~np.isfinite(ev.torque[idx])
            err = np.where(failed, FAILED_RESIDUAL_NM / self.torque_scale_Nm, err)
            parts.append(np.where(np.isfinite(self.measured[idx]), err, 0.0).ravel())
            err = self.battery_error(ev.power[idx], idx) / self.power_scale_W
            err = np.where(~ev.ok[idx][:, None] | ~np.isfinite(ev.power[idx]), FAILED_RESIDUAL_NM / 0.05, err)
            parts.append(np.where(np.isfinite(self.battery[idx]), err, 0.0).ravel())
        if self.fit_to in ('motion', 'both'):
            pred = np.column_stack([ev.speed[idx], ev.yaw[idx]])
            err = (pred - self.motion[idx]) / np.array([SPEED_SCALE_M_S, YAW_SCALE_RAD_S])
            err = np.where(np.isfinite(pred), err, FAILED_RESIDUAL_NM / SPEED_SCALE_M_S)
            parts.append(np.where(np.isfinite(self.motion[idx]), err, 0.0).ravel())
        out: np.ndarray = np.nan_to_num(np.concatenate(parts), nan=0.0, posinf=1e6, neginf=-1e6)
        return out

    def battery_error(self, predicted_W: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """(S, 2) predicted minus measured battery-side power [W] of segments ``idx``
        (:func:`battery_error`)."""
        total = None if self.battery_total is None else self.battery_total[idx]
        return battery_error(predicted_W, self.battery[idx], total)

    def observations(self, idx: np.ndarray) -> int:
        """How many measured numbers segments ``idx`` give the residuals."""
        count = 0
        if self.fit_to in ('torque', 'both'):
            count += int(np.isfinite(self.measured[idx]).sum()) + int(np.isfinite(self.battery[idx]).sum())
            if self.battery_total is not None:  # a total is one number, not one per side
                count -= int(np.count_nonzero(self.battery_total[idx] & np.isfinite(self.battery[idx, 1])))
        if self.fit_to in ('motion', 'both'):
            count += int(np.isfinite(self.motion[idx]).sum())
        return count


def battery_error(predicted_W: np.ndarray, measured_W: np.ndarray, total: np.ndarray | None) -> np.ndarray:
    """(S, 2) predicted minus measured battery-side power per side [W]; where ``total`` (S,) is True
    only a whole-robot total was measured (split half per side): the sum's error, in the left column,
    0 in the right (a total is one observation, whatever the model's split between the sides)."""
    err: np.ndarray = predicted_W - measured_W
    if total is None or not np.any(total):
        return err
    summed = np.column_stack([err.sum(axis=1), np.zeros(len(err))])
    out: np.ndarray = np.where(total[:, None], summed, err)
    return out


def prepare(
    vehicle: Vehicle,
    terrain: Terrain,
    powertrain: Powertrain,
    segments: Sequence[SteadyWindow],
    fit: Sequence[str],
    *,
    holdout: float,
    seed: int,
    fit_at: str,
    fit_to: str,
) -> FitData:
    """Step 1: the hold-out split, the segment model, the measurements and the start values."""
    fit_at, note = prediction_mode(fit_at, '--fit-at', FIT_AT)
    if note:  # an earlier spelling: it works, and the caller learns the name
        warnings.warn(note, FutureWarning, stacklevel=3)
    if fit_to not in FIT_TO:
        raise InputError(f'fit_to must be one of {", ".join(FIT_TO)}, not {fit_to!r}')
    segments = list(segments)
    fit_idx, hold_idx = split_holdout(len(segments), holdout, seed)
    model = segment_model(vehicle, terrain, powertrain, segments, fit_at)
    measured = np.array([s.motor_torque_Nm for s in segments], dtype=float).reshape(-1, 2)
    motion = np.array(
        [
            (s.speed_m_s, s.yaw_rate_rad_s) if s.motion_source != 'command' else (math.nan,) * 2
            for s in segments
        ],
        dtype=float,
    ).reshape(-1, 2)
    battery = np.array([s.battery_W for s in segments], dtype=float).reshape(-1, 2)
    if fit_to != 'motion' and not np.any(np.isfinite(measured)) and not np.any(np.isfinite(battery)):
        raise InputError(
            'the segments carry no measured torque, current or power: fit the motion (--fit auto)'
        )
    if fit_to != 'torque' and not np.any(np.isfinite(motion)):
        raise InputError('the segments carry no measured motion (no odometry, pose or yaw-rate topic)')
    if fit_to != 'torque' and fit_at != CMD:
        raise InputError('a motion fit predicts the motion at the set points: --fit-at cmd')
    finite = measured[np.isfinite(measured)]
    rms = float(np.sqrt(np.mean(finite**2))) if finite.size else 1.0
    kind = terrain_params(terrain)
    wrong = [n for n in fit if n in TERRAIN_PARAMS and n not in kind]
    if wrong:
        ground = 'rigid ground' if terrain.is_rigid else 'a soil'
        raise InputError(f'--fit: {", ".join(wrong)} is no parameter of {ground} (its: {", ".join(kind)})')
    candidates = list(dict.fromkeys([*fit, *[k for k in kind if k not in fit]]))
    start = {n: model.start_value(n) for n in candidates}
    for name in fit:
        lo, hi = PARAMS[name].bounds
        if not lo <= start[name] <= hi:
            raise InputError(
                f'starting {name} = {start[name]:.6g} {PARAMS[name].unit} '
                f'is outside its physical range [{lo:g}, {hi:g}]'
            )
    scale = max(1e-3, TORQUE_SCALE_SHARE * rms)
    measured_w = battery[np.isfinite(battery)]
    power_scale = (
        max(0.1, TORQUE_SCALE_SHARE * float(np.sqrt(np.mean(measured_w**2)))) if measured_w.size else 1.0
    )
    return FitData(
        segments,
        model,
        fit_idx,
        hold_idx,
        measured,
        motion,
        fit_to,
        scale,
        start,
        candidates,
        battery,
        power_scale,
        battery_total=np.array([s.battery_total for s in segments], dtype=bool),
    )


LOSS_TERMS = (
    'left_b',
    'left_c',
    'right_b',
    'right_c',
    'sides_b',
    'sides_c',
    'copper_loss_W_per_Nm2',
    'idle_power_W',
)
"""The powertrain terms a battery-side measurement makes linear (:func:`battery_prefit`)."""


def battery_prefit(data: FitData, fit: Sequence[str]) -> None:
    """Step 1b: a start for the powertrain's loss terms from battery-side power, by linear least
    squares. A neutral start (an effective powertrain: no loss, k_cu 0, no idle) is no place to screen
    or fit from: a term at 0 moves nothing, and a log term at its floor cannot move. Per motoring side
    of every fit segment (motor torque T, speed w of the start, amplifier efficiency eta)

        eta P_bus = T_t w + b w^2 + c |w| + k_cu T^2 + eta P_idle / 2       [W]

    (T_t = T - the start's internal torque: the load; T^2 of the start, so the copper term's cross
    terms in b and c are dropped; a whole-robot total: the two sides' equations summed, where both
    sides motor) is linear in b, c per side, k_cu and P_idle: non-negative least
    squares (scipy.optimize.nnls), each clipped to its range. Terms not in ``fit`` keep their start.
    The start (``data.start``, the model's powertrain) becomes that estimate, said in ``data.notes``.
    Nothing happens without battery-side power or a loss term in ``fit``."""
    free = [n for n in LOSS_TERMS if n in fit]
    rows = data.fit_idx[np.all(np.isfinite(data.battery[data.fit_idx]), axis=1)]
    if not free or rows.size == 0:
        return
    model = data.model
    base = model.evaluate({})
    if not np.all(base.ok[rows]):
        return  # the screen says which segment has no steady state
    pt = model.powertrain
    eta = pt.amplifier.efficiency
    columns: dict[str, list[np.ndarray]] = {n: [] for n in LOSS_TERMS}
    target: list[np.ndarray] = []
    total = data.battery_total[rows] if data.battery_total is not None else np.zeros(rows.size, bool)
    power_in = base.torque[rows] * base.omega[rows]
    motoring = [(power_in[:, k] > 0.0) & (np.abs(base.omega[rows, k]) > 1e-6) for k in (0, 1)]
    both = motoring[0] & motoring[1]
    side_cols: list[dict[str, np.ndarray]] = []
    side_target: list[np.ndarray] = []
    for k, side in enumerate(('left', 'right')):
        torque, omega = base.torque[rows, k], base.omega[rows, k]
        load = torque - np.asarray(pt.resistance(side).torque(omega))
        cols = {n: np.zeros(rows.size) for n in LOSS_TERMS}
        cols[f'{side}_b'] = cols['sides_b'] = omega * omega
        cols[f'{side}_c'] = cols['sides_c'] = np.abs(omega)
        cols['copper_loss_W_per_Nm2'] = torque**2
        cols['idle_power_W'] = np.full(rows.size, 0.5 * eta)
        side_cols.append(cols)
        side_target.append(eta * data.battery[rows, k] - load * omega)
    for k in (0, 1):  # a side's own V x I: one equation per motoring side (eta applies)
        keep = motoring[k] & ~total
        for name in LOSS_TERMS:
            columns[name].append(side_cols[k][name][keep])
        target.append(side_target[k][keep])
    keep = both & total  # a whole-robot total: one equation, the two sides summed, both motoring
    for name in LOSS_TERMS:
        columns[name].append((side_cols[0][name] + side_cols[1][name])[keep])
    target.append((side_target[0] + side_target[1])[keep])
    design = {n: np.concatenate(c) for n, c in columns.items()}
    rhs = np.concatenate(target) - sum(
        (design[n] * data.start.get(n, model.start_value(n)) for n in LOSS_TERMS if n not in free),
        np.zeros(len(np.concatenate(target))),
    )
    if rhs.size <= len(free):
        return
    solution, _ = optimize.nnls(np.column_stack([design[n] for n in free]), rhs)
    values = {n: float(np.clip(v, *PARAMS[n].bounds)) for n, v in zip(free, solution, strict=True)}
    _, powertrain = model.with_values(values)
    model.powertrain = powertrain
    model._warm = None
    for name in free:
        data.start[name] = model.start_value(name)
    listed = ', '.join(f'{n} {data.start[n]:.4g} {PARAMS[n].unit}' for n in free)
    data.notes.append(
        f'loss terms started from their linear least-squares estimate on battery power: {listed}'
    )


@dataclass
class Screen:
    """Step 2's answer: the start's predictions, what each candidate moves and what the data see."""

    base: Evaluation
    sensitivity_Nm: dict[str, float]
    identifiable: dict[str, bool]
    names: list[str]
    unexplained: dict[str, float]


def screen(data: FitData, fit: Sequence[str], tol: float) -> Screen:
    """Step 2: solve the start; the change of the scaled residuals under a 10 % change of every
    candidate; :func:`select_identifiable` picks what the data see (``tol``, scaled RMS)."""
    model = data.model
    base = model.evaluate({})
    if not np.all(base.ok):
        bad = np.flatnonzero(~base.ok)
        raise InputError(
            f'FESS has no steady state on the starting terrain for {bad.size} segment(s), e.g. '
            f'V = {model.speed[bad[0]]:.3g} m/s, yaw rate {model.yaw[bad[0]]:.3g} rad/s: '
            'choose a closer --terrain'
        )
    every = np.arange(len(data.segments))
    base_r = data.residuals(base, every)
    columns: dict[str, np.ndarray] = {}
    sensitivity: dict[str, float] = {}
    for name in data.candidates:
        value = data.start[name]
        lo, hi = PARAMS[name].bounds
        # 10 %, and for a linear parameter at least 1 % of its range (a Coulomb term of 0.05 N m or
        # an idle power of 0 W is no scale for what the data can see)
        step = 0.1 * abs(value) if PARAMS[name].log else max(0.1 * abs(value), 0.01 * (hi - lo))
        trial = value + step if value + step <= hi else value - step  # stay inside the range
        ev = model.evaluate({name: trial})
        columns[name] = data.residuals(ev, every) - base_r
        torque_change = np.where(ev.ok[:, None], ev.torque - base.torque, 0.0)
        sensitivity[name] = _rmse(torque_change.ravel())
    names, unexplained = select_identifiable(columns, fit, tol)
    identifiable = {n: bool(unexplained[n] >= tol) for n in data.candidates}
    return Screen(base, sensitivity, identifiable, names, unexplained)


@dataclass
class Optimum:
    """Step 3's answer: fitted names, z, scaled residuals and Jacobian, success."""

    names: list[str]
    z: np.ndarray
    residuals: np.ndarray
    jac: np.ndarray
    success: bool


def optimize_z(data: FitData, names: Sequence[str], f_scale: float) -> Optimum:
    """Step 3: robust least squares over the fit segments in z in [0, 1] (module doc, "Method")."""
    names = list(names)
    p = len(names)
    z0 = np.clip([_to_z(n, data.start[n]) for n in names], 1e-6, 1.0 - 1e-6)

    def residuals(z: np.ndarray) -> np.ndarray:
        return data.residuals(data.model.evaluate(_values(names, z)), data.fit_idx)

    sol = optimize.least_squares(
        residuals,
        z0,
        bounds=(np.zeros(p), np.ones(p)),
        loss='soft_l1',
        f_scale=f_scale,
        x_scale='jac',
        diff_step=DIFF_STEP,
        method='trf',
        max_nfev=60 * (p + 1),
    )
    return Optimum(names, np.asarray(sol.x), residuals(sol.x), np.asarray(sol.jac), bool(sol.success))


@dataclass
class Uncertainty:
    """Step 4's answer (module doc, "Uncertainty" and "Honesty")."""

    ci95: dict[str, tuple[float, float] | None]
    covariance: np.ndarray
    correlation: np.ndarray
    at_bound: dict[str, str]
    leaves_range: dict[str, str]  # name -> why: its interval leaves the physical range
    s2: float
    warnings: list[str]
    half_width_z: dict[str, float] = field(default_factory=dict)  # t sigma_z of each free parameter


def uncertainty(opt: Optimum, observations: int) -> Uncertainty:
    """Step 4: covariance, 95 % intervals, bounds, and the intervals that leave the physical range."""
    names, p = opt.names, len(opt.names)
    fitted = _values(names, opt.z)
    at_bound = bound_hits(names, opt.z)
    free = np.array([n not in at_bound for n in names], dtype=bool)
    dof = max(1, observations - int(free.sum()))
    s2 = float(opt.residuals @ opt.residuals) / dof
    # a parameter pinned at a bound is no estimate: no interval, and the others' covariance is that
    # of the free parameters with it held (the Jacobian's pinned columns dropped)
    cov_z = np.zeros((p, p))
    if np.any(free):
        cov_z[np.ix_(free, free)] = s2 * np.linalg.pinv(opt.jac[:, free].T @ opt.jac[:, free])
    sigma_z = np.sqrt(np.clip(np.nan_to_num(np.diag(cov_z), nan=np.inf), 0.0, None))
    t = float(stats.t.ppf(0.975, dof))
    ci95: dict[str, tuple[float, float] | None] = {}
    leaves: dict[str, str] = {}
    half: dict[str, float] = {}
    for k, name in enumerate(names):
        ci95[name] = None
        if name in at_bound:
            continue
        z_lo, z_hi = opt.z[k] - t * sigma_z[k], opt.z[k] + t * sigma_z[k]
        half[name] = float(t * sigma_z[k]) if math.isfinite(sigma_z[k]) else math.inf
        if not (z_lo >= 0.0 and z_hi <= 1.0):  # also catches a NaN or infinite sigma
            lo, hi = PARAMS[name].bounds
            leaves[name] = (
                f'its 95 % interval (+- {t * sigma_z[k] * 100:.3g} % of the range in search coordinates) '
                f'leaves the physical range [{lo:g}, {hi:g}] {PARAMS[name].unit}'
            )
            continue
        ci95[name] = (_from_z(name, z_lo), _from_z(name, z_hi))
    deriv = np.array([_dvalue_dz(n, fitted[n]) for n in names])
    covariance = cov_z * np.outer(deriv, deriv)  # delta method, parameter units
    with np.errstate(invalid='ignore', divide='ignore'):
        correlation = cov_z / np.outer(sigma_z, sigma_z)
    correlation = np.nan_to_num(np.clip(correlation, -1.0, 1.0))
    warnings = [
        f'{names[i]} and {names[j]} are strongly correlated (rho = {correlation[i, j]:+.3f}): '
        'the data fix only a combination of the two'
        for i in range(p)
        for j in range(i + 1, p)
        if abs(correlation[i, j]) > RHO_WARN
    ]
    for name, side in at_bound.items():
        bound = PARAMS[name].bounds[0 if side == 'lower' else 1]
        warnings.append(
            f'{name} = {fitted[name]:.6g} {PARAMS[name].unit} is at its {side} fit bound ({bound:g}): '
            'the data push it beyond; it is no estimate and has no interval (a closer --terrain, or other '
            'drives)'
        )
    return Uncertainty(ci95, covariance, correlation, at_bound, leaves, s2, warnings, half)


@dataclass
class Assessment:
    """Step 5's answer: hold-out before / after, and whether the start is kept."""

    after: Evaluation
    energy_before: float
    energy_after: float
    cost_before: float
    cost_after: float
    motion: dict[str, float]
    kept_start: str


def _motion_errors(data: FitData, ev: Evaluation, idx: np.ndarray) -> tuple[float, float]:
    """(V MAE [m/s], yaw rate MAE [rad/s]) of ``ev`` on segments ``idx`` with a measured motion."""
    pred = np.column_stack([ev.speed, ev.yaw])[idx]
    err = np.abs(pred - data.motion[idx])
    out = []
    for k in range(2):
        col = err[:, k][np.isfinite(err[:, k])]
        out.append(float(col.mean()) if col.size else math.nan)
    return out[0], out[1]


def assess(data: FitData, base: Evaluation, fitted: dict[str, float]) -> Assessment:
    """Step 5: the hold-out (the fit segments without one) before and after; the start is kept when
    the fit predicts it worse: its |energy error| where power is measured (a handful of hold-out
    segments' RMS, torque and motion together, rejected fits that halved the energy error), else
    the scaled residual RMS."""
    model, segments = data.model, data.segments
    after = model.evaluate(fitted)
    idx = data.hold_idx if data.hold_idx.size else data.fit_idx
    _, powertrain_fit = model.with_values(fitted)
    energy_before = _energy_error(segments, data.hold_idx, base, model.powertrain.motor)
    energy_after = _energy_error(segments, data.hold_idx, after, powertrain_fit.motor)
    cost_before = _rmse(data.residuals(base, idx))
    cost_after = _rmse(data.residuals(after, idx))
    v0, w0 = _motion_errors(data, base, idx)
    v1, w1 = _motion_errors(data, after, idx)
    motion = {'speed_mae_before_m_s': v0, 'speed_mae_after_m_s': v1, 'yaw_mae_before_rad_s': w0,
              'yaw_mae_after_rad_s': w1}  # fmt: skip
    which = 'hold-out' if data.hold_idx.size else 'fit'
    kept = ''
    if math.isfinite(energy_before):  # power measured: the energy is what is predicted, and decides
        if abs(energy_after) > abs(energy_before) + ENERGY_WORSE:
            kept = (
                f'the fit predicted the {which} segments worse than the start (energy error '
                f'{energy_before:+.1%} -> {energy_after:+.1%}): the start is kept'
            )
    elif cost_after > cost_before * (1.0 + COST_WORSE):
        kept = (
            f'the fit predicted the {which} segments worse than the start (scaled residual RMS '
            f'{cost_before:.3g} -> {cost_after:.3g}): the start is kept'
        )
    return Assessment(after, energy_before, energy_after, cost_before, cost_after, motion, kept)


def calibrate(
    vehicle: Vehicle,
    terrain: Terrain,
    powertrain: Powertrain,
    segments: Sequence[SteadyWindow],
    fit: Sequence[str] = DEFAULT_FIT,
    *,
    holdout: float = 0.3,
    seed: int = 0,
    ident_tol_Nm: float | None = None,
    dropped: dict[str, int] | None = None,
    fit_at: str = CMD,
    fit_to: str = 'torque',
    left_fixed: dict[str, str] | None = None,
) -> CalibrationResult:
    """Fit ``fit`` (names of :data:`PARAMS`) to ``segments``; see the module doc for the method,
    for ``fit_at`` ('cmd': the commands at their set points, 'motion': the measured motion) and
    ``fit_to`` ('torque', 'motion' or 'both': what the residuals compare, :data:`FIT_TO`).

    ``ident_tol_Nm`` : RMS torque change [N m] below which a 10 % parameter change counts as
    invisible (None: :data:`IDENT_TOL` noise scales, 0.2 % of the RMS measured torque).
    ``left_fixed`` : candidates already left at their start, with why (``--fit auto``).
    """
    started = time.perf_counter()
    data = prepare(
        vehicle, terrain, powertrain, segments, fit, holdout=holdout, seed=seed, fit_at=fit_at, fit_to=fit_to
    )
    battery_prefit(data, fit)
    tol = ident_tol_Nm / data.torque_scale_Nm if ident_tol_Nm is not None else IDENT_TOL
    scr = screen(data, fit, tol)
    observations = count_observations(data, scr)
    opt, unc = fit_inside_ranges(data, scr.names, observations)
    fitted = {n: v for n, v in _values(opt.names, opt.z).items() if n not in unc.leaves_range}
    steps = Steps(data, scr, opt, unc, assess(data, scr.base, fitted), fitted)
    why_fixed = reasons_fixed(steps, fit, tol, left_fixed)
    return _result(steps, why_fixed, dropped, time.perf_counter() - started)


def count_observations(data: FitData, scr: Screen) -> int:
    """Step 2b: the fit segments' measured numbers; InputError when nothing is left to fit or there
    are no more numbers than parameters."""
    if not scr.names:
        raise InputError('no parameter in --fit changes the prediction visibly on these segments')
    observations = data.observations(data.fit_idx)
    if observations <= len(scr.names):
        raise InputError(
            f'{data.fit_idx.size} fit segment(s) give {observations} measurement(s): '
            f'too few for {len(scr.names)} parameters'
        )
    return observations


def fit_inside_ranges(data: FitData, names: Sequence[str], observations: int) -> tuple[Optimum, Uncertainty]:
    """Steps 3 and 4 with the module doc's "Honesty": fit, and while an interval leaves its physical
    range, put the widest such parameter back at its start and fit the others again."""
    opt = optimize_z(data, names, f_scale=1.0)
    unc = uncertainty(opt, observations)
    leaves: dict[str, str] = {}
    while unc.leaves_range and len(unc.leaves_range) < len(opt.names):  # refit without the worst one
        worst = max(unc.leaves_range, key=lambda n: unc.half_width_z.get(n, math.inf))
        leaves[worst] = unc.leaves_range[worst]
        opt = optimize_z(data, [n for n in opt.names if n != worst], f_scale=1.0)
        unc = uncertainty(opt, observations)
    unc.leaves_range = {**leaves, **unc.leaves_range}
    return opt, unc


@dataclass
class Steps:
    """The answers of every step of one calibration (what :func:`_result` reports)."""

    data: FitData
    scr: Screen
    opt: Optimum
    unc: Uncertainty
    check: Assessment
    fitted: dict[str, float]  # fitted values inside their ranges, parameter units


def reasons_fixed(
    steps: Steps, fit: Sequence[str], tol: float, left_fixed: dict[str, str] | None
) -> dict[str, str]:
    """Step 6a: why each candidate that was not fitted stayed at its start (not in ``fit``, or
    invisible in the screen); ``left_fixed`` (``--fit auto``'s reasons) first."""
    why_fixed = dict(left_fixed or {})
    for name in steps.data.candidates:
        if name not in fit:
            why_fixed.setdefault(name, 'not in --fit')
        elif name not in steps.scr.names:
            why_fixed[name] = (
                f'not identifiable: a 10 % change moves the prediction by {steps.scr.unexplained[name]:.3g} '
                f'noise scales (RMS, after what the others explain), below {tol:.3g}'
            )
        else:
            why_fixed.pop(name, None)
    return why_fixed


def _result(
    steps: Steps, why_fixed: dict[str, str], dropped: dict[str, int] | None, seconds: float
) -> CalibrationResult:
    """Step 6: the :class:`CalibrationResult` (the start's terrain and powertrain if it was kept)."""
    data, scr, opt, unc, check = steps.data, steps.scr, steps.opt, steps.unc, steps.check
    model, start = data.model, data.start
    warnings = [*data.notes, *unc.warnings]
    for name, why in unc.leaves_range.items():
        warnings.append(f'{name} is not identifiable: {why}; left at its start {start[name]:.6g}')
    if check.kept_start:
        warnings.append(check.kept_start)
        fitted_used: dict[str, float] = {}
        after = scr.base
    else:
        fitted_used, after = steps.fitted, check.after
    terrain_fit, powertrain_fit = model.with_values(fitted_used)
    err_idx = data.hold_idx if data.hold_idx.size else data.fit_idx
    torque_r = (after.torque - data.measured)[data.fit_idx]
    return CalibrationResult(
        names=list(opt.names),
        values={n: fitted_used.get(n, start[n]) for n in data.candidates},
        start=dict(start),
        ci95={n: (unc.ci95.get(n) if not check.kept_start else None) for n in data.candidates},
        sensitivity_Nm=scr.sensitivity_Nm,
        identifiable=scr.identifiable,
        covariance=unc.covariance,
        correlation=unc.correlation,
        correlations_warnings=warnings,
        segments_fit=int(data.fit_idx.size),
        segments_holdout=int(data.hold_idx.size),
        torque_rmse_before_Nm=_rmse((scr.base.torque - data.measured)[err_idx].ravel()),
        torque_rmse_after_Nm=_rmse((after.torque - data.measured)[err_idx].ravel()),
        holdout_energy_error_before=check.energy_before,
        holdout_energy_error_after=check.energy_before if check.kept_start else check.energy_after,
        residual_rms_Nm=_rmse(torque_r.ravel()),
        seconds=seconds,
        terrain=terrain_fit,
        powertrain=powertrain_fit,
        dropped=dict(dropped or {}),
        converged=opt.success and bool(np.all(after.ok)),
        at_bound=unc.at_bound,
        jacobian_z=opt.jac,
        z=opt.z,
        residual_variance=unc.s2,
        measured_Nm=data.measured,
        before_Nm=scr.base.torque,
        after_Nm=after.torque,
        holdout_index=data.hold_idx,
        from_cmd=setpoint_check(
            model.vehicle, terrain_fit, powertrain_fit, data.segments, data.measured, err_idx, data.hold_idx
        ),
        fit_at=model.fit_at,
        fit_to=data.fit_to,
        not_identifiable=dict(unc.leaves_range),
        left_fixed=why_fixed,
        kept_start=check.kept_start,
        motion=check.motion,
    )


def segment_model(
    vehicle: Vehicle, terrain: Terrain, powertrain: Powertrain, segments: Sequence[SteadyWindow], fit_at: str
) -> Model:
    """The :class:`Model` of ``segments``: at their commands ('cmd') or measured motion ('motion')."""
    if fit_at == CMD:
        at = np.array([s.command for s in segments], dtype=float).reshape(-1, 2)
    else:
        at = np.array([(s.speed_m_s, s.yaw_rate_rad_s) for s in segments], dtype=float).reshape(-1, 2)
    return Model(vehicle, terrain, powertrain, at[:, 0], at[:, 1], fit_at)


def setpoint_check(
    vehicle: Vehicle,
    terrain: Terrain,
    powertrain: Powertrain,
    segments: Sequence[SteadyWindow],
    measured: np.ndarray,
    err_idx: np.ndarray,
    hold_idx: np.ndarray,
) -> dict[str, float]:
    """The fitted terrain and powertrain predicting each segment from its COMMAND, at the wheel
    speed set points (issue 25), whatever the fit was solved at (with ``fit_at`` 'cmd' the
    torques and energy are the fit's own; the motion errors say how far FESS's set-point motion is
    from the measured one).

    Keys: ``torque_rmse_Nm`` (motor torque vs measured, the segments of ``torque_rmse_after_Nm``),
    ``holdout_energy_error`` (signed), ``speed_error_median`` and ``yaw_rate_error_median``
    (|predicted - measured| / |measured| of the body motion [-]), ``limited_segments``.
    """
    from skidsteer_power.models.predict import CommandPredictor

    if not segments:
        return {}
    commands = np.array([seg.command for seg in segments], dtype=float)
    pred = CommandPredictor(vehicle, terrain, powertrain).predict(commands[:, 0], commands[:, 1])
    torque, omega, power = motor_points(powertrain, pred.torque, pred.setpoint)
    ev = Evaluation(torque, omega, np.ones(len(torque), bool), pred.speed, pred.yaw_rate, power)
    speed = np.array([seg.speed_m_s for seg in segments])
    yaw = np.array([seg.yaw_rate_rad_s for seg in segments])
    with np.errstate(invalid='ignore', divide='ignore'):
        speed_err = np.abs(pred.speed - speed) / np.abs(speed)
        yaw_err = np.abs(pred.yaw_rate - yaw) / np.abs(yaw)
    return {
        'torque_rmse_Nm': _rmse(torque[err_idx] - measured[err_idx]),
        'holdout_energy_error': _energy_error(segments, hold_idx, ev, powertrain.motor),
        'speed_error_median': _median(speed_err[np.abs(speed) > 1e-3]),
        'yaw_rate_error_median': _median(yaw_err[np.abs(yaw) > 1e-3]),
        'limited_segments': int(np.sum(pred.limited)),
    }


def _median(values: np.ndarray) -> float:
    """Median of the finite ``values`` (NaN when there is none, without a warning)."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else math.nan
