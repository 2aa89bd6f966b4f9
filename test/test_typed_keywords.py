"""Each TypedDict that lists another thing's names (a constructor's keywords, a dataclass's fields)
lists exactly those names: the keywords are typed in one place and checked against the other here,
so neither can drift from it (issue 38, "one idea, one name, one place")."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from skidsteer_power.des.simulator import SimulatedDes, SimulatorOptions
from skidsteer_power.drive.controller import ControllerChanges, DriveController
from skidsteer_power.estimator.inputs import JointMap, JointMapFields
from skidsteer_power.maps.power_map import MapKeywords, MapOptions
from skidsteer_power.terramechanics.terrain import Terrain, TerrainNumbers


def _keyword_only(cls: type) -> set[str]:
    params = inspect.signature(cls).parameters.values()
    return {p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY}


def _fields(cls: type, without: frozenset[str] = frozenset()) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)} - without


CASES = [
    # SimulatedPair names each side itself
    ('SimulatorOptions', set(SimulatorOptions.__annotations__), _keyword_only(SimulatedDes) - {'name'}),
    # the numbers: not the name, the shear law or the contact kind (strings)
    (
        'TerrainNumbers',
        set(TerrainNumbers.__annotations__),
        _fields(Terrain, frozenset({'name', 'shear_type', 'contact'})),
    ),
    # the sources are prose, not a value with_values replaces
    (
        'ControllerChanges',
        set(ControllerChanges.__annotations__),
        _fields(DriveController, frozenset({'sources'})),
    ),
    ('JointMapFields', set(JointMapFields.__annotations__), _fields(JointMap)),
    ('MapKeywords', set(MapKeywords.__annotations__), set(MapOptions.__annotations__)),
]


@pytest.mark.parametrize(('name', 'listed', 'source'), CASES, ids=[c[0] for c in CASES])
def test_typed_keywords_list_the_same_names(name: str, listed: set[str], source: set[str]) -> None:
    assert listed == source, f'{name}: missing {sorted(source - listed)}, extra {sorted(listed - source)}'


def test_terrain_numbers_are_the_numeric_fields() -> None:
    """The three fields TerrainNumbers leaves out are the only ones that are not numbers."""
    non_numeric = {f.name for f in dataclasses.fields(Terrain) if 'float' not in str(f.type)}
    assert non_numeric == {'name', 'shear_type', 'contact'}
