"""Fit terrain (and drivetrain) parameters to steady segments of the user's own recordings.

The model of a segment is what the estimator predicts for it (``fit_at``, :data:`FIT_AT`):

* ``setpoints`` (default, issue 27): FESS driven by the wheel speed set points of the segment's
  COMMAND (:class:`~skidsteer_power.models.predict.CommandPredictor`, issue 25: the driver's
  kinematics, the body motion FESS finds for them, the amplifiers' current limit), as power_estimator
  and ``validate --kinematics cmd`` predict. Fitting what the node predicts is what makes calibrating
  improve the prediction from the command: a terrain fitted at the measured motion can make it worse
  (on the twin's wheeled robot FESS turns far more at the set points than the robot does, so the
  terrain that matches the torques at the measured motion over-predicts them from the command);
* ``motion``: FESS solved directly at the segment's measured forward speed V [m/s] and yaw rate
  [rad/s] (the terrain as a terramechanics description of the ground; needs a pose topic).

All segments are solved in one batched Newton solve per parameter vector (no map is rebuilt), followed
by the powertrain (eqs. 7.1-7.4: axle torque / G + internal resistance at the motor shaft). Residuals
are predicted minus measured motor torque K_t i [N m], both sides of every fit segment.

Method
------
* Parameters are searched in transformed coordinates z: ln(value) for the strictly positive moduli
  (kphi, kc, c, K), the value itself for n, phi [deg] and the internal-resistance coefficients.
  ``scipy.optimize.least_squares`` (trust-region reflective) with bounds, ``soft_l1`` loss (a robust
  loss: a segment spoiled by a stall or a bump cannot dominate) and forward differences of 0.2 % in
  z (FESS is solved to 1e-6 N, so the difference quotient is far above solver noise).
* Identifiability: before fitting, the change of the torques under a 10 % change of every terrain
  parameter (kc always included, so the report shows it) is computed at the starting terrain, and
  the parameters are ranked by orthogonalization (:func:`select_identifiable`): a parameter whose
  10 % change, after removing what the parameters ranked above it can explain, moves the torques by
  less than ``ident_tol`` (RMS, N m) cannot be seen in the data: it is reported as non-identifiable
  and kept fixed at its starting value. For small robots this is k_c: it enters only through
  kc / b + kphi (eq. 2.1) with b ~ 0.1 m, so it matters ~1 % as much as kphi. For a track, kphi and
  n act only through the compaction resistance (eq. 2.10), one number per load, so only one of them
  is identifiable; the other is fixed.
* Uncertainty: covariance of z = s^2 (J^T J)^-1 at the optimum (J the Jacobian of the raw residuals,
  s^2 = sum r^2 / (m - p)); 95 % intervals z +- t(0.975, m - p) sigma_z mapped back to the parameter
  (asymmetric for log parameters); covariance in the parameter's own units by the delta method; the
  correlation matrix; a warning for every pair with |rho| > 0.95 (those two are seen only together).
* Validation: the segments are split into fit and hold-out sets by segment (never by sample, so the
  hold-out is not a neighbour of a fitted sample); the hold-out torque RMSE and energy error are
  reported before (starting terrain) and after (fitted).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize, stats

from skidsteer_power.calibration.segments import Segment
from skidsteer_power.errors import ConvergenceError, InputError
from skidsteer_power.models.fess import FessSolver
from skidsteer_power.powertrain.drivetrain import Powertrain
from skidsteer_power.powertrain.internal import Resistance, SideResistance
from skidsteer_power.powertrain.motor import terminal_power
from skidsteer_power.terramechanics.terrain import Terrain
from skidsteer_power.vehicle import Vehicle

RHO_WARN = 0.95
SOLVE_TOL_N = 1e-6  # FESS equilibrium tolerance during the fit [N, N m]
DIFF_STEP = 2e-3  # forward-difference step in z (relative, scipy's diff_step)
FAILED_RESIDUAL_NM = 1.0  # residual given to a segment where FESS has no steady state [N m]


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
}
INTERNAL_PARAMS: dict[str, FitParameter] = {
    'left_b': FitParameter('N m s/rad', False, (0.0, 0.05)),
    'left_c': FitParameter('N m', False, (0.0, 3.0)),
    'right_b': FitParameter('N m s/rad', False, (0.0, 0.05)),
    'right_c': FitParameter('N m', False, (0.0, 3.0)),
}
PARAMS = {**TERRAIN_PARAMS, **INTERNAL_PARAMS}
DEFAULT_FIT = ('kphi', 'n', 'c', 'phi', 'K')
FIT_AT = ('setpoints', 'motion')  # what the model of a segment is solved at (module doc)


def parse_fit_list(text: str) -> list[str]:
    """Comma-separated names; ``internal`` expands to the four per-side b, c. InputError if unknown."""
    names: list[str] = []
    for raw in text.split(','):
        name = raw.strip()
        if not name:
            continue
        expanded = list(INTERNAL_PARAMS) if name == 'internal' else [name]
        for item in expanded:
            if item not in PARAMS:
                known = ', '.join([*TERRAIN_PARAMS, 'internal'])
                raise InputError(f'--fit: unknown parameter {name!r} (known: {known})')
            if item not in names:
                names.append(item)
    if not names:
        raise InputError('--fit: no parameter named')
    return names


@dataclass
class Model:
    """Predicted motor torque and speed of every segment for a set of parameter values."""

    vehicle: Vehicle
    terrain: Terrain
    powertrain: Powertrain
    speed: np.ndarray  # (S,) [m/s]: the measured motion, or the command with fit_at 'setpoints'
    yaw: np.ndarray  # (S,) [rad/s]
    fit_at: str = 'motion'
    _warm: np.ndarray | None = field(default=None, init=False)

    def start_value(self, name: str) -> float:
        """Value of ``name`` in the starting terrain / powertrain, in the parameter's unit."""
        if name in TERRAIN_PARAMS:
            return float(getattr(self.terrain, name)) / TERRAIN_PARAMS[name].to_si
        side, kind = name.split('_')
        total = self.powertrain.resistance(side).total
        return float(total.viscous_Nm_s if kind == 'b' else total.coulomb_Nm)

    def with_values(self, values: dict[str, float]) -> tuple[Terrain, Powertrain]:
        """(terrain, powertrain) with ``values`` (parameter units) substituted."""
        # the keys are Terrain's float fields named in TERRAIN_PARAMS
        terrain_fields: dict[str, Any] = {
            k: v * TERRAIN_PARAMS[k].to_si for k, v in values.items() if k in TERRAIN_PARAMS
        }
        terrain = dataclasses.replace(self.terrain, **terrain_fields) if terrain_fields else self.terrain
        powertrain = self.powertrain

        def side_with_values(side: str) -> SideResistance:
            b, c = values.get(f'{side}_b'), values.get(f'{side}_c')
            current = powertrain.resistance(side)
            return current if b is None and c is None else scaled_side(current, b, c)

        left, right = side_with_values('left'), side_with_values('right')
        if left is not powertrain.left or right is not powertrain.right:
            powertrain = dataclasses.replace(powertrain, left=left, right=right)
        return terrain, powertrain

    def predict(self, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(motor torque (S, 2) [N m], motor speed (S, 2) [rad/s], converged (S,)) for ``values``."""
        terrain, powertrain = self.with_values(values)
        try:
            if self.fit_at == 'setpoints':
                return self._predict_setpoints(terrain, powertrain)
            return self._predict_motion(terrain, powertrain)
        except ConvergenceError:  # a trial terrain where FESS's contact has no solution at all
            nan = np.full((len(self.speed), 2), np.nan)
            return nan, nan.copy(), np.zeros(len(self.speed), dtype=bool)

    def _predict_motion(
        self, terrain: Terrain, powertrain: Powertrain
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`predict`, FESS solved at the measured motion (``speed``, ``yaw``)."""
        sol = FessSolver(self.vehicle, terrain).solve_twist(
            self.speed, self.yaw, x0=self._warm, tol=SOLVE_TOL_N
        )
        if np.all(sol.converged):
            self._warm = sol.state
        torque = np.empty_like(sol.torque)
        omega = np.empty_like(sol.omega)
        for i, side in enumerate(('left', 'right')):
            point = powertrain.motor_side(side, sol.torque[:, i], sol.omega[:, i])
            torque[:, i] = point.motor_torque_Nm
            omega[:, i] = point.motor_omega_rad_s
        return torque, omega, np.asarray(sol.converged)

    def _predict_setpoints(
        self, terrain: Terrain, powertrain: Powertrain
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`predict` for commands (``speed``, ``yaw``) at their wheel speed set points, as
        :class:`CommandPredictor` predicts them (its dug-in answer where FESS has no steady state is
        the node's prediction too, so every segment counts as solved)."""
        from skidsteer_power.models.predict import CommandPredictor

        predictor = CommandPredictor(self.vehicle, terrain, powertrain)
        setpoints, _ = predictor.setpoints(self.speed, self.yaw)
        sol = predictor.solver.solve(setpoints, x0=self._warm, tol=SOLVE_TOL_N)
        self._warm = np.where(sol.limited[:, None], np.nan, sol.state)  # dug in: start from no slip
        axle_torque, *_ = predictor.electrical(sol.torque, setpoints)
        torque, omega = np.empty_like(axle_torque), np.empty_like(axle_torque)
        for i, side in enumerate(('left', 'right')):
            point = powertrain.motor_side(side, axle_torque[:, i], setpoints[:, i])
            torque[:, i], omega[:, i] = point.motor_torque_Nm, point.motor_omega_rad_s
        return torque, omega, np.ones(len(torque), dtype=bool)


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
    residual_variance: float = math.nan  # s^2 [N m^2]
    setpoints: dict[str, float] = field(default_factory=dict)
    fit_at: str = 'motion'

    def as_json(self) -> dict[str, Any]:
        parameters = {}
        for name in self.values:
            ci = self.ci95.get(name)
            status = 'fixed' if name not in self.names else 'fitted'
            if name in self.at_bound:
                status = f'at_bound ({self.at_bound[name]})'
            elif not self.identifiable.get(name, True):
                status = 'fixed: not identifiable'
            parameters[name] = {
                'value': self.values[name],
                'ci95': list(ci) if ci is not None else None,
                'status': status,
                'at_bound': name in self.at_bound,
                'unit': PARAMS[name].unit,
                'fitted': name in self.names,
                'identifiable': self.identifiable.get(name, True),
                'start': self.start[name],
                'sensitivity_Nm': self.sensitivity_Nm.get(name),
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
            'setpoints': self.setpoints,
        }


def _to_z(name: str, value: float) -> float:
    return math.log(value) if PARAMS[name].log else value


def _from_z(name: str, z: float) -> float:
    return math.exp(z) if PARAMS[name].log else z


def _values(names: Sequence[str], z: np.ndarray) -> dict[str, float]:
    return {n: _from_z(n, float(v)) for n, v in zip(names, z, strict=True)}


def select_identifiable(
    columns: dict[str, np.ndarray], fit: Sequence[str], tol: float
) -> tuple[list[str], dict[str, float]]:
    """Which of ``fit`` the data can see, by orthogonalization (Yao et al. 2003).

    ``columns`` maps every candidate to the torque change [N m] (all segments and sides) of a 10 %
    change of it. Greedily pick the ``fit`` parameter whose change is largest after removing what the
    already picked ones can explain (least-squares projection); stop when the largest unexplained RMS
    is below ``tol`` [N m]. Returns (picked names in ``fit`` order, unexplained RMS of every
    candidate against the picked set: for a picked one, against the others picked before it).
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


BOUND_TOL_Z = 1e-4  # a fitted z this close to a bound (in z units) is at it


def bound_hits(names: Sequence[str], z: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> dict[str, str]:
    """Fitted parameters whose search coordinate ended at (within :data:`BOUND_TOL_Z` of) a bound."""
    hits = {}
    for name, value, lo, hi in zip(names, z, lower, upper, strict=True):
        if math.isfinite(lo) and value - lo <= BOUND_TOL_Z * max(1.0, abs(lo)):
            hits[name] = 'lower'
        elif math.isfinite(hi) and hi - value <= BOUND_TOL_Z * max(1.0, abs(hi)):
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
    segments: Sequence[Segment], idx: np.ndarray, torque: np.ndarray, omega: np.ndarray, motor: Any
) -> float:
    """Signed relative error of the summed terminal energy of segments ``idx`` [-] (predicted vs measured)."""
    if idx.size == 0:
        return math.nan
    duration = np.array([segments[i].duration_s for i in idx])
    measured = np.array([sum(segments[i].terminal_W) for i in idx]) @ duration
    predicted = np.sum(np.asarray(terminal_power(motor, torque[idx], omega[idx])), axis=1) @ duration
    return float((predicted - measured) / measured) if measured != 0 else math.nan


def _rmse(err: np.ndarray) -> float:
    return float(np.sqrt(np.mean(err**2))) if err.size else math.nan


def calibrate(
    vehicle: Vehicle,
    terrain: Terrain,
    powertrain: Powertrain,
    segments: Sequence[Segment],
    fit: Sequence[str] = DEFAULT_FIT,
    *,
    holdout: float = 0.3,
    seed: int = 0,
    ident_tol_Nm: float | None = None,
    dropped: dict[str, int] | None = None,
    fit_at: str = 'setpoints',
) -> CalibrationResult:
    """Fit ``fit`` (names of :data:`PARAMS`) to ``segments``; see the module doc for the method
    and for ``fit_at`` ('setpoints': the commands at their set points, 'motion': the measured motion).

    ``ident_tol_Nm`` : RMS torque change [N m] below which a 10 % parameter change counts as
    invisible (None: 0.2 % of the RMS measured torque, at least 1e-3 N m).
    """
    started = time.perf_counter()
    if fit_at not in FIT_AT:
        raise InputError(f'--fit-at must be one of {", ".join(FIT_AT)}, not {fit_at!r}')
    segments = list(segments)
    fit_idx, hold_idx = split_holdout(len(segments), holdout, seed)
    model = segment_model(vehicle, terrain, powertrain, segments, fit_at)
    measured = np.array([s.motor_torque_Nm for s in segments])
    candidates = list(dict.fromkeys([*fit, *[k for k in TERRAIN_PARAMS if k not in fit]]))
    start = {n: model.start_value(n) for n in candidates}
    for name in fit:
        lo, hi = PARAMS[name].bounds
        if not lo <= start[name] <= hi:
            raise InputError(
                f'starting {name} = {start[name]:.6g} {PARAMS[name].unit} '
                f'is outside the fit bounds [{lo:g}, {hi:g}]'
            )
    # sensitivity of the torques to a 10 % change of every candidate, at the start
    base_torque, base_omega, base_ok = model.predict({})
    if not np.all(base_ok):
        bad = np.flatnonzero(~base_ok)
        raise InputError(
            f'FESS has no steady state on the starting terrain for {bad.size} segment(s), e.g. '
            f'V = {model.speed[bad[0]]:.3g} m/s, yaw rate {model.yaw[bad[0]]:.3g} rad/s: '
            'choose a closer --terrain'
        )
    rms_measured = float(np.sqrt(np.mean(measured**2)))
    tol = ident_tol_Nm if ident_tol_Nm is not None else max(1e-3, 0.002 * rms_measured)
    columns: dict[str, np.ndarray] = {}
    for name in candidates:
        step = 0.1 * start[name] if start[name] != 0 else 0.01
        torque, _, ok = model.predict({name: start[name] + step})
        columns[name] = np.where(ok[:, None], torque - base_torque, 0.0).ravel()
    sensitivity = {n: _rmse(col) for n, col in columns.items()}
    names, unexplained = select_identifiable(columns, fit, tol)
    identifiable = {n: bool(unexplained[n] >= tol) for n in candidates}
    if not names:
        raise InputError('no parameter in --fit changes the predicted torque visibly on these segments')
    m, p = 2 * fit_idx.size, len(names)
    if m <= p:
        raise InputError(f'{fit_idx.size} fit segment(s) give {m} torques: too few for {p} parameters')

    z0 = np.array([_to_z(n, start[n]) for n in names])
    lower = np.array(
        [
            _to_z(n, PARAMS[n].bounds[0]) if PARAMS[n].bounds[0] > 0 or not PARAMS[n].log else -np.inf
            for n in names
        ]
    )
    upper = np.array([_to_z(n, PARAMS[n].bounds[1]) for n in names])
    z0 = np.clip(z0, lower + 1e-9, upper - 1e-9)

    def residuals(z: np.ndarray) -> np.ndarray:
        torque, _, ok = model.predict(_values(names, z))
        err = torque[fit_idx] - measured[fit_idx]
        err[~ok[fit_idx]] = FAILED_RESIDUAL_NM
        flat: np.ndarray = err.ravel()
        return flat

    sol = optimize.least_squares(
        residuals,
        z0,
        bounds=(lower, upper),
        loss='soft_l1',
        f_scale=max(tol, 0.02 * rms_measured),
        x_scale='jac',
        diff_step=DIFF_STEP,
        method='trf',
        max_nfev=60 * (p + 1),
    )
    fitted = _values(names, sol.x)
    r = residuals(sol.x)
    jac = sol.jac
    at_bound = bound_hits(names, sol.x, lower, upper)
    free = np.array([n not in at_bound for n in names])
    dof = max(1, m - int(free.sum()))
    s2 = float(r @ r) / dof
    # a parameter pinned at a bound is no estimate: no interval, and the others' covariance is that
    # of the free parameters with it held (the Jacobian's pinned columns dropped)
    cov_z = np.zeros((p, p))
    cov_z[np.ix_(free, free)] = s2 * np.linalg.pinv(jac[:, free].T @ jac[:, free])
    sigma_z = np.sqrt(np.clip(np.diag(cov_z), 0.0, None))
    t = float(stats.t.ppf(0.975, dof))
    ci95: dict[str, tuple[float, float] | None] = {}
    deriv = np.empty(p)
    for k, name in enumerate(names):
        deriv[k] = fitted[name] if PARAMS[name].log else 1.0
        if name in at_bound:
            ci95[name] = None
            continue
        lo = _from_z(name, sol.x[k] - t * sigma_z[k])
        hi = _from_z(name, sol.x[k] + t * sigma_z[k])
        ci95[name] = (lo, hi)
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
    after_torque, after_omega, after_ok = model.predict(fitted)
    err_idx = hold_idx if hold_idx.size else fit_idx
    values = {n: fitted.get(n, start[n]) for n in candidates}
    for n in candidates:
        ci95.setdefault(n, None)
    terrain_fit, powertrain_fit = model.with_values(fitted)
    before_error = _energy_error(segments, hold_idx, base_torque, base_omega, powertrain.motor)
    after_error = _energy_error(segments, hold_idx, after_torque, after_omega, powertrain_fit.motor)
    if abs(after_error) > abs(before_error):
        warnings.append(
            f'the hold-out energy error grew with calibrating ({before_error:+.1%} -> {after_error:+.1%} '
            f'at the {fit_at}): the fit segments do not represent the hold-out ones (more, or other, drives)'
        )
    return CalibrationResult(
        names=names,
        values=values,
        start=start,
        ci95=ci95,
        sensitivity_Nm=sensitivity,
        identifiable=identifiable,
        covariance=covariance,
        correlation=correlation,
        correlations_warnings=warnings,
        segments_fit=int(fit_idx.size),
        segments_holdout=int(hold_idx.size),
        torque_rmse_before_Nm=_rmse(base_torque[err_idx] - measured[err_idx]),
        torque_rmse_after_Nm=_rmse(after_torque[err_idx] - measured[err_idx]),
        holdout_energy_error_before=before_error,
        holdout_energy_error_after=after_error,
        residual_rms_Nm=_rmse(r),
        seconds=time.perf_counter() - started,
        terrain=terrain_fit,
        powertrain=powertrain_fit,
        dropped=dict(dropped or {}),
        converged=bool(sol.success) and bool(np.all(after_ok)),
        at_bound=at_bound,
        jacobian_z=np.asarray(jac),
        z=np.asarray(sol.x),
        residual_variance=s2,
        measured_Nm=measured,
        before_Nm=base_torque,
        after_Nm=after_torque,
        holdout_index=hold_idx,
        setpoints=setpoint_check(vehicle, terrain_fit, powertrain_fit, segments, measured, err_idx, hold_idx),
        fit_at=fit_at,
    )


def segment_model(
    vehicle: Vehicle, terrain: Terrain, powertrain: Powertrain, segments: Sequence[Segment], fit_at: str
) -> Model:
    """The :class:`Model` of ``segments``: at their commands ('setpoints') or measured motion ('motion')."""
    if fit_at == 'setpoints':
        at = np.array([s.command for s in segments], dtype=float).reshape(-1, 2)
    else:
        at = np.array([(s.speed_m_s, s.yaw_rate_rad_s) for s in segments], dtype=float).reshape(-1, 2)
    return Model(vehicle, terrain, powertrain, at[:, 0], at[:, 1], fit_at)


def setpoint_check(
    vehicle: Vehicle,
    terrain: Terrain,
    powertrain: Powertrain,
    segments: Sequence[Segment],
    measured: np.ndarray,
    err_idx: np.ndarray,
    hold_idx: np.ndarray,
) -> dict[str, float]:
    """The fitted terrain and powertrain predicting each segment from its COMMAND, at the wheel
    speed set points (issue 25), whatever the fit was solved at (with ``fit_at`` 'setpoints' the
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
    torque = np.empty_like(pred.torque)
    omega = np.empty_like(pred.torque)
    for i, side in enumerate(('left', 'right')):
        point = powertrain.motor_side(side, pred.torque[:, i], pred.setpoint[:, i])
        torque[:, i], omega[:, i] = point.motor_torque_Nm, point.motor_omega_rad_s
    speed = np.array([seg.speed_m_s for seg in segments])
    yaw = np.array([seg.yaw_rate_rad_s for seg in segments])
    with np.errstate(invalid='ignore', divide='ignore'):
        speed_err = np.abs(pred.speed - speed) / np.abs(speed)
        yaw_err = np.abs(pred.yaw_rate - yaw) / np.abs(yaw)
    return {
        'torque_rmse_Nm': _rmse(torque[err_idx] - measured[err_idx]),
        'holdout_energy_error': _energy_error(segments, hold_idx, torque, omega, powertrain.motor),
        'speed_error_median': float(np.nanmedian(np.where(np.abs(speed) > 1e-3, speed_err, np.nan))),
        'yaw_rate_error_median': float(np.nanmedian(np.where(np.abs(yaw) > 1e-3, yaw_err, np.nan))),
        'limited_segments': int(np.sum(pred.limited)),
    }
