"""The DDS cost of one lockstep period with no physics and no control law in it.

Two processes on the same topics, QoS, executor and wire format as the nodes (pre-serialized
messages published as bytes, raw subscriptions read with ``wire``): a *driver* publishes
/contact_wrench and /joint_states (and /clock) and waits for a command; a *controller*
subscribes to both and answers each joint state with a command. The mean period of this
exchange is the floor under ``impact-arm run --mode lockstep`` on this machine: its real-time
factor at 1 kHz can never exceed 1 ms / floor. ``bench rates`` prints it next to the real run.

Run as ``python -m impact_arm_bench.transport_floor driver|controller``; ``measure()``
starts both (local DDS domain, ended by PID) and returns the floor in seconds.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from impact_arm import contract
from impact_arm.contract import CLOCK, COMMANDS, CONTACT_WRENCH, JOINT_STATES, joint_names

from .common import worker_environment

WARM_UP = 200


def _controller(seconds):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.experimental import EventsExecutor
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from impact_arm.io.wire import PatchedMessage, joint_state_fields, wrench_stamped_fields

    node = rclpy.create_node('floor_controller')
    pub = node.create_publisher(Float64MultiArray, COMMANDS, contract.qos(COMMANDS).to_rclpy())
    command = PatchedMessage(Float64MultiArray(data=[0.0, 0.0]), ('data',), stamp=None)
    latest_only = contract.qos(JOINT_STATES).to_rclpy()
    latest_only.depth = 1

    def on_joint_state(raw):
        joint_state_fields(raw)
        pub.publish(command.fill([0.0, 0.0]))

    node.create_subscription(
        WrenchStamped, CONTACT_WRENCH, wrench_stamped_fields, latest_only, raw=True
    )
    node.create_subscription(JointState, JOINT_STATES, on_joint_state, latest_only, raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    end = time.monotonic() + seconds
    while time.monotonic() < end and rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def _driver(periods, clock):
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.experimental import EventsExecutor
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from impact_arm.io.wire import PatchedMessage, float64_array_data

    node = rclpy.create_node('floor_driver')

    def publisher(msg_type, topic):
        return node.create_publisher(msg_type, topic, contract.qos(topic).to_rclpy())

    pub_wrench = publisher(WrenchStamped, CONTACT_WRENCH)
    pub_joints = publisher(JointState, JOINT_STATES)
    pub_clock = publisher(Clock, CLOCK) if clock else None
    joints = PatchedMessage(
        JointState(
            name=joint_names(2), position=[0.1, 0.2], velocity=[0.0, 0.0], effort=[0.0, 0.0]
        ),
        ('position', 'velocity', 'effort'),
    )
    wrench = PatchedMessage(WrenchStamped(), ('wrench.force.x', 'wrench.force.y'))
    tick = PatchedMessage(Clock(), (), stamp='clock')
    count, times = [0], []

    def send():
        stamp = divmod(count[0], 1000)
        pub_wrench.publish(wrench.fill((0.0, 0.0), stamp))
        pub_joints.publish(joints.fill([0.1, 0.2, 0.0, 0.0, 0.0, 0.0], stamp))
        if pub_clock is not None:
            pub_clock.publish(tick.fill((), stamp))

    def on_command(raw):
        float64_array_data(raw)
        count[0] += 1
        if count[0] in (WARM_UP, WARM_UP + periods):
            times.append(time.perf_counter())
        if count[0] < WARM_UP + periods:
            send()

    node.create_subscription(
        Float64MultiArray, COMMANDS, on_command, contract.qos(COMMANDS).to_rclpy(), raw=True
    )
    deadline = time.monotonic() + 30
    while (
        pub_joints.get_subscription_count() < 1
        or pub_wrench.get_subscription_count() < 1
        or node.count_publishers(COMMANDS) < 1
    ):
        rclpy.spin_once(node, timeout_sec=0.05)
        if time.monotonic() > deadline:
            raise SystemExit('no controller matched within 30 s')
    time.sleep(0.3)
    executor = EventsExecutor()
    executor.add_node(node)
    send()
    deadline = time.monotonic() + 60
    while len(times) < 2 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    if len(times) < 2:
        raise SystemExit('the exchange stalled')
    print(f'{(times[1] - times[0]) / periods:.9f}', flush=True)


def measure(periods=3000, clock=True, env=None) -> float:
    """Mean period [s] of the bare exchange, both sides in their own processes."""
    env = worker_environment(env)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    module = [sys.executable, '-m', __name__]
    controller = subprocess.Popen(
        module + ['controller'], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        out = subprocess.run(
            module + ['driver', str(periods)] + (['--clock'] if clock else []),
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        controller.terminate()
        try:
            controller.wait(5)
        except subprocess.TimeoutExpired:
            controller.kill()
            controller.wait()
    if out.returncode != 0:
        raise RuntimeError(f'transport floor: {out.stderr.strip()[-300:]}')
    return float(out.stdout.split()[-1])


def main(argv=None) -> int:
    import rclpy

    argv = sys.argv[1:] if argv is None else argv
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    rclpy.init()
    try:
        if argv[0] == 'controller':
            _controller(150.0)
        else:
            _driver(int(argv[1]), '--clock' in argv)
    except KeyboardInterrupt:
        pass
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
