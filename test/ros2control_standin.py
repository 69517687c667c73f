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

Prints JSON lines every 100 updates: {"event": "update", "n": updates, "zeros": zero
commands written, "stale": updates whose effort controller had no newer command}.
"""

import argparse
import json
import time
from collections import deque

import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

JOINTS = ['joint1', 'joint2']


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--rate', type=float, default=1000.0, help='updates per wall second')
    parser.add_argument('--late', type=int, default=1, help='updates a command is written late')
    parser.add_argument('--duration', type=float, default=60.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node('standin_controller_manager')
    qos = QoSProfile(depth=10)
    broadcast = node.create_publisher(JointState, '/joint_state_broadcaster/joint_states', qos)
    hardware_out = node.create_publisher(JointState, '/robot_joint_commands', qos)
    newest = {'state': None, 'command': None}

    def on_state(msg):
        newest['state'] = msg

    def on_command(msg):
        if len(msg.data) == len(JOINTS):
            newest['command'] = list(msg.data)

    node.create_subscription(JointState, '/robot_joint_states', on_state, qos)
    node.create_subscription(Float64MultiArray, '/arm_effort_controller/commands', on_command, qos)
    state_interfaces = None  # (position, velocity, effort) in JOINTS order
    command_interfaces = [0.0] * len(JOINTS)  # zeros from activation
    written = deque([list(command_interfaces)] * args.late)
    period = 1.0 / args.rate
    start = time.monotonic()
    k = zeros = slot = stale = 0
    while time.monotonic() - start < args.duration:
        # read
        msg = newest['state']
        if msg is not None:
            index = [list(msg.name).index(j) for j in JOINTS]
            state_interfaces = tuple(
                [float(values[i]) for i in index]
                for values in (msg.position, msg.velocity, msg.effort)
            )
        stamp = node.get_clock().now().to_msg()  # the update's wall-clock time
        # update: broadcaster, then the effort controller
        if state_interfaces is not None:
            out = JointState(name=list(JOINTS))
            out.header.stamp = stamp
            out.position, out.velocity, out.effort = state_interfaces
            broadcast.publish(out)
        if newest['command'] is not None:
            stale += newest['command'] is command_interfaces
            command_interfaces = newest['command']
        # write, late by --late updates
        written.append(list(command_interfaces))
        value = written.popleft()
        command = JointState(name=list(JOINTS), effort=value)
        command.header.stamp = stamp
        hardware_out.publish(command)
        zeros += not any(value)
        k += 1
        if k % 100 == 0:
            print(
                json.dumps({'event': 'update', 'n': k, 'zeros': zeros, 'stale': stale}), flush=True
            )
        # the next update at the next deadline of the schedule (missed ones are skipped, as
        # the controller manager does); the subscriptions are served meanwhile, at least once
        slot = max(slot + 1, int((time.monotonic() - start) / period))
        deadline = start + slot * period
        while True:
            rclpy.spin_once(node, timeout_sec=max(0.0, deadline - time.monotonic()))
            if time.monotonic() >= deadline:
                break
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    try:
        main()
    except KeyboardInterrupt:
        pass
