"""argparse types for ROS names (a namespace, a service name): checked with rclpy's own validators
before any node is made, so a bad name is one line and exit 2, not rclpy's traceback (issue 34's
"tracebacks and silent acceptance"). ``_ros_names`` starts with '_': it adds no subcommand."""

from __future__ import annotations

import argparse


def _first_line(err: Exception) -> str:
    """What rclpy says is wrong, without its 'Invalid namespace: ' prefix and its caret lines."""
    line = str(err).strip().splitlines()[0].rstrip(':')
    return line.split(': ', 1)[-1]


def namespace(text: str) -> str:
    """argparse type: a ROS namespace ('' = none; 'robot1' and '/robot1' are the same)."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_namespace import validate_namespace

    if text.strip('/') == '':
        return ''
    try:
        validate_namespace('/' + text.strip('/'))
    except NameValidationException as err:
        raise argparse.ArgumentTypeError(f'invalid namespace {text!r}: {_first_line(err)}') from None
    return text


def full_service_name(name: str) -> str:
    """``name`` if it is a valid absolute ROS service name (ValueError naming what is wrong)."""
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    try:
        validate_full_topic_name(name, is_service=True)
    except NameValidationException as err:
        raise ValueError(f'{name!r}: {_first_line(err)}') from None
    return name
