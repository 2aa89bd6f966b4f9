"""The package as a ROS developer installs it: ``colcon build`` in a clean workspace, then the
INSTALLED power_estimator and des_driver (``install/skidsteer_power/lib/skidsteer_power/<exe>``,
environment from ``install/setup.bash``) with the INSTALLED parameter file, against simulated DES
70/10 amplifiers on pseudo-terminals, until they publish.

colcon comes from colcon-common-extensions (requirements-dev.txt) in the test venv; the build uses
that venv's Python, as ``colcon build`` on a robot uses the distribution's. The package source is
copied (not symlinked: colcon would then install a symlink back into this checkout, and the
resolver would find ``config/`` next to the code instead of the installed share directory).

The workspace holds a Python venv the way docs/ROS.md's recipe makes one (``VENV_RECIPE``): a venv
inside a colcon workspace breaks ``colcon build`` once the ROS wheels are in it (colcon crawls
``venv/share/<pkg>/package.xml`` and finds every ROS package twice), so the recipe writes
``COLCON_IGNORE`` into it. The wheels' ``share/`` tree is copied from this test venv, where pip put it.

TODO(lead): des_driver becomes a managed (lifecycle) node on the driver branch. The test already
handles both: :func:`activate_if_managed` calls configure and activate through
``/des_driver/change_state`` when that service exists; a plain node publishes without it.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import pytest
import rclpy
from geometry_msgs.msg import Twist
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import BatteryState, JointState

from skidsteer_power.des.simulator import SimulatedPair

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ('package.xml', 'setup.py', 'setup.cfg', 'resource', 'config', 'launch', 'skidsteer_power')
COLCON = Path(sys.executable).with_name('colcon')
VENV_RECIPE = 'python3 -m venv --system-site-packages venv && touch venv/COLCON_IGNORE'
"""docs/ROS.md's line (section "Building on the robot with colcon"), run in the workspace root."""


def _colcon() -> Path:
    if COLCON.exists():
        return COLCON
    if os.environ.get('CI'):
        pytest.fail(f'colcon is not installed next to {sys.executable} (requirements-dev.txt)')
    pytest.skip('colcon-common-extensions is not installed in this environment (requirements-dev.txt)')


@pytest.fixture(scope='module')
def workspace(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A colcon workspace with this package built and installed (ament_python, copied sources)."""
    colcon = _colcon()
    ws = tmp_path_factory.mktemp('colcon_ws')
    src = ws / 'src' / 'skidsteer_power'
    src.mkdir(parents=True)
    ignore = shutil.ignore_patterns('__pycache__', '*.pyc')
    for name in SHIPPED:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=ignore)
        else:
            shutil.copy2(path, src / name)
    env = {**os.environ, 'PATH': f'{COLCON.parent}{os.pathsep}{os.environ["PATH"]}'}
    subprocess.run(['bash', '-c', VENV_RECIPE], cwd=ws, env=env, check=True, timeout=120)
    add_ros_wheels_share(ws / 'venv')
    build = subprocess.run(
        [str(colcon), 'build', '--event-handlers', 'console_cohesion+'],
        cwd=ws, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    return ws


def add_ros_wheels_share(venv: Path) -> None:
    """The ``share/<pkg>/package.xml`` files pip installs with the ROS wheels (copied from this
    test venv, which has them), so that colcon would find them in ``venv``."""
    found = list(Path(sys.prefix, 'share').glob('*/package.xml'))
    if not found:
        pytest.skip(f'no ROS wheels with share/<pkg>/package.xml in {sys.prefix}')
    for xml in found:
        (venv / 'share' / xml.parent.name).mkdir(parents=True, exist_ok=True)
        shutil.copy2(xml, venv / 'share' / xml.parent.name / 'package.xml')


def test_ros_doc_recipe_is_the_one_tested_and_colcon_ignores_the_venv(tmp_path: Path) -> None:
    """docs/ROS.md's colcon recipe makes its venv the way this test does; with the ROS wheels in that
    venv, colcon sees only this package there, and without COLCON_IGNORE it would see them all."""
    colcon = _colcon()
    ros_doc = (ROOT / 'docs' / 'ROS.md').read_text()
    recipe = ros_doc.split('### Building on the robot with colcon', 1)[1].split('```', 2)[1]
    assert VENV_RECIPE in recipe
    shutil.copytree(ROOT / 'resource', tmp_path / 'src' / 'skidsteer_power' / 'resource')
    shutil.copy2(ROOT / 'package.xml', tmp_path / 'src' / 'skidsteer_power' / 'package.xml')
    shutil.copy2(ROOT / 'setup.py', tmp_path / 'src' / 'skidsteer_power' / 'setup.py')
    subprocess.run(['bash', '-c', VENV_RECIPE], cwd=tmp_path, check=True, timeout=120)
    add_ros_wheels_share(tmp_path / 'venv')

    def listed() -> list[str]:
        out = subprocess.run([str(colcon), 'list', '--names-only'], cwd=tmp_path, capture_output=True,
                             text=True, timeout=120, check=True)  # fmt: skip
        return out.stdout.split()

    assert listed() == ['skidsteer_power']
    (tmp_path / 'venv' / 'COLCON_IGNORE').unlink()
    assert len(listed()) > 1  # what breaks `colcon build` (duplicate and foreign packages)


def installed(ws: Path, *parts: str) -> Path:
    return ws.joinpath('install', 'skidsteer_power', *parts)


def in_workspace(ws: Path, argv: list[str]) -> list[str]:
    """``argv`` run by bash after ``source install/setup.bash`` (as an operator would)."""
    command = ' '.join(f"'{a}'" for a in argv)
    return ['bash', '-c', f'source {ws}/install/setup.bash && exec {command}']


def test_colcon_installs_the_executables_config_and_ament_marker(workspace: Path) -> None:
    for exe in ('power_estimator', 'des_driver', 'energy_monitor', 'skidsteer-power'):
        assert installed(workspace, 'lib', 'skidsteer_power', exe).is_file(), exe
    share = installed(workspace, 'share', 'skidsteer_power')
    assert (share / 'package.xml').is_file() and (share / 'config' / 'estimator.yaml').is_file()
    for kind, name in (('vehicles', 'test_robot_track.yaml'), ('powertrains', 'test_robot.yaml'),
                       ('batteries', 'test_robot.yaml'), ('foxglove', 'operator_layout.json'),
                       ('joints', 'ros2_control_4wheel.yaml')):  # fmt: skip
        assert (share / 'config' / kind / name).is_file()
    marker = installed(workspace, 'share', 'ament_index', 'resource_index', 'packages', 'skidsteer_power')
    assert marker.is_file()
    # the installed code finds its files through the ament index, not in this checkout
    probe = subprocess.run(
        in_workspace(workspace, [sys.executable, '-c', 'import skidsteer_power.resources as r;'
                                 'print(r.__file__); print(r.config_roots()[0])']),
        capture_output=True, text=True, timeout=60, cwd=workspace,  # not this checkout: '' is on sys.path
    )  # fmt: skip
    module, config = probe.stdout.split()
    assert Path(module).is_relative_to(workspace / 'install'), module
    assert Path(config) == share / 'config'


def activate_if_managed(
    node: Node, executor: Executor, fqn: str = '/des_driver', timeout_s: float = 20.0
) -> bool:
    """Configure and activate the node ``fqn`` if it is managed (lifecycle); True if it was.

    A plain node has no ``<fqn>/change_state`` service and publishes on its own. Waits up to
    ``timeout_s`` for the node to come up: its lifecycle service, or (every rclpy node has them) its
    parameter services without a lifecycle service. ``executor`` spins ``node``.
    """
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    service = f'{fqn}/change_state'
    deadline = time.monotonic() + timeout_s
    while True:
        services = {name for name, _ in node.get_service_names_and_types()}
        if service in services:
            break
        if f'{fqn}/get_parameters' in services:
            executor.spin_once(timeout_sec=0.5)  # a lifecycle node creates both at once: look again
            if service not in {name for name, _ in node.get_service_names_and_types()}:
                return False
            break
        assert time.monotonic() < deadline, f'{fqn} did not come up within {timeout_s} s'
        executor.spin_once(timeout_sec=0.1)
    client = node.create_client(ChangeState, service)
    for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(ChangeState.Request(transition=Transition(id=transition)))
        executor.spin_until_future_complete(future, timeout_sec=20.0)
        assert future.done() and future.result().success, f'{fqn}: transition {transition} failed'
    return True


def test_installed_nodes_start_with_installed_params_and_publish(workspace: Path, tmp_path: Path) -> None:
    params = installed(workspace, 'share', 'skidsteer_power', 'config', 'estimator.yaml')
    exe = installed(workspace, 'lib', 'skidsteer_power')
    env = {**os.environ, 'ROS_DOMAIN_ID': os.environ['ROS_DOMAIN_ID']}
    namespace = f'colcon_{uuid.uuid4().hex[:6]}'
    remap = ['-r', f'__ns:=/{namespace}']
    procs: list[subprocess.Popen[str]] = []
    with SimulatedPair() as sims:
        estimator = in_workspace(workspace, [str(exe / 'power_estimator'), '--ros-args', '--params-file',
                                             str(params), *remap, '-p', f'map_cache_dir:={tmp_path / "maps"}',
                                             '-p', f'state_file:={tmp_path / "energy.json"}'])  # fmt: skip
        ports = ['-p', f'left_port:={sims.left.port}', '-p', f'right_port:={sims.right.port}']
        driver = in_workspace(workspace, [str(exe / 'des_driver'), '--ros-args', *remap, *ports])
        for argv in (estimator, driver):
            procs.append(subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                          text=True, start_new_session=True, cwd=tmp_path))  # fmt: skip
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node('colcon_probe', namespace=namespace, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            received: dict[str, list[Any]] = {}  # ROS messages by topic
            qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
            for topic, kind in (('joint_states', JointState), ('power/predicted', JointState),
                                ('power/measured', JointState), ('battery/state', BatteryState)):  # fmt: skip
                received[topic] = []
                node.create_subscription(kind, topic, received[topic].append, qos)
            cmd = node.create_publisher(Twist, 'cmd_vel', 10)
            twist = Twist()
            twist.linear.x = 0.1
            activate_if_managed(node, executor, f'/{namespace}/des_driver')
            deadline = time.monotonic() + 60.0
            while not all(received.values()):
                for proc in procs:
                    assert proc.poll() is None, proc.communicate()[0][-3000:]
                assert time.monotonic() < deadline, {k: len(v) for k, v in received.items()}
                cmd.publish(twist)
                executor.spin_once(timeout_sec=0.05)
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            for proc in procs:
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGINT)
            outputs = [proc.communicate(timeout=30)[0] for proc in procs]
    assert list(received['joint_states'][-1].name) == ['left_motor', 'right_motor']
    assert list(received['power/predicted'][-1].name)[:2] == ['left_motor', 'right_motor']
    assert 0.0 < received['battery/state'][-1].percentage <= 1.0
    assert all(proc.returncode == 0 for proc in procs), outputs
