"""DDS test helpers: a private domain per test module, node processes that are always ended
(by PID), and a small publisher/subscriber program (run this file) for node tests.

    from ros_helpers import ros_env, start_process, wait_for   # ros_env is a fixture

Every process gets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and the module's ROS_DOMAIN_ID.
"""

import argparse
import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time

import pytest
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
PYTHON = sys.executable
HERE = os.path.abspath(__file__)


class Probe:
    """Subscriptions that store (receive time, message) and publishers, on one node."""

    def __init__(self, domain):
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node('test_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.subscriptions = {}
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception as exc:  # noqa: BLE001 - keep spinning unless shutting down
                if self.context.ok():
                    print(f'probe executor: {exc!r}', file=sys.stderr)

    def listen(self, msg_type, topic, depth=1000, transient=False, keep=None):
        """Messages of ``topic`` as they arrive, those ``keep(msg)`` accepts when given."""
        from rclpy.qos import DurabilityPolicy, QoSProfile

        store = []
        qos = QoSProfile(
            depth=depth,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE,
        )
        with self.lock:
            self.subscriptions[id(store)] = self.node.create_subscription(
                msg_type,
                topic,
                lambda m: (keep is None or keep(m)) and store.append((time.monotonic(), m)),
                qos,
            )
        return store

    def forget(self, *stores):
        """Stop filling these stores (a busy probe must not lag behind later tests)."""
        with self.lock:
            for store in stores:
                self.node.destroy_subscription(self.subscriptions.pop(id(store)))

    def publisher(self, msg_type, topic):
        with self.lock:
            return self.node.create_publisher(msg_type, topic, 10)

    def close(self):
        self.rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=2)


@pytest.fixture(scope='module')
def probe(ros_env):
    """A Probe in the test module's domain."""
    p = Probe(int(ros_env['ROS_DOMAIN_ID']))
    yield p
    p.close()


# Test modules draw their domains from one shuffled list, so two modules of a session never
# share one: a participant a killed node leaves behind lingers for its lease (seconds) and,
# on a shared domain, looks like a reader to the next module's publishers.
# IMPACT_ARM_TEST_DOMAINS=LOW-HIGH narrows the draw, so that test sessions run side by side
# (several worktrees on one machine) never meet either.
def domain_range():
    low, _, high = os.environ.get('IMPACT_ARM_TEST_DOMAINS', '1-100').partition('-')
    return range(int(low), int(high) + 1)


_DOMAINS = iter(random.sample(domain_range(), len(domain_range())))


# a joint-space PD on the stand-in driver (standin_driver.py), with no surface in reach: what
# the controller tests drive it with. The stand-in's joints (unit inertia, no gravity) are not
# the scene's arm, so the controller must not predict with the scene's model over the
# commands in flight: a measured latency of one period would make it hold the joints where
# the paper arm's gravity, predicted over that period, would carry them to the target
STANDIN_PD = (
    'latency_periods:=0',
    'law:=pd',
    'space:=joint',
    'p:=[40.0,40.0]',
    'd:=[13.0,13.0]',
    'down_target:=[-0.5,0.3]',
    'switch_height:=100.0',
    'surface_height:=-100.0',
    'rate:=200.0',
)


@contextlib.contextmanager
def driven_standin(env, workdir, seconds, params, name):
    """The stand-in driver (standin_driver.py, running ``seconds``) and a controller node
    named ``name`` with ``params`` driving it: yields the two processes (driver, controller),
    both ended by PID on the way out."""
    driver = [PYTHON, os.path.join(os.path.dirname(HERE), 'standin_driver.py'), str(seconds)]
    node = controller(*params, ros_args=['-r', f'__node:={name}'])
    with (
        start_process(driver, env, workdir, 'standin') as standin,
        start_process(node, env, workdir, 'ctl') as ctl,
    ):
        yield standin, ctl


def driver_position(driver):
    """The stand-in driver's joint positions at the latest command it printed, or None."""
    lines = [x for x in driver.lines() if 'q' in x]
    return lines[-1]['q'] if lines else None


def driver_commands(driver):
    """Every command the stand-in driver printed, oldest first."""
    return [x['cmd'] for x in driver.lines() if 'cmd' in x]


def make_env(domain=None, **extra) -> dict:
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = str(domain if domain is not None else next(_DOMAINS))
    env['PYTHONUNBUFFERED'] = '1'
    env['PYTHONPATH'] = ROOT + os.pathsep + env.get('PYTHONPATH', '')
    env.update({k: str(v) for k, v in extra.items()})
    return env


@pytest.fixture(scope='module')
def ros_env():
    """Environment for the node processes of one test module: its own random DDS domain."""
    return make_env()


class Proc:
    """A started process whose stdout/stderr go to files (no pipe can fill up and block it)."""

    def __init__(self, args, env, workdir, name):
        self.name = name
        self.out_path = os.path.join(workdir, f'{name}.out')
        self.err_path = os.path.join(workdir, f'{name}.err')
        with open(self.out_path, 'wb') as out, open(self.err_path, 'wb') as err:
            self.popen = subprocess.Popen(
                args, env=env, cwd=workdir, stdout=out, stderr=err, stdin=subprocess.DEVNULL
            )
        self.pid = self.popen.pid

    def signal(self, sig):
        if self.popen.poll() is None:
            os.kill(self.pid, sig)

    def wait(self, timeout=10.0):
        return self.popen.wait(timeout)

    def alive(self):
        return self.popen.poll() is None

    @property
    def stdout(self):
        with open(self.out_path, encoding='utf-8', errors='replace') as f:
            return f.read()

    @property
    def stderr(self):
        with open(self.err_path, encoding='utf-8', errors='replace') as f:
            return f.read()

    def lines(self):
        """stdout JSON lines (the helper programs' events)."""
        out = []
        for line in self.stdout.splitlines():
            if line.startswith('{'):
                with contextlib.suppress(ValueError):
                    out.append(json.loads(line))
        return out

    def stop(self, timeout=5.0):
        """SIGINT, then SIGKILL by PID if it does not exit in time."""
        if self.alive():
            self.signal(signal.SIGINT)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.signal(signal.SIGKILL)
                self.popen.wait(5)


@contextlib.contextmanager
def start_process(args, env, workdir, name='proc'):
    """Run ``args``; always ended (SIGINT then SIGKILL, by PID) when the block leaves."""
    proc = Proc(args, env, workdir, name)
    try:
        yield proc
    finally:
        proc.stop()


def node_args(module, *params, ros_args=()):
    """``python -m module --ros-args -p k:=v ...``."""
    args = [PYTHON, '-m', module, '--ros-args']
    for p in params:
        args += ['-p', p]
    return args + list(ros_args)


def simulator(*params, ros_args=()):
    return node_args('impact_arm.nodes.simulator', *params, ros_args=ros_args)


def controller(*params, ros_args=()):
    return node_args('impact_arm.nodes.controller', *params, ros_args=ros_args)


def stamp(msg):
    """A message's header stamp in seconds."""
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def from_simulator(msg):
    """A /diagnostics message of the simulator (the controller publishes its own)."""
    from impact_arm.contract import SIMULATOR_STATUS

    return bool(msg.status) and msg.status[0].name == SIMULATOR_STATUS


def simulator_report(msg):
    """The simulator's status in a /diagnostics message, parsed (runner.SimulatorReport:
    level, message, status), or None when it holds only other nodes' statuses."""
    from impact_arm.tools.runner import simulator_report as parse

    return parse(msg)


def simulator_status(msg):
    """The simulator's values (contract.SimulatorStatus) in a /diagnostics message of the
    simulator (``from_simulator``)."""
    return simulator_report(msg).status


def diagnostics_values(msg):
    """The key/values of a /diagnostics message's first status, with its level and message
    (the controller's; the simulator's are read typed: ``simulator_report``)."""
    status = msg.status[0]
    values = {kv.key: kv.value for kv in status.values}
    level = status.level
    values['level'] = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
    values['message'] = status.message
    return values


def helper_args(*args):
    return [PYTHON, HERE] + [str(a) for a in args]


def recorder_matched(log, topic):
    """The recorder's log says its reader matched a publisher on ``topic`` (its readers, not
    only the publisher's writers: matching is not symmetric in time). A line may name other
    topics matched in the same round."""
    from impact_arm.nodes.recorder import MATCHED_LINE

    return any(
        MATCHED_LINE in line and topic in line.partition(MATCHED_LINE)[2].split()
        for line in log.splitlines()
    )


def wait_for(predicate, timeout=10.0, interval=0.05):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    return predicate()


# ------------------------------------------------------- helper program (run as a process)
def _publish(args):
    """Publish numbered JointState (+ WrenchStamped) messages; print one JSON line per batch."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from impact_arm.contract import qos as contract_qos

    rclpy.init()
    node = rclpy.create_node('test_publisher')
    js = node.create_publisher(
        JointState, '/joint_states', contract_qos('/joint_states').to_rclpy()
    )
    wr = (
        node.create_publisher(
            WrenchStamped, '/contact_wrench', contract_qos('/contact_wrench').to_rclpy()
        )
        if args.wrench
        else None
    )
    end = time.monotonic() + args.wait_sub
    # every publisher matched (not just the first), or its first messages go nowhere
    while (
        js.get_subscription_count() < 1 or (wr is not None and wr.get_subscription_count() < 1)
    ) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps({'event': 'matched', 'subs': js.get_subscription_count()}), flush=True)
    # Our writer matching a reader is not the reader matching us: a volatile reader drops what
    # was written before its own match. --go-file: start once the test saw the reader's side.
    while args.go_file and not os.path.exists(args.go_file) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    period = 1.0 / args.rate
    start = time.monotonic()
    for i in range(args.count):
        target = start + i * period
        delay = target - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        m = JointState(
            name=['joint1', 'joint2'],
            position=[i * 1e-3, -i * 1e-3],
            velocity=[float(i), 0.5],
            effort=[0.25, -0.25],
        )
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(i, 1000)[0], (i % 1000) * 1_000_000
        js.publish(m)
        if wr is not None:
            w = WrenchStamped()
            w.header.stamp = m.header.stamp
            w.wrench.force.x, w.wrench.force.y = float(i), 2.0 * i
            wr.publish(w)
        if i % args.batch == args.batch - 1 or i == args.count - 1:
            print(json.dumps({'event': 'sent', 'n': i + 1, 't': time.time_ns()}), flush=True)
    print(json.dumps({'event': 'done', 'elapsed': time.monotonic() - start}), flush=True)
    end = time.monotonic() + args.linger  # keep answering (parameter services) for a while
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()
    rclpy.try_shutdown()


def _subscribe(args):
    """Print one JSON line per received message: topic, wall time, a value identifying it."""
    import rclpy
    from impact_arm.contract import TOPICS as CONTRACT_TOPICS
    from impact_arm.contract import qos as contract_qos
    from impact_arm.io.mcap_ros2 import message_class

    rclpy.init()
    node = rclpy.create_node('test_subscriber')

    def make_cb(topic):
        def cb(msg):
            now = time.time_ns()
            stamp = getattr(getattr(msg, 'header', None), 'stamp', None) or getattr(
                msg, 'clock', None
            )
            value = (stamp.sec * 10**9 + stamp.nanosec) if stamp is not None else None
            print(json.dumps({'topic': topic, 't': now, 'stamp': value}), flush=True)

        return cb

    subs = [
        node.create_subscription(
            message_class(CONTRACT_TOPICS[t][0]), t, make_cb(t), contract_qos(t).to_rclpy(1000)
        )
        for t in args.topics
    ]
    print(json.dumps({'event': 'ready', 'n': len(subs)}), flush=True)
    end = time.monotonic() + args.duration
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest='cmd', required=True)
    p = sub.add_parser('pub')
    p.add_argument('--count', type=int, default=100)
    p.add_argument('--rate', type=float, default=100.0)
    p.add_argument('--wrench', action='store_true')
    p.add_argument('--batch', type=int, default=10)
    p.add_argument('--wait-sub', type=float, default=10.0)
    p.add_argument('--go-file', default='')
    p.add_argument('--linger', type=float, default=0.5)
    s = sub.add_parser('sub')
    s.add_argument('topics', nargs='+')
    s.add_argument('--duration', type=float, default=5.0)
    a = parser.parse_args()
    try:
        _publish(a) if a.cmd == 'pub' else _subscribe(a)
    except KeyboardInterrupt:
        pass
