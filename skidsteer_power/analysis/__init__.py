"""Analysis of measured runs: circle fit of a trace and mean speed (chapter 7.3.3).

Shared by the bag tools and the motion-capture tracker.
"""

from __future__ import annotations

from skidsteer_power.analysis.trace import CircleFit, fit_circle, mean_speed

__all__ = ['CircleFit', 'fit_circle', 'mean_speed']
