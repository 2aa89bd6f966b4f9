"""The Foxglove bridge's exposure and compatibility (issues 28, 29): real foxglove-sdk server behind
the websockets front door, real rclpy and DDS, real WebSocket clients (websockets; the npm
@foxglove/ws-protocol client where node and npm are installed).

- It listens on 127.0.0.1 by default; ``--host 0.0.0.0`` warns.
- A web page from another origin is refused (HTTP 403); no Origin, localhost origins and
  ``--allow-origin`` ones are accepted.
- A client offering only the classic ``foxglove.websocket.v1`` is served (foxglove-sdk alone answers
  it with HTTP 400).
- ``--allow-publish cmd_vel``: a client's Twist reaches des_driver, whose checks apply (clamped).
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from rclpy.context import Context
from rclpy.node import Node
from websockets.exceptions import InvalidStatus
from websockets.sync import client as websockets_sync  # requirements.txt
from websockets.typing import Origin, Subprotocol

from skidsteer_power.nodes.foxglove_front import origin_allowed

if TYPE_CHECKING:
    from des_harness import Harness

    from skidsteer_power.des.simulator import SimulatedPair


pytestmark = pytest.mark.ros
CLIENT_JS = Path(__file__).resolve().parent / 'foxglove_npm' / 'client.js'
NPM_PACKAGES = ('@foxglove/ws-protocol@0.8.0', 'ws@8.23.0')
CLIENT_DATA = struct.Struct('<BI')  # client message data: opcode 0x01, client channel id


@pytest.fixture
def bridge_node(ros_context: Context) -> Iterator[Node]:
    """A node spun by an executor in a thread, to host an in-process bridge."""
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    node = rclpy.create_node(f'fox_{uuid.uuid4().hex[:6]}', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    yield node
    executor.shutdown()
    thread.join(5)
    node.destroy_node()


def test_origin_policy() -> None:
    assert origin_allowed(None, ())
    assert origin_allowed('http://localhost:8080', ()) and origin_allowed('http://127.0.0.1', ())
    assert origin_allowed('http://[::1]:3000', ())
    assert not origin_allowed('https://app.foxglove.dev', ())
    assert origin_allowed('https://app.foxglove.dev', ('https://app.foxglove.dev/',))
    assert not origin_allowed('https://evil.example', ('https://app.foxglove.dev',))
    assert not origin_allowed('http://localhost.evil.example', ())


def test_default_host_is_loopback_and_origins_are_checked(bridge_node: Node) -> None:
    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge(
        bridge_node, port=0, topics=['/none'], allowed_origins=['https://app.foxglove.dev']
    )
    try:
        assert bridge.front._server.sockets[0].getsockname()[0] == '127.0.0.1'
        url = f'ws://127.0.0.1:{bridge.port}'
        with pytest.raises(InvalidStatus) as refused:
            websockets_sync.connect(
                url, subprotocols=[Subprotocol('foxglove.sdk.v1')], origin=Origin('https://evil.example')
            )
        assert refused.value.response.status_code == 403
        for origin in (None, Origin('http://localhost:8080'), Origin('https://app.foxglove.dev')):
            with websockets_sync.connect(
                url, subprotocols=[Subprotocol('foxglove.sdk.v1')], origin=origin
            ) as ws:
                assert json.loads(ws.recv(timeout=10))['op'] == 'serverInfo'
        assert bridge.front.refused == 1
    finally:
        bridge.close()


def test_the_backend_refuses_a_direct_handshake_from_a_web_page(bridge_node: Node) -> None:
    """Issue 34: the SDK server behind the front door listens on a second 127.0.0.1 port, and a
    handshake there with Origin http://evil.example was accepted, skipping the front's check. Now it
    speaks only TLS with a certificate made for this run: a plain ws:// handshake fails, and a
    wss:// one fails certificate verification as a browser's does (no authority signed it); the
    front door, which pins that certificate, still serves the same client."""
    import ssl

    from websockets.exceptions import InvalidMessage

    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge(bridge_node, port=0, topics=['/none'])
    try:
        backend = bridge.server.port
        assert backend != bridge.port
        protocols, evil = [Subprotocol('foxglove.sdk.v1')], Origin('http://evil.example')
        with pytest.raises((InvalidMessage, OSError, EOFError)):
            websockets_sync.connect(f'ws://127.0.0.1:{backend}', subprotocols=protocols, origin=evil)
        with pytest.raises(ssl.SSLCertVerificationError):
            websockets_sync.connect(f'wss://127.0.0.1:{backend}', subprotocols=protocols, origin=evil)
        with pytest.raises(InvalidStatus) as refused:  # and the front door still refuses that page
            websockets_sync.connect(f'ws://127.0.0.1:{bridge.port}', subprotocols=protocols, origin=evil)
        assert refused.value.response.status_code == 403
        with websockets_sync.connect(
            f'ws://127.0.0.1:{bridge.port}', subprotocols=[Subprotocol('foxglove.sdk.v1')]
        ) as ws:  # the control: through the front door, no Origin: served by that backend
            assert json.loads(ws.recv(timeout=10))['op'] == 'serverInfo'
    finally:
        bridge.close()


def test_a_client_offering_only_the_classic_subprotocol_is_served(bridge_node: Node) -> None:
    import foxglove

    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    bridge = FoxgloveBridge(bridge_node, port=0, topics=['/none'])
    try:
        with websockets_sync.connect(
            f'ws://127.0.0.1:{bridge.port}', subprotocols=[Subprotocol('foxglove.websocket.v1')]
        ) as ws:
            assert ws.subprotocol == 'foxglove.websocket.v1'
            info = json.loads(ws.recv(timeout=10))
            assert info['op'] == 'serverInfo' and 'clientPublish' not in info['capabilities']
    finally:
        bridge.close()
    # the SDK's own server (what `bridge` was before) refuses that client
    context = foxglove.Context()
    server = foxglove.start_server(host='127.0.0.1', port=0, context=context)
    try:
        with pytest.raises(InvalidStatus) as refused:
            websockets_sync.connect(
                f'ws://127.0.0.1:{server.port}', subprotocols=[Subprotocol('foxglove.websocket.v1')]
            )
        assert refused.value.response.status_code == 400
    finally:
        server.stop()


def test_host_0000_warns(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'bridge', '--host', '0.0.0.0', '--port', '0',
         '--duration', '0.5', '--topics', '/none', '--allow-publish', 'cmd_vel'],
        capture_output=True, text=True, timeout=60, cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert 'warning: serving Foxglove on 0.0.0.0: no authentication' in run.stderr
    assert 'publishes to cmd_vel' in run.stderr and 'SSH tunnel' in run.stderr
    helped = subprocess.run(
        [sys.executable, '-m', 'skidsteer_power.cli.main', 'bridge', '--help'],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert 'default 127.0.0.1' in helped.stdout and '--allow-publish' in helped.stdout


@pytest.fixture
def driver(ros_context: Context) -> Iterator[tuple[Harness, SimulatedPair, str]]:
    from des_harness import Harness

    from skidsteer_power.des.simulator import SimulatedPair

    with SimulatedPair(38400) as pair:
        ns = f'/t{uuid.uuid4().hex[:8]}'
        harness = Harness(ros_context, pair, namespace=ns)
        yield harness, pair, ns
        harness.close()


def twist_cdr(speed_m_s: float) -> bytes:
    from geometry_msgs.msg import Twist
    from rclpy.serialization import serialize_message

    msg = Twist()
    msg.linear.x = speed_m_s
    return serialize_message(msg)


# 5 m/s asked; des_driver clamps to max_speed_m_s 1.5: test_robot_track (sprocket r 0.1 m, 12:1):
# 1.5 / 0.1 * 12 = 180 rad/s = 1718.9 rpm at most on each motor.
CLAMPED_RPM = 1.5 / 0.1 * 12 * 60 / (2 * 3.141592653589793)


def test_client_publishing_reaches_des_driver_and_its_checks(
    driver: tuple[Harness, SimulatedPair, str],
) -> None:
    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    harness, pair, ns = driver
    bridge = FoxgloveBridge(
        harness.node, port=0, topics=[f'{ns}/joint_states'], allow_publish=[f'{ns}/cmd_vel']
    )
    try:
        with websockets_sync.connect(
            f'ws://127.0.0.1:{bridge.port}', subprotocols=[Subprotocol('foxglove.websocket.v1')]
        ) as ws:
            info = json.loads(ws.recv(timeout=10))
            assert 'clientPublish' in info['capabilities'] and 'cdr' in info['supportedEncodings']
            channels = [
                {
                    'id': 7,
                    'topic': f'{ns}/cmd_vel',
                    'encoding': 'cdr',
                    'schemaName': 'geometry_msgs/msg/Twist',
                },
                {'id': 8, 'topic': f'{ns}/other', 'encoding': 'cdr', 'schemaName': 'geometry_msgs/msg/Twist'},
            ]
            ws.send(json.dumps({'op': 'advertise', 'channels': channels}))
            fast = CLIENT_DATA.pack(1, 7) + twist_cdr(5.0)

            def driving_clamped() -> bool:
                ws.send(fast)
                ws.send(CLIENT_DATA.pack(1, 8) + twist_cdr(5.0))
                return harness.driver.counts['clamped'] > 0 and pair.left.speed_setpoint_rpm > 1000

            assert harness.spin_until(driving_clamped, timeout_s=20)
            assert 0 < pair.left.speed_setpoint_rpm <= CLAMPED_RPM + 1
            # the client stops sending: the driver's watchdog stops the motors
            assert harness.spin_until(lambda: pair.left.speed_setpoint_rpm == 0)
        assert bridge.client_publish is not None
        assert bridge.client_publish.refused == 1  # the channel on /other
        assert set(bridge.client_publish.published) == {f'{ns}/cmd_vel'}
    finally:
        bridge.close()


@pytest.fixture(scope='session')
def npm_client(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with @foxglove/ws-protocol and ws installed from the npm registry (skipped, with the
    reason, where node or npm is absent)."""
    node, npm = shutil.which('node'), shutil.which('npm')
    if node is None or npm is None:
        pytest.skip('node and npm are not installed: the npm Foxglove client test needs them')
    folder = tmp_path_factory.mktemp('foxglove_npm')
    install = subprocess.run(
        [npm, 'install', '--no-audit', '--no-fund', '--silent', '--prefix', str(folder), *NPM_PACKAGES],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    if install.returncode != 0:
        if os.environ.get('CI'):
            pytest.fail(f'npm install failed: {install.stderr[-2000:]}')
        pytest.skip(f'npm install failed (offline?): {install.stderr[-300:]}')
    shutil.copy2(CLIENT_JS, folder / 'client.js')
    return folder


def test_the_npm_foxglove_client_subscribes_and_drives(
    npm_client: Path, driver: tuple[Harness, SimulatedPair, str]
) -> None:
    """@foxglove/ws-protocol 0.8.0 (what Lichtblick and older Foxglove use), offering only
    foxglove.websocket.v1: it is served, decodes joint_states' channel, and its Teleop-style Twist
    (0.3 m/s) drives the simulated amplifiers through des_driver."""
    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    harness, pair, ns = driver
    bridge = FoxgloveBridge(
        harness.node, port=0, topics=[f'{ns}/joint_states'], allow_publish=[f'{ns}/cmd_vel']
    )
    try:
        argv = ['node', str(npm_client / 'client.js'), f'ws://127.0.0.1:{bridge.port}', f'{ns}/joint_states',
                f'{ns}/cmd_vel', twist_cdr(0.3).hex()]  # fmt: skip
        proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=npm_client
        )
        moved: list[int] = []

        def record_until_done() -> bool:
            moved.append(pair.left.speed_setpoint_rpm)
            return proc.poll() is not None

        harness.spin_until(record_until_done, 40)
        out, err = proc.communicate(timeout=30)
    finally:
        bridge.close()
    assert proc.returncode == 0, out + err
    seen = json.loads(out.strip().splitlines()[-1])
    assert seen['subprotocol'] == 'foxglove.websocket.v1' and 'clientPublish' in seen['capabilities']
    assert seen['schemaName'] == 'sensor_msgs/msg/JointState' and seen['messages'] >= 3
    # 0.3 m/s straight on test_robot_track: 0.3 / 0.1 * 12 rad/s = 343.8 rpm left (slewed up to it)
    assert max(moved) > 0 and max(moved) <= 344
