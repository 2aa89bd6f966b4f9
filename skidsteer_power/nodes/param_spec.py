"""Node parameters declared once: a typed spec per parameter (name, default and so type, description
with its unit in brackets, optional range), from which the node declares them (with ROS ranges),
the shipped parameter files (config/*.yaml) and the tables of docs/INTERFACES.md are rendered.

``python -m skidsteer_power.nodes.param_files`` writes the files (``--check`` in CI);
test/test_param_spec.py checks the shipped ones equal the rendering, so a parameter is added or
changed in its node's ``PARAMETERS`` only. Every number has a range: ROS refuses a set outside it,
and :func:`declare` turns an out-of-range or mistyped start value into one ConfigError. A parameter
with ``choices`` takes only those values (:func:`read` checks them, one ConfigError); one a node reads
only at its start says ``read_only`` (the descriptor's: ROS refuses every later set).

A node reads its parameters as one frozen, typed object (as generate_parameter_library does for
ros2_controllers' diff_drive_controller): :func:`render_parameters_module` writes a dataclass per node
(skidsteer_power/nodes/parameters.py, by ``param_files``; its fields are the specs' names, types and
defaults), and :func:`parameters_of` fills one from values after :meth:`ParamSpec.check` (type,
range, choices), so ``p.poll_rate_hz`` is a float to mypy and a mistyped name an error.
"""

from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node

from skidsteer_power.errors import ConfigError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    Params = TypeVar('Params', bound=DataclassInstance)

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
        """``value`` if it has the default's type (an int stands for a float, as a float), lies in
        ``range`` and is one of ``choices`` (or there are none), else one ConfigError."""
        kind = type(self.default)
        if kind is float and type(value) is int:
            value = float(value)
        if type(value) is not kind:
            raise ConfigError(f'{self.name} must be of type {self.type_name}, not {value!r}')
        if self.range is not None and not isinstance(value, (bool, str)):
            low, high = self.range
            if not low <= value <= high:
                unit = f' [{self.unit}]' if self.unit else ''
                raise ConfigError(f'{self.name} must be within {self.range_text()}{unit}, got {value!r}')
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


def read_parameters(node: Node, specs: Sequence[ParamSpec], cls: type[Params]) -> Params:
    """The values of ``specs``' parameters on ``node`` (:func:`read`) as one ``cls`` object."""
    return parameters_of(cls, specs, read(node, specs))


def parameters_of(cls: type[Params], specs: Sequence[ParamSpec], values: Mapping[str, ParamValue]) -> Params:
    """``cls`` (a dataclass of :func:`render_parameters_module`) from ``values`` by name, each checked
    by its spec (:meth:`ParamSpec.check`: type, range, choices; one ConfigError), a missing one at its
    default. A name no spec has is a ConfigError; a ``cls`` whose fields are not ``specs``' names (a
    stale rendering) is a RuntimeError naming the command that renders it."""
    fields = tuple(f.name for f in dataclasses.fields(cls))
    names = tuple(spec.name for spec in specs)
    if fields != names:
        command = 'python -m skidsteer_power.nodes.param_files'
        raise RuntimeError(f'{cls.__name__} is not the rendering of its specs: run {command}')
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ConfigError(f'no such parameter: {", ".join(unknown)}')
    checked = {spec.name: spec.check(values.get(spec.name, spec.default)) for spec in specs}
    return cls(**checked)


def render_parameters_module(classes: Sequence[tuple[str, str, Sequence[ParamSpec]]], header: str) -> str:
    """A Python module (``header``: its docstring) with one frozen dataclass per ``(class name, what it
    holds, specs)``: a field per spec in order, of the default's type, with the default and the
    description (and range, choices) as its docstring. Formatted as ``ruff format`` leaves it."""
    lines = [f'"""{header.strip()}\n"""', '', 'from __future__ import annotations', '']
    lines += ['from dataclasses import dataclass']
    for name, summary, specs in classes:
        lines += ['', '', '@dataclass(frozen=True)', f'class {name}:', f'    """{summary}"""', '']
        for spec in specs:
            kind = {bool: 'bool', int: 'int', float: 'float', str: 'str'}[type(spec.default)]
            lines.append(f'    {spec.name}: {kind} = {spec.default!r}')
            lines += _field_doc(spec)
    return '\n'.join(lines) + '\n'


def _field_doc(spec: ParamSpec) -> list[str]:
    text = spec.description
    if spec.range is not None:
        text += f'; range {spec.range_text()}'
    if spec.choices:
        text += f'; one of {", ".join(repr(c) for c in spec.choices)}'
    if spec.read_only:
        text += '; read only'
    text = text.replace('\\', '\\\\').replace('"', "'")
    keep = '\xa0'  # not a break for textwrap: a range 'lo .. hi' stays on one line
    text = text.replace(' .. ', f'{keep}..{keep}')
    wrapped = [line.replace(keep, ' ') for line in textwrap.wrap(text, width=100, break_on_hyphens=False)]
    if len(wrapped) == 1:
        return [f'    """{wrapped[0]}"""']
    return ['    """' + wrapped[0], *(f'    {line}' for line in wrapped[1:]), '    """']


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
