"""Process life cycle for the record/replay nodes.

rclpy's own SIGINT handler shuts the context down at once, after which a node can no longer
ask other nodes anything. Here SIGINT/SIGTERM only set a flag: the spin loop ends, the node's
``finish`` runs with the middleware still up (final parameter query, closing the file), and the
process exits with the node's exit code and no traceback.
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import Executor
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.subscription import MessageInfo, Subscription


def realtime_priority(priority: int, thread: int = 0) -> str:
    """Run the calling thread (or the thread with task id ``thread``) under SCHED_FIFO at
    ``priority`` (1-99), as ros2_control's loop does when the system allows it; 0 leaves the
    normal scheduler. Returns what was obtained, for /diagnostics."""
    if priority <= 0 or not hasattr(os, 'sched_setscheduler'):
        return 'normal'
    try:
        os.sched_setscheduler(thread, os.SCHED_FIFO, os.sched_param(priority))
        return f'SCHED_FIFO {priority}'
    except (PermissionError, OSError) as exc:
        return f'normal (SCHED_FIFO refused: {exc.strerror or exc})'


def name_thread(name: str) -> None:
    """Give the calling thread an OS name (``ps -T``, ``top -H``, /proc/PID/task/*/comm):
    Python names its threads for itself only."""
    try:
        import ctypes

        ctypes.CDLL('libc.so.6', use_errno=True).prctl(15, name.encode()[:15])  # PR_SET_NAME
    except OSError:
        pass


def take_raw(
    subscription: Subscription[Any], msg_type: type | None = None
) -> tuple[bytes, MessageInfo] | None:
    """The oldest queued message of a ``raw=True`` subscription as (serialized bytes,
    message info), or None when its queue is empty. A node polls its readers with this
    instead of an executor callback: in the realtime loop thread (no second Python thread
    contending for the GIL each period), in the recorder's drain, in the controller right
    after a wrench."""
    handle = subscription.handle
    with handle:
        return handle.take_message(msg_type or subscription.msg_type, True)


class SampleWait:
    """Blocks a node's own thread until one of ``subscriptions`` (of a reader node that no
    executor spins, ``reader_node``) has a sample queued, or until ``wake()``; the thread then
    takes them with ``take_raw``. A loop that waits here handles each sample in one Python
    call, where an executor wakes its spin, dispatches and calls back per sample.

    ``owner`` is the reader node: the wake-up guard condition lives with it, so no executor
    sees it either. rclpy's executors and ``wait_for_message`` wait on the same wait set; it
    has no public wrapper."""

    def __init__(self, owner: Node, subscriptions: Iterable[Subscription[Any]]) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation

        context = owner.context.handle
        if context is None:  # (never: a node's context is initialised while it exists)
            raise RuntimeError(f'{owner.get_name()}: its context is not initialised')
        self.subscriptions = tuple(subscriptions)
        self.guard = owner.create_guard_condition(lambda: None)
        self._wait_set = rclpy_implementation.WaitSet(
            len(self.subscriptions), 1, 0, 0, 0, 0, context
        )

    def wait(
        self, timeout: float, subscriptions: Iterable[Subscription[Any]] | None = None
    ) -> None:
        """Until a sample is queued on any of ``subscriptions`` (a subset of the ones given
        at construction; default all), ``wake()`` or ``timeout`` s (the GIL is released
        meanwhile)."""
        wait_set = self._wait_set
        wait_set.clear_entities()
        for subscription in self.subscriptions if subscriptions is None else subscriptions:
            wait_set.add_subscription(subscription.handle)
        wait_set.add_guard_condition(self.guard.handle)
        wait_set.wait(int(timeout * 1e9))

    def wake(self) -> None:
        """End the current (or next) ``wait`` at once, from any thread."""
        self.guard.trigger()


def reader_node(owner: Node, suffix: str) -> Node:
    """A helper node for ``owner``'s polled readers (no executor spins it), named
    ``_<owner>_<suffix>`` in the owner's namespace. It ignores the process's global ROS
    arguments: launch's ``__node`` remap names the owner, and would give this one the same
    name (``ros2 node list`` showed it twice). The topic remaps among them still apply."""
    import rclpy

    return rclpy.create_node(
        f'_{owner.get_name()}_{suffix}',
        namespace=owner.get_namespace(),
        context=owner.context,
        start_parameter_services=False,
        enable_rosout=False,
        use_global_arguments=False,
        cli_args=topic_remaps(sys.argv),
    )


def topic_remaps(argv: Sequence[str]) -> list[str]:
    """The remap rules of ``argv``'s ROS arguments, except those naming the node
    (``__node``, ``__name``, ``__ns``), as ROS arguments for another node."""
    rules: list[str] = []
    inside, args = False, iter(argv)
    for arg in args:
        if arg in ('--ros-args', '--'):
            inside = arg == '--ros-args'
        elif inside and arg in ('-r', '--remap'):
            rule = next(args, '')
            if rule.partition(':=')[0].rpartition(':')[2] not in ('__node', '__name', '__ns'):
                rules += ['-r', rule]
    return ['--ros-args', *rules] if rules else []


def await_acknowledgements(node: Node, publishers: Iterable[Publisher[Any]], wait: float) -> None:
    """Samples a reader has not acknowledged die with the process (a lagging recorder lost
    the last impact reports of a run): give the readers of ``publishers`` up to ``wait`` s
    in all. A reader that missed samples asks for them again only when the writer's periodic
    heartbeat reaches it (every 3 s with Fast DDS's defaults); the wait ends as soon as
    every reader has acknowledged."""
    import time

    from rclpy.duration import Duration

    end = time.monotonic() + wait
    for pub in publishers:
        left = end - time.monotonic()
        if left <= 0 or not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
            node.get_logger().warning(
                f'{pub.topic_name}: not every reader acknowledged the '
                f'last samples within {wait:g} s'
            )
            return


def _threads() -> set[int]:
    try:
        return {int(t) for t in os.listdir('/proc/self/task')}
    except OSError:  # not Linux: nothing to raise
        return set()


def raise_middleware_threads(threads: Iterable[int], priority: int) -> None:
    """The middleware's own threads (created with the node's participant: socket receivers,
    timed events) deliver every sample the loop waits for. Traced under load, a loop at
    realtime priority still waited 100-450 ms for samples those threads, at normal priority,
    were not scheduled to receive; so they get the loop's priority, as ``chrt -f`` on the
    whole process would give them, while the node's Python executor thread keeps its own."""
    for thread in threads:
        realtime_priority(priority, thread)


def guard_parameter_services(node: Node) -> None:
    """Answer a malformed request to the node's parameter services with a refusal instead of
    letting it end the node. rclpy converts each requested ``ParameterValue`` inside its
    service callback, and an invalid ``type`` (e.g. 200) raises ValueError there, which the
    executor re-raises from spin: one bad request from any peer would stop the node."""
    from rcl_interfaces.msg import SetParametersResult

    def guarded(callback: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
        def call(request: Any, response: Any) -> Any:
            try:
                return callback(request, response)
            except (ValueError, TypeError) as exc:
                reason = f'malformed request refused: {str(exc)[:200]}'
                node.get_logger().warning(f'parameter service: {reason}', throttle_duration_sec=2.0)
                if hasattr(response, 'results'):  # SetParameters
                    response.results = [
                        SetParametersResult(successful=False, reason=reason)
                        for _ in request.parameters
                    ]
                elif hasattr(response, 'result'):  # SetParametersAtomically
                    response.result = SetParametersResult(successful=False, reason=reason)
                return response

        return call

    for service in node.services:
        if service.srv_type.__module__.startswith('rcl_interfaces.'):
            service.callback = guarded(service.callback)


def make_executor(context: Context | None = None, prefer: str | None = None) -> Executor:
    """A single-threaded executor. ``IMPACT_ARM_EXECUTOR=events`` picks rclpy's C++ events
    executor instead; it is not the default because in rclpy 9 (Kilted) it cannot call
    subscription callbacks that take a ``MessageInfo`` (spin fails with "SystemError: null
    argument to internal routine"), which the recorder needs for publish times. The recorder
    drains its queues in each callback, so the single-threaded executor keeps up anyway."""
    import os

    # nodes without MessageInfo callbacks (simulator, controller) prefer 'events': several
    # times cheaper per callback, which is what a lockstep round trip is made of
    if (os.environ.get('IMPACT_ARM_EXECUTOR') or prefer) == 'events':
        try:
            from rclpy.experimental import EventsExecutor

            return EventsExecutor(context=context)
        except ImportError:
            pass
    from rclpy.executors import SingleThreadedExecutor

    return SingleThreadedExecutor(context=context)


def run(node_factory: Callable[[], Any], args: list[str] | None = None) -> int:
    """Create the node, spin until it is done or a signal arrives, let it finish. The node
    provides ``done`` (bool) and ``finish(executor) -> int`` (the exit code)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    from ..physics.errors import ImpactArmError

    # DDS stays on this machine unless the user chose otherwise (multi-machine set-ups set
    # ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET explicitly)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    stopped = []
    previous = {
        s: signal.signal(s, lambda signum, frame: stopped.append(signum))
        for s in (signal.SIGINT, signal.SIGTERM)
    }
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node, executor, code = None, None, 0
    try:
        before = _threads()
        node = node_factory()
        # a node whose loop runs at realtime priority says so: ``middleware_priority``
        raise_middleware_threads(
            _threads() - before - {threading.get_native_id()},
            getattr(node, 'middleware_priority', 0),
        )
        guard_parameter_services(node)
        # Everything built so far (numba dispatchers, message classes, the model) lives for
        # the whole process: move it out of the collector's sight, so that a periodic full
        # collection cannot stall a period for milliseconds.
        gc.collect()
        gc.freeze()
        executor = make_executor(prefer=getattr(node, 'executor_kind', None))
        executor.add_node(node)
        if hasattr(node, 'start'):  # a node with periods of its own starts them now, not
            node.start()  # under the collection above (it holds the GIL)
        if hasattr(node, 'spin'):  # a node with its own loop (the realtime simulator)
            node.spin(executor, lambda: bool(stopped) or node.done or not rclpy.ok())
        else:
            while not stopped and not node.done and rclpy.ok():
                executor.spin_once(timeout_sec=0.1)
        code = node.finish(executor if rclpy.ok() else None)
    except (KeyboardInterrupt, ExternalShutdownException):
        code = node.finish(None) if node is not None else 0
    except (ImpactArmError, ValueError) as e:  # bad parameters, unreadable files
        print(f'[ERROR] {e}', file=sys.stderr)
        code = 2 if node is None else (node.finish(None) or 1)
    finally:
        if node is not None:
            node.destroy_node()
        if executor is not None and hasattr(executor, 'shutdown'):
            executor.shutdown()
        rclpy.try_shutdown()
        for s, handler in previous.items():
            signal.signal(s, handler)
    return code
