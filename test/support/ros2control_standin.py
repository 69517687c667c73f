"""A stand-in for a ros2_control stack around topic hardware, sharing no code with impact_arm:
what ``controller_manager`` with ``topic_based_ros2_control/TopicBasedSystem``,
``joint_state_broadcaster`` and ``effort_controllers/JointGroupEffortController`` do on the
wire, one update loop at its own rate on the wall clock:

* read: the newest JointState on /robot_joint_states becomes the state interfaces;
* update: the broadcaster publishes the state interfaces on
  /joint_state_broadcaster/joint_states stamped with the update's wall-clock time, every
  update, whether or not a new state came (repetitions); the effort controller copies the
  newest /arm_effort_controller/commands into the command interfaces (zeros from activation);
* write: the hardware publishes the command interfaces as a JointState on
  /robot_joint_commands, stamped with the wall clock, ``--late`` updates late.

``--joints``: the arm's joints, as the URDF's ``<ros2_control>`` block lists them (default:
the article's joint1 joint2).

``--initial-positions``: the state interfaces' ``initial_value`` of the URDF's position
interfaces (default 0, as TopicBasedSystem without one; velocities and efforts 0): until the
hardware's first state the broadcaster publishes these, every update, as the real one does.

``--wait-for-peers S``: once the controller has sent its first command, an update does not
start before the hardware's new state and the controller's answer to the previous update's
state have arrived (or S seconds have passed): a controller_manager that never outruns its
hardware and its controller, as one at realtime priority on an idle machine, so that the
latency is what the stack makes it and not the machine's scheduling (0: the wall-clock
schedule alone).

``--unsynchronised P``: an update loop whose phase drifts against the hardware's period
(a controller_manager not synchronised with its hardware): with probability P (``--seed``)
the effort controller takes a new command only at the update after the one it would have
(never two updates in a row), the newest then, so that the latency a controller sees varies
by a period from command to command, some commands never reach the hardware and some are
written twice; counted in the JSON lines as "postponed". Decided per update, it stays on the
updates' grid whatever the machine's scheduling.

``--use-sim-time``: the update loop on simulated time, as ``ros2_control_node`` with
``use_sim_time`` (4.26: it sleeps with ``cm->get_clock()->sleep_until(current_time +
period)``): an update runs at time 0 (no /clock yet), then each time /clock reaches the
previous update's time + 1/``--rate``; the broadcaster's states and the commands are stamped
with that time. Its read waits (at most ``--wait-for-peers`` wall seconds, default 1 here) for
the hardware's state stamped with the update's time: /clock and the states are different
topics, and the real TopicBasedSystem takes one state per read, the oldest it has queued,
which may be the previous period's (a period of variation the stand-in does not show). Its
effort controller, when the state it broadcast has moved (an answer is due), waits (as long)
for the controller's answer to it before it takes the newest command: the controller as if it
ran inside the update, as gz_ros2_control's and mujoco_ros2_control's controllers do; the real
JointGroupEffortController takes what has arrived. Waits that ran out are counted in the JSON
lines ("late_states", of which "late_driven" once a torque was written, and "unanswered").
Written ``--late`` updates late (default 1): a command
computed from the state at t acts from t + 1/rate on, whatever the machine's load.

Scheduled as a controller_manager's update loop: each update sleeps until its deadline on a
fixed schedule (missed deadlines are skipped), then reads what the subscriptions queued
meanwhile (no executor, no timer); the loop thread and the middleware threads created with the
node run under SCHED_FIFO ``--priority`` (the controller_manager's default 50; 0: normal
scheduling; refused without the right, with a note on stderr).

Prints JSON lines every 100 updates: {"event": "update", "n": updates, "zeros": zero
commands written, "stale": updates whose effort controller had no newer command,
"postponed": new commands taken an update later}.

``--threads-model stack``: instead of that one loop, the real stack's threads (C++ there,
Python threads here, sharing one interpreter lock):

* the update thread (the main thread, SCHED_FIFO ``--priority``) on a fixed schedule that,
  like ros2_control_node 4.26, runs missed updates back to back instead of skipping them.
  Read: TopicBasedSystem 0.3 spins its own node (``rclcpp::spin_some``) inside read(),
  which takes *one* state per read from a best-effort subscription keeping the last 5 (the
  oldest queued, not the newest: a state that arrives just after a read leaves one queued
  for good, until the queue overflows or the simulator misses a period). Update: the
  broadcaster hands its message to its publishing thread; the effort controller takes the
  newest command from its realtime buffer. Write: the command interfaces published at once
  (``--late`` updates late, default 0 in this model: TopicBasedSystem writes what the effort
  controller set in the same update).
* an executor thread at normal priority: the effort controller's subscription, whose
  callback writes the command into a latest-value buffer under a lock; the update thread
  only tries that lock and keeps the previous command when a write holds it (realtime_tools'
  RealtimeBuffer). ``--state-reader executor``: the states' subscription there too, into
  such a buffer, read newest-first (not what TopicBasedSystem 0.3 does; for comparison).
* the broadcaster's publishing thread at normal priority (realtime_tools' RealtimePublisher):
  the update thread tries its lock and hands the message over only while the thread waits
  for one; while it is still publishing the previous message, this update's is skipped.

``--reception-stall S`` (spin-some): from the hardware's first state on, S seconds of reads
that take nothing, as when the stack's participant stalls all reception while it discovers a
joining one: the subscription keeps the last 5 states meanwhile, and the reads that follow,
one state each, go on reading states that old.

Its JSON lines count, besides "n", "zeros" and "stale": "broadcasts_skipped", "empty_reads"
(reads that found no state queued), "behind" (updates that started a period or more after
their deadline; the updates after them catch up) and "state_age" (how many whole periods the
state read had been received before: {periods: reads}).
"""

import argparse
import ctypes
import gc
import json
import os
import random
import sys
import threading
import time
from collections import deque

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

JOINTS = ['joint1', 'joint2']  # the article's arm: the URDF's <ros2_control> joints
WaitSet = rclpy_implementation.WaitSet  # what rclpy's executors wait on


def set_fifo(task, priority):
    if priority <= 0:
        return
    try:
        os.sched_setscheduler(task, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:  # (PermissionError included) no right: normal scheduling
        print(f'SCHED_FIFO {priority} refused: {exc}', file=sys.stderr, flush=True)


def set_normal_scheduling():
    """The calling thread back to normal scheduling: threads inherit their creator's policy,
    and the real stack's executor and publishing threads are not realtime."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        pass  # already normal


def set_thread_name(name):
    """The calling thread's name as /proc shows it (per-thread CPU figures go by it)."""
    try:
        ctypes.CDLL('libc.so.6', use_errno=True).prctl(15, name.encode()[:15])  # PR_SET_NAME
    except OSError:
        pass  # not Linux: the name is only for reading /proc


class LatestValueBuffer:
    """A realtime buffer: the writer (the executor thread) stores the newest value under the
    lock; the reader (the update thread) only tries the lock and, when it gets it, takes the
    value written since its last read, and otherwise keeps the value it had (a write holding
    the lock delays a new command by an update, as realtime_tools' RealtimeBuffer does)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._written = None
        self._new = False
        self.value = None  # what the reader took last
        self.busy_reads = 0  # reads that found the lock held

    def write(self, value):
        with self._lock:
            self._written = value
            self._new = True

    def read(self):
        if not self._lock.acquire(blocking=False):
            self.busy_reads += 1
            return self.value
        try:
            if self._new:
                self.value, self._new = self._written, False
        finally:
            self._lock.release()
        return self.value


class HandoffPublisher:
    """realtime_tools' RealtimePublisher: a thread at normal priority calls publish(); the
    update thread only tries the lock and hands a message over while that thread waits for
    one. While it still publishes the previous message (or the lock is held) this update's
    message is skipped, so that the update thread never waits for the middleware."""

    def __init__(self, publisher, thread_name):
        self._publisher = publisher
        self._handoff = threading.Condition(threading.Lock())
        self._message = None
        self._waiting = False  # the thread waits for a message: the update may hand one over
        self._running = True
        self.skipped = 0
        self._thread = threading.Thread(target=self._loop, args=(thread_name,), daemon=True)

    def start(self):
        self._thread.start()

    def try_publish(self, message):
        if not self._handoff.acquire(blocking=False):
            self.skipped += 1
            return False
        try:
            if not self._waiting:
                self.skipped += 1
                return False
            self._message, self._waiting = message, False
            self._handoff.notify()
            return True
        finally:
            self._handoff.release()

    def _loop(self, thread_name):
        set_normal_scheduling()
        set_thread_name(thread_name)
        while True:
            with self._handoff:
                self._waiting = True
                self._handoff.wait_for(lambda: not self._waiting or not self._running)
                if not self._running:
                    return
                message = self._message
            self._publisher.publish(message)

    def stop(self):
        with self._handoff:
            self._running = False
            self._handoff.notify()
        self._thread.join(timeout=1.0)


def take_all(subscription):
    """Every message the subscription has queued, oldest first, with its message info."""
    taken = []
    while True:
        with subscription.handle:
            one = subscription.handle.take_message(subscription.msg_type, False)
        if one is None:
            return taken
        taken.append(one)


def run_executor(node, readers, stop):
    """The executor thread: waits on ``readers`` ((subscription, callback) pairs) and calls
    each callback for every message taken, until ``stop`` is set."""
    set_normal_scheduling()
    set_thread_name('standin_exec')
    wait_set = WaitSet(len(readers), 0, 0, 0, 0, 0, node.context.handle)
    while not stop.is_set() and rclpy.ok():
        wait_set.clear_entities()
        for subscription, _ in readers:
            wait_set.add_subscription(subscription.handle)
        wait_set.wait(100_000_000)  # ns: a bounded wait, to see ``stop``
        for subscription, callback in readers:
            for message, _ in take_all(subscription):
                callback(message)


def run_thread_model(node, args, joints, initial):
    """``--threads-model stack``: the update thread (the calling one) on its schedule, the
    executor thread taking the commands (and with ``--state-reader executor`` the states),
    the broadcaster's publishing thread (the module's docstring)."""
    broadcast = HandoffPublisher(
        node.create_publisher(JointState, '/joint_state_broadcaster/joint_states', 10),
        'standin_jsb_pub',
    )
    # TopicBasedSystem: commands reliable, keeping the last one; states best effort, the last 5
    hardware_out = node.create_publisher(JointState, '/robot_joint_commands', QoSProfile(depth=1))
    commands = LatestValueBuffer()
    states = LatestValueBuffer()

    def on_command(msg):
        if len(msg.data) == len(joints):
            commands.write(list(msg.data))

    command_sub = node.create_subscription(
        Float64MultiArray, '/arm_effort_controller/commands', on_command, 10
    )
    readers = [(command_sub, on_command)]
    state_sub = node.create_subscription(
        JointState,
        '/robot_joint_states',
        states.write,  # (the executor thread's callback with --state-reader executor)
        qos_profile_sensor_data,
    )
    if args.state_reader == 'executor':
        readers.append((state_sub, states.write))
    # the threads share the interpreter's lock, which the C++ stack's threads do not: a
    # thread waiting for it asks the holder to drop it only after the switch interval, so
    # keep that short for the update thread
    sys.setswitchinterval(0.0002)
    stop = threading.Event()
    executor = threading.Thread(target=run_executor, args=(node, readers, stop), daemon=True)
    executor.start()
    broadcast.start()

    state_interfaces = (list(initial), [0.0] * len(joints), [0.0] * len(joints))
    command_interfaces = [0.0] * len(joints)  # zeros from activation
    written = deque([list(command_interfaces)] * args.late)
    counts = {
        'n': 0,
        'zeros': 0,
        'stale': 0,
        'broadcasts_skipped': 0,
        'empty_reads': 0,
        'behind': 0,  # updates that started a period or more after their deadline
    }
    state_age = {}  # periods a state read had been queued: reads
    latest_state = None
    period_ns = round(1e9 / args.rate)
    gc.collect()
    gc.freeze()  # what lives for the whole run, out of the collector's sight
    start_ns = next_ns = time.monotonic_ns()
    stall_end_ns = None  # --reception-stall: when the reads take states again
    while rclpy.ok() and next_ns - start_ns < args.duration * 1e9:
        counts['behind'] += time.monotonic_ns() - next_ns >= period_ns
        # read
        if stall_end_ns is not None and time.monotonic_ns() < stall_end_ns:
            pass  # the stalled reception: the subscription's queue keeps its last 5
        elif args.state_reader == 'spin-some':
            # one state per read, the oldest queued (spin_some runs each ready
            # subscription once)
            with state_sub.handle:
                taken = state_sub.handle.take_message(JointState, False)
            if taken is None:
                counts['empty_reads'] += 1
            else:
                latest_state, info = taken
                age = (time.time_ns() - info['received_timestamp']) // period_ns
                state_age[age] = state_age.get(age, 0) + 1
                if stall_end_ns is None and args.reception_stall:
                    stall_end_ns = time.monotonic_ns() + round(args.reception_stall * 1e9)
        else:
            latest_state = states.read()
        if latest_state is not None:
            index = [list(latest_state.name).index(j) for j in joints]
            state_interfaces = tuple(
                [float(values[i]) for i in index]
                for values in (latest_state.position, latest_state.velocity, latest_state.effort)
            )
        stamp = node.get_clock().now().to_msg()
        # update: the broadcaster hands its message over (or skips), then the effort
        # controller takes the newest command
        out = JointState(name=list(joints))
        out.header.stamp = stamp
        out.position, out.velocity, out.effort = state_interfaces
        broadcast.try_publish(out)
        command = commands.read()
        if command is not None:
            counts['stale'] += command is command_interfaces
            command_interfaces = command
        # write
        written.append(list(command_interfaces))
        value = written.popleft()
        message = JointState(name=list(joints), effort=value)
        message.header.stamp = stamp
        hardware_out.publish(message)
        counts['zeros'] += not any(value)
        counts['n'] += 1
        if counts['n'] % 100 == 0:
            counts['broadcasts_skipped'] = broadcast.skipped
            ages = {str(k): v for k, v in sorted(state_age.items())}
            print(json.dumps({'event': 'update', **counts, 'state_age': ages}), flush=True)
        # the next deadline of the schedule; missed ones run at once, back to back
        next_ns += period_ns
        left = next_ns - time.monotonic_ns()
        if left > 0:
            time.sleep(left / 1e9)
    stop.set()
    broadcast.stop()
    executor.join(timeout=1.0)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--rate', type=float, default=1000.0, help='updates per wall second')
    parser.add_argument(
        '--late',
        type=int,
        help='updates a command is written late (default 1; 0 with --threads-model stack)',
    )
    parser.add_argument('--duration', type=float, default=60.0)
    parser.add_argument('--unsynchronised', type=float, default=0.0, help='chance 0..1')
    parser.add_argument('--wait-for-peers', type=float, help='s, at most (default 0; sim time 1)')
    parser.add_argument(
        '--use-sim-time', action='store_true', help='update on /clock (simulated time)'
    )
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--priority', type=int, default=50, help='SCHED_FIFO, 0: normal')
    parser.add_argument(
        '--fifo-threads',
        choices=('all', 'update'),
        default='all',
        help='which threads run under --priority: all (the update thread and the middleware '
        "threads that deliver its samples) or update (the controller_manager's own choice: its "
        'update thread only, the executor and the middleware at normal priority)',
    )
    parser.add_argument(
        '--threads-model',
        choices=('loop', 'stack'),
        default='loop',
        help='loop: one loop takes the samples and publishes (default); stack: the real '
        "stack's update, executor and broadcaster publishing threads (wall clock only)",
    )
    parser.add_argument(
        '--state-reader',
        choices=('spin-some', 'executor'),
        default='spin-some',
        help='with --threads-model stack, where the states are taken: spin-some (in the '
        "update's read, one per read, as TopicBasedSystem 0.3) or executor (newest wins)",
    )
    parser.add_argument(
        '--reception-stall',
        type=float,
        default=0.0,
        metavar='S',
        help='with --threads-model stack and spin-some: from the first state on, S seconds '
        "of reads that take nothing (a reception stall, as a participant's discovery causes)",
    )
    parser.add_argument(
        '--joints', nargs='+', default=JOINTS, help="the arm's joint names, base to tip"
    )
    parser.add_argument(
        '--initial-positions', nargs='+', type=float, help='rad (default 0 for each joint)'
    )
    args = parser.parse_args()
    if args.threads_model == 'stack' and (
        args.use_sim_time or args.wait_for_peers or args.unsynchronised
    ):
        parser.error('--threads-model stack: wall clock only, no waiting, synchronised')
    if args.late is None:
        args.late = 0 if args.threads_model == 'stack' else 1
    if args.wait_for_peers is None:
        args.wait_for_peers = 1.0 if args.use_sim_time else 0.0
    joints = args.joints
    initial = args.initial_positions or [0.0] * len(joints)
    if len(initial) != len(joints):
        parser.error(f'--initial-positions: {len(initial)} values for {len(joints)} joints')
    rclpy.init()
    before = set(os.listdir('/proc/self/task'))
    node = rclpy.create_node('standin_controller_manager')
    # the update thread and the middleware threads that deliver its samples
    middleware = sorted(set(os.listdir('/proc/self/task')) - before)
    for task in [0] + (middleware if args.fifo_threads == 'all' else []):
        set_fifo(int(task), args.priority)
    if args.threads_model == 'stack':
        run_thread_model(node, args, joints, initial)
        node.destroy_node()
        rclpy.try_shutdown()
        return
    qos = QoSProfile(depth=10)
    broadcast = node.create_publisher(JointState, '/joint_state_broadcaster/joint_states', qos)
    hardware_out = node.create_publisher(JointState, '/robot_joint_commands', qos)
    newest = {'state': None, 'command': None}
    received = {'states': 0, 'commands': 0}

    def on_state(msg):
        newest['state'] = msg
        received['states'] += 1

    def on_command(msg):
        if len(msg.data) == len(joints):
            newest['command'] = list(msg.data)
            received['commands'] += 1

    clock = {'ns': 0}  # simulated time: 0 until the first /clock, as rclpy's

    def on_clock(msg):
        clock['ns'] = max(clock['ns'], msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)

    states_by_stamp = {}  # sim time: the states by stamp (ns), until read

    def on_state_stamped(msg):
        on_state(msg)
        states_by_stamp[msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec] = msg

    readers = (
        (
            node.create_subscription(
                JointState,
                '/robot_joint_states',
                on_state_stamped if args.use_sim_time else on_state,
                qos,
            ),
            on_state_stamped if args.use_sim_time else on_state,
        ),
        (
            node.create_subscription(
                Float64MultiArray, '/arm_effort_controller/commands', on_command, qos
            ),
            on_command,
        ),
    )
    if args.use_sim_time:  # (the simulator's /clock is best effort, as rclcpp's ClockQoS)
        clock_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        readers += ((node.create_subscription(Clock, '/clock', on_clock, clock_qos), on_clock),)
    wait_set = WaitSet(len(readers), 0, 0, 0, 0, 0, node.context.handle)

    def read_queued():
        """What the subscriptions queued since the last look, oldest first."""
        for subscription, callback in readers:
            while True:
                with subscription.handle:
                    taken = subscription.handle.take_message(subscription.msg_type, False)
                if taken is None:
                    break
                callback(taken[0])

    def wait_for_sample(timeout):
        wait_set.clear_entities()
        for subscription, _ in readers:
            wait_set.add_subscription(subscription.handle)
        wait_set.wait(int(timeout * 1e9))

    # (position, velocity, effort) in joints order: the initial values until the hardware's
    # first state
    state_interfaces = (list(initial), [0.0] * len(joints), [0.0] * len(joints))
    command_interfaces = [0.0] * len(joints)  # zeros from activation
    written = deque([list(command_interfaces)] * args.late)

    def write(interfaces, stamp):
        """The hardware's write, ``--late`` updates late: the command ``interfaces`` of
        that update as a JointState stamped ``stamp``; returns the efforts written."""
        written.append(list(interfaces))
        value = written.popleft()
        command = JointState(name=list(joints), effort=value)
        command.header.stamp = stamp
        hardware_out.publish(command)
        return value

    period = 1.0 / args.rate
    start = time.monotonic()
    k = zeros = slot = stale = postponed = 0
    rng = random.Random(args.seed)
    missed = False  # the previous update missed a new command (never two in a row)
    states_read = commands_before = 0  # counts at the previous update's read / broadcast
    answer_due = False  # the previous update broadcast a state the controller answers
    previous_position = None

    def peers_ready():
        if not args.wait_for_peers or not received['commands']:
            return True  # (before the controller runs, the stack runs on its own)
        answered = not answer_due or received['commands'] > commands_before
        return received['states'] > states_read and answered

    def wait_until(condition):
        """Take samples until ``condition()`` or --wait-for-peers wall seconds; whether it
        held."""
        read_queued()
        end = time.monotonic() + args.wait_for_peers
        while not condition():
            left = end - time.monotonic()
            if left <= 0:
                return False
            wait_for_sample(left)
            read_queued()
        return True

    gc.collect()
    gc.freeze()  # what lives for the whole run, out of the collector's sight
    if args.use_sim_time:
        # late_driven: late states once a torque has been written (the arm released)
        counts = {'n': 0, 'zeros': 0, 'late_states': 0, 'late_driven': 0, 'unanswered': 0}
        now_ns = 0
        period_ns = round(1e9 / args.rate)
        previous = None  # the positions broadcast by the previous update
        while rclpy.ok() and time.monotonic() - start < args.duration:
            # read: the state stamped with this update's time (else, after the wait, the
            # newest: what the real TopicBasedSystem takes at once)
            if not wait_until(lambda t=now_ns: t in states_by_stamp):
                counts['late_states'] += 1
                counts['late_driven'] += counts['n'] > counts['zeros']
            msg = states_by_stamp.get(now_ns, newest['state'])
            for stamp_ns in [t for t in states_by_stamp if t <= now_ns]:
                del states_by_stamp[stamp_ns]
            if msg is not None:
                index = [list(msg.name).index(j) for j in joints]
                state_interfaces = tuple(
                    [float(values[i]) for i in index]
                    for values in (msg.position, msg.velocity, msg.effort)
                )
            stamp = JointState().header.stamp
            stamp.sec, stamp.nanosec = divmod(now_ns, 1_000_000_000)
            out = JointState(name=list(joints))
            out.header.stamp = stamp
            out.position, out.velocity, out.effort = state_interfaces
            before = received['commands']
            broadcast.publish(out)
            # the controller answers a state that moved (not a repetition): taken in this
            # update, as a controller inside the update loop would be
            if previous is not None and list(out.position) != previous:
                if not wait_until(lambda n=before: received['commands'] > n):
                    counts['unanswered'] += 1
            previous = list(out.position)
            if newest['command'] is not None:
                command_interfaces = newest['command']
            value = write(command_interfaces, stamp)
            counts['zeros'] += not any(value)
            counts['n'] += 1
            if counts['n'] % 100 == 0:
                print(json.dumps({'event': 'update', **counts}), flush=True)
            # sleep until /clock reaches this update's time + period
            due = now_ns + period_ns
            while rclpy.ok() and time.monotonic() - start < args.duration:
                if wait_until(lambda t=due: clock['ns'] >= t):
                    break
            now_ns = clock['ns']
        node.destroy_node()
        rclpy.try_shutdown()
        return
    while rclpy.ok() and time.monotonic() - start < args.duration:
        # read
        read_queued()
        msg = newest['state']
        states_read = received['states']
        if msg is not None:
            index = [list(msg.name).index(j) for j in joints]
            state_interfaces = tuple(
                [float(values[i]) for i in index]
                for values in (msg.position, msg.velocity, msg.effort)
            )
        stamp = node.get_clock().now().to_msg()  # the update's wall-clock time
        # update: the broadcaster (every update from activation on, the initial values until
        # the hardware's first state), then the effort controller
        out = JointState(name=list(joints))
        out.header.stamp = stamp
        out.position, out.velocity, out.effort = state_interfaces
        # a controller answers a new state, not a repetition
        answer_due = list(out.position) != previous_position
        previous_position = list(out.position)
        commands_before = received['commands']
        broadcast.publish(out)
        if newest['command'] is not None:
            fresh = newest['command'] is not command_interfaces
            if fresh and not missed and rng.random() < args.unsynchronised:
                postponed += 1  # the update's phase missed it: taken at the next one
                missed = True
            else:
                missed = False
                stale += not fresh
                command_interfaces = newest['command']
        # write, late by --late updates
        value = write(command_interfaces, stamp)
        zeros += not any(value)
        k += 1
        if k % 100 == 0:
            print(
                json.dumps(
                    {
                        'event': 'update',
                        'n': k,
                        'zeros': zeros,
                        'stale': stale,
                        'postponed': postponed,
                    }
                ),
                flush=True,
            )
        # the next update at the next deadline of the schedule (missed ones are skipped, as
        # the controller manager does): sleep until it, then (waiting for peers) until their
        # samples are queued
        slot = max(slot + 1, int((time.monotonic() - start) / period))
        deadline = start + slot * period
        now = time.monotonic()
        if deadline > now:
            time.sleep(deadline - now)
        if args.wait_for_peers:
            read_queued()
            while not peers_ready():
                left = deadline + args.wait_for_peers - time.monotonic()
                if left <= 0:
                    break
                wait_for_sample(left)
                read_queued()
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    try:
        main()
    except KeyboardInterrupt:
        pass
    except Exception:
        if rclpy.ok():
            raise
        # ended (SIGINT) between the loop's check and a publish: the context is gone
