"""Internal resistance of a skid-steer drivetrain (ch. 7.2, eqs. 7.1-7.4, Table 7.1) and its fit.

Each component of one side's drivetrain (motor, gear train, roller chain, and for tracks the track and
sprockets) resists with a viscous plus a Coulomb torque, referred to the **motor shaft** because every
coefficient was measured from motor current and motor speed (eqs. 7.1, 7.3, 7.4):

    T_k(omega_m) = b_k omega_m + c_k sign(omega_m)          [N m]       (7.1)
    P_k(omega_m) = b_k omega_m^2 + c_k |omega_m|            [W]         (7.2)

Eq. (7.3) and (7.4) identify the gear train, roller chain and track by subtracting the previous
assembly's fit from the next one, so a component's coefficients are differences of cumulative fits.
Eq. (7.4) names omega "the rotational speed of the sprockets", but its right-hand side subtracts the
motor's and gear train's terms, which use the motor speed, from the same motor-current torque: the
equation is only consistent with motor-shaft speed, which is what we use (the track's viscous term
is so small that the choice changes its power by < 1 % at mission speeds anyway).

Table 7.1 (the decision, recorded here, in ``config/powertrains/test_robot.yaml`` and in
docs/PHYSICS_NOTES.md): the table heads its columns "a, a_g, a_c, a_t" and "b, b_g, b_c, b_t", while
the equations call the viscous constants b, b_g, b_r, b_t and the Coulomb constants c, c_g, c_r, c_t.

* the first column (1e-4) is the viscous, the second (0.02-0.65) the Coulomb coefficient (a Coulomb
  term of 1e-4 would be invisible in Figures 7.12-7.14);
* the values are **torques** at the motor shaft, N m s/rad and N m, as eq. 7.1 defines b and c
  (K_t i = b omega + c) and as the text says they are "listed in Table 7.1". This literal reading is
  the model the dissertation's chapter 8 results were computed with: only under it does the tracked
  Packbot use more energy than the wheeled ones (ch. 8.1-8.4, 9.1).

Against it, kept on record: the EC-45 alone would then draw (0.0617 + 0.0001 x 420) / K_t = 0.91 A at
its no-load speed, 4.7 x Appendix B's 193 mA; read as motor *currents* (A per rad/s and A) the motor
draws 0.104 A, which fits the hardware better. That alternative is a data-only change: give the
components ``viscous_A_s``/``coulomb_A`` instead of ``viscous_Nm_s``/``coulomb_Nm``.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.numeric import Real, real, sign

COMPONENTS = ('motor', 'gear_train', 'roller_chain', 'track')
"""Drivetrain components in assembly order (ch. 7.2.1-7.2.3)."""

LUMPED = 'lumped'
"""The component name of a lumped side (:func:`side_from_config`); ``drivetrain``, its name before
(issue 38: "drivetrain" also named the vehicle file's joint mapping), is still read."""
LUMPED_EARLIER = 'drivetrain'

COMPONENTS_BY_RUNNING_GEAR = {
    'track': COMPONENTS,
    # ch. 7.2.3: wheels are assumed rigid, no loss between running gear and axle.
    'wheel': ('motor', 'gear_train', 'roller_chain'),
}


@dataclass(frozen=True)
class Resistance:
    """Viscous plus Coulomb resistance at the motor shaft (eq. 7.1).

    Attributes
    ----------
    viscous_Nm_s : viscous damping constant b [N m s / rad]
    coulomb_Nm : Coulomb friction constant c [N m]
    """

    viscous_Nm_s: float
    coulomb_Nm: float

    def torque(self, motor_omega_rad_s: Real) -> Real:
        """Resisting torque b omega + c sign(omega) [N m] at motor speed omega [rad/s] (eq. 7.1); a
        float or an array (:mod:`skidsteer_power.numeric`)."""
        omega = real(motor_omega_rad_s)
        return self.viscous_Nm_s * omega + self.coulomb_Nm * sign(omega)

    def power(self, motor_omega_rad_s: Real) -> Real:
        """Dissipated power b omega^2 + c |omega| [W] (eq. 7.2); never negative for b, c >= 0."""
        omega = real(motor_omega_rad_s)
        power: Real = self.torque(omega) * omega
        return power

    def __add__(self, other: Resistance) -> Resistance:
        return Resistance(self.viscous_Nm_s + other.viscous_Nm_s, self.coulomb_Nm + other.coulomb_Nm)

    def __sub__(self, other: Resistance) -> Resistance:
        return Resistance(self.viscous_Nm_s - other.viscous_Nm_s, self.coulomb_Nm - other.coulomb_Nm)


@dataclass(frozen=True)
class SideResistance:
    """The components of one side's drivetrain, each a :class:`Resistance` at the motor shaft."""

    components: Mapping[str, Resistance] = field(default_factory=dict)

    @functools.cached_property
    def total(self) -> Resistance:
        """Sum of all components (eq. 7.4's left-hand side); computed once (per message otherwise)."""
        total = Resistance(0.0, 0.0)
        for part in self.components.values():
            total = total + part
        return total

    def torque(self, motor_omega_rad_s: Real) -> Real:
        """Total resisting torque at the motor shaft [N m] for motor speed [rad/s]."""
        return self.total.torque(motor_omega_rad_s)

    def power(self, motor_omega_rad_s: Real) -> Real:
        """Total dissipated power [W] for motor speed [rad/s] (sum of eq. 7.2 over components)."""
        return self.total.power(motor_omega_rad_s)

    def component_power(self, motor_omega_rad_s: Real) -> dict[str, Real]:
        """Dissipated power of each component [W] (Figure 7.14's breakdown)."""
        return {name: part.power(motor_omega_rad_s) for name, part in self.components.items()}


def side_from_config(
    entries: Mapping[str, Mapping[str, float]], torque_constant_Nm_A: float, running_gear: str
) -> SideResistance:
    """Build one side from a config mapping ``component -> coefficients``.

    Each component gives either torques (``viscous_Nm_s``, ``coulomb_Nm``; the project's reading of
    Table 7.1) or motor currents (``viscous_A_s``, ``coulomb_A``; converted with K_t [N m/A]).
    Components not used by ``running_gear`` ('track' | 'wheel') are dropped (ch. 7.2.3). A side of
    one component ``lumped`` is the whole side lumped (motor to running gear, as one viscous plus
    Coulomb term at the motor shaft: what a robot's measured battery power identifies, issue 35).
    """
    try:
        wanted = COMPONENTS_BY_RUNNING_GEAR[running_gear]
    except KeyError:
        raise ConfigError(f"running_gear must be 'track' or 'wheel', not {running_gear!r}") from None
    if set(entries) == {LUMPED_EARLIER}:  # its earlier name: the same part, and the owner learns it
        note = f"internal resistance: the component '{LUMPED_EARLIER}' is now spelled '{LUMPED}'"
        warnings.warn(note + ' (the old name still works)', FutureWarning, stacklevel=2)
        entries = {LUMPED: entries[LUMPED_EARLIER]}
    if set(entries) == {LUMPED}:
        wanted = (LUMPED,)
    parts: dict[str, Resistance] = {}
    for name in wanted:
        if name not in entries:
            raise ConfigError(f'internal resistance: component {name!r} missing for {running_gear}')
        parts[name] = _resistance(name, entries[name], torque_constant_Nm_A)
    return SideResistance(parts)


def _resistance(name: str, entry: Mapping[str, float], kt: float) -> Resistance:
    try:
        if 'viscous_Nm_s' in entry:
            b, c = float(entry['viscous_Nm_s']), float(entry['coulomb_Nm'])
        else:
            b, c = kt * float(entry['viscous_A_s']), kt * float(entry['coulomb_A'])
    except (KeyError, TypeError, ValueError) as err:
        raise ConfigError(
            f'internal resistance {name!r}: need viscous_Nm_s + coulomb_Nm or viscous_A_s + coulomb_A ({err})'
        ) from err
    if not (np.isfinite(b) and np.isfinite(c)) or b < 0 or c < 0:
        raise ConfigError(f'internal resistance {name!r}: coefficients must be finite and >= 0')
    return Resistance(b, c)


@dataclass(frozen=True)
class InternalFit:
    """Least-squares fit of eq. (7.1), K_t i = b omega + c sign(omega), to no-load samples.

    Attributes
    ----------
    viscous_Nm_s : fitted b [N m s / rad]
    coulomb_Nm : fitted c [N m]
    rms_residual_Nm : root-mean-square torque residual [N m]
    n_samples : number of samples used (samples at omega = 0 are dropped: sign undefined)
    """

    viscous_Nm_s: float
    coulomb_Nm: float
    rms_residual_Nm: float
    n_samples: int

    @property
    def resistance(self) -> Resistance:
        return Resistance(self.viscous_Nm_s, self.coulomb_Nm)

    def as_dict(self) -> dict[str, float | int]:
        return {
            'viscous_Nm_s': self.viscous_Nm_s,
            'coulomb_Nm': self.coulomb_Nm,
            'rms_residual_Nm': self.rms_residual_Nm,
            'n_samples': self.n_samples,
        }


def fit_internal(
    motor_omega_rad_s: Sequence[float] | np.ndarray, torque_Nm: Sequence[float] | np.ndarray
) -> InternalFit:
    """Fit b and c of eq. (7.1) by linear least squares (numpy lstsq) to no-load samples.

    ``motor_omega_rad_s`` is the motor speed [rad/s], ``torque_Nm`` the motor torque K_t i [N m].
    Both directions of rotation may be mixed. Raises InputError for too few or non-finite samples,
    or if all samples share one speed (b and c are then not separable).
    """
    omega = np.asarray(motor_omega_rad_s, dtype=float).ravel()
    torque = np.asarray(torque_Nm, dtype=float).ravel()
    if omega.shape != torque.shape:
        raise InputError(f'speed and torque sample counts differ: {omega.size} vs {torque.size}')
    if not (np.all(np.isfinite(omega)) and np.all(np.isfinite(torque))):
        raise InputError('speed/current samples contain NaN or inf')
    moving = omega != 0.0
    omega, torque = omega[moving], torque[moving]
    design = np.column_stack([omega, np.sign(omega)])
    if omega.size < 2 or np.linalg.matrix_rank(design) < 2:
        raise InputError('need moving samples at two or more distinct speeds to fit b and c (eq. 7.1)')
    (b, c), *_ = np.linalg.lstsq(design, torque, rcond=None)
    rms = float(np.sqrt(np.mean((design @ np.array([b, c]) - torque) ** 2)))
    return InternalFit(float(b), float(c), rms, int(omega.size))


def components_from_stages(stage_fits: Mapping[str, InternalFit]) -> dict[str, Resistance]:
    """Component coefficients from cumulative assembly fits (eqs. 7.3, 7.4).

    ``stage_fits`` maps each assembly stage ('motor', 'gear_train', 'roller_chain', 'track'; the
    stage named after the last component added) to the fit of the whole assembly at that stage; each
    component is its stage minus the previous stage present.
    """
    parts: dict[str, Resistance] = {}
    previous = Resistance(0.0, 0.0)
    for name in COMPONENTS:
        if name in stage_fits:
            cumulative = stage_fits[name].resistance
            parts[name] = cumulative - previous
            previous = cumulative
    unknown = set(stage_fits) - set(COMPONENTS)
    if unknown:
        raise InputError(f'unknown stage(s) {sorted(unknown)}; use {", ".join(COMPONENTS)}')
    return parts
