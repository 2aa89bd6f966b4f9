"""Dead reckoning of the predicted motion: where the robot will be if it does what the model expects.

The set-point prediction (issue 25) gives the body twist (V [m/s], yaw rate w_z [rad/s]) a command
really produces. Integrated over time it is an odometry an operator can set beside the measured one,
so the slip shows before it happens. Between two updates the twist is constant, so the pose moves
along the exact circular arc (REP 103, x forward, yaw counter-clockwise):

    dx = V dt sinc-form,  with theta = w_z dt:
    x += V dt (sin(yaw + theta) - sin(yaw)) / theta,  y += V dt (cos(yaw) - cos(yaw + theta)) / theta

written with the half-angle form V dt sin(theta/2)/(theta/2) along yaw + theta/2, which is exact and
has no 0/0 at w_z = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MAX_STEP_S = 1.0
"""Longest interval integrated at once [s]: a longer gap (a stalled caller) is cut to this, so a
pause never turns into a jump."""


@dataclass
class PredictedOdometry:
    """Pose (x, y [m], yaw [rad]) dead-reckoned from a piecewise constant twist; not thread-safe."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    speed_m_s: float = 0.0
    yaw_rate_rad_s: float = 0.0
    last_s: float | None = None

    def advance(self, now_s: float) -> None:
        """Move along the current twist up to ``now_s`` [s] (at most MAX_STEP_S at once)."""
        if self.last_s is None or not math.isfinite(now_s):
            self.last_s = now_s if math.isfinite(now_s) else self.last_s
            return
        dt = min(max(now_s - self.last_s, 0.0), MAX_STEP_S)
        self.last_s = max(now_s, self.last_s)
        theta = self.yaw_rate_rad_s * dt
        half = 0.5 * theta
        chord = self.speed_m_s * dt * (math.sin(half) / half if half != 0.0 else 1.0)
        heading = self.yaw_rad + half
        self.x_m += chord * math.cos(heading)
        self.y_m += chord * math.sin(heading)
        self.yaw_rad = math.atan2(math.sin(self.yaw_rad + theta), math.cos(self.yaw_rad + theta))

    def set_twist(self, speed_m_s: float, yaw_rate_rad_s: float, now_s: float) -> None:
        """Integrate up to ``now_s`` with the old twist, then hold the new one (non-finite: 0)."""
        self.advance(now_s)
        finite = math.isfinite(speed_m_s) and math.isfinite(yaw_rate_rad_s)
        self.speed_m_s = speed_m_s if finite else 0.0
        self.yaw_rate_rad_s = yaw_rate_rad_s if finite else 0.0

    def reset(self, now_s: float) -> None:
        """Back to the origin, heading 0, keeping the twist in force."""
        self.x_m = self.y_m = self.yaw_rad = 0.0
        self.last_s = now_s

    def quaternion(self) -> tuple[float, float, float, float]:
        """(x, y, z, w) of the yaw rotation about z."""
        return 0.0, 0.0, math.sin(0.5 * self.yaw_rad), math.cos(0.5 * self.yaw_rad)
