"""Recorder throughput: publish JointState + WrenchStamped at a total rate for a few seconds to
a recorder process over DDS (this machine only), then count what reached the file.

    .venv/bin/python bench/recorder_throughput.py [--rate 10000] [--seconds 4]

with impact_arm importable (installed, or PYTHONPATH naming the clone); the recorder it starts
inherits the environment.

Prints the achieved publish rate, messages recorded and drops (published - recorded).
Not a test: numbers depend on the machine (two cores share publisher, DDS and recorder).
"""

import argparse
import os
import random
import resource
import signal
import subprocess
import sys
import tempfile
import time


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--rate', type=float, default=10000.0, help='messages/s, both topics')
    ap.add_argument('--seconds', type=float, default=4.0)
    ap.add_argument('--output', default=None, help='MCAP file (default: a temporary file)')
    a = ap.parse_args()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
    tmp = tempfile.mkdtemp(prefix='recbench-')
    out = a.output or os.path.join(tmp, 'bench.mcap')

    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from impact_arm.io.mcap_ros2 import contract_qos, iter_raw

    rec = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'impact_arm.nodes.recorder',
            '--ros-args',
            '-p',
            f'output:={out}',
            '-p',
            'param_nodes:=[""]',
        ],
        stdout=subprocess.DEVNULL,
        stderr=open(os.path.join(tmp, 'rec.err'), 'w'),
    )
    rclpy.init()
    try:
        node = rclpy.create_node('recorder_bench')
        js = node.create_publisher(
            JointState, '/joint_states', contract_qos('/joint_states').to_rclpy()
        )
        wr = node.create_publisher(
            WrenchStamped, '/contact_wrench', contract_qos('/contact_wrench').to_rclpy()
        )
        end = time.monotonic() + 15
        while (
            js.get_subscription_count() < 1 or wr.get_subscription_count() < 1
        ) and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.5)  # let both endpoints finish matching
        m = JointState(
            name=['joint1', 'joint2'], position=[0.1, 0.2], velocity=[0.0, 0.0], effort=[1.0, -1.0]
        )
        w = WrenchStamped()
        n, start = 0, time.monotonic()
        total = int(a.rate * a.seconds)
        batch = max(1, int(a.rate / 200))  # publish in 5 ms batches, paced from the start
        while n < total:
            for _ in range(min(batch, total - n)):
                if n % 2:
                    w.header.stamp.nanosec = n
                    wr.publish(w)
                else:
                    m.header.stamp.nanosec = n
                    js.publish(m)
                n += 1
            delay = start + n / a.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        elapsed = time.monotonic() - start
        time.sleep(1.0)  # let the recorder drain its queues
    finally:
        rec.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 20
        while rec.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)  # poll() would reap the child; keep it for wait4 below
        if rec.returncode is None:
            rec.kill()
        rclpy.try_shutdown()
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    recorded = sum(1 for _ in iter_raw(out))
    print(
        f'published {n} messages in {elapsed:.2f} s = {n / elapsed:.0f} msg/s (target {a.rate:.0f})'
    )
    print(
        f'recorded {recorded}, drops {n - recorded} ({100.0 * (n - recorded) / n:.2f} %), '
        f'recorder exit code {rec.returncode}, file {os.path.getsize(out)} bytes: {out}'
    )
    cpu = usage.ru_utime + usage.ru_stime
    print(f'recorder CPU {cpu:.2f} s = {1e6 * cpu / max(recorded, 1):.0f} us per message')


if __name__ == '__main__':
    main()
