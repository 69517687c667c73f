"""A minimal stand-in for a real arm driver, sharing no code with impact_arm: two independent
joints with unit inertia and no gravity (q̈_i = τ_i), integrated at 1 kHz, publishing
sensor_msgs/JointState at 200 Hz (stamps = its own time) and taking std_msgs/Float64MultiArray
on /effort_controller/commands, as a ros2_control effort controller's hardware would.

Prints JSON lines: {"cmd": [...], "q": [...], "t": ...} per received command.
"""

import json
import sys
import time

import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray


def main():
    rclpy.init()
    node = rclpy.create_node('standin_driver')
    pub = node.create_publisher(JointState, '/joint_states', QoSProfile(depth=10))
    q, qd, tau = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    clock = {'t': 0.0}

    def on_command(msg):
        values = list(msg.data)
        if len(values) == 2:
            tau[:] = values
        print(
            json.dumps({'cmd': values, 'q': list(q), 't': clock['t'], 'wall': time.time()}),
            flush=True,
        )

    node.create_subscription(
        Float64MultiArray, '/effort_controller/commands', on_command, QoSProfile(depth=10)
    )
    duration = float(sys.argv[1]) if len(sys.argv) > 1 else 30.0
    start = time.monotonic()
    k = 0
    msg = JointState(name=['joint1', 'joint2'])
    while time.monotonic() - start < duration:
        for _ in range(5):  # 5 x 1 ms of physics per published sample
            for i in range(2):
                qd[i] += 1e-3 * tau[i]
                q[i] += 1e-3 * qd[i]
            k += 1
        clock['t'] = k * 1e-3
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * 1_000_000, 1_000_000_000)
        msg.position, msg.velocity, msg.effort = list(q), list(qd), list(tau)
        pub.publish(msg)
        deadline = start + clock['t']
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            rclpy.spin_once(node, timeout_sec=remaining)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    try:
        main()
    except KeyboardInterrupt:
        pass
