"""A powertrain with sampled internal-resistance parameters (the studies' Monte Carlo draws).

A sample maps names to SI values: ``internal_scale`` [-] multiplies every internal-resistance
coefficient of both sides (eqs. 7.1-7.4); ``{left,right}_b`` [N m s/rad] and ``{left,right}_c`` [N m]
replace the side's components by one total viscous / Coulomb pair at the motor shaft (eq. 7.1).
Here, below :mod:`skidsteer_power.missions` and :mod:`skidsteer_power.studies`, so that both use it
(the design study applies a sample inside its tasks; the studies draw the samples).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

from skidsteer_power.powertrain.internal import Resistance, SideResistance

if TYPE_CHECKING:
    from skidsteer_power.powertrain.power_flow import Powertrain


def apply_powertrain(powertrain: Powertrain, sample: Mapping[str, float]) -> Powertrain:
    """``powertrain`` with the sample's powertrain parameters applied (module doc)."""
    scale = sample.get('internal_scale', 1.0)
    sides = {}
    for side in ('left', 'right'):
        resistance = powertrain.resistance(side)
        if f'{side}_b' in sample or f'{side}_c' in sample:
            total = resistance.total
            b = sample.get(f'{side}_b', total.viscous_Nm_s)
            c = sample.get(f'{side}_c', total.coulomb_Nm)
            resistance = SideResistance({'total': Resistance(b, c)})
        if scale != 1.0:
            resistance = SideResistance(
                {
                    k: Resistance(r.viscous_Nm_s * scale, r.coulomb_Nm * scale)
                    for k, r in resistance.components.items()
                }
            )
        sides[side] = resistance
    return dataclasses.replace(powertrain, left=sides['left'], right=sides['right'])
