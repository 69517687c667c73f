"""The arm in 3D from a recording alone: /robot_description, /tf_static, /tf and
/impact_markers in ``simulate --mcap`` files, read back with rosbags."""
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from impact_arm.core.model import ArmModel
from impact_arm.core.simulate import run
from impact_arm.contract import to_absolute
from impact_arm.io.offline_mcap import OfflineRecorder
from impact_arm.io.urdf import robot_description
from scenes import scene_from

TF_RATE = 100.0


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp('visuals') / 'run.mcap'
    scene = scene_from(cycles=2)
    rec = OfflineRecorder(path, scene, tf_rate=TF_RATE)
    result = None
    try:
        result = run(scene, observer=rec)
    finally:
        rec.close(result)
    by_topic = {}
    with AnyReader([Path(path)]) as reader:
        for conn, t_ns, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(
                (t_ns, reader.deserialize(raw, conn.msgtype)))
    return path, scene, result, by_topic


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def compose(chain):
    """world -> ... pose (x, y, yaw) composing planar TransformStamped's in order."""
    x = y = yaw = 0.0
    for t in chain:
        tx, ty = t.transform.translation.x, t.transform.translation.y
        r = t.transform.rotation
        assert r.x == r.y == 0.0   # planar: rotations about z only
        x, y = x + math.cos(yaw) * tx - math.sin(yaw) * ty, y + math.sin(yaw) * tx + \
            math.cos(yaw) * ty
        yaw += 2 * math.atan2(r.z, r.w)
    return x, y


def test_tf_composes_to_the_model_tip_at_the_joint_state_stamps(recording):
    _, scene, result, by_topic = recording
    model = ArmModel(scene)
    states = {stamp_ns(m.header): m for _, m in by_topic['/joint_states']}
    (_, static), = by_topic['/tf_static']
    tip = next(t for t in static.transforms if t.child_frame_id == 'tip')
    tfs = by_topic['/tf']
    duration = result.samples[-1].t
    assert abs(len(tfs) - (math.floor(duration * TF_RATE) + 1)) <= 1
    for _, msg in tfs:
        stamp = stamp_ns(msg.transforms[0].header)
        js = states[stamp]           # every /tf stamp is a joint-state stamp
        frames = {t.child_frame_id: t for t in msg.transforms}
        chain, parent = [], 'world'
        for k in range(scene.n_links):   # walk the tree from world down to the last link
            t = frames[f'link{k + 1}']
            assert t.header.frame_id == parent and stamp_ns(t.header) == stamp
            chain.append(t)
            parent = t.child_frame_id
        assert tip.header.frame_id == parent
        q = to_absolute(js.position)
        x_b, y_b = model.tip(np.array(q), np.zeros(len(q)))[:2]
        assert compose(chain + [tip]) == pytest.approx((x_b, y_b), abs=1e-9)
    stamps = [stamp_ns(m.transforms[0].header) for _, m in tfs]
    # paced by tf_rate; the file ends with the final pose
    assert np.diff(stamps[:-1]) == pytest.approx(1e9 / TF_RATE, abs=1e6)
    assert stamps[-1] == max(states) and 0 < stamps[-1] - stamps[-2] <= 1e9 / TF_RATE


def test_description_and_static_frames_are_stored_once(recording):
    _, scene, _, by_topic = recording
    (_, description), = by_topic['/robot_description']
    assert description.data == robot_description(scene)
    (_, static), = by_topic['/tf_static']
    assert {t.child_frame_id for t in static.transforms} == {'tip', 'surface1'}


def test_markers_show_the_surface_the_contact_force_and_every_impact(recording):
    _, scene, result, by_topic = recording
    markers = [m for _, m in by_topic['/impact_markers']]
    assert len(markers) == len(by_topic['/tf'])
    arrows = [next(m for m in ma.markers if m.ns == 'contact_force') for ma in markers]
    shown = [a for a in arrows if a.action == a.ADD]
    # at least one arrow per impact (contact shorter than the marker period included)
    assert len(result.impacts) == 2 and len(shown) >= 2
    for a in shown:   # the arrow starts at the tip, near the surface, pointing up
        assert a.points[0].y == pytest.approx(scene.surfaces[0].height, abs=5e-3)
        assert a.points[1].y > a.points[0].y
    last = markers[-1].markers
    points = [m for m in last if m.ns == 'impact_points']
    assert len(points) == len(result.impacts)
    for m in points:
        assert m.pose.position.y == pytest.approx(scene.surfaces[0].height, abs=1e-9)
    assert sum(m.ns == 'surface' for m in last) == len(scene.surfaces)


def test_stored_definitions_equal_the_official_ones(recording):
    """The TFMessage definition is written without the tf2_msgs package; both it and the
    MarkerArray's must parse to the same types as rosbags' own Kilted store."""
    path = recording[0]
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    official = get_typestore(Stores.ROS2_KILTED)
    for name in ('tf2_msgs/msg/TFMessage', 'visualization_msgs/msg/MarkerArray'):
        schema = next(s for s in summary.schemas.values() if s.name == name)
        assert schema.encoding == 'ros2msg'
        types = get_types_from_msg(schema.data.decode(), name)
        assert name in types and len(types) > 3
        for type_name, fields in types.items():
            assert fields == official.fielddefs[type_name], type_name


def test_marker_bytes_built_from_a_kept_prefix_equal_whole_message_serialization():
    """The markers' CDR is a cached prefix (surfaces, impact points) plus the arrow: it must be
    byte for byte what serializing the whole MarkerArray gives, whatever the prefix length
    does to the arrow's alignment."""
    from visualization_msgs.msg import Marker, MarkerArray

    from impact_arm.io.msgdefs import append_cdr, sequence_cdr_prefix, serialize_cdr
    for n in range(5):
        items = [Marker(ns='x' * k, id=k, text='t' * (3 * k)) for k in range(n)]
        last = Marker(ns='arrow', frame_locked=True)
        last.points = [last.pose.position] * (n % 3)
        data = append_cdr(sequence_cdr_prefix(items, n + 1), last)
        assert data == serialize_cdr(MarkerArray(markers=items + [last]))
