"""The one ``main`` every node shares (ros2/demos style): init, spin, clean shutdown, one error line."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

from skidsteer_power.errors import SkidsteerError


def spin_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None) -> None:
    """Create the node with ``make_node`` and spin it until Ctrl-C or an external shutdown.

    A bad configuration (``SkidsteerError`` or a rejected parameter) is one line on stderr and exit
    code 2; the node is always destroyed (its ``destroy_node`` does the safe stop) and rclpy shut down.
    """
    rclpy.init(args=args)
    node = None
    exit_code = 0
    try:
        node = make_node()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SkidsteerError, ParameterException) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        exit_code = 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if exit_code:
        sys.exit(exit_code)
