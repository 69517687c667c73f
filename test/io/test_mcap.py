"""MCAP writer, message definitions and CDR: every file is read back with the independent
``rosbags`` library (which builds its types from the definitions stored in the file) and with
the ``mcap`` library's reader."""

import errno
import json
import os
import shutil
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from impact_arm.io import mcap_ros2
from impact_arm.contract import TOPICS as CONTRACT_TOPICS
from impact_arm.contract import TopicQos
from impact_arm.io.mcap_ros2 import RecordingError, Ros2McapWriter, parse_qos_yaml
from impact_arm.io.msgdefs import message_class, message_definition, serialize_cdr

TYPES = sorted({t for t, _ in CONTRACT_TOPICS.values()} | {'std_msgs/msg/Float64MultiArray'})
QOS_KEYS = {
    'history',
    'depth',
    'reliability',
    'durability',
    'deadline',
    'lifespan',
    'liveliness',
    'liveliness_lease_duration',
    'avoid_ros_namespace_conventions',
}


def rosbags_read(path):
    """{topic: (type, [message objects])} via rosbags, types from the file's own schemas."""
    out = {}
    with AnyReader([Path(path)]) as reader:
        for c in reader.connections:
            out[c.topic] = (c.msgtype, [])
        for con, _, raw in reader.messages():
            out[con.topic][1].append(reader.deserialize(raw, con.msgtype))
    return out


# ------------------------------------------------------------------------- definitions
@pytest.mark.parametrize('type_name', TYPES)
def test_definition_text_matches_the_standard_type(type_name):
    text = message_definition(type_name)
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if set(line) == {'='}:
            assert len(line) == 80
            pkg, _, name = lines[i + 1].partition('MSG: ')[2].partition('/')
            assert lines[i + 1].startswith('MSG: ') and pkg and name and '/' not in name
    parsed = get_types_from_msg(text, type_name)
    reference = get_typestore(Stores.ROS2_KILTED).fielddefs
    assert parsed[type_name] == reference[type_name]
    for dep, fields in parsed.items():  # every nested type, once, as ROS defines it
        assert fields == reference[dep], dep
    # each dependency appears exactly once
    deps = [ln for ln in lines if ln.startswith('MSG: ')]
    assert len(deps) == len(set(deps)) == len(parsed) - 1


def _samples():
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import WrenchStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

    js = JointState(
        name=['joint1', 'joint2'], position=[0.5, -1.25], velocity=[3.0, 1e-9], effort=[12.5, -7.0]
    )
    js.header.stamp.sec, js.header.stamp.nanosec = 3, 123456789
    ws = WrenchStamped()
    ws.header.frame_id = 'surface1'
    ws.wrench.force.x, ws.wrench.force.y, ws.wrench.torque.z = -1.5, 27790.25, 0.125
    diag = DiagnosticArray(
        status=[
            DiagnosticStatus(
                level=DiagnosticStatus.WARN,
                name='simulator',
                message='overrun',
                hardware_id='sim',
                values=[KeyValue(key='rate', value='999.5')],
            )
        ]
    )
    clock = Clock()
    clock.clock.sec, clock.clock.nanosec = 7, 5
    arr = Float64MultiArray(data=[1.0, 2.5, -3.0, 4.0])
    arr.layout.dim = [
        MultiArrayDimension(label='row', size=2, stride=4),
        MultiArrayDimension(label='a,b', size=2, stride=2),
    ]
    return {
        '/joint_states': js,
        '/contact_wrench': ws,
        '/diagnostics': diag,
        '/clock': clock,
        '/impact_report': String(data=json.dumps({'index': 1, 'F_max': 2.5e4})),
        '/effort_controller/commands': Float64MultiArray(data=[1.5, -0.25]),
        '/impact_trace': arr,
    }


def _same(ours, theirs):
    """Field-by-field equality of an rclpy message and a rosbags message."""
    for name in ours.get_fields_and_field_types():
        a, b = getattr(ours, name), getattr(theirs, name)
        if hasattr(a, 'get_fields_and_field_types'):
            _same(a, b)
        elif isinstance(a, list) and a and hasattr(a[0], 'get_fields_and_field_types'):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                _same(x, y)
        elif isinstance(a, bytes):  # byte fields: rclpy gives bytes, rosbags an int
            assert a == bytes([b]), name
        elif isinstance(a, (str, int, float)):
            assert a == b, name
        else:
            assert list(a) == list(b), name


def test_cdr_bytes_are_what_rosbags_serializes():
    store = get_typestore(Stores.ROS2_KILTED)
    for topic, msg in _samples().items():
        data = serialize_cdr(msg)
        type_name = mcap_ros2.type_name_of(msg)
        theirs = store.deserialize_cdr(data, type_name)
        _same(msg, theirs)
        assert store.serialize_cdr(theirs, type_name) == data, topic


# ------------------------------------------------------------------------------ writer
def _write_all(path, **kw):
    samples = _samples()
    with Ros2McapWriter(path, **kw) as w:
        w.add_topic(
            '/impact_trace',
            'std_msgs/msg/Float64MultiArray',
            TopicQos(durability='transient_local', depth=100),
        )
        for k in range(5):
            for j, (topic, msg) in enumerate(samples.items()):
                # log times deliberately out of order between topics
                t = 1_000_000_000 + k * 10_000_000 + (len(samples) - j) * 1000
                w.write_message(topic, msg, t, t - 500)
        w.add_metadata('scene', {'yaml': 'name: x\n'})
        w.add_attachment('x.yaml', 'name: x\n', 'application/yaml')
    return samples


def test_writer_round_trip_rosbags_and_mcap(tmp_path):
    path = tmp_path / 'all.mcap'
    samples = _write_all(path, chunk_size=600)
    got = rosbags_read(path)
    assert set(got) == set(samples)
    for topic, msg in samples.items():
        type_name, msgs = got[topic]
        assert type_name == mcap_ros2.type_name_of(msg)
        assert len(msgs) == 5
        for m in msgs:
            _same(msg, m)

    with open(path, 'rb') as f:
        reader = make_reader(f)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {s.name for s in summary.schemas.values()} == {
            mcap_ros2.type_name_of(m) for m in samples.values()
        }
        assert all(
            s.encoding == 'ros2msg' and s.data.decode() == message_definition(s.name)
            for s in summary.schemas.values()
        )
        assert all(c.message_encoding == 'cdr' for c in summary.channels.values())
        for c in summary.channels.values():
            profiles = yaml.safe_load(c.metadata['offered_qos_profiles'])
            assert len(profiles) == 1 and set(profiles[0]) == QOS_KEYS
            for key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
                assert set(profiles[0][key]) == {'sec', 'nsec'}
            expected = CONTRACT_TOPICS.get(
                c.topic, (None, TopicQos(durability='transient_local', depth=100))
            )[1]
            assert parse_qos_yaml(c.metadata['offered_qos_profiles']) == [expected]
            assert c.metadata['topic_type_hash'].startswith('RIHS01_')
        assert summary.statistics.message_count == 5 * len(samples)
        assert set(summary.statistics.channel_message_counts.values()) == {5}
        assert len(summary.chunk_indexes) > 1  # several chunks, each with message indexes
        for ci in summary.chunk_indexes:
            assert ci.message_index_offsets and ci.compression == 'zstd'
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
        assert times == sorted(times) and len(times) == 5 * len(samples)
        assert all(m.publish_time == m.log_time - 500 for _, _, m in reader.iter_messages())
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        bag = yaml.safe_load(meta['rosbag2']['serialized_metadata'])
        assert bag['version'] == 9 and bag['storage_identifier'] == 'mcap'
        assert bag['message_count'] == 5 * len(samples)
        counts = {
            t['topic_metadata']['name']: t['message_count']
            for t in bag['topics_with_message_count']
        }
        assert counts == {t: 5 for t in samples}
        for t in bag['topics_with_message_count']:
            assert set(t['topic_metadata']['offered_qos_profiles'][0]) == QOS_KEYS
        assert meta['scene'] == {'yaml': 'name: x\n'}
        att = {a.name: a for a in reader.iter_attachments()}
        assert att['x.yaml'].data == b'name: x\n' and att['x.yaml'].media_type == 'application/yaml'


def test_uncompressed_and_lz4_files_read_back(tmp_path):
    for compression in ('', 'lz4'):
        path = tmp_path / f'c{compression}.mcap'
        samples = _write_all(path, compression=compression)
        assert {k: len(v[1]) for k, v in rosbags_read(path).items()} == {t: 5 for t in samples}


def test_file_is_complete_after_every_flush(tmp_path):
    """What a SIGKILL leaves: a copy taken with unflushed data pending holds what was
    flushed, and both readers open it."""
    from std_msgs.msg import String

    path = tmp_path / 'live.mcap'
    w = Ros2McapWriter(path, flush_interval=None, chunk_size=1 << 30)
    empty = tmp_path / 'empty.mcap'
    shutil.copy(path, empty)
    assert rosbags_read(empty) == {}
    w.add_topic('/impact_report', 'std_msgs/msg/String')
    for i in range(100):
        w.write_message('/impact_report', String(data=str(i)), i * 1000)
    w.flush()
    for i in range(100, 150):
        w.write_message('/impact_report', String(data=str(i)), i * 1000)
    snapshot = tmp_path / 'snapshot.mcap'
    shutil.copy(path, snapshot)
    assert [m.data for m in rosbags_read(snapshot)['/impact_report'][1]] == [
        str(i) for i in range(100)
    ]
    with open(snapshot, 'rb') as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == 100
    w.close()
    assert len(rosbags_read(path)['/impact_report'][1]) == 150


def test_unwritable_path_is_a_clear_error(tmp_path):
    blocker = tmp_path / 'not_a_dir'
    blocker.write_text('x')
    with pytest.raises(RecordingError, match='not_a_dir'):
        Ros2McapWriter(blocker / 'out.mcap')


def test_disk_full_stops_writing_and_keeps_what_was_flushed(tmp_path, monkeypatch):
    from std_msgs.msg import String

    path = tmp_path / 'full.mcap'
    w = Ros2McapWriter(path, flush_interval=None)
    w.add_topic('/impact_report', 'std_msgs/msg/String')
    for i in range(10):
        w.write_message('/impact_report', String(data=str(i)), i)
    w.flush()
    real = os.pwrite
    calls = []

    def full(fd, data, offset):
        calls.append(len(data))
        if len(calls) == 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, offset)

    monkeypatch.setattr(mcap_ros2.os, 'pwrite', full)
    w.write_message('/impact_report', String(data='lost'), 11)
    with pytest.raises(RecordingError, match='No space left'):
        w.flush()
    with pytest.raises(RecordingError):
        w.write_message('/impact_report', String(data='after'), 12)
    with pytest.raises(RecordingError):
        w.close()
    monkeypatch.setattr(mcap_ros2.os, 'pwrite', real)
    assert [m.data for m in rosbags_read(path)['/impact_report'][1]] == [str(i) for i in range(10)]


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(ValueError, match='compression'):
        Ros2McapWriter(tmp_path / 'a.mcap', compression='gzip')
    with pytest.raises(ValueError, match='not installed'):
        message_class('no_such_pkg/msg/Nothing')
    with Ros2McapWriter(tmp_path / 'b.mcap') as w:
        with pytest.raises(ValueError, match='rosbag2'):
            w.add_metadata('rosbag2', {})
