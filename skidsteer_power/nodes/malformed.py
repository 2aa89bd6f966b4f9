"""Raw subscriptions that survive a malformed message (issue 34 item 8).

A raw subscription hands the node whatever bytes a writer sent; nothing in DDS checks that they are
a valid CDR serialization of the topic's type (rclpy's ``publish(bytes)`` sends any bytes, and so does
``bridge --allow-publish`` for a WebSocket client). One such message used to raise rosbags'
``SerdeError`` out of the callback and end ``power_estimator`` (and, under ``run``, the whole suite).

:class:`MalformedInputs` wraps a decoder: a message that does not decode is dropped, counted per
topic, and logged at most once per ``warn_period_s`` per topic (with the count so far). The node
shows the counts in its diagnostics (``malformed_<topic>``) and WARNs for :data:`MALFORMED_WARN_S`
after the latest one.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from typing import TypeVar

MALFORMED_WARN_S = 10.0
"""How long the diagnostics WARN after the latest malformed message [s]."""
PREVIEW_BYTES = 16
"""How many leading bytes of a malformed message the warning shows."""

_Decoded = TypeVar('_Decoded')


class MalformedInputs:
    """Counts and rate-limits malformed messages of a node's raw subscriptions.

    ``warn`` logs one line; ``clock`` gives the time for the rate limit and the WARN window [s]
    (monotonic by default: a clock step cannot silence or flood the warnings)."""

    def __init__(
        self,
        warn: Callable[[str], object],
        warn_period_s: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.warn = warn
        self.warn_period_s = float(warn_period_s)
        self.clock = clock
        self.counts: Counter[str] = Counter()
        self.last_s: float | None = None
        self._warned_s: dict[str, float] = {}

    def guard(self, topic: str, decode: Callable[[bytes], _Decoded]) -> Callable[[bytes], _Decoded | None]:
        """``decode`` for ``topic`` that returns None (counted, maybe logged) instead of raising."""
        self.counts[topic] += 0  # listed in the diagnostics from the start

        def safe(data: bytes) -> _Decoded | None:
            try:
                return decode(data)
            except Exception as err:  # untrusted bytes: any decoder error is the message's fault
                self.record(topic, data, err)
                return None

        return safe

    def record(self, topic: str, data: bytes, err: Exception) -> None:
        """Count one malformed message on ``topic``; log it unless one was logged within the period."""
        now = self.clock()
        self.counts[topic] += 1
        self.last_s = now
        last = self._warned_s.get(topic)
        if last is not None and now - last < self.warn_period_s:
            return
        self._warned_s[topic] = now
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        self.warn(
            f'{topic}: malformed message of {len(data)} bytes dropped '
            f'(starts {bytes(data[:PREVIEW_BYTES]).hex()}): {reason} '
            f'(malformed so far: {dict(self.counts)})'
        )

    def diagnostics(self) -> tuple[str, dict[str, str]]:
        """(problem, key/values): the problem is '' unless one came within :data:`MALFORMED_WARN_S`."""
        values = {f'malformed_{topic}': str(n) for topic, n in sorted(self.counts.items())}
        recent = self.last_s is not None and self.clock() - self.last_s <= MALFORMED_WARN_S
        total = sum(self.counts.values())
        return (f'malformed messages dropped ({total} so far)' if recent else ''), values
