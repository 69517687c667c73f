"""Replay schedule of a ROS 2 MCAP file (no rclpy): which serialized message is due when.

``ReplayPlan.open(path, rate=, start_offset=, topics=, loop=)`` checks the file and the options
(errors name the option and the allowed range) and ``plan.events()`` yields, in recorded
log-time order, ``(due, RawMessage)`` with ``due`` the wall-clock seconds after the start of the
replay at which the message is to be published::

    due = (log_time - (t_first + start_offset)) / rate      (+ one span per completed loop)

``t_first`` is the first log time of the selected topics. With ``loop`` the file is replayed
again right after its last message, for ever (the caller stops). ``plan.recorded_time_ns(e)``
maps elapsed replay seconds back to the recorded time (what ``/clock`` carries). The node
``impact_arm.nodes.replay`` publishes these events; tests and tools can use the schedule
directly.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from collections.abc import Iterable
from typing import Any, Iterator

from ..physics.errors import ImpactArmError
from .mcap_ros2 import RawMessage, TopicInfo, iter_raw, topics_info, unreadable_reason


class ReplayError(ImpactArmError, ValueError):
    """The file or a replay option cannot be used (the message says which and why)."""


def _float(name, value, allowed) -> float:
    try:
        if isinstance(value, bool):
            raise TypeError
        return float(value)
    except (TypeError, ValueError):
        raise ReplayError(f'{name} = {value!r}: must be a number {allowed}') from None


def check_rate(rate: Any) -> float:
    rate = _float('rate', rate, 'in (0, 1000]')
    if not (math.isfinite(rate) and 0.0 < rate <= 1000.0):
        raise ReplayError(f'rate = {rate}: must be in (0, 1000] (1.0 = recorded speed)')
    return rate


@dataclass
class ReplayPlan:
    path: str
    topics: dict  # topic -> TopicInfo of the replayed topics
    rate: float
    start_offset: float  # s of recorded time skipped at the start
    loop: bool
    t_first_ns: int  # first log time of the replayed topics in the file
    t_last_ns: int  # last log time of the replayed topics

    @classmethod
    def open(
        cls,
        path: str | os.PathLike,
        *,
        rate: float = 1.0,
        start_offset: float = 0.0,
        topics: Iterable[str] | None = None,
        loop: bool = False,
    ) -> 'ReplayPlan':
        path = os.fspath(path)
        if not os.path.isfile(path):
            raise ReplayError(f'file = {path!r}: no such file')
        rate = check_rate(rate)
        start_offset = _float('start_offset', start_offset, '>= 0 s')
        if not (math.isfinite(start_offset) and start_offset >= 0.0):
            raise ReplayError(f'start_offset = {start_offset}: must be >= 0 s')
        try:
            info = topics_info(path)
        except Exception as e:  # noqa: BLE001 - any reader failure means "not a usable file"
            raise ReplayError(f'file = {path!r}: {unreadable_reason(path, e)}') from None
        if not info:
            raise ReplayError(f'file = {path!r}: no topics recorded')
        selected = [t for t in (topics or []) if t]
        unknown = [t for t in selected if t not in info]
        if unknown:
            raise ReplayError(f'topics = {unknown}: not in {path} (it has {sorted(info)})')
        chosen = {t: i for t, i in info.items() if not selected or t in selected}
        first, last = _time_range(path, chosen)
        if first is None:
            raise ReplayError(f'file = {path!r}: no messages on {sorted(chosen)}')
        span = (last - first) / 1e9
        if start_offset > span:
            raise ReplayError(
                f'start_offset = {start_offset}: must be in [0, {span:.6g}] s '
                f'(the recorded duration)'
            )
        return cls(path, chosen, rate, start_offset, bool(loop), first, last)

    @property
    def start_ns(self) -> int:
        """Recorded time at which the replay starts."""
        return self.t_first_ns + int(round(self.start_offset * 1e9))

    @property
    def duration(self) -> float:
        """Wall-clock seconds of one pass."""
        return (self.t_last_ns - self.start_ns) / 1e9 / self.rate

    @property
    def message_count(self) -> int:
        return sum(i.message_count for i in self.topics.values())

    def recorded_time_ns(self, elapsed: float) -> int:
        """Recorded time (ns) reached ``elapsed`` wall seconds into the replay (loops wrap)."""
        offset = elapsed * self.rate * 1e9
        span = self.t_last_ns - self.start_ns
        if self.loop and span > 0:
            offset %= span
        return self.start_ns + int(offset)

    def events(self) -> Iterator[tuple]:
        """(due seconds after the replay start, RawMessage), in log-time order."""
        passes = 0
        while True:
            base = passes * self.duration
            count = 0
            for m in iter_raw(self.path, list(self.topics), self.start_ns):
                count += 1
                yield base + (m.log_time_ns - self.start_ns) / 1e9 / self.rate, m
            passes += 1
            if not self.loop or count == 0:
                return


def _time_range(path, topics: dict) -> tuple:
    """(first, last) log time of the messages on ``topics`` (one pass, nothing deserialized)."""
    first = last = None
    for m in iter_raw(path, list(topics)):
        if first is None:
            first = m.log_time_ns
        last = m.log_time_ns if last is None else max(last, m.log_time_ns)
    return first, last


def summarize(plan: ReplayPlan) -> str:
    return (
        f'{plan.path}: {plan.message_count} messages on {len(plan.topics)} topics, '
        f'{plan.duration:.3f} s at rate {plan.rate:g}'
        + (f' from {plan.start_offset:g} s' if plan.start_offset else '')
        + (' (loop)' if plan.loop else '')
    )


__all__ = ['RawMessage', 'ReplayError', 'ReplayPlan', 'TopicInfo', 'check_rate', 'summarize']
