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
topics, and the real TopicBasedSystem takes the newest state it has, which may be the
previous period's (a period of variation the stand-in does not show). Its effort controller,
when the state it broadcast has moved (an answer is due), waits (as long) for the controller's
answer to it before it takes the newest command: the controller as if it ran inside the update,
as gz_ros2_control's and mujoco_ros2_control's controllers do; the real
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
"""

import argparse
import gc
import json
import os
import random
import sys
import time
from collections import deque

import rclpy
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.qos import QoSProfile, ReliabilityPolicy
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


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--rate', type=float, default=1000.0, help='updates per wall second')
    parser.add_argument('--late', type=int, default=1, help='updates a command is written late')
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
        '--joints', nargs='+', default=JOINTS, help="the arm's joint names, base to tip"
    )
    parser.add_argument(
        '--initial-positions', nargs='+', type=float, help='rad (default 0 for each joint)'
    )
    args = parser.parse_args()
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
