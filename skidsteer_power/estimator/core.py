"""The estimator core: commands and motor readings in; predictions, measurements, energy out.

:class:`EstimatorCore` holds no ROS object: every method takes the current time ``now_s`` [s]
(any monotonic clock), so it runs the same in a node, a replay or a unit test.

Physically impossible power never stops it. A joint_states reading within the input limits can still
ask more battery-side power than the battery can deliver at all (``Battery.max_power_W``, the
maximum-power-transfer bound OCV^2 / 4R at the lowest OCV): such a reading is SKIPPED (not fed to the
energy integral, so the measured source goes stale and the prediction takes over), counted in
``implausible['joint_states']`` and raised as :class:`RejectedInput`. A prediction beyond the bound is
CLAMPED to it and counted in ``implausible['predictions']``. Either makes :meth:`EstimatorCore.diagnostics`
WARN for :data:`IMPLAUSIBLE_WARN_S`. So the battery model is only ever stepped with a power it can
deliver, and no measurement can make a timer callback raise.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from skidsteer_power.errors import ConfigError, InputError
from skidsteer_power.estimator.adaptation import AdaptationSettings, Correction, TorqueAdaptation
from skidsteer_power.estimator.energy import EnergyTracker
from skidsteer_power.estimator.inputs import (
    TEST_ROBOT_JOINTS,
    Freshness,
    InputLimits,
    JointMap,
    JointReader,
    RejectCounter,
    check_command,
)
from skidsteer_power.estimator.measured import MeasuredPower, measure_battery_power, measure_motor_power
from skidsteer_power.estimator.persistence import battery_tallies, restored_tallies
from skidsteer_power.estimator.prediction import Prediction, Predictor
from skidsteer_power.estimator.tte_bounds import TimeToEmptyBounds
from skidsteer_power.powertrain.battery import BatteryState
from skidsteer_power.powertrain.motor import bus_power, terminal_power
from skidsteer_power.seams import BatteryModel, PowertrainLike

if TYPE_CHECKING:
    from skidsteer_power.jsonout import JsonObject

LEVEL_OK, LEVEL_WARN, LEVEL_ERROR = 0, 1, 2
IMPLAUSIBLE_WARN_S = 10.0
"""Diagnostics stay WARN this long after the last implausible reading or prediction [s]."""
TERRAIN_CHANGE_SHOWN_S = 10.0  # diagnostics warn "terrain changed" this long after a detection [s]


def adaptation_values(c: Correction, enabled: bool) -> dict[str, str]:
    """Diagnostic key/values of a :class:`~skidsteer_power.estimator.adaptation.Correction`."""
    return {
        'adaptation': 'on' if enabled else 'off',
        'terrain_changes': str(c.terrain_changes),
        'terrain_changed_at_s': f'{c.last_change_s:.3f}',
        'correction_scale_left': f'{c.scale[0]:.4f}',
        'correction_scale_right': f'{c.scale[1]:.4f}',
        'correction_offset_left_Nm': f'{c.offset_Nm[0]:.4f}',
        'correction_offset_right_Nm': f'{c.offset_Nm[1]:.4f}',
        'terrain_scale': f'{c.terrain_scale:.4f}',
    }


def outside_map(prediction: Prediction) -> bool:
    """True if the map did not cover the command: outside its envelope (``clamped``) or at a physics
    limit (``limited``: a spin or a turn tighter than the small-radius limit, or no steady state)."""
    return bool(prediction.clamped or prediction.limited)


class RejectedInput(InputError):
    """An input message was rejected; ``warn`` says whether the throttled warning is due."""

    def __init__(self, message: str, warn: bool) -> None:
        super().__init__(message)
        self.warn = warn


@dataclass(frozen=True)
class EstimatorSettings:
    """Tunables of the core (the node declares each as a parameter).

    cmd_timeout_s, joint_timeout_s : an input older than this is stale [s]
    traction_warning_margin : warn when the traction margin falls to this or below [-]
    power_filter_s : time constant of the power filter behind time to empty [s]
    warn_period_s : least time between two warnings about rejected inputs on one topic [s]
    joint_map : which joint_states joints belong to each side, and their units (:class:`JointMap`)
    """

    cmd_timeout_s: float = 0.5
    joint_timeout_s: float = 0.5
    traction_warning_margin: float = 0.1
    power_filter_s: float = 5.0
    warn_period_s: float = 2.0
    limits: InputLimits = field(default_factory=InputLimits)
    joint_map: JointMap = TEST_ROBOT_JOINTS

    def __post_init__(self) -> None:
        for name in ('cmd_timeout_s', 'joint_timeout_s', 'warn_period_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f'{name} must be a finite number > 0, got {value!r}')
        if not (math.isfinite(self.power_filter_s) and self.power_filter_s >= 0):
            raise ConfigError(f'power_filter_s must be >= 0, got {self.power_filter_s!r}')
        if not math.isfinite(self.traction_warning_margin):
            raise ConfigError('traction_warning_margin must be finite')


@dataclass(frozen=True)
class Comparison:
    """Measured against predicted, per side (left, right): error = measured - predicted.

    torque_error_Nm : motor torque error [N m]; power_error_W : motor terminal power error [W];
    NaN when no prediction exists yet.
    """

    measured: MeasuredPower
    torque_error_Nm: tuple[float, float]
    power_error_W: tuple[float, float]


class EstimatorCore:
    """Per-command prediction, per-reading measurement, battery integration and diagnostics.

    ``battery`` is a :class:`skidsteer_power.seams.BatteryModel` (e.g.
    :class:`skidsteer_power.powertrain.Battery`); ``powertrain`` (a
    :class:`skidsteer_power.seams.PowertrainLike`, e.g. :class:`skidsteer_power.powertrain.Powertrain`)
    gives the motor and amplifier that convert joint_states into power.
    """

    def __init__(
        self,
        predictor: Predictor,
        battery: BatteryModel,
        powertrain: PowertrainLike,
        settings: EstimatorSettings | None = None,
        adaptation: AdaptationSettings | None = None,
    ) -> None:
        self.settings = settings or EstimatorSettings()
        # online correction of the prediction and terrain-change detection (estimator/adaptation.py),
        # time-to-empty bounds (estimator/tte_bounds.py)
        self.adaptation = TorqueAdaptation(adaptation)
        self.tte_bounds = TimeToEmptyBounds()
        self.time_to_empty_p10_s = self.time_to_empty_p90_s = math.inf
        self.predictor = predictor
        self.powertrain = powertrain
        self.energy = EnergyTracker(
            battery,
            measured_timeout_s=self.settings.joint_timeout_s,
            predicted_timeout_s=self.settings.cmd_timeout_s,
            filter_s=self.settings.power_filter_s,
        )
        self.rejects = RejectCounter(period_s=self.settings.warn_period_s)
        self.cmd_fresh = Freshness(self.settings.cmd_timeout_s)
        self.joint_fresh = Freshness(self.settings.joint_timeout_s)
        self.joints = JointReader(
            self.settings.joint_map,
            powertrain.gear_ratio,
            powertrain.motor.torque_constant_Nm_A,
            self.settings.limits,
        )
        self.prediction: Prediction | None = None
        self.expired_commands = 0  # commands that went stale: the prediction fell back to standing
        self.standing = False  # the prediction is standing still's (the last command went stale)
        self.comparison: Comparison | None = None
        self.command: tuple[float, float] | None = None
        self.clamped_count = 0
        self.outside_map_count = 0
        self.no_data_count = 0  # joint_states saying "no fresh data" (NaN): neither used nor rejected
        self.time_to_empty_s = math.inf
        self.implausible: Counter[str] = Counter()
        self._implausible_s: float | None = None
        self._limit_of: BatteryModel | None = None  # the battery whose power limit is in _limit_W [W]
        self._limit_W = math.inf
        self._uncorrected_bus: tuple[Prediction | None, float] = (None, 0.0)  # (prediction, its bus W)

    @property
    def battery(self) -> BatteryModel:
        return self.energy.battery

    def _reject(self, topic: str, err: InputError, now_s: float) -> RejectedInput:
        return RejectedInput(f'{topic}: {err}', self.rejects.reject(topic, now_s))

    def on_command(
        self, speed_m_s: float, yaw_rate_rad_s: float, now_s: float, hold_s: float | None = None
    ) -> Prediction:
        """Predict for a cmd_vel (V [m/s], yaw rate [rad/s]); raises RejectedInput for a bad one.

        The command is in force for ``hold_s`` [s] (None: ``settings.cmd_timeout_s``); offline
        validation passes each recorded command's hold (:mod:`skidsteer_power.validation.cmd_timing`).
        """
        try:
            speed, yaw_rate = check_command(speed_m_s, yaw_rate_rad_s, self.settings.limits)
        except InputError as err:
            raise self._reject('cmd_vel', err, now_s) from err
        self.cmd_fresh.mark(now_s)
        self.cmd_fresh.timeout_s = self.settings.cmd_timeout_s if hold_s is None else float(hold_s)
        self.command = (speed, yaw_rate)
        self.standing = False
        self.adaptation.on_command(self.command, now_s)
        return self._update_prediction(now_s)

    def _update_prediction(self, now_s: float) -> Prediction:
        assert self.command is not None
        self.prediction = self.predictor.predict(*self.command)
        self.clamped_count += int(self.prediction.clamped)
        self.outside_map_count += int(outside_map(self.prediction))
        power = self.corrected_bus_W()  # the online correction feeds the battery forecast
        limit = self.power_limit_W()
        if not abs(power) <= limit:  # NaN too
            self._flag_implausible('predictions', now_s)
            power = math.copysign(limit, power) if not math.isnan(power) else 0.0
        self.energy.set_predicted(power, now_s, self.cmd_fresh.timeout_s)
        return self.prediction

    def power_limit_W(self) -> float:
        """Largest battery-side power [W] the battery can deliver (inf if the battery does not say);
        asked of each battery once (twice per input pair otherwise)."""
        battery = self.battery
        if battery is not self._limit_of:
            self._limit_W = float(battery.max_power_W())
            self._limit_of = battery
        return self._limit_W

    def _flag_implausible(self, what: str, now_s: float) -> None:
        self.implausible[what] += 1
        self._implausible_s = now_s

    def corrected_torque_Nm(self) -> tuple[float, float]:
        """Predicted motor torques [N m] with the online correction applied (left, right)."""
        assert self.prediction is not None
        return self.adaptation.corrected(self.prediction.motor_torque_Nm)

    def corrected_terminal_W(self) -> tuple[float, float]:
        """Motor terminal power [W] (left, right) of the corrected prediction, at the predicted motor
        speeds (validate's ``online_power_*`` where the measurement is not battery-side:
        :func:`skidsteer_power.validation.online.online_columns`)."""
        p = self.prediction
        assert p is not None
        left, right = (
            float(terminal_power(self.powertrain.motor, torque, omega))
            for torque, omega in zip(self.corrected_torque_Nm(), p.motor_omega_rad_s, strict=True)
        )
        return left, right

    def corrected_bus_W(self) -> float:
        """Battery power [W] of the corrected prediction: the prediction's own plus the change the
        correction makes through the motor and amplifier at the predicted motor speeds (exactly the
        prediction's when uncorrected, whatever the predictor put in ``bus_W``)."""
        p = self.prediction
        assert p is not None
        corrected = self.corrected_torque_Nm()
        if corrected == p.motor_torque_Nm:  # adaptation off or not yet settled: the common case
            return p.bus_total_W
        if self._uncorrected_bus[0] is not p:  # per prediction: a held command repeats it
            self._uncorrected_bus = (p, self._bus_W(p, p.motor_torque_Nm))
        return p.bus_total_W + self._bus_W(p, corrected) - self._uncorrected_bus[1]

    def _bus_W(self, p: Prediction, torques: tuple[float, float]) -> float:
        """Battery power [W] of motor ``torques`` [N m] at ``p``'s motor speeds."""
        pt = self.powertrain
        return sum(
            bus_power(terminal_power(pt.motor, torque, omega), pt.amplifier, pt.regen_efficiency)
            for torque, omega in zip(torques, p.motor_omega_rad_s, strict=True)
        )

    def set_predictor(self, predictor: Predictor, now_s: float) -> Prediction | None:
        """Swap the predictor (a terrain change); re-predict the current command with it."""
        self.energy.advance(now_s)
        self.predictor = predictor
        if self.command is None:
            return None
        return self._update_prediction(now_s) if self.cmd_fresh.is_fresh(now_s) else None

    def on_joint_state(
        self,
        names: Sequence[str],
        velocity: Sequence[float],
        effort: Sequence[float],
        now_s: float,
        position: Sequence[float] = (),
    ) -> Comparison | None:
        """Measure power from joint_states, mapped to the sides by ``settings.joint_map``; raises
        RejectedInput for a bad one. None while a speed differentiated from positions needs a second
        sample, and for a message saying "no fresh data" (NaN in every field of a joint; counted in
        ``no_data_count``)."""
        try:
            reading = self.joints.read(names, position, velocity, effort, now_s)
        except InputError as err:
            if self.joints.no_data(names, position, velocity, effort):  # checked only on this path
                self.no_data_count += 1
                return None
            raise self._reject('joint_states', err, now_s) from err
        if reading is None:
            return None
        omega, torque = reading
        pt = self.powertrain
        if self.settings.joint_map.measures_battery:  # the "torque" is the side's V x I [W]
            measured = measure_battery_power(omega, torque, pt)
            torque = measured.torque_Nm
        else:
            measured = measure_motor_power(omega, torque, pt.motor, pt.amplifier, pt.regen_efficiency)
        limit = self.power_limit_W()
        if not abs(measured.bus_total_W) <= limit:
            self._flag_implausible('joint_states', now_s)
            reason = InputError(
                f'implausible reading skipped: battery-side power {measured.bus_total_W:.0f} W is more '
                f'than the battery can deliver ({limit:.0f} W)'
            )
            raise self._reject('joint_states', reason, now_s)
        self.joint_fresh.mark(now_s)
        self.energy.set_measured(measured.bus_total_W, now_s)
        self.comparison = self._compare(measured)
        p = self.prediction
        if p is not None and self.cmd_fresh.is_fresh(now_s):
            terrain = (p.terrain_torque_Nm[0] / pt.gear_ratio, p.terrain_torque_Nm[1] / pt.gear_ratio)
            self.adaptation.update(now_s, p.motor_torque_Nm, p.motor_omega_rad_s, torque, omega, terrain)
        return self.comparison

    def _compare(self, measured: MeasuredPower) -> Comparison:
        p = self.prediction
        if p is None:
            nan = (math.nan, math.nan)
            return Comparison(measured, nan, nan)
        return Comparison(
            measured,
            (measured.torque_Nm[0] - p.motor_torque_Nm[0], measured.torque_Nm[1] - p.motor_torque_Nm[1]),
            (measured.electrical_W[0] - p.electrical_W[0], measured.electrical_W[1] - p.electrical_W[1]),
        )

    def tick(self, now_s: float) -> None:
        """Integrate the battery up to ``now_s`` and refresh the time to empty [s].

        Call from a timer, so the gauge moves between inputs; the time to empty (an integral over the
        battery's voltage curve) is refreshed only here, not per message.
        """
        self._expire_command(now_s)
        self.energy.advance(now_s)
        self.energy.flush()
        self.time_to_empty_s = self.energy.time_to_empty_s()
        self.tte_bounds.add(now_s, self.energy.power_W(now_s))
        model_spread = 0.0
        if self.energy.source(now_s) == 'predicted' and self.prediction is not None:
            model_spread = self.adaptation.state().relative_residual(self.prediction.motor_torque_Nm)
        self.time_to_empty_p10_s, self.time_to_empty_p90_s = self.tte_bounds.bounds(
            self.battery, self.energy.filtered_power_W, model_spread
        )

    def _expire_command(self, now_s: float) -> None:
        """A command older than its hold is no command: the driver's watchdog holds the motors at zero,
        so the prediction becomes that of standing still (V = 0, yaw rate 0: idle power), never the
        last moving command's (issue 37 item 4). Counted in ``expired_commands``; the energy is not
        charged with it (the hold of the last command ended: the energy source says so)."""
        if self.command is None or self.standing or self.cmd_fresh.is_fresh(now_s):
            return
        # ``command`` stays the last one given (the path energy plans at its speed: path_hook.py)
        self.prediction = self.predictor.predict(0.0, 0.0)
        self.standing = True
        self.expired_commands += 1

    def traction_warning(self) -> bool:
        """True when the last prediction's traction margin is at or below the warning margin."""
        p = self.prediction
        return p is not None and p.traction_margin <= self.settings.traction_warning_margin

    def diagnostics(self, now_s: float) -> tuple[int, str, dict[str, str]]:
        """(level, message, key/values) describing the estimator at ``now_s``."""
        self.energy.flush()
        problems = []
        notes = []  # not problems: standing still on a stale command is the normal idle state
        if not self.cmd_fresh.is_fresh(now_s):
            notes.append('standing: cmd_vel stale, commanded zero')
        if not self.joint_fresh.is_fresh(now_s):
            problems.append('joint_states stale')
        if self.traction_warning():
            problems.append('traction margin low: robot may get stuck')
        outside = (
            self.prediction is not None and self.cmd_fresh.is_fresh(now_s) and outside_map(self.prediction)
        )
        if outside:
            problems.append('command outside the power map: prediction clamped or limited')
        correction = self.adaptation.state()
        if now_s - correction.last_change_s <= TERRAIN_CHANGE_SHOWN_S:
            problems.append('terrain changed: adaptation restarted')
        if self._implausible_s is not None and now_s - self._implausible_s <= IMPLAUSIBLE_WARN_S:
            problems.append('implausible power (beyond what the battery can deliver) skipped or clamped')
        clock_problem, clock_values = self.energy.clock_diagnostics(now_s)
        if clock_problem:
            problems.append(clock_problem)
        level = LEVEL_WARN if problems else LEVEL_OK
        source = self.energy.source(now_s)
        values = {
            'energy_source': source,
            'cmd_vel_age_s': f'{self.cmd_fresh.age_s(now_s):.3f}',
            'joint_states_age_s': f'{self.joint_fresh.age_s(now_s):.3f}',
            'cmd_vel_stale': str(not self.cmd_fresh.is_fresh(now_s)).lower(),
            'joint_states_stale': str(not self.joint_fresh.is_fresh(now_s)).lower(),
            'rejected_cmd_vel': str(self.rejects.counts['cmd_vel']),
            'rejected_joint_states': str(self.rejects.counts['joint_states']),
            'joint_states_no_data': str(self.no_data_count),
            'clamped_commands': str(self.clamped_count),
            'expired_commands': str(self.expired_commands),
            'command_outside_map': str(outside).lower(),
            'commands_outside_map': str(self.outside_map_count),
            'implausible_joint_states': str(self.implausible['joint_states']),
            'implausible_predictions': str(self.implausible['predictions']),
            'energy_measured_J': f'{self.energy.energy_J["measured"]:.3f}',
            'energy_predicted_J': f'{self.energy.energy_J["predicted"]:.3f}',
            'remaining_wh': f'{self.battery.remaining_wh:.4f}',
            'predictor': self.predictor.description,
        }
        values.update(clock_values)
        if self.prediction is not None:
            values['traction_margin'] = f'{self.prediction.traction_margin:.4f}'
        values.update(adaptation_values(correction, self.adaptation.settings.enabled))
        message = '; '.join(problems + notes) if problems else f'ok, energy from {source} power'
        if notes and not problems:
            message += '; ' + '; '.join(notes)
        return level, message, values

    def state_dict(self) -> JsonObject:
        """What a restart needs: the battery's tallies and the energy tallies (no configuration:
        estimator/persistence.py)."""
        self.energy.flush()
        return {
            'battery': {'state': battery_tallies(vars(self.battery.state))},
            'energy_J': dict(self.energy.energy_J),
        }

    def reset_energy(self, battery: BatteryModel, now_s: float) -> None:
        """A battery swap at ``now_s`` [s]: ``battery`` (a full one) replaces the old, the energy
        tallies restart at 0 J; power drawn before ``now_s`` is charged to the old battery."""
        self.energy.advance(now_s)
        self.energy.flush()
        self.energy.battery = battery
        self.energy.energy_J.update(measured=0.0, predicted=0.0)
        self.time_to_empty_s = self.energy.time_to_empty_s()

    def restore(self, state: JsonObject) -> None:
        """Restore the tallies of :meth:`state_dict` output into this battery (its configuration
        stays this vehicle's); ConfigError if a number is missing or outside its range."""
        tallies, energy = restored_tallies(state)
        battery = self.battery.with_state(BatteryState(**tallies))
        self.energy.flush()
        self.energy.battery = battery
        self.energy.energy_J.update(energy)
