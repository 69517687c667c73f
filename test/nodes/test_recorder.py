"""The recorder node over DDS (separate processes, this machine only, a private domain): what
was published is what the file holds; SIGKILL keeps everything up to the last flush; an
unwritable output is a clear error and a non-zero exit."""

import json
import math
import os
import re
import signal
import time
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from impact_arm import contract
from ros_helpers import (
    controller,
    helper_args,
    node_args,
    recorder_matched,
    simulator,
    start_process,
    wait_for,
)
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
PAPER = os.path.join(ROOT, 'config', 'paper.yaml')
RECORDER = 'impact_arm.nodes.recorder'


def read(path):
    out = {}
    with AnyReader([Path(path)]) as reader:
        for c in reader.connections:
            out[c.topic] = (c.msgtype, [])
        for con, t, raw in reader.messages():
            out[con.topic][1].append(reader.deserialize(raw, con.msgtype))
    return out


def count_messages(path):
    """Messages in the file as it is now, or None while it cannot be read (mid-write)."""
    try:
        with open(path, 'rb') as f:
            return make_reader(f).get_summary().statistics.message_count
    except Exception:  # noqa: BLE001 - polling a file another process is writing
        return None


def topic_count(path, topic):
    """Messages on ``topic`` in the file as it is now (0 while it cannot be read)."""
    try:
        with open(path, 'rb') as f:
            summary = make_reader(f).get_summary()
        ids = [i for i, c in summary.channels.items() if c.topic == topic]
        return sum(summary.statistics.channel_message_counts.get(i, 0) for i in ids)
    except Exception:  # noqa: BLE001 - polling a file another process is writing
        return 0


def metadata(path):
    try:
        with open(path, 'rb') as f:
            return {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    except Exception:  # noqa: BLE001 - polling a file another process is writing
        return {}


def test_records_what_was_published(ros_env, tmp_path):
    out = tmp_path / 'run.mcap'
    n = 150
    rec_args = node_args(
        RECORDER,
        f'output:={out}',
        f'scene:={PAPER}',
        'param_nodes:=[test_publisher]',
        'flush_interval:=0.2',
    )
    go = tmp_path / 'go'
    pub_args = ('pub', '--count', n, '--rate', 300, '--wrench', '--linger', 30.0)
    with (
        start_process(rec_args, ros_env, tmp_path, 'recorder') as rec,
        start_process(
            helper_args(*pub_args, '--wait-sub', 60, '--go-file', go), ros_env, tmp_path, 'pub'
        ) as pub,
    ):
        # the publisher's writers matching says nothing of the recorder's readers (matching
        # is not symmetric in time): it starts once the recorder's log says both matched
        assert wait_for(
            lambda: all(
                recorder_matched(rec.stderr, t) for t in ('/joint_states', '/contact_wrench')
            ),
            60,
        ), rec.stderr
        go.touch()
        assert wait_for(lambda: any(e.get('event') == 'done' for e in pub.lines()), 30), (
            pub.stderr + rec.stderr
        )
        assert [e for e in pub.lines() if e.get('event') == 'matched'][0]['subs'] >= 1
        # everything published has reached a flushed file before the recorder is stopped;
        # with the scene, the file also holds the derived description, static frames and,
        # for each 10 ms of stamps (0 ... 140 ms), /tf and /impact_markers (and, once the
        # recorder stops, at the last stamp)
        n_tf = 15
        # (and, once a second, the recorder's own status on /diagnostics)
        assert wait_for(
            lambda: (
                (count_messages(out) or 0) - topic_count(out, '/diagnostics')
                == 2 * n + 2 + 2 * n_tf
            ),
            10,
        ), rec.stderr
        # the publisher's parameters are asked once its services are discovered
        assert wait_for(lambda: 'parameters/test_publisher/start' in metadata(out), 20)
        pub.stop()
        rec.stop()
        assert rec.popen.returncode == 0, rec.stderr

    got = read(out)
    # the recorder's own status (what it lost: nothing) is recorded with the rest
    status = got.pop('/diagnostics', (None, []))[1]
    assert {s.name for msg in status for s in msg.status} <= {contract.RECORDER_STATUS}
    assert all(s.message == 'recording, nothing lost' for msg in status for s in msg.status)
    assert {t: (ty, len(m)) for t, (ty, m) in got.items()} == {
        '/joint_states': ('sensor_msgs/msg/JointState', n),
        '/contact_wrench': ('geometry_msgs/msg/WrenchStamped', n),
        '/robot_description': ('std_msgs/msg/String', 1),
        '/tf_static': ('tf2_msgs/msg/TFMessage', 1),
        '/tf': ('tf2_msgs/msg/TFMessage', n_tf + 1),
        '/impact_markers': ('visualization_msgs/msg/MarkerArray', n_tf + 1),
        '/impact_table': ('std_msgs/msg/String', 0),  # a table only at impacts: none here
    }
    last = got['/tf'][1].pop()  # the final pose, joint state 149
    assert last.transforms[0].header.stamp.nanosec == 149 * 10**6
    for k, tf in enumerate(got['/tf'][1]):  # joint state 10 k: q1 = 10 k ms, q2 - q1 = -q1
        link1, link2 = tf.transforms
        assert (link1.header.stamp.sec, link1.header.stamp.nanosec) == (0, k * 10**7)
        # REP 103: the joints turn about -y (the model's z axis in the z-up world)
        for link, angle in ((link1, k * 1e-2), (link2, -k * 1e-2)):
            r = link.transform.rotation
            assert r.x == r.z == 0.0
            assert -2 * math.atan2(r.y, r.w) == pytest.approx(angle, abs=1e-12)
        assert link2.transform.translation.x == 1.0  # at the end of link 1 (L1 = 1 m)
    # the force arrow comes from impact reports (exact contact point), none were published:
    # sampled wrenches alone draw no arrow
    assert not any(m.ns == 'contact_force' for ma in got['/impact_markers'][1] for m in ma.markers)
    for i, m in enumerate(got['/joint_states'][1]):
        assert list(m.name) == ['joint1', 'joint2']
        assert list(m.position) == [i * 1e-3, -i * 1e-3]
        assert list(m.velocity) == [float(i), 0.5] and list(m.effort) == [0.25, -0.25]
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (i // 1000, (i % 1000) * 10**6)
    for i, m in enumerate(got['/contact_wrench'][1]):
        assert (m.wrench.force.x, m.wrench.force.y) == (float(i), 2.0 * i)

    with open(out, 'rb') as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for c in summary.channels.values():
            qos = yaml.safe_load(c.metadata['offered_qos_profiles'])
            assert qos and qos[0]['reliability'] == 'reliable'
            assert {'deadline', 'lifespan', 'liveliness_lease_duration'} <= set(qos[0])
        messages = [
            m for _, c, m in reader.iter_messages(log_time_order=True) if c.topic == '/joint_states'
        ]
        # log time = the joint state's own stamp (simulated time: one clock in the file),
        # publish time = send time (wall clock)
        from impact_arm.io.wire import header_stamp_ns

        assert all(m.log_time == header_stamp_ns(m.data) for m in messages)
        batches = [e for e in pub.lines() if e.get('event') == 'sent']
        for e in batches:  # message n-1 was sent before the publisher printed its batch line
            assert messages[e['n'] - 1].publish_time <= e['t']
        assert messages[0].publish_time > batches[0]['t'] - 10**9
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert meta['impact_arm']['version'] and meta['impact_arm']['node'] == 'recorder'
    with open(PAPER, 'rb') as f:
        scene_text = f.read()
    assert attachments['paper.yaml'] == scene_text
    assert meta['scene']['yaml'].encode() == scene_text
    own = {k: json.loads(v) for k, v in meta['parameters/recorder'].items()}
    assert own['output'] == str(out) and own['flush_interval'] == 0.2
    assert 'use_sim_time' in meta['parameters/test_publisher/start']


def test_sigkill_leaves_a_readable_file(ros_env, tmp_path):
    out = tmp_path / 'killed.mcap'
    rec_args = node_args(RECORDER, f'output:={out}', 'flush_interval:=0.2', 'param_nodes:=[""]')
    go = tmp_path / 'go'
    with (
        start_process(rec_args, ros_env, tmp_path, 'recorder') as rec,
        start_process(
            helper_args('pub', '--count', 3000, '--rate', 200, '--wait-sub', 30, '--go-file', go),
            ros_env,
            tmp_path,
            'pub',
        ) as pub,
    ):
        # the recorder's reader has matched the publisher: nothing published from now on is
        # dropped at the start (the file must hold a prefix of what was published)
        # (the line may name other topics matched in the same round: /diagnostics too)
        assert wait_for(lambda: recorder_matched(rec.stderr, '/joint_states'), 30), rec.stderr
        go.touch()
        seen = wait_for(lambda: (count_messages(out) or 0) >= 60 and count_messages(out), 30)
        assert seen, rec.stderr + pub.stderr
        rec.signal(signal.SIGKILL)
        rec.wait(10)
        assert rec.popen.returncode == -signal.SIGKILL
        assert pub.alive()  # the recorder died mid-run
    got = read(out)['/joint_states'][1]
    assert len(got) >= seen
    # a prefix of what was published, in order, nothing missing
    assert [m.velocity[0] for m in got] == [float(i) for i in range(len(got))]
    with open(out, 'rb') as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == len(got)


def test_unwritable_output_is_a_clear_error(ros_env, tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('x')
    with start_process(
        node_args(RECORDER, f'output:={blocker}/run.mcap'), ros_env, tmp_path, 'recorder'
    ) as rec:
        code = rec.wait(30)
    assert code != 0
    assert 'output' in rec.stderr and str(blocker) in rec.stderr
    assert 'Traceback' not in rec.stderr


def test_bad_parameter_names_the_parameter(ros_env, tmp_path):
    with start_process(
        node_args(RECORDER, f'output:={tmp_path}/x.mcap', 'flush_interval:=0.0'),
        ros_env,
        tmp_path,
        'recorder',
    ) as rec:
        code = rec.wait(30)
    assert code == 2 and 'flush_interval' in rec.stderr and '> 0' in rec.stderr
    time.sleep(0)  # nothing left running: start_process ends it by PID


def test_impact_reports_are_read_as_dds_sends_them():
    """The recorder draws each impact from the report's CDR: rclpy's bytes, with or without
    the wire's padding to 4 bytes, give the text back; garbage is refused with an error the
    node catches (SerdeError), never drawn."""
    from rclpy.serialization import serialize_message
    from rosbags.serde import SerdeError
    from std_msgs.msg import String

    from impact_arm.nodes.recorder import _string_reader

    read = _string_reader()
    for text in ('', 'ab', json.dumps({'q_contact_deg': [30.0, -12.5]})):
        raw = serialize_message(String(data=text))
        assert read(raw).data == text
        assert read(raw + bytes(-len(raw) % 4)).data == text
    header = b'\x00\x01\x00\x00'
    for garbage in (b'', header + b'\xff\xff\xff\x7fab', header + b'\x02\0\0\0\xff\0'):
        with pytest.raises(SerdeError):
            read(garbage)


def test_an_impact_report_nothing_needs_read_is_stored_unread():
    """log_time reception and no scene: neither the log time nor a 3D view needs a report's
    content, so the recorder builds no reader for it and stores each report as it came,
    without reading it (reading it then raised TypeError and ended the recording)."""
    from types import SimpleNamespace

    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from impact_arm.nodes.recorder import Recorder

    no_reader = SimpleNamespace(_read_string=None)
    raw = serialize_message(String(data=json.dumps({'t_contact': 0.1, 'duration': 1e-4})))
    assert Recorder._report(no_reader, raw) is None


def test_says_recording_once_every_topic_has_a_publisher(ros_env, tmp_path):
    """A subscription is not a matched reader. The recorder names the topics
    without a publisher after its grace period, logs each topic as its reader matches one,
    and says "recording" only once all have: then nothing published is lost."""
    from impact_arm.nodes.recorder import MATCHED_LINE

    out = tmp_path / 'matched.mcap'
    n = 100
    rec_args = node_args(
        RECORDER, f'output:={out}', 'topics:=[/joint_states,/contact_wrench]', 'flush_interval:=0.2'
    )
    with start_process(rec_args, ros_env, tmp_path, 'recorder') as rec:
        assert wait_for(
            lambda: 'no publisher yet on /contact_wrench /joint_states' in rec.stderr, 20
        ), rec.stderr
        assert not [
            line
            for line in rec.stderr.splitlines()
            if ']: recording' in line and 'no publisher yet' not in line
        ], rec.stderr
        with start_process(
            helper_args('pub', '--count', n, '--rate', 200, '--wrench'), ros_env, tmp_path, 'pub'
        ) as pub:
            assert wait_for(lambda: 'every topic has a publisher' in rec.stderr, 20), (
                rec.stderr + pub.stderr
            )
            assert wait_for(lambda: count_messages(out) == 2 * n, 10), rec.stderr
        rec.stop()
        assert rec.popen.returncode == 0, rec.stderr
    lines = rec.stderr.splitlines()
    said = next(i for i, line in enumerate(lines) if 'every topic has a publisher' in line)
    matched = {
        t
        for line in lines[:said]
        if MATCHED_LINE in line
        for t in line.partition(MATCHED_LINE)[2].split()
    }
    assert matched == {'/joint_states', '/contact_wrench'}, lines


def test_progress_waits_for_every_per_period_topic(probe, ros_env, tmp_path):
    """/recorder/progress says how far every per-period topic with a publisher has been
    written: not while one of them has nothing written yet, then the older of the newest
    stamps (what `impact-arm run` and a lockstep simulator rely on to lose no period)."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    out = tmp_path / 'progress.mcap'
    rec_args = node_args(
        RECORDER, f'output:={out}', 'topics:=[/joint_states,/contact_wrench]', 'flush_interval:=0.1'
    )
    progress = []
    with probe.lock:
        sub = probe.node.create_subscription(
            Time,
            contract.RECORDER_PROGRESS,
            lambda m: progress.append(m.sec + 1e-9 * m.nanosec),
            contract.PROGRESS_QOS.to_rclpy(),
        )
    states = probe.publisher(JointState, contract.JOINT_STATES)
    wrenches = probe.publisher(WrenchStamped, contract.CONTACT_WRENCH)

    def state(sec):
        msg = JointState(name=['a'], position=[0.0])
        msg.header.stamp.sec = sec
        return msg

    def wrench(sec):
        msg = WrenchStamped()
        msg.header.stamp.sec = sec
        return msg

    def publishing(publish, until, timeout=20.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            publish()
            if until():
                return True
            time.sleep(0.05)
        return False

    try:
        with start_process(rec_args, ros_env, tmp_path, 'recorder') as rec:
            assert wait_for(lambda: 'every topic has a publisher' in rec.stderr, 20), rec.stderr
            # joint states written, the wrench's publisher silent: no progress
            assert publishing(
                lambda: states.publish(state(3)),
                lambda: topic_count(out, contract.JOINT_STATES) >= 5,
            ), rec.stderr
            time.sleep(0.5)
            assert progress == [], progress
            assert publishing(lambda: wrenches.publish(wrench(2)), lambda: progress), rec.stderr
            assert wait_for(lambda: progress[-1] == 2.0, 5), progress
            assert publishing(
                lambda: wrenches.publish(wrench(5)), lambda: topic_count(out, '/contact_wrench') > 5
            ), rec.stderr
            time.sleep(0.3)
            assert progress[-1] == 3.0, progress  # the joint states' newest
            rec.stop()
            assert rec.popen.returncode == 0, rec.stderr
    finally:
        # nothing of this test stays in the module's graph for the next one
        with probe.lock:
            probe.node.destroy_subscription(sub)
            probe.node.destroy_publisher(states)
            probe.node.destroy_publisher(wrenches)


def test_simulator_exit_waits_for_a_lagging_recorder(ros_env, tmp_path):
    """The end of a run: the simulator exits right after the last impact report, while a
    recorder on a loaded machine may not have taken the last samples yet (stopped here with
    SIGSTOP). The simulator waits for its readers' acknowledgements, so a recorder that
    resumes within that wait still gets every report."""
    out = tmp_path / 'lag.mcap'
    rec_args = node_args(RECORDER, f'output:={out}', 'topics:=[/impact_report,/joint_states]')
    sim_args = simulator('mode:=lockstep', 'rate_factor:=0.0')
    ctl_args = controller('command_readers:=1')
    with (
        start_process(rec_args, ros_env, tmp_path, 'recorder') as rec,
        start_process(sim_args, ros_env, tmp_path, 'sim') as sim,
    ):
        assert wait_for(lambda: 'every topic has a publisher' in rec.stderr, 60), (
            rec.stderr + sim.stderr
        )
        with start_process(ctl_args, ros_env, tmp_path, 'ctl') as ctl:
            # the recorder stops taking anything (and acknowledging) while the run goes on:
            # once a report is recorded (not after a fixed 3 s, which a loaded machine can
            # spend before the arm first strikes), then for 2 s of impacts reported meanwhile
            assert wait_for(lambda: topic_count(out, '/impact_report'), 120), rec.stderr
            rec.signal(signal.SIGSTOP)
            time.sleep(2.0)
            ctl.stop()
            sim.signal(signal.SIGINT)
            # resumed at once (was 0.5 s; the test failed 2 of 4 runs under load): the
            # simulator's ACK_WAIT is for the recorder to catch up, not for this test's sleeps,
            # which load stretches. A simulator that exits without waiting is gone still sooner
            time.sleep(0.1)
            rec.signal(signal.SIGCONT)
            assert sim.wait(10) == 0, sim.stderr
        time.sleep(0.5)
        rec.stop()
        assert rec.popen.returncode == 0, rec.stderr
    impacts = int(re.findall(r'(\d+) impacts', sim.stderr)[-1])
    assert impacts >= 1, sim.stderr
    recorded = len(read(out).get('/impact_report', (None, []))[1])
    # the simulator's log says whether its ack wait ran out (a warning per topic)
    assert recorded == impacts, (recorded, impacts, sim.stderr[-800:])
