"""Missions (ch. 8): routes, mission power and energy, soil sensitivity, the Table 8.4 design study."""

from __future__ import annotations

from skidsteer_power.commands import Segment
from skidsteer_power.missions.energy import MissionResult, run_mission
from skidsteer_power.missions.routes import (
    Route,
    patrol,
    read_route_csv,
    resolve_route,
    search_retrieve,
)

__all__ = [
    'MissionResult',
    'Route',
    'Segment',
    'patrol',
    'read_route_csv',
    'resolve_route',
    'run_mission',
    'search_retrieve',
]
