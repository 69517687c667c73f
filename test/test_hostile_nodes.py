"""Hostile peers on the graph (issue 17 items 1-4): garbage on the controller's raw inputs,
absurd states, stamp jumps and a malformed SetParameters request must not stop a node nor
make the controller send a non-finite or absurd torque."""
import os
import random
import signal
import struct
import time

from ros_helpers import (PYTHON, node_args, probe, ros_env, start_process,  # noqa: F401
                         wait_for)

HERE = os.path.dirname(os.path.abspath(__file__))


def garbage_payloads(good, rng, count):
    """Random bytes, truncations, flipped bytes, absurd lengths, bad headers. Flips and lengths
    stay before the doubles: a flipped double is a valid (if wrong) state, not garbage."""
    numbers_at = good.index(struct.pack('<d', 0.1))
    out = [b'\x00\x01\x00\x00', b'\x07\x01\x00\x00' + good[4:],
           good.replace(b'jointA', b'joi\xffnA')]
    while len(out) < count:
        raw = bytearray(good)
        kind = rng.randrange(4)
        if kind == 0:
            raw = bytearray(rng.randbytes(rng.randrange(64)))
        elif kind == 1:
            raw = raw[:rng.randrange(len(raw))]
        elif kind == 2:
            raw[rng.randrange(numbers_at)] ^= rng.randrange(1, 256)
        else:
            at = rng.randrange(4, numbers_at - 4)
            raw[at:at + 4] = struct.pack('<I', 2**31 - 1)
        out.append(bytes(raw))
    return out


def test_controller_survives_garbage_absurd_states_stamp_jumps_and_bad_requests(
        probe, ros_env, tmp_path):  # noqa: F811
    from geometry_msgs.msg import WrenchStamped
    from rcl_interfaces.msg import Parameter, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    standin = [PYTHON, os.path.join(HERE, 'standin_driver.py'), '60']
    params = ('law:=pd', 'space:=joint', 'p:=[40.0,40.0]', 'd:=[13.0,13.0]',
              'down_target:=[-0.5,0.3]', 'switch_height:=100.0', 'surface_height:=-100.0',
              'rate:=200.0')
    states = probe.publisher(JointState, '/joint_states')
    with start_process(standin, ros_env, tmp_path, 'standin') as driver, \
            start_process(node_args('impact_arm.nodes.controller', *params,
                                    ros_args=['-r', '__node:=hostile_controller']),
                          ros_env, tmp_path, 'ctl') as ctl:
        def commands():
            return [x['cmd'] for x in driver.lines() if 'cmd' in x]
        assert wait_for(lambda: len(commands()) > 20, timeout=60), ctl.stderr
        rng = random.Random(17)
        # (only now: while a wrench publisher exists the controller waits for wrenches)
        wrenches = probe.publisher(WrenchStamped, '/contact_wrench')
        assert wait_for(lambda: states.get_subscription_count() >= 1 and
                        wrenches.get_subscription_count() >= 1, timeout=20), \
            (states.get_subscription_count(), wrenches.get_subscription_count())
        # other joints' names: a mutation that still parses is ignored, not a state to act on
        good = serialize_message(JointState(name=['jointA', 'jointB'], position=[0.1, 0.2],
                                            velocity=[0.0, 0.0]))
        absurd = [JointState(name=['joint1', 'joint2'], position=p, velocity=[0.0, 0.0])
                  for p in ([1e308, 0.0], [1e308, 1e308], [1e200, 0.0], [float('nan'), 0.0])]
        far = JointState(name=['joint1', 'joint2'], position=[0.1, 0.2], velocity=[0.0, 0.0])
        far.header.stamp.sec = 2**31 - 2
        for k, raw in enumerate(garbage_payloads(good, rng, 600)):
            states.publish(raw)
            wrenches.publish(raw[:60])
            if k % 100 == 0:     # the controller keeps only the newest state: let each be taken
                for msg in (*absurd, far):    # far: one state far in the future
                    states.publish(msg)
                    time.sleep(0.05)
            time.sleep(0.001)
        # a wrench publisher makes the controller wait for the wrench of each instant: gone
        probe.node.destroy_publisher(wrenches)
        sent_before = len(commands())

        client = probe.node.create_client(SetParameters, '/hostile_controller/set_parameters')
        assert client.wait_for_service(timeout_sec=10)
        bad = SetParameters.Request(parameters=[
            Parameter(name='p', value=ParameterValue(type=200)), Parameter(name='')])
        future = client.call_async(bad)
        assert wait_for(future.done, timeout=10)
        assert not any(r.successful for r in future.result().results)

        # still alive and still controlling on the driver's own states after all of that
        assert wait_for(lambda: len(commands()) > sent_before + 50, timeout=30), ctl.stderr
        assert ctl.alive(), ctl.stderr
        q = [x['q'] for x in driver.lines() if 'q' in x][-1]
        assert all(abs(a - b) < 0.05 for a, b in zip(q, [-0.5, 0.3])), q

        ctl.signal(signal.SIGINT)
        assert ctl.wait(10) == 0, ctl.stderr
    # the counters, as the controller reports them on exit
    import re
    summary = [line for line in ctl.stderr.splitlines() if 'commands sent' in line]
    assert summary, ctl.stderr[-2000:]
    seen = dict(re.findall(r'(\w+) (\d+)', summary[-1].partition('dropped: ')[2]))
    # the controller keeps only the newest sample (depth 1): many are replaced before taken
    assert int(seen.get('malformed_joint_states', 0)) > 10, (seen, ctl.stderr[-2000:])
    assert int(seen.get('malformed_wrenches', 0)) > 10, seen
    assert int(seen.get('stamp_jumps', 0)) > 0, seen
    sent = commands()
    # what it SENT: every command finite and of the size a PD on this error gives
    assert all(abs(v) < 1e3 for cmd in sent for v in cmd), max(max(map(abs, c)) for c in sent)
    assert 'Traceback' not in ctl.stderr
