"""The estimator's messages on the wire: inputs decoded by rosbags, outputs kept serialized.

Per message, rclpy's conversion between Python messages and their serialization cost more than the
estimator's physics (issue 18). Inputs: the subscriptions take the raw bytes and :func:`decoder`
deserializes them with rosbags (TwistStamped 3.9 us instead of rclpy's 20 us, JointState 6.4 us
instead of 11 us, measured on this machine). Outputs: :class:`PackedJointState`.

rclpy's ``publish(msg)`` converts the whole Python message to C (every name string again) before
serializing it. Here the message is serialized once by rclpy itself
(``rclpy.serialization.serialize_message``); the byte offsets of the stamp and of each number array
are found in that serialization by sentinel values, and each publish writes the new values there with
``struct.pack_into`` (5 us) and hands the bytes to ``Publisher.publish`` (rclpy's raw path): in the
estimator at 1 kHz a publish went from 60 to 44 us, most of the rest being Fast DDS's write. The
layout is rclpy's, not hand-written: ``test/test_nodes_wire.py`` compares patched bytes with rclpy's
serialization of the message built the ordinary way.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from functools import partial
from typing import TYPE_CHECKING

from rclpy.serialization import serialize_message
from rosbags.typesys import Stores, get_typestore
from sensor_msgs.msg import JointState

if TYPE_CHECKING:
    from skidsteer_power.nodes.ros_types import RosMessage

_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

FIELDS = ('position', 'velocity', 'effort')
_SENTINEL_SEC, _SENTINEL_NANOSEC = 0x7A5E_1F03, 0x2B6C_9D14  # a stamp no real message carries


class PackedJointState:
    """sensor_msgs/JointState with fixed ``names`` and ``fields`` (each of ``len(names)`` numbers),
    serialized once; :meth:`pack` returns the bytes of a message with a new stamp and new numbers.

    Fields not listed are empty; the header's frame_id is ``frame_id``."""

    def __init__(self, names: Sequence[str], fields: Sequence[str], frame_id: str = '') -> None:
        unknown = set(fields) - set(FIELDS)
        if unknown:
            raise ValueError(f'JointState has no number field {sorted(unknown)}')
        self.fields = tuple(fields)
        self.size = len(names)
        sentinels = {field: self._sentinel(k) for k, field in enumerate(self.fields)}
        msg = JointState(name=list(names), **sentinels)
        msg.header.frame_id = frame_id
        msg.header.stamp.sec, msg.header.stamp.nanosec = _SENTINEL_SEC, _SENTINEL_NANOSEC
        data = serialize_message(msg)
        self._order = '<' if data[1] & 1 else '>'  # CDR encapsulation: 0x0001 little, 0x0000 big endian
        self._buffer = bytearray(data)
        self._stamp_at = self._find(struct.pack(self._order + 'iI', _SENTINEL_SEC, _SENTINEL_NANOSEC))
        self._numbers = struct.Struct(self._order + 'd' * self.size)
        self._field_at = [self._find(self._numbers.pack(*sentinels[f])) for f in self.fields]
        self._stamp = struct.Struct(self._order + 'iI')

    def _sentinel(self, field_index: int) -> list[float]:
        return [float(0x5EED_0000 + 1000 * field_index + i) + 0.5 for i in range(self.size)]

    def _find(self, pattern: bytes) -> int:
        at = self._buffer.find(pattern)
        if at < 0 or self._buffer.find(pattern, at + 1) >= 0:
            raise RuntimeError('PackedJointState: the sentinel is not found exactly once in the CDR')
        return at

    def pack(self, sec: int, nanosec: int, *numbers: Sequence[float]) -> bytes:
        """The serialized message with stamp ``sec``/``nanosec`` and one sequence of ``len(names)``
        numbers per field, in the order of ``fields``."""
        buffer = self._buffer
        self._stamp.pack_into(buffer, self._stamp_at, sec, nanosec)
        for at, values in zip(self._field_at, numbers, strict=True):
            self._numbers.pack_into(buffer, at, *values)
        return bytes(buffer)


def decoder(msg_type: type) -> Callable[[bytes], RosMessage]:
    """Serialized ``msg_type`` (an rclpy message class) -> its rosbags message: a dataclass with the
    same fields, number sequences as numpy arrays."""
    package = msg_type.__module__.split('.')[0]
    return partial(_TYPESTORE.deserialize_cdr, typename=f'{package}/msg/{msg_type.__name__}')
