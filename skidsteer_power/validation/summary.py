"""What a validation reports (:func:`skidsteer_power.validation.validate.validate`), typed.

Each result is a frozen dataclass whose fields are named as the JSON keys of ``validate --json``
(docs/VALIDATION.md, DESIGN.md's CLI contract) and whose ``as_json`` gives that JSON object, keys in
the order the command has always printed them; code reads the fields, only the JSON boundary (the
CLI, summary.json, a fleet row) reads ``as_json``. Units as the key names say (SI).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from skidsteer_power.jsonout import FieldsAsJson, JsonObject
from skidsteer_power.validation.series import TraceSegment

QUANTITIES = (('torque', 'Nm'), ('power', 'W'))
"""The compared quantities and their units, in the order of the JSON keys and the report's tables."""
SIDES = ('left', 'right')


@dataclass(frozen=True)
class SideError:
    """Mean absolute and root-mean-square error of one side's quantity, in ``unit`` ('Nm' or 'W')."""

    mae: float
    rmse: float
    unit: str

    def as_json(self) -> JsonObject:
        return {f'mae_{self.unit}': self.mae, f'rmse_{self.unit}': self.rmse}


NO_ERROR = {unit: SideError(math.nan, math.nan, unit) for _, unit in QUANTITIES}


@dataclass(frozen=True)
class ErrorMetrics:
    """Predicted against measured (:func:`skidsteer_power.validation.validate_metrics.error_metrics`):
    rows compared, per side torque [N m] and power [W] errors, energy [J] and its error [%]."""

    samples_compared: int
    torque_left: SideError
    torque_right: SideError
    power_left: SideError
    power_right: SideError
    energy_predicted_J: float
    energy_measured_J: float
    energy_error_pct: float

    def error(self, quantity: str, side: str) -> SideError:
        """The error of ``quantity`` ('torque', 'power') on ``side`` ('left', 'right')."""
        found: SideError = getattr(self, f'{quantity}_{side}')
        return found

    def energy_json(self) -> JsonObject:
        return {
            'energy_predicted_J': self.energy_predicted_J,
            'energy_measured_J': self.energy_measured_J,
            'energy_error_pct': self.energy_error_pct,
        }

    def as_json(self) -> JsonObject:
        errors = {f'{q}_{s}': self.error(q, s).as_json() for q, _ in QUANTITIES for s in SIDES}
        return {'samples_compared': self.samples_compared, **errors, **self.energy_json()}


@dataclass(frozen=True)
class MapCoverage(FieldsAsJson):
    """Share of the time and of the predicted energy whose prediction came from outside the power
    map (clamped or limited) [-] (:func:`skidsteer_power.validation.validate_metrics.map_coverage`)."""

    clamped_time_fraction: float
    clamped_energy_fraction: float


@dataclass(frozen=True)
class LiveComparison:
    """The offline predictions against the live node's ``power/predicted`` (``live_comparison``)."""

    messages: int
    matching_within_1e_6: int
    max_abs_torque_diff_Nm: float
    commands_without_live_prediction: int

    def as_json(self) -> JsonObject:
        return {
            'messages': self.messages,
            'matching_within_1e-6': self.matching_within_1e_6,
            'max_abs_torque_diff_Nm': self.max_abs_torque_diff_Nm,
            'commands_without_live_prediction': self.commands_without_live_prediction,
        }


@dataclass(frozen=True)
class MotionPrediction:
    """The estimator run again from a measured twist (``motion_prediction``): which, and its metrics."""

    kinematics: str
    metrics: ErrorMetrics

    def as_json(self) -> JsonObject:
        return {'kinematics': self.kinematics, 'metrics': self.metrics.as_json()}


@dataclass(frozen=True)
class OnlinePrediction:
    """What power_estimator would have published from the bag (``online_prediction``,
    :func:`skidsteer_power.validation.online.online_summary`): the corrected prediction's metrics, the
    terrain-scaled prediction's (energy and power only), the corrected battery energy [J] and the
    adaptation's final state (terrain scale k [-], per-side scale [-] and offset [N m])."""

    metrics: ErrorMetrics
    terrain_scaled: ErrorMetrics
    battery_energy_predicted_J: float
    adaptation_enabled: bool
    terrain_scale: float
    correction_scale: tuple[float, float]
    correction_offset_Nm: tuple[float, float]
    terrain_changes: int

    def as_json(self) -> JsonObject:
        scaled = self.terrain_scaled
        return {
            'metrics': self.metrics.as_json(),
            'terrain_scaled': {
                **scaled.energy_json(),
                'power_left': scaled.power_left.as_json(),
                'power_right': scaled.power_right.as_json(),
            },
            'battery_energy_predicted_J': self.battery_energy_predicted_J,
            'adaptation_enabled': self.adaptation_enabled,
            'terrain_scale': self.terrain_scale,
            'correction_scale': list(self.correction_scale),
            'correction_offset_Nm': list(self.correction_offset_Nm),
            'terrain_changes': self.terrain_changes,
        }


@dataclass(frozen=True)
class JointsUsed:
    """The joint_states mapping used (``joints``): joint names per side, what effort is, where."""

    left: tuple[str, ...]
    right: tuple[str, ...]
    effort_is: str
    at: str

    def as_json(self) -> JsonObject:
        return {
            'left': list(self.left),
            'right': list(self.right),
            'effort_is': self.effort_is,
            'at': self.at,
        }


@dataclass(frozen=True)
class MessageCounts(FieldsAsJson):
    """Messages decoded per input (``messages``)."""

    cmd_vel: int
    joint_states: int
    poses: int


@dataclass(frozen=True)
class BatteryFigures(FieldsAsJson):
    """The battery over the run (``battery``): energy drawn from measured power, the open-loop
    prediction over the same time, energy drawn from predicted power [J], what remains [W h], [-]."""

    energy_measured_J: float
    energy_predicted_J: float
    energy_drawn_from_prediction_J: float
    remaining_wh: float
    soc: float


@dataclass(frozen=True)
class ReportFiles:
    """Where the report was written (``report``)."""

    directory: str
    markdown: str
    timeseries_csv: str
    segments_csv: str
    summary_json: str
    plots: tuple[str, ...]

    def as_json(self) -> JsonObject:
        return {**asdict(self), 'plots': list(self.plots)}


@dataclass(frozen=True)
class ValidationSummary:
    """Everything ``validate`` reports; :meth:`as_json` is ``validate --json`` (before the bag's
    integrity keys, which the CLI adds)."""

    bag: str
    storage: str
    duration_s: float
    vehicle: str
    terrain: str
    predictor: str
    has_motor_data: bool
    motor_data_note: str | None
    motor_currents_from: str | None
    joints: JointsUsed
    pose_topic: str | None
    cmd_vel_mode: str
    cmd_hold_s: float
    cmd_hold_inferred: bool
    cmd_period_s: float
    cmd_timing: str
    coverage: MapCoverage
    messages: MessageCounts
    rejected: dict[str, int]
    rejected_reasons: dict[str, int]
    power_compared: str
    joint_states_read: int
    joint_states_no_data: int
    undecodable_topics: list[str]
    kinematics: str
    metrics: ErrorMetrics
    motion_prediction: MotionPrediction | None
    online_prediction: OnlinePrediction
    battery: BatteryFigures
    segments: list[TraceSegment]
    segments_with_too_few_poses: int
    live_comparison: LiveComparison | None
    processing_s: float
    real_time_factor: float
    report: ReportFiles | None = field(default=None)

    def as_json(self) -> JsonObject:
        motion, live = self.motion_prediction, self.live_comparison
        return {
            'bag': self.bag,
            'storage': self.storage,
            'duration_s': self.duration_s,
            'vehicle': self.vehicle,
            'terrain': self.terrain,
            'predictor': self.predictor,
            'has_motor_data': self.has_motor_data,
            'motor_data_note': self.motor_data_note,
            'motor_currents_from': self.motor_currents_from,
            'joints': self.joints.as_json(),
            'pose_topic': self.pose_topic,
            'cmd_vel_mode': self.cmd_vel_mode,
            'cmd_hold_s': self.cmd_hold_s,
            'cmd_hold_inferred': self.cmd_hold_inferred,
            'cmd_period_s': self.cmd_period_s,
            'cmd_timing': self.cmd_timing,
            **self.coverage.as_json(),
            'messages': self.messages.as_json(),
            'rejected': dict(self.rejected),
            'rejected_reasons': dict(self.rejected_reasons),
            'power_compared': self.power_compared,
            'joint_states_read': self.joint_states_read,
            'joint_states_no_data': self.joint_states_no_data,
            'undecodable_topics': list(self.undecodable_topics),
            'kinematics': self.kinematics,
            'metrics': self.metrics.as_json(),
            'motion_prediction': None if motion is None else motion.as_json(),
            'online_prediction': self.online_prediction.as_json(),
            'battery': self.battery.as_json(),
            'segments': [asdict(s) for s in self.segments],
            'segments_with_too_few_poses': self.segments_with_too_few_poses,
            'live_comparison': None if live is None else live.as_json(),
            'processing_s': self.processing_s,
            'real_time_factor': self.real_time_factor,
            **({} if self.report is None else {'report': self.report.as_json()}),
        }
