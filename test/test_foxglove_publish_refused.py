"""Client publishing through the bridge, the refusals (issue 37 item 6): the npm @foxglove/ws-protocol
client (what Lichtblick and older Foxglove use) against the real bridge, real rclpy and DDS, the
real des_driver on the simulated DES 70/10.

- subscribe / unsubscribe no longer log ``Callback failed: AttributeError ... on_unsubscribe``;
- a client channel of another type than the topic's in the bridge process (TwistStamped on a Twist
  cmd_vel) or on a topic not allowed is refused with a status message back, never an RCLError.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from test_foxglove_security import driver, npm_client, twist_cdr  # noqa: F401  (fixtures)

from skidsteer_power.nodes.foxglove_bridge import ClientPublish

if TYPE_CHECKING:
    from des_harness import Harness

    from skidsteer_power.des.simulator import SimulatedPair

pytestmark = pytest.mark.ros


def test_listener_has_every_method_the_sdk_calls() -> None:
    from foxglove.websocket import ServerListener

    wanted = {n for n in dir(ServerListener) if n.startswith('on_') and 'parameters' not in n}
    wanted -= {'on_get_parameters', 'on_set_parameters', 'on_playback_control_request'}  # not offered
    assert wanted <= set(dir(ClientPublish)), sorted(wanted - set(dir(ClientPublish)))


def run_client(npm_dir: Path, url: str, topic: str, pub_topic: str, schema: str) -> dict[str, object]:
    argv = ['node', str(npm_dir / 'client.js'), url, topic, pub_topic, twist_cdr(0.3).hex()]
    env = {**os.environ, 'PUB_SCHEMA': schema}
    done = subprocess.run(argv, capture_output=True, text=True, cwd=npm_dir, env=env, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    result: dict[str, object] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


@pytest.mark.parametrize(
    ('suffix', 'schema', 'why'),
    [
        (
            'cmd_vel',
            'geometry_msgs/msg/TwistStamped',
            'in the bridge process, not geometry_msgs/msg/TwistStamped',
        ),
        ('other', 'geometry_msgs/msg/Twist', 'publishing is allowed on'),
    ],
)
def test_a_refused_client_channel_gets_a_status_and_nothing_moves(
    npm_client: Path,  # noqa: F811
    driver: tuple[Harness, SimulatedPair, str],  # noqa: F811
    capfd: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    suffix: str,
    schema: str,
    why: str,
) -> None:
    import threading

    from skidsteer_power.nodes.foxglove_bridge import FoxgloveBridge

    harness, pair, ns = driver
    bridge = FoxgloveBridge(
        harness.node, port=0, topics=[f'{ns}/joint_states'], allow_publish=[f'{ns}/cmd_vel']
    )
    result: dict[str, object] = {}
    moved: list[int] = []
    try:
        url = f'ws://127.0.0.1:{bridge.port}'
        worker = threading.Thread(
            target=lambda: result.update(
                run_client(npm_client, url, f'{ns}/joint_states', f'{ns}/{suffix}', schema)
            )
        )
        worker.start()

        def record_until_done() -> bool:
            moved.append(pair.left.speed_setpoint_rpm)
            return not worker.is_alive()

        harness.spin_until(record_until_done, 60)
        worker.join(5)
    finally:
        bridge.close()
    statuses = [str(s) for s in result['status']]  # type: ignore[attr-defined]
    assert any('refused channel' in s and why in s for s in statuses), statuses
    assert int(str(result['messages'])) >= 3  # the client subscribed and got joint_states meanwhile
    assert max(moved) == 0  # nothing it sent reached the motors
    assert bridge.client_publish is not None and bridge.client_publish.refused == 1
    logged = capfd.readouterr().err + caplog.text
    assert 'Callback failed' not in logged and 'RCLError' not in logged
