"""Hostile peers on the graph: garbage on the controller's raw inputs,
absurd states, stamp jumps and a malformed SetParameters request must not stop a node nor
make the controller send a non-finite or absurd torque."""

import os
import random
import signal
import struct
import time

from ros_helpers import (
    STANDIN_PD,
    simulator_report,
    simulator_status,
    driven_standin,
    driver_commands,
    driver_position,
    from_simulator,
    node_args,
    recorder_matched,
    simulator,
    start_process,
    wait_for,
)

from impact_arm_bench.generators import malformed_commands
from repo_paths import CONFIG


def garbage_payloads(good, rng, count):
    """Random bytes, truncations, flipped bytes, absurd lengths, bad headers. Flips and lengths
    stay before the doubles: a flipped double is a valid (if wrong) state, not garbage."""
    numbers_at = good.index(struct.pack('<d', 0.1))
    out = [
        b'\x00\x01\x00\x00',
        b'\x07\x01\x00\x00' + good[4:],
        good.replace(b'jointA', b'joi\xffnA'),
    ]
    while len(out) < count:
        raw = bytearray(good)
        kind = rng.randrange(4)
        if kind == 0:
            raw = bytearray(rng.randbytes(rng.randrange(64)))
        elif kind == 1:
            raw = raw[: rng.randrange(len(raw))]
        elif kind == 2:
            raw[rng.randrange(numbers_at)] ^= rng.randrange(1, 256)
        else:
            at = rng.randrange(4, numbers_at - 4)
            raw[at : at + 4] = struct.pack('<I', 2**31 - 1)
        out.append(bytes(raw))
    return out


def test_controller_survives_garbage_absurd_states_stamp_jumps_and_bad_requests(
    probe, ros_env, tmp_path
):  # noqa: F811
    from geometry_msgs.msg import WrenchStamped
    from rcl_interfaces.msg import Parameter, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    states = probe.publisher(JointState, '/joint_states')
    with driven_standin(ros_env, tmp_path, 60, STANDIN_PD, 'hostile_controller') as (driver, ctl):

        def commands():
            return driver_commands(driver)

        assert wait_for(lambda: len(commands()) > 20, timeout=60), ctl.stderr
        rng = random.Random(17)
        # (only now: while a wrench publisher exists the controller waits for wrenches)
        wrenches = probe.publisher(WrenchStamped, '/contact_wrench')
        assert wait_for(
            lambda: states.get_subscription_count() >= 1 and wrenches.get_subscription_count() >= 1,
            timeout=20,
        ), (states.get_subscription_count(), wrenches.get_subscription_count())
        # other joints' names: a mutation that still parses is ignored, not a state to act on
        good = serialize_message(
            JointState(name=['jointA', 'jointB'], position=[0.1, 0.2], velocity=[0.0, 0.0])
        )
        absurd = [
            JointState(name=['joint1', 'joint2'], position=p, velocity=[0.0, 0.0])
            for p in ([1e308, 0.0], [1e308, 1e308], [1e200, 0.0], [float('nan'), 0.0])
        ]
        far = JointState(name=['joint1', 'joint2'], position=[0.1, 0.2], velocity=[0.0, 0.0])
        far.header.stamp.sec = 2**31 - 2
        for k, raw in enumerate(garbage_payloads(good, rng, 600)):
            states.publish(raw)
            wrenches.publish(raw[:60])
            if k % 100 == 0:  # the controller keeps only the newest state: let each be taken
                for msg in (*absurd, far):  # far: one state far in the future
                    states.publish(msg)
                    time.sleep(0.05)
            time.sleep(0.001)
        # a wrench publisher makes the controller wait for the wrench of each instant: gone
        probe.node.destroy_publisher(wrenches)
        sent_before = len(commands())

        client = probe.node.create_client(SetParameters, '/hostile_controller/set_parameters')
        assert client.wait_for_service(timeout_sec=10)
        bad = SetParameters.Request(
            parameters=[Parameter(name='p', value=ParameterValue(type=200)), Parameter(name='')]
        )
        future = client.call_async(bad)
        assert wait_for(future.done, timeout=10)
        assert not any(r.successful for r in future.result().results)
        future = client.call_async(SetParameters.Request(parameters=[Parameter(name='')]))
        assert wait_for(future.done, timeout=10)
        assert [r.successful for r in future.result().results] == [False]

        # still alive and still controlling on the driver's own states after all of that
        assert wait_for(lambda: len(commands()) > sent_before + 50, timeout=30), ctl.stderr
        assert ctl.alive(), ctl.stderr
        q = driver_position(driver)
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


def not_applied(status):
    """Commands a simulator's status counts as refused or superseded."""
    return status.commands_rejected + status.commands_superseded


def test_simulator_applies_only_valid_commands_among_1000_malformed(probe, ros_env, tmp_path):  # noqa: F811,E501
    """>= 1 000 malformed raw payloads mixed with valid commands on the
    realtime simulator's command topic: it keeps running and publishing every period, holds
    only the valid commands' torques, and counts the rest (refused, or superseded: not
    checked because a newer valid command of the same period was). Counts and values only:
    no wall-clock rate is asserted.

    A zero-length payload is sent by a publisher of its own: with rmw_fastrtps it blocks every
    later sample of the publisher that sent it (reliable, in order: the receiver waits for a
    sample that never comes, until it leaves the writer's history), so mixed into the garbage
    stream it would hide the rest. It harms only its sender: the valid stream must go on."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from rclpy.serialization import serialize_message
    from impact_arm.contract import COMMANDS

    states = probe.listen(JointState, '/joint_states', depth=5000)
    diags = probe.listen(DiagnosticArray, '/diagnostics', keep=from_simulator)
    with probe.lock:  # deep writer histories: the test's own bursts must not overwrite them
        commands, hostile, empty = (
            probe.node.create_publisher(Float64MultiArray, COMMANDS, QoSProfile(depth=1000))
            for _ in range(3)
        )
    valid = ([1.5, -0.75], [-0.5, 0.25])
    garbage = malformed_commands(random.Random(15), 1200)
    sim_args = simulator('mode:=realtime', 'publish_rate:=1000.0', 'command_timeout:=30.0')
    try:
        with start_process(sim_args, ros_env, tmp_path, 'sim') as sim:
            assert (
                wait_for(
                    lambda: (
                        states
                        and all(p.get_subscription_count() >= 1 for p in (commands, hostile, empty))
                        or not sim.alive()
                    ),
                    timeout=60,
                )
                and sim.alive()
            ), sim.stderr
            for _ in range(3):
                empty.publish(b'')
            valid_sent = 0
            for k in range(0, len(garbage), 4):
                for raw in garbage[k : k + 4]:
                    hostile.publish(raw)
                commands.publish(serialize_message(Float64MultiArray(data=valid[valid_sent % 2])))
                valid_sent += 1
                time.sleep(0.003)  # about the pace a 1 kHz controller sends at
            flood_end = len(states)

            def settled():  # two diagnostics after the flood with the same counts
                statuses = [simulator_status(m) for _, m in diags]
                return (
                    len(statuses) >= 2
                    and not_applied(statuses[-1]) == not_applied(statuses[-2]) != 0
                    and statuses[-1].commands == statuses[-2].commands
                    and statuses
                )

            running = wait_for(settled, timeout=15)
            assert running, [
                (r.level, *((k, v) for k, v in r.status.values() if k.startswith('command')))
                for r in (simulator_report(m) for _, m in diags)
            ][-4:]
            assert wait_for(lambda: len(states) > flood_end + 500, timeout=15), sim.stderr
            assert sim.alive(), sim.stderr
    finally:
        probe.forget(states, diags)
        with probe.lock:
            for publisher in (commands, hostile, empty):
                probe.node.destroy_publisher(publisher)
    last = running[-1]
    rejected, accepted = last.commands_rejected, last.commands
    # a queue overflow on a stalled machine may drop some of either kind, never add any; a
    # superseded message may be garbage or an older valid command of the same period
    assert rejected <= len(garbage), (rejected, len(garbage))
    assert len(garbage) // 2 <= not_applied(last) <= len(garbage) + valid_sent - accepted, (
        last,
        len(garbage),
        valid_sent,
    )
    assert 0 < accepted <= valid_sent, (accepted, valid_sent)
    # every period of the run was published (the simulator's own count against sim time)
    running = [s for s in running if s.periods_published_until_s > 0.2]
    first = running[0]
    periods = round((last.periods_published_until_s - first.periods_published_until_s) / 1e-3)
    # (a diagnostics second may hold fewer than 1000 periods: a stalling VM makes the loop
    # skip periods, which advance neither count)
    assert periods >= 500 and last.periods_published - first.periods_published == periods, (
        first,
        last,
    )
    # the torques held: zero before the first command, then only ever a valid command's
    held = {tuple(m.effort) for _, m in states}
    assert held <= {(0.0, 0.0), *map(tuple, valid)}, held - {(0.0, 0.0), *map(tuple, valid)}
    assert held & set(map(tuple, valid)), held
    assert 'Traceback' not in sim.stderr


def test_recorder_with_a_scene_stores_garbage_without_dying(probe, ros_env, tmp_path):  # noqa: F811,E501
    """With a scene the recorder reads /joint_states and /contact_wrench to draw the arm: a
    malformed sample is stored as it came and not drawn; the recorder keeps recording."""
    from mcap.reader import make_reader
    from rclpy.serialization import serialize_message
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    out = tmp_path / 'garbage.mcap'
    paper = os.path.join(CONFIG, 'paper.yaml')
    states = probe.publisher(JointState, '/joint_states')
    wrenches = probe.publisher(WrenchStamped, '/contact_wrench')
    rec = node_args(
        'impact_arm.nodes.recorder',
        f'output:={out}',
        f'scene:={paper}',
        'topics:=[/joint_states,/contact_wrench]',
        'flush_interval:=0.2',
    )
    with start_process(rec, ros_env, tmp_path, 'recorder') as recorder:
        assert wait_for(
            lambda: (
                states.get_subscription_count() >= 1
                and wrenches.get_subscription_count() >= 1
                and recorder_matched(recorder.stderr, '/joint_states')
                and recorder_matched(recorder.stderr, '/contact_wrench')
            ),
            timeout=60,
        ), recorder.stderr
        good = serialize_message(
            JointState(name=['joint1', 'joint2'], position=[0.1, 0.2], velocity=[0.0, 0.0])
        )
        for raw in garbage_payloads(good, random.Random(5), 100):
            states.publish(raw)
            wrenches.publish(raw[:60])
            time.sleep(0.002)
        states.publish(JointState(name=['joint1', 'joint2'], position=[0.1, 0.2]))
        time.sleep(1.0)
        assert recorder.alive(), recorder.stderr
        recorder.stop()
        assert recorder.popen.returncode == 0, recorder.stderr
    assert 'malformed sample not drawn' in recorder.stderr
    assert 'Traceback' not in recorder.stderr
    with open(out, 'rb') as f:
        counts = {c.topic: 0 for c in make_reader(f).get_summary().channels.values()}
        f.seek(0)
        for _, channel, _ in make_reader(f).iter_messages():
            counts[channel.topic] += 1
    assert counts['/joint_states'] >= 50 and counts.get('/tf', 0) >= 1, counts
