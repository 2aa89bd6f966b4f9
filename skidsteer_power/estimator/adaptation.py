"""Online adaptation of the torque prediction, and a terrain-change detector (pure, no ROS).

Correction
----------
Per side, the measured motor torque K_t i [N m] is modelled as a scale and an offset of the
predicted one: ``T_meas = a T_pred + b``. (a, b) are estimated by recursive least squares with
exponential forgetting; the forgetting is set by a memory time ``memory_s`` [s] (a sample dt seconds
old weighs exp(-dt / memory_s)), so the estimate does not depend on the joint_states rate. Under a
constant command the regressor (T_pred, 1) does not excite both directions and plain forgetting
would blow the covariance up (wind-up); the covariance is therefore capped at its initial trace.
Only settled motion is used: the command has been held ``settle_s`` [s] and the measured motor speed
is within ``speed_tol`` of the predicted one (no acceleration, no stall). The model's error differs
from one command to the next (a turn is not a straight run), so when a new command has settled the
covariance is reset to its initial value (the correction re-converges in a fraction of a second)
and the change detector waits ``warmup_s`` [s]: a new command is not a new terrain.

Terrain scale
-------------
The per-side correction is the model's error for one command and restarts with the next, so it says
nothing about a path of other commands. Beside it, one number carries over between commands: the
ratio k [-] of the measured to the predicted *terrain* torque at the motor (the torque beyond the
powertrain's internal resistance, eqs. 7.1-7.4: measured K_t i minus the predicted internal torque,
against the predicted axle torque / G). It is the least-squares slope through the origin over the
settled samples of both sides and all commands, with exponential forgetting of time constant
``terrain_memory_s`` [s]: k = S_xy / S_xx, S_xy = sum w dt x y, S_xx = sum w dt x^2 (dt: the
sample's interval, the time since the previous reading the adaptation was given (every accepted
joint_states while a command is fresh), at most MAX_SAMPLE_S; so the first settled sample after a
command change counts as much as any other), w = exp(-age /
terrain_memory_s). Large torques weigh most, as they do in energy. It is used (else 1) once the
settled time behind it, sum w dt, reaches ``terrain_min_s`` [s], kept within ``scale_limits``, and
restarted with the rest when a terrain change is flagged. The path energy
(:mod:`skidsteer_power.estimator.path_energy`) multiplies the map's axle torques by k. k also
absorbs what the map gets wrong about the motion (a wheeled robot turning at less than the commanded
yaw rate needs less torque than the commanded turn): the path is predicted from commands too.

Change detector
---------------
Each settled sample's innovation (measured minus corrected torque, before the update) is normalized
by its scale sigma = max(running RMS innovation, ``sigma_rel`` |T_pred|, ``sigma_floor_Nm``) and fed
to a two-sided CUSUM per side (Page 1954): g+ = max(0, g+ + z - k), g- = max(0, g- - z - k). When
either side's statistic passes ``cusum_h``, the terrain is flagged as changed, and the adaptation
restarts from (a, b) = (1, 0) with its initial covariance (and waits ``warmup_s`` again). The running
RMS is updated only outside the warm-up and from samples with |z| < 3, so a change cannot inflate it
and hide itself. So a change is flagged while a command is held; one that coincides with a new
command is absorbed into that command's correction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from skidsteer_power.errors import ConfigError


@dataclass(frozen=True)
class AdaptationSettings:
    """Tunables (the node declares each as a parameter).

    enabled : adapt at all; memory_s : forgetting time constant [s]; settle_s : command hold before
    samples count [s]; warmup_s : settled time after a new command or a restart before the change
    detector runs [s]; speed_tol : allowed relative difference of measured and predicted motor
    speed [-]; cusum_k : CUSUM drift allowance [sigma]; cusum_h : CUSUM alarm threshold [sigma];
    sigma_rel : least residual scale relative to the predicted torque [-]; sigma_floor_Nm : least
    residual scale [N m]; scale_limits : the scale a is kept within these [-].
    """

    enabled: bool = True
    memory_s: float = 10.0
    settle_s: float = 1.0
    warmup_s: float = 1.0
    speed_tol: float = 0.3
    cusum_k: float = 0.5
    cusum_h: float = 10.0
    sigma_rel: float = 0.03
    sigma_floor_Nm: float = 0.01
    scale_limits: tuple[float, float] = (0.2, 5.0)
    terrain_memory_s: float = 60.0
    terrain_min_s: float = 2.0

    def __post_init__(self) -> None:
        for name in ('memory_s', 'settle_s', 'speed_tol', 'cusum_h', 'sigma_floor_Nm', 'terrain_memory_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f'adaptation {name} must be a finite number > 0, got {value!r}')
        for name in ('cusum_k', 'sigma_rel', 'terrain_min_s'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ConfigError(f'adaptation {name} must be a finite number >= 0, got {value!r}')


MAX_SAMPLE_S = 0.2
"""A settled sample counts in the terrain scale for the time since the previous reading given to the
adaptation, and at most this long [s]: a pause in the readings is no settled time."""

P0 = (100.0, 0.0, 1.0)  # initial covariance of (a [-], b [N m]) as (aa, ab, bb): a weak prior (+-10, +-1 N m)
P0_TRACE = P0[0] + P0[2]


@dataclass
class SideEstimator:
    """RLS of (scale a [-], offset b [N m]) and the CUSUM statistics of one side. The covariance of
    (a, b) is kept as its three distinct entries ``p_aa``, ``p_ab``, ``p_bb``: the update runs on every
    settled joint_states: one update of both sides took 42 us in 2 x 2 numpy algebra, 5 us in floats
    (measured; issue 18)."""

    a: float = 1.0
    b: float = 0.0
    p_aa: float = P0[0]
    p_ab: float = P0[1]
    p_bb: float = P0[2]
    ms_innovation: float = math.nan  # running mean square innovation [N m^2]
    g_pos: float = 0.0
    g_neg: float = 0.0
    samples: int = 0

    def reset(self) -> None:
        self.a, self.b = 1.0, 0.0
        self.restart_covariance()
        self.ms_innovation = math.nan
        self.g_pos = self.g_neg = 0.0
        self.samples = 0

    def corrected(self, predicted: float) -> float:
        return self.a * predicted + self.b

    def restart_covariance(self) -> None:
        self.p_aa, self.p_ab, self.p_bb = P0


@dataclass(frozen=True)
class Correction:
    """The current correction (per side, left, right) and the detector's state.

    scale : a [-]; offset_Nm : b [N m]; residual_rms_Nm : running RMS innovation [N m] (NaN before
    any settled sample); cusum : larger CUSUM statistic per side [sigma]; samples : settled samples
    since the last restart; terrain_changes : how many changes were flagged; last_change_s : time of
    the last one [s] (NaN if none); settled : the last sample was used; terrain_scale : k, measured /
    predicted terrain torque over all commands [-] (1 until known); terrain_scale_evidence_s :
    forgetting-weighted settled time behind k [s] (module doc, "Terrain scale").
    """

    scale: tuple[float, float]
    offset_Nm: tuple[float, float]
    residual_rms_Nm: tuple[float, float]
    cusum: tuple[float, float]
    samples: int
    terrain_changes: int
    last_change_s: float
    settled: bool
    terrain_scale: float = 1.0
    terrain_scale_evidence_s: float = 0.0

    def relative_residual(self, predicted_Nm: tuple[float, float]) -> float:
        """Residual RMS relative to the mean |predicted torque| [-] (NaN when unknown)."""
        scale = float(np.mean(np.abs(predicted_Nm)))
        known = [r for r in self.residual_rms_Nm if math.isfinite(r)]
        rms = math.sqrt(sum(r * r for r in known) / len(known)) if self.samples and known else math.nan
        return rms / scale if scale > 1e-9 else math.nan


@dataclass
class TerrainScale:
    """Forgetting least-squares slope k of measured on predicted terrain torque (module doc)."""

    s_xy: float = 0.0  # [N m^2 s]
    s_xx: float = 0.0  # [N m^2 s]
    evidence_s: float = 0.0  # forgetting-weighted settled time [s]

    def add(self, xy: float, xx: float, dt_s: float, lam: float) -> None:
        """One settled sample of both sides, as the sums over the sides of predicted x measured and
        predicted x predicted terrain torque at the motor [N m^2], held ``dt_s`` [s], after the older
        ones are weighted by ``lam`` [-] (plain floats: this runs on every joint_states)."""
        self.s_xy = lam * self.s_xy + dt_s * xy
        self.s_xx = lam * self.s_xx + dt_s * xx
        self.evidence_s = lam * self.evidence_s + dt_s

    def value(self, min_s: float, limits: tuple[float, float]) -> float:
        """k [-], or 1 while less than ``min_s`` [s] of settled time (or no terrain torque) is behind it."""
        if self.evidence_s < min_s or self.s_xx <= 0.0:
            return 1.0
        return min(max(self.s_xy / self.s_xx, limits[0]), limits[1])


class TorqueAdaptation:
    """Per-side RLS correction with CUSUM change detection; feed :meth:`update` per joint_states."""

    def __init__(self, settings: AdaptationSettings | None = None) -> None:
        self.settings = settings or AdaptationSettings()
        self.sides = (SideEstimator(), SideEstimator())
        self.terrain = TerrainScale()
        self.terrain_changes = 0
        self.last_change_s = math.nan
        self._command: tuple[float, float] | None = None
        self._command_since = math.nan
        self._last_update_s = math.nan  # of the last settled sample [s]
        self._last_sample_s = math.nan  # of the last reading given, settled or not [s]
        self._settled = False
        self._new_command = True
        self._detect_from_s = math.inf

    def on_command(self, command: tuple[float, float], now_s: float) -> None:
        """Note a command (V [m/s], yaw rate [rad/s]); a different one restarts the settle clock."""
        if self._command is None or any(
            abs(a - b) > 1e-6 for a, b in zip(command, self._command, strict=True)
        ):
            self._command_since = now_s
            self._new_command = True
        self._command = command

    def corrected(self, predicted_Nm: tuple[float, float]) -> tuple[float, float]:
        """Corrected motor torques [N m] for predicted ones (unchanged when adaptation is off)."""
        if not self.settings.enabled:
            return predicted_Nm
        return (self.sides[0].corrected(predicted_Nm[0]), self.sides[1].corrected(predicted_Nm[1]))

    def update(
        self,
        now_s: float,
        predicted_Nm: tuple[float, float],
        predicted_omega: tuple[float, float],
        measured_Nm: tuple[float, float],
        measured_omega: tuple[float, float],
        predicted_terrain_Nm: tuple[float, float] | None = None,
    ) -> bool:
        """One joint_states sample (motor torques [N m], motor speeds [rad/s]); True if a terrain
        change was flagged by it. ``predicted_terrain_Nm``, the part of ``predicted_Nm`` the terrain
        needs (axle torque / G) [N m], feeds the terrain scale (none given: it is not updated)."""
        s = self.settings
        self._settled = False
        held_s = now_s - self._last_sample_s if math.isfinite(self._last_sample_s) else 0.0
        self._last_sample_s = now_s
        if not s.enabled or self._command is None or now_s - self._command_since < s.settle_s:
            return False
        (wp_l, wp_r), (wm_l, wm_r) = predicted_omega, measured_omega
        standing = abs(wp_l) < 1e-6 and abs(wp_r) < 1e-6
        if (
            standing
            or abs(wm_l - wp_l) > s.speed_tol * abs(wp_l) + 1.0
            or (abs(wm_r - wp_r) > s.speed_tol * abs(wp_r) + 1.0)
        ):
            return False
        self._settled = True
        if self._new_command:  # the model's error is another one now: re-converge, do not detect yet
            self._new_command = False
            self._detect_from_s = now_s + s.warmup_s
            for side in self.sides:
                side.restart_covariance()
                side.g_pos = side.g_neg = 0.0
        detect = now_s >= self._detect_from_s
        dt = now_s - self._last_update_s if math.isfinite(self._last_update_s) else 0.0
        self._last_update_s = now_s
        lam = math.exp(-max(dt, 0.0) / s.memory_s)
        alarm = False
        for side, pred, meas in zip(self.sides, predicted_Nm, measured_Nm, strict=True):
            alarm |= self._update_side(side, float(pred), float(meas), lam, detect)
        if alarm:
            self.terrain_changes += 1
            self.last_change_s = now_s
            self._detect_from_s = now_s + s.warmup_s
            for side in self.sides:
                side.reset()
            self.terrain = TerrainScale()
        elif predicted_terrain_Nm is not None:
            # measured terrain torque = measured - internal, internal = predicted - predicted terrain
            # (eqs. 7.1-7.4 at the motor)
            xy = xx = 0.0
            for x, pred, meas in zip(predicted_terrain_Nm, predicted_Nm, measured_Nm, strict=True):
                xy += x * (meas - (pred - x))
                xx += x * x
            held_s = min(max(held_s, 0.0), MAX_SAMPLE_S)
            self.terrain.add(xy, xx, held_s, math.exp(-max(dt, 0.0) / s.terrain_memory_s))
        return alarm

    def terrain_scale(self) -> float:
        """k, measured / predicted terrain torque over all commands [-] (module doc); 1 when off."""
        if not self.settings.enabled:
            return 1.0
        return self.terrain.value(self.settings.terrain_min_s, self.settings.scale_limits)

    def _update_side(self, side: SideEstimator, pred: float, meas: float, lam: float, detect: bool) -> bool:
        s = self.settings
        innovation = meas - side.corrected(pred)  # regressor phi = (pred, 1)
        rms = math.sqrt(side.ms_innovation) if math.isfinite(side.ms_innovation) else 0.0
        sigma = max(rms, s.sigma_rel * abs(pred), s.sigma_floor_Nm)
        z = innovation / sigma
        if detect:
            side.g_pos = max(0.0, side.g_pos + z - s.cusum_k)
            side.g_neg = max(0.0, side.g_neg - z - s.cusum_k)
            if max(side.g_pos, side.g_neg) > s.cusum_h:
                return True
            if not math.isfinite(side.ms_innovation):
                side.ms_innovation = innovation**2
            elif abs(z) < 3.0:
                side.ms_innovation = lam * side.ms_innovation + (1.0 - lam) * innovation**2
        # RLS with forgetting factor lam (covariance capped at its initial trace: no wind-up)
        # (P phi = phi' P for a symmetric P), gain = P phi / (lam + phi' P phi),
        # P <- (P - gain phi' P) / lam, kept symmetric
        pa, pb = side.p_aa * pred + side.p_ab, side.p_ab * pred + side.p_bb
        denominator = lam + pred * pa + pb
        ga, gb = pa / denominator, pb / denominator
        side.a = min(max(side.a + ga * innovation, s.scale_limits[0]), s.scale_limits[1])
        side.b += gb * innovation
        side.p_aa = (side.p_aa - ga * pa) / lam
        side.p_ab = (side.p_ab - 0.5 * (ga * pb + gb * pa)) / lam
        side.p_bb = (side.p_bb - gb * pb) / lam
        trace = side.p_aa + side.p_bb
        if trace > P0_TRACE:
            shrink = P0_TRACE / trace
            side.p_aa, side.p_ab, side.p_bb = side.p_aa * shrink, side.p_ab * shrink, side.p_bb * shrink
        side.samples += 1
        return False

    def state(self) -> Correction:
        """The current :class:`Correction`."""
        left, right = self.sides
        return Correction(
            scale=(left.a, right.a),
            offset_Nm=(left.b, right.b),
            residual_rms_Nm=(math.sqrt(left.ms_innovation), math.sqrt(right.ms_innovation)),
            cusum=(max(left.g_pos, left.g_neg), max(right.g_pos, right.g_neg)),
            samples=min(left.samples, right.samples),
            terrain_changes=self.terrain_changes,
            last_change_s=self.last_change_s,
            settled=self._settled,
            terrain_scale=self.terrain_scale(),
            terrain_scale_evidence_s=self.terrain.evidence_s,
        )


CORRECTION_FIELDS = (
    'scale_left',
    'scale_right',
    'offset_left_Nm',
    'offset_right_Nm',
    'residual_rms_left_Nm',
    'residual_rms_right_Nm',
    'cusum_left',
    'cusum_right',
    'terrain_changes',
    'enabled',
    'terrain_scale',
    'terrain_scale_evidence_s',
)
"""Names of ``power/correction`` (JointState: names = fields, position = values; units in the names)."""


def correction_values(adaptation: TorqueAdaptation) -> list[float]:
    """Values of :data:`CORRECTION_FIELDS` for the current state of ``adaptation``."""
    c = adaptation.state()
    return [
        *c.scale,
        *c.offset_Nm,
        *c.residual_rms_Nm,
        *c.cusum,
        float(c.terrain_changes),
        float(adaptation.settings.enabled),
        c.terrain_scale,
        c.terrain_scale_evidence_s,
    ]
