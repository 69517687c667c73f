"""``simulate --mcap``: the offline recording holds exactly what the run computed, read back with
``rosbags`` and the ``mcap`` reader."""

import json
import math
import os
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from impact_arm import __version__
from impact_arm.contract import IMPACT_TRACE as TRACE_TOPIC
from impact_arm.contract import to_absolute, to_joint_space
from impact_arm.io.offline_mcap import OFFLINE_TOPICS as TOPICS
from impact_arm.io.offline_mcap import OfflineRecorder, sim_time_ns, trace_columns
from impact_arm.physics.scene import load_scene
from impact_arm.physics.simulate import run
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT


@pytest.fixture(scope='module')
def offline(tmp_path_factory):
    path = tmp_path_factory.mktemp('offline') / 'paper.mcap'
    scene = load_scene(os.path.join(ROOT, 'config', 'paper.yaml'))
    rec = OfflineRecorder(path, scene)
    result = None
    try:
        result = run(scene, observer=rec, trace=True)
    finally:
        rec.close(result)
    return path, scene, result


def test_topics_types_and_counts(offline):
    path, _, result = offline
    with AnyReader([Path(path)]) as reader:
        got = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
    n, k = len(result.samples), len(result.impacts)
    assert n > 1000 and k == 15
    n_tf = got['/tf'][1]
    # at the default tf_rate, and at each impact's three events
    assert n_tf - 3 * k == pytest.approx(result.samples[-1].t * 100, abs=1.5)
    assert got == {
        '/joint_states': (TOPICS['/joint_states'], n),
        '/contact_wrench': (TOPICS['/contact_wrench'], n),
        '/contact_force_peak': (TOPICS['/contact_force_peak'], n),
        '/impact_report': (TOPICS['/impact_report'], k),
        TRACE_TOPIC: (TOPICS[TRACE_TOPIC], k),
        '/robot_description': ('std_msgs/msg/String', 1),
        '/tf_static': ('tf2_msgs/msg/TFMessage', 1),
        '/tf': ('tf2_msgs/msg/TFMessage', n_tf),
        '/impact_markers': ('visualization_msgs/msg/MarkerArray', n_tf),
        '/impact_table': ('std_msgs/msg/String', k),
    }


def test_field_values_equal_what_the_run_computed(offline):
    path, scene, result = offline
    js, ws, peaks, reports, traces = [], [], [], [], []
    with AnyReader([Path(path)]) as reader:
        wanted = {
            '/joint_states': js,
            '/contact_wrench': ws,
            '/contact_force_peak': peaks,
            '/impact_report': reports,
            TRACE_TOPIC: traces,
        }
        for con, t, raw in reader.messages([c for c in reader.connections if c.topic in wanted]):
            wanted[con.topic].append((t, reader.deserialize(raw, con.msgtype)))
    for (t, m), s in zip(js, result.samples):
        assert t == sim_time_ns(s.t) == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        assert list(m.name) == ['joint1', 'joint2']
        assert list(m.position) == to_joint_space(s.q)
        assert list(m.velocity) == to_joint_space(s.qd)
        assert list(m.effort) == list(s.tau)
        assert to_absolute(m.position) == pytest.approx(list(s.q), abs=1e-15)
    assert len(peaks) == len(ws) == len(result.samples)
    for (t, m), s in zip(peaks, result.samples):
        assert t == sim_time_ns(s.t) and m.header.frame_id == 'surface1'
        assert (m.wrench.force.x, m.wrench.force.y, m.wrench.force.z) == (0.0, s.force_peak, 0.0)
    assert max(m.wrench.force.y for _, m in peaks) == max(r.F_max for r in result.impacts)
    for (t, m), s in zip(ws, result.samples):
        assert (m.wrench.force.x, m.wrench.force.y) == tuple(s.wrench)
        assert m.header.frame_id == 'surface1'  # the TF frame of the surface
    # each report is its record's JSON, as ``simulate --json`` writes the record
    assert [m.data for _, m in reports] == [json.dumps(i.to_dict()) for i in result.impacts]
    columns = trace_columns(scene.n_links)
    for (t, m), rows, rep in zip(traces, result.traces, reports):
        dims = m.layout.dim
        assert dims[0].label == 'row' and dims[1].label == ','.join(columns)
        assert dims[0].size == len(rows) > 10 and dims[1].size == len(columns)
        assert list(m.data) == [float(v) for row in rows for v in row]
        assert t == rep[0]  # each trace is logged with its report


def test_metadata_scene_and_summary_indexes(offline):
    path, scene, result = offline
    with open(path, 'rb') as f:
        reader = make_reader(f)
        assert reader.get_header().profile == 'ros2'
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        summary = reader.get_summary()
    with open(os.path.join(ROOT, 'config', 'paper.yaml'), 'rb') as f:
        text = f.read()
    assert attachments['paper.yaml'] == text
    assert meta['scene']['yaml'].encode() == text
    info = meta['impact_arm']
    assert info['version'] == __version__ and info['mode'] == 'offline'
    assert info['control'] == 'continuous' and float(info['publish_rate_hz']) == 1000.0
    assert info['trace_columns'] == ','.join(trace_columns(2))
    run_summary = json.loads(meta['run']['summary'])
    assert run_summary['impacts'] == 15 and meta['run']['error'] == ''
    assert math.isclose(run_summary['t_end'], result.t_end)
    bag = yaml.safe_load(meta['rosbag2']['serialized_metadata'])
    n_tf = summary.statistics.channel_message_counts[
        next(c.id for c in summary.channels.values() if c.topic == '/tf')
    ]
    assert (
        bag['message_count']
        == summary.statistics.message_count
        == 3 * len(result.samples) + 3 * 15 + 2 + 2 * n_tf
    )  # states, wrenches, peaks; reports, traces, tables; description, static; tf, markers
    assert summary.chunk_indexes and all(c.message_index_offsets for c in summary.chunk_indexes)


def test_cli_writes_the_file_and_refuses_an_unwritable_path(tmp_path):
    import subprocess
    import sys

    blocker = tmp_path / 'file'
    blocker.write_text('x')
    proc = subprocess.run(
        [
            sys.executable,
            '-m',
            'impact_arm.tools.cli',
            'simulate',
            '--mcap',
            str(blocker / 'out.mcap'),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert proc.returncode == 2
    # refused before the run, naming the parent that is not a directory
    assert 'is not a directory' in proc.stderr and 'Traceback' not in proc.stderr
