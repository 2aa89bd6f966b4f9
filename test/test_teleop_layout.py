"""The shipped Foxglove layout's Teleop panel publishes fast enough for des_driver's watchdog (issue
37 item 2): Foxglove's default is 1 Hz against a 0.5 s watchdog, which stops the robot between two
commands."""

from __future__ import annotations

import json
from typing import Any

from skidsteer_power import resources
from skidsteer_power.nodes.des_driver import PARAMETERS


def panels(value: Any) -> list[dict[str, Any]]:
    found: list[dict[str, Any]] = []
    if isinstance(value, dict):
        if value.get('type') == 'panel':
            found.append(value)
        for v in value.values():
            found += panels(v)
    elif isinstance(value, list):
        for v in value:
            found += panels(v)
    return found


def test_shipped_teleop_panel_rate_beats_the_driver_watchdog() -> None:
    shipped = resources.find('foxglove', 'operator_layout', ('.json',)).read_text(encoding='utf-8')
    teleop = [p for p in panels(json.loads(shipped)) if p.get('panelType') == 'Teleop']
    assert len(teleop) == 1
    config = teleop[0]['config']
    timeout_s = next(spec.default for spec in PARAMETERS if spec.name == 'cmd_timeout_s')
    assert isinstance(timeout_s, float) and timeout_s == 0.5
    # a gap of 1/rate must stay below the watchdog with room for one lost message: rate >= 2 / timeout
    assert config['publishRate'] >= 2.0 / timeout_s  # 4 Hz; Foxglove's default 1 Hz fails this
    assert config['publishRate'] == 10.0
    assert config['topic'] == '/cmd_vel'
