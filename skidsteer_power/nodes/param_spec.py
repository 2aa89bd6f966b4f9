"""Node parameters declared once: a typed spec per parameter (name, default and so type, description
with its unit in brackets, optional range), from which the node declares them (with ROS ranges),
the shipped parameter files (config/*.yaml) and the tables of docs/INTERFACES.md are rendered.

``python -m skidsteer_power.nodes.param_files`` writes the files (``--check`` in CI);
test/test_param_spec.py checks the shipped ones equal the rendering, so a parameter is added or
changed in its node's ``PARAMETERS`` only. Every number has a range: ROS refuses a set outside it,
and :func:`declare` turns an out-of-range or mistyped start value into one ConfigError. A parameter
with ``choices`` takes only those values (:func:`read` checks them, one ConfigError); one a node reads
only at its start says ``read_only`` (the descriptor's: ROS refuses every later set).
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node

from skidsteer_power.errors import ConfigError

_UNIT = re.compile(r'\[([^\]]+)\]')

ParamValue = bool | int | float | str
"""A declared parameter's value: every default is one of these types, and so is every value ROS lets
a set give it (a typed parameter keeps its type)."""


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter: name, default (its type is the parameter's), description, range."""

    name: str
    default: ParamValue
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[ParamValue, ...] = ()  # the only values it takes (none: any in the range)
    read_only: bool = False  # read at the node's start only: ROS refuses a later set

    def check(self, value: ParamValue) -> ParamValue:
        """``value`` if it is one of ``choices`` (or there are none), else one ConfigError."""
        if self.choices and value not in self.choices:
            allowed = ', '.join(str(c) for c in self.choices)
            raise ConfigError(f'{self.name} must be one of {allowed}, not {value!r}')
        return value

    @property
    def type_name(self) -> str:
        """The ROS parameter type of the default: bool, integer, double or string."""
        kind = type(self.default)
        return {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[kind]

    @property
    def unit(self) -> str:
        """The unit written in the description's first [...] ('' if none or not a number), e.g. 'rad/s'."""
        if isinstance(self.default, (bool, str)):
            return ''
        found = _UNIT.search(self.description)
        return found.group(1) if found else ''

    def range_text(self) -> str:
        """'lo .. hi' of the range in %g, or ''."""
        return '' if self.range is None else f'{self.range[0]:g} .. {self.range[1]:g}'


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of ``spec``: its description and, with a range, an integer or float range
    that ROS enforces on every set."""
    result = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.choices:
        result.additional_constraints = f'one of {", ".join(str(c) for c in spec.choices)}'
    if spec.range is not None:
        low, high = spec.range
        if isinstance(spec.default, int) and not isinstance(spec.default, bool):
            result.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        else:
            result.floating_point_range = [FloatingPointRange(from_value=low, to_value=high, step=0.0)]
    return result


def declare(node: Node, specs: Sequence[ParamSpec]) -> dict[str, ParamValue]:
    """Declare every parameter of ``specs`` on ``node`` (:func:`descriptor`: ROS enforces the range on
    every later set) and return their values by name (:func:`read`). A start value (override,
    parameter file) out of its range, of another type or not one of its choices is one ConfigError
    naming the parameter, the value and what it may be."""
    for spec in specs:
        try:
            node.declare_parameter(spec.name, spec.default, descriptor(spec))
        except InvalidParameterValueException as err:
            raise ConfigError(_out_of_range(spec, str(err.args[0]))) from None
        except InvalidParameterTypeException as err:
            raise ConfigError(f'{spec.name} must be of type {spec.type_name}: {err.args[0]}') from None
    return read(node, specs)


def read(node: Node, specs: Sequence[ParamSpec]) -> dict[str, ParamValue]:
    """The values of ``specs``' parameters on ``node`` by name, each checked against its choices (a
    set after the declaration is range-checked by ROS, not against the choices: read again, here)."""
    values: dict[str, ParamValue] = {}
    for spec in specs:
        value = node.get_parameter(spec.name).value
        assert isinstance(value, (bool, int, float, str)), spec.name  # a typed parameter keeps its type
        values[spec.name] = spec.check(value)
    return values


def _out_of_range(spec: ParamSpec, ros_message: str) -> str:
    found = re.match(r'Invalid parameter value \((.*)\) for parameter', ros_message)
    unit = f' [{spec.unit}]' if spec.unit else ''
    got = found.group(1) if found else ros_message
    return f'{spec.name} must be within {spec.range_text()}{unit}, got {got}'


def yaml_value(value: bool | int | float | str) -> str:
    """``value`` as a YAML scalar that loads back to the same Python value and type."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (int, float)):
        return repr(value)
    if value == '':
        return "''"
    plain = re.fullmatch(r'[A-Za-z_/][A-Za-z0-9_./-]*', value) and value.lower() not in {
        'true', 'false', 'yes', 'no', 'on', 'off', 'null', 'none', '~',
    }  # fmt: skip
    return value if plain else json.dumps(value)


def render_yaml(node: str, specs: Sequence[ParamSpec], header: str) -> str:
    """The ROS 2 parameter file of ``node``: ``header`` (comment lines), then every parameter with its
    default and a comment with its description and range."""
    lines = [*header.rstrip('\n').split('\n'), f'{node}:', '  ros__parameters:']
    for spec in specs:
        comment = spec.description + (f' [{spec.range_text()}]' if spec.range else '')
        lines.append(f'    {spec.name}: {yaml_value(spec.default)}  # {comment}')
    return '\n'.join(lines) + '\n'


def render_table(specs: Sequence[ParamSpec]) -> str:
    """A Markdown table of ``specs``: name, type, default, range, unit, description."""
    rows = [
        '| parameter | type | default | range | unit | description |',
        '| --- | --- | --- | --- | --- | --- |',
    ]
    for spec in specs:
        cells = (
            f'`{spec.name}`',
            spec.type_name,
            f'`{yaml_value(spec.default)}`',
            spec.range_text(),
            spec.unit,
            spec.description.replace('|', '\\|'),
        )
        rows.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(rows) + '\n'
