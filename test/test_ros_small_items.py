"""Issue 37 item 10: one diagnostics publisher per node, the launch file's namespace and remap
arguments, 3-pose circles not counted as fitted, trace.png's window holding whole circles."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
from rclpy.context import Context
from test_cmd_vel_input import Graph

from skidsteer_power.validation.report import MIN_FIT_POSES, is_fitted, is_turn, trace_window
from skidsteer_power.validation.validate import TraceSegment

ROOT = Path(__file__).resolve().parents[1]


def test_power_estimator_has_one_diagnostics_publisher(ros_context: Context, tmp_path: Path) -> None:
    g = Graph(ros_context, tmp_path)
    try:
        topic = f'{g.namespace}/diagnostics'

        def publishers() -> list[str]:
            return [i.node_name for i in g.client.get_publishers_info_by_topic(topic)]

        assert g.spin_until(lambda: 'power_estimator' in publishers())
        assert publishers().count('power_estimator') == 1  # the path energy status shares it
    finally:
        g.close()


def test_launch_file_declares_namespace_and_remaps() -> None:
    tree = ast.parse((ROOT / 'launch' / 'skidsteer_power.launch.py').read_text(encoding='utf-8'))
    declared = {
        node.args[0].value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and getattr(node.func, 'id', '') == 'DeclareLaunchArgument'
        and isinstance(node.args[0], ast.Constant)
    }
    assert {'namespace', 'cmd_vel_topic', 'joint_states_topic', 'cmd_vel_type'} <= declared
    nodes = [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, 'id', '') in ('Node', 'LifecycleNode')
    ]
    assert len(nodes) == 3
    for node in nodes:
        keywords = {k.arg: k.value for k in node.keywords}
        assert isinstance(keywords['namespace'], ast.Name) and keywords['namespace'].id == 'namespace'


def segment(points: int, radius_m: float = 1.0, cx: float = 0.0, duration_s: float = 10.0) -> TraceSegment:
    return TraceSegment(0.0, duration_s, 0.1, 0.1, 1.0, points, radius_m, cx, 0.0, 0.0, 0.1)


def test_three_poses_are_not_a_fitted_circle() -> None:
    assert MIN_FIT_POSES == 4  # a circle passes through any 3 points exactly (zero residual)
    assert not is_fitted(segment(3)) and not is_turn(segment(3))
    assert is_fitted(segment(4)) and is_turn(segment(4))  # 0.1 m/s x 10 s on 1 m: 1 rad swept
    assert not is_fitted(segment(40, radius_m=math.inf))  # collinear poses: no circle


def test_trace_window_holds_every_turn_circle_whole() -> None:
    x, y = np.array([0.0, 0.5]), np.array([0.0, 0.1])  # a short path
    turns = [segment(20, radius_m=1.0, cx=0.0), segment(20, radius_m=2.0, cx=3.0)]
    (x_lo, x_hi), (y_lo, y_hi) = trace_window(x, y, turns)
    for s in turns:  # the whole circle is inside the window
        assert x_lo <= s.center_x_m - s.radius_m and s.center_x_m + s.radius_m <= x_hi
        assert y_lo <= s.center_y_m - s.radius_m and s.center_y_m + s.radius_m <= y_hi
    assert math.isclose(x_hi - x_lo, y_hi - y_lo)  # square: equal aspect
