"""Node parameters declared once (nodes/param_spec.py): the shipped parameter files and the doc
tables are the rendering of the nodes' specs, and the rendering loads back to the specs' defaults."""

from __future__ import annotations

import pytest
import yaml
from rclpy.context import Context

from skidsteer_power.nodes import param_files
from skidsteer_power.nodes.param_files import NodeParams
from skidsteer_power.nodes.param_spec import (
    ParamSpec,
    descriptor,
    render_table,
    render_yaml,
    yaml_value,
)


def test_shipped_parameter_files_and_doc_tables_are_the_specs_rendering() -> None:
    for path, text in param_files.rendered().items():
        shipped = (param_files.ROOT / path).read_text(encoding='utf-8')
        assert shipped == text, f'{path} is stale: run python -m skidsteer_power.nodes.param_files'
    assert param_files.main(['--check']) == 0


@pytest.mark.parametrize('entry', param_files.NODES, ids=lambda e: e.node)
def test_each_shipped_file_loads_to_the_node_defaults_with_their_types(entry: NodeParams) -> None:
    """Independent of the renderer: the YAML parser reads back every default, type included."""
    shipped = yaml.safe_load((param_files.ROOT / entry.yaml_file).read_text(encoding='utf-8'))
    values = shipped[entry.node]['ros__parameters']
    assert list(values) == [spec.name for spec in entry.specs]
    for spec in entry.specs:
        assert values[spec.name] == spec.default and type(values[spec.name]) is type(spec.default), spec.name


@pytest.mark.parametrize('value', ['', 'true', 'on', 'No', '1.5', '~', 'a: b', "it's", '/dev/ttyUSB0', 'x y'])
def test_yaml_value_round_trips_strings_yaml_would_read_as_something_else(value: str) -> None:
    assert yaml.safe_load(f'k: {yaml_value(value)}')['k'] == value


def test_ranges_become_ros_ranges_and_docs_of_the_right_kind() -> None:
    count = ParamSpec('status_every', 5, 'read the status every N polls [-]', (1, 1000))
    rate = ParamSpec('poll_rate_hz', 50.0, 'poll rate [Hz]', (0.1, 1000.0))
    name = ParamSpec('frame_id', '', 'frame of joint_states')
    d = descriptor(count)
    assert (d.integer_range[0].from_value, d.integer_range[0].to_value) == (
        1,
        1000,
    ) and not d.floating_point_range
    d = descriptor(rate)
    assert d.floating_point_range[0].from_value == pytest.approx(0.1) and not d.integer_range
    assert not descriptor(name).integer_range and not descriptor(name).floating_point_range
    assert (count.type_name, rate.type_name, name.type_name) == ('integer', 'double', 'string')
    assert (rate.unit, name.unit) == ('Hz', '')
    table = render_table([rate, name])
    assert '| `poll_rate_hz` | double | `50.0` | 0.1 .. 1000 | Hz | poll rate [Hz] |' in table
    assert "| `frame_id` | string | `''` |  |  | frame of joint_states |" in table
    text = render_yaml('n', [rate], '# header')
    assert (
        text == '# header\nn:\n  ros__parameters:\n    poll_rate_hz: 50.0  # poll rate [Hz] [0.1 .. 1000]\n'
    )


@pytest.mark.ros
def test_a_value_out_of_its_range_is_one_clear_error_at_start_and_refused_by_ros_later(
    ros_context: Context,
) -> None:
    """A real rclpy node declaring a spec: a start value outside the range is one ConfigError naming
    the parameter, its range, unit and value; a later set outside it is ROS's rejection."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes.param_spec import declare

    spec = ParamSpec('poll_rate_hz', 50.0, 'poll rate [Hz]', (0.1, 1000.0))
    node = Node(
        'param_range_bad', context=ros_context, parameter_overrides=[Parameter('poll_rate_hz', value=0.0)]
    )
    try:
        with pytest.raises(ConfigError) as caught:
            declare(node, [spec])
        assert str(caught.value) == 'poll_rate_hz must be within 0.1 .. 1000 [Hz], got 0.0'
    finally:
        node.destroy_node()
    node = Node(
        'param_range_good', context=ros_context, parameter_overrides=[Parameter('poll_rate_hz', value=20.0)]
    )
    try:
        assert declare(node, [spec]) == {'poll_rate_hz': 20.0}
        (result,) = node.set_parameters([Parameter('poll_rate_hz', value=2000.0)])
        assert not result.successful and 'out of range' in result.reason
        assert node.get_parameter('poll_rate_hz').value == 20.0
    finally:
        node.destroy_node()


@pytest.mark.parametrize('entry', param_files.NODES, ids=lambda e: e.node)
def test_every_numeric_parameter_has_a_range_holding_its_default(entry: NodeParams) -> None:
    for spec in entry.specs:
        if spec.type_name in ('integer', 'double'):
            assert spec.range is not None, spec.name
            assert isinstance(spec.default, (int, float)), spec.name
            assert spec.range[0] <= spec.default <= spec.range[1], spec.name


def test_a_value_not_among_its_choices_is_one_clear_error_at_start_and_at_every_read(
    ros_context: Context,
) -> None:
    """``choices`` (the des_driver's baud, polarities, current source): a start value not among them
    is one ConfigError; a later set ROS accepts (in the range) is caught where the node reads again."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes.param_spec import declare, read

    spec = ParamSpec('polarity', 1, 'sense of forward motion: +1 or -1', (-1, 1), choices=(1, -1))
    assert descriptor(spec).additional_constraints == 'one of 1, -1'
    node = Node('param_choice_bad', context=ros_context, parameter_overrides=[Parameter('polarity', value=0)])
    try:
        with pytest.raises(ConfigError) as caught:
            declare(node, [spec])
        assert str(caught.value) == 'polarity must be one of 1, -1, not 0'
    finally:
        node.destroy_node()
    node = Node('param_choice_later', context=ros_context)
    try:
        assert declare(node, [spec]) == {'polarity': 1}
        (result,) = node.set_parameters([Parameter('polarity', value=0)])
        assert result.successful  # inside the range: ROS has no word against it
        with pytest.raises(ConfigError, match='polarity must be one of 1, -1, not 0'):
            read(node, [spec])
    finally:
        node.destroy_node()


def test_a_start_only_parameter_is_read_only_in_its_descriptor(ros_context: Context) -> None:
    """power_estimator's parameters but ``terrain`` are read at start only: ROS refuses a later set."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from skidsteer_power.nodes.param_spec import declare
    from skidsteer_power.nodes.power_estimator import PARAMETERS, RUN_TIME_PARAMETERS

    assert {s.name for s in PARAMETERS if not s.read_only} == set(RUN_TIME_PARAMETERS) == {'terrain'}
    spec = ParamSpec('vehicle', 'test_robot_track', 'vehicle name', read_only=True)
    assert descriptor(spec).read_only
    node = Node('param_read_only', context=ros_context)
    try:
        declare(node, [spec])
        (result,) = node.set_parameters([Parameter('vehicle', value='packbot_track')])
        assert not result.successful and 'read-only' in result.reason
        assert node.get_parameter('vehicle').value == 'test_robot_track'
    finally:
        node.destroy_node()


# -- typed parameter objects (nodes/parameters.py, rendered from the specs) ------------------------


@pytest.mark.parametrize('entry', param_files.NODES, ids=lambda e: e.node)
def test_each_node_parameter_object_has_the_specs_names_types_and_defaults(entry: NodeParams) -> None:
    """The generated dataclass, read with dataclasses (not the renderer): a field per spec, in order,
    annotated with the default's Python type, defaulting to it; frozen."""
    import dataclasses

    from skidsteer_power.nodes import parameters

    cls = getattr(parameters, entry.class_name)
    fields = dataclasses.fields(cls)
    assert [f.name for f in fields] == [spec.name for spec in entry.specs]
    for f, spec in zip(fields, entry.specs, strict=True):
        assert f.type == type(spec.default).__name__ and f.default == spec.default, spec.name
    defaults = cls()
    with pytest.raises(dataclasses.FrozenInstanceError):
        defaults.vehicle = 'other'


def test_parameters_of_checks_type_range_and_choices_by_spec() -> None:
    """parameters_of: every value checked by its spec (one ConfigError naming it), an int taken for
    a float as a float, a missing value at its default, an unknown name refused."""
    from skidsteer_power.des.protocol import BAUD_CODES
    from skidsteer_power.errors import ConfigError
    from skidsteer_power.nodes import des_driver
    from skidsteer_power.nodes.param_spec import parameters_of
    from skidsteer_power.nodes.parameters import DesDriverParameters

    specs = des_driver.PARAMETERS
    p = parameters_of(DesDriverParameters, specs, {'poll_rate_hz': 20, 'baud': 115200})
    assert p.poll_rate_hz == 20.0 and type(p.poll_rate_hz) is float and p.baud == 115200
    assert p.left_port == '/dev/ttyUSB0' and p.right_polarity == -1  # the spec's defaults
    with pytest.raises(ConfigError, match=r'poll_rate_hz must be within 0\.1 \.\. 1000 \[Hz\], got 0\.0'):
        parameters_of(DesDriverParameters, specs, {'poll_rate_hz': 0.0})
    assert 12345 not in BAUD_CODES
    with pytest.raises(ConfigError, match=r'baud must be one of .*, not 12345'):
        parameters_of(DesDriverParameters, specs, {'baud': 12345})
    with pytest.raises(ConfigError, match="guardian must be of type bool, not 'yes'"):
        parameters_of(DesDriverParameters, specs, {'guardian': 'yes'})
    with pytest.raises(ConfigError, match='status_every must be of type integer, not True'):
        parameters_of(DesDriverParameters, specs, {'status_every': True})  # a bool is no int here
    with pytest.raises(ConfigError, match='no such parameter: poll_rate'):
        parameters_of(DesDriverParameters, specs, {'poll_rate': 20.0})


def test_a_stale_parameter_object_is_a_runtime_error_naming_the_renderer() -> None:
    from skidsteer_power.nodes import des_driver
    from skidsteer_power.nodes.param_spec import parameters_of
    from skidsteer_power.nodes.parameters import DesDriverParameters

    with pytest.raises(RuntimeError, match=r'skidsteer_power\.nodes\.param_files'):
        parameters_of(DesDriverParameters, (*des_driver.PARAMETERS, ParamSpec('extra', 1.0, 'x', (0, 2))), {})


def test_the_rendered_module_is_formatted_and_compiles() -> None:
    """render_parameters_module's text for a small spec: what ruff format leaves (checked on the
    shipped file by ``ruff format --check``) and a dataclass that builds with the defaults."""
    from skidsteer_power.nodes.param_spec import render_parameters_module

    specs = (
        ParamSpec('rate_hz', 2.0, 'a rate [Hz]', (0.5, 4.0)),
        ParamSpec('mode', 'a', 'the "mode"', choices=('a', 'b'), read_only=True),
    )
    text = render_parameters_module([('Small', 'Two parameters.', specs)], 'Header.')
    assert '    rate_hz: float = 2.0\n    """a rate [Hz]; range 0.5 .. 4"""\n' in text
    assert "    mode: str = 'a'\n    \"\"\"the 'mode'; one of 'a', 'b'; read only\"\"\"\n" in text
    namespace: dict[str, object] = {}
    exec(compile(text, 'small.py', 'exec'), namespace)
    small = namespace['Small']
    assert isinstance(small, type)
    assert (small().rate_hz, small().mode) == (2.0, 'a')
