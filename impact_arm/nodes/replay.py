"""replay: republish a recorded MCAP file, like ``ros2 bag play``.

``ros2 run impact_arm replay --ros-args -p file:=run.mcap -p rate:=2.0`` and
``impact-arm replay run.mcap --rate 2``. Each topic is published with its recorded type and the
QoS its publishers offered (from the file), as the recorded serialized bytes (nothing is
deserialized); timing follows the recorded log times scaled by ``rate``
(``impact_arm.io.replay_plan`` computes the schedule). Parameters: replay_params.py (their
table in docs/topics.md is generated from it).

Publishing runs in its own thread paced by the monotonic clock, so the executor (parameter
services) never delays a message; a late message is published at once, never skipped.
"""

from __future__ import annotations

import argparse
import math
import os
import threading
import time
from typing import TYPE_CHECKING, Any, NoReturn

from rclpy.node import Node
from rclpy.parameter import Parameter

from ..physics.errors import ImpactArmError
from .. import contract
from ..contract import CLOCK, TopicQos
from ..io.mcap_ros2 import TopicInfo, message_class
from ..io.msgdefs import has_type_support
from ..io.replay_plan import ReplayError, ReplayPlan, summarize
from ._runner import run
from .params import NODE_OPTIONS, declare, refuse_unknown, validator
from .param_types import ReplayParameters
from .replay_params import PARAMS, WAIT_SUBSCRIBERS_MAX

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.publisher import Publisher

PROGRESS_PERIOD = 5.0  # s of wall time between progress lines in the log


class Replay(Node):
    def __init__(self, **overrides: Any) -> None:
        super().__init__(
            'replay',
            parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
            **NODE_OPTIONS,
        )
        self._declare()
        self._configure()
        self._activate()

    # ------------------------------------------------------------------------ start-up
    def _declare(self) -> None:
        """The parameters as ``self.p``; ParameterError for a bad value or an unknown name,
        ReplayError without a file."""
        self.p: ReplayParameters = declare(self, PARAMS, ReplayParameters)
        refuse_unknown(self, PARAMS)
        if not self.p.file:
            raise ReplayError('file = "": the MCAP file to replay is required (-p file:=run.mcap)')

    def _configure(self) -> None:
        """The schedule of the file's messages (``ReplayPlan``) and the playing state."""
        p = self.p
        self.delay, self.wait_subs = p.delay, p.wait_for_subscribers
        topics = [t for t in p.topics if t]
        self.plan = ReplayPlan.open(
            p.file, rate=p.rate, start_offset=p.start_offset, topics=topics, loop=p.loop
        )
        self.clock_period = 1.0 / p.clock if p.clock else math.inf
        self.published = 0
        self.error: Exception | None = None
        self._stop = threading.Event()

    def _activate(self) -> None:
        """Parameter changes refused, a publisher per replayed topic (and /clock), then the
        thread that plays the schedule starts."""
        # every parameter is fixed at start-up: a change is refused, not silently ignored
        self.add_on_set_parameters_callback(validator(PARAMS, lambda values: None))
        self._create_publishers()
        self.clock_pub = None
        if self.p.clock:
            from rosgraph_msgs.msg import Clock

            self.clock_pub = self.create_publisher(Clock, CLOCK, contract.qos(CLOCK).to_rclpy())
            self._Clock = Clock
        self._thread = threading.Thread(target=self._play, name='replay', daemon=True)
        self.get_logger().info('replaying ' + summarize(self.plan))
        self._thread.start()

    def _create_publishers(self) -> None:
        """A publisher per recorded topic with its recorded type and QoS; not the recorded
        /clock when the replay publishes its own, nor a type not installed here."""
        self.publishers_: dict[str, Publisher[Any]] = {}
        for topic, info in self.plan.topics.items():
            if topic == CLOCK and self.p.clock:
                self.get_logger().warning(
                    'not replaying the recorded /clock: clock > 0 publishes it from the replay'
                )
                continue
            qos = _recorded_qos(topic, info)
            cls = message_class(info.type_name)
            if not has_type_support(cls):  # /tf without tf2_msgs: rclpy cannot publish it
                self.get_logger().info(
                    f'not replaying {topic}: {info.type_name} is not installed here'
                )
                continue
            self.publishers_[topic] = self.create_publisher(cls, topic, qos.to_rclpy(min_depth=10))

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()

    def _wait_for_subscribers(self) -> None:
        if not self.wait_subs:
            return
        end = time.monotonic() + WAIT_SUBSCRIBERS_MAX
        while not self._stop.is_set() and time.monotonic() < end:
            if all(p.get_subscription_count() >= self.wait_subs for p in self.publishers_.values()):
                return
            self._stop.wait(0.02)
        self.get_logger().warning(
            f'starting without {self.wait_subs} subscribers on '
            f'every topic after {WAIT_SUBSCRIBERS_MAX:g} s'
        )

    def _play(self) -> None:
        try:
            self._wait_for_subscribers()
            if self._stop.wait(self.delay):
                return
            wall0 = time.monotonic()
            next_progress = PROGRESS_PERIOD
            clock_pub = self.clock_pub
            next_clock = 0.0 if clock_pub else math.inf
            for due, m in self.plan.events():
                while True:
                    now = time.monotonic() - wall0
                    if clock_pub is not None and next_clock <= min(due, now):
                        self._publish_clock(clock_pub, self.plan.recorded_time_ns(next_clock))
                        next_clock += self.clock_period
                        continue
                    wait = min(due, next_clock) - now
                    if wait <= 0:
                        break
                    if self._stop.wait(min(wait, 0.1)):
                        return
                pub = self.publishers_.get(m.topic)
                if pub is not None:
                    pub.publish(m.data)
                    self.published += 1
                    if now >= next_progress:  # the node's log, not a terminal line of its own
                        self.get_logger().info(
                            f'{self.published} messages replayed, {due:.1f} s of the schedule'
                        )
                        next_progress = now + PROGRESS_PERIOD
        except Exception as e:  # noqa: BLE001 - reported by finish(), exit code 1
            self.error = e

    def _publish_clock(self, publisher: Publisher[Any], t_ns: int) -> None:
        msg = self._Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        publisher.publish(msg)

    def finish(self, executor: Executor | None) -> int:
        self._stop.set()
        self._thread.join(5.0)
        if self.error is not None:
            self.get_logger().error(f'replay stopped: {self.error}')
            return 1
        self.get_logger().info(f'{self.published} messages replayed')
        return 0


def _recorded_qos(topic: str, info: TopicInfo) -> TopicQos:
    """The QoS the topic's recorded publishers offered, where they all agreed on reliability
    and durability; else the contract's."""
    return (
        info.qos[0]
        if info.qos
        and all(
            (q.reliability, q.durability) == (info.qos[0].reliability, info.qos[0].durability)
            for q in info.qos
        )
        else contract.qos(topic)
    )


# ------------------------------------------------------------------- impact-arm replay
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('file', help='MCAP file to replay')
    parser.add_argument(
        '--rate',
        type=float,
        default=1.0,
        help='speed factor, (0, 1000] (default 1.0: recorded speed)',
    )
    parser.add_argument(
        '--clock',
        type=float,
        nargs='?',
        const=100.0,
        default=0.0,
        metavar='HZ',
        help='publish /clock with the recorded time (default 100 Hz when given without a value)',
    )
    parser.add_argument('--loop', action='store_true', help='start again after the end')
    parser.add_argument(
        '--topics',
        nargs='+',
        default=[],
        metavar='TOPIC',
        help='replay only these topics (default: all)',
    )
    parser.add_argument(
        '--start-offset',
        type=float,
        default=0.0,
        metavar='S',
        help='skip this many seconds of recorded time',
    )
    parser.add_argument(
        '--delay',
        type=float,
        default=0.0,
        metavar='S',
        help='wait this long before the first message',
    )
    parser.add_argument(
        '--wait-for-subscribers',
        type=int,
        default=0,
        metavar='N',
        help='wait (at most 30 s) until every topic has N subscribers',
    )


def cli(args: argparse.Namespace) -> int:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    overrides = {
        'file': os.path.abspath(args.file),
        'rate': float(args.rate),
        'clock': float(args.clock),
        'loop': bool(args.loop),
        'topics': list(args.topics) or [''],
        'start_offset': float(args.start_offset),
        'delay': float(args.delay),
        'wait_for_subscribers': int(args.wait_for_subscribers),
    }
    # the same checks as the node, before any DDS start-up: errors come as one line
    for param in PARAMS:
        param.check(overrides[param.name])
    ReplayPlan.open(
        overrides['file'],
        rate=overrides['rate'],
        start_offset=overrides['start_offset'],
        topics=[t for t in overrides['topics'] if t],
        loop=overrides['loop'],
    )
    return run(lambda: Replay(**overrides), ['impact-arm-replay'])


def main(args: list[str] | None = None) -> NoReturn:
    raise SystemExit(run(Replay, args))


__all__ = ['Replay', 'ImpactArmError', 'add_arguments', 'cli', 'main']

if __name__ == '__main__':
    main()
