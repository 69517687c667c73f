"""The arm in 3D from a recording alone: /robot_description, /tf_static, /tf and
/impact_markers in ``simulate --mcap`` files, read back with rosbags."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from impact_arm.physics.impact import impact_from_json
from impact_arm.physics.model import ArmModel
from impact_arm.physics.simulate import run
from impact_arm.contract import to_absolute
from impact_arm.io.offline_mcap import OfflineRecorder
from impact_arm.io.scene_visuals import ARROW_HOLD, force_colour
from impact_arm.io.urdf import robot_description
from scenes import scene_from
from tf_frames import rotation, stamp_ns, tip_in_world

TF_RATE = 100.0


@pytest.fixture(scope='module', params=[None, 0.0], ids=['sampled control', 'continuous'])
def recording(tmp_path_factory, request):
    """A recorded run; with continuous control the impact reports reach the recorder after
    later samples (the integrator's steps run on), so the writer must hold frames back."""
    path = tmp_path_factory.mktemp('visuals') / 'run.mcap'
    scene = scene_from(cycles=2)
    rec = OfflineRecorder(path, scene, tf_rate=TF_RATE)
    result = None
    try:
        result = run(scene, observer=rec, control_rate=request.param)
    finally:
        rec.close(result)
    by_topic = {}
    with open(path, 'rb') as f:  # written in time order (as stored)
        log_times = [m.log_time for _, _, m in make_reader(f).iter_messages(log_time_order=False)]
    assert log_times == sorted(log_times)
    with AnyReader([Path(path)]) as reader:
        for conn, t_ns, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(
                (t_ns, reader.deserialize(raw, conn.msgtype))
            )
    return path, scene, result, by_topic


def model_tip_in_world(model, q):
    """The model's tip B mapped into the REP 103 world: (x, 0, y)."""
    x_b, y_b = model.tip(np.array(q), np.zeros(len(q)))[:2]
    return np.array([x_b, 0.0, y_b])


def test_tf_composes_to_the_model_tip_at_the_joint_state_stamps(recording):
    _, scene, result, by_topic = recording
    model = ArmModel(scene)
    states = {stamp_ns(m.header): m for _, m in by_topic['/joint_states']}
    ((_, static),) = by_topic['/tf_static']
    tip = next(t for t in static.transforms if t.child_frame_id == 'tip')
    tfs = [m for _, m in by_topic['/tf'] if stamp_ns(m.transforms[0].header) in states]
    duration = result.samples[-1].t
    assert abs(len(tfs) - (math.floor(duration * TF_RATE) + 1)) <= 1
    for msg in tfs:
        stamp = stamp_ns(msg.transforms[0].header)
        js = states[stamp]  # a paced /tf stamp is a joint-state stamp
        frames = {t.child_frame_id: t for t in msg.transforms}
        parent = 'world'
        for k in range(scene.n_links):  # walk the tree from world down to the last link
            t = frames[f'link{k + 1}']
            assert t.header.frame_id == parent and stamp_ns(t.header) == stamp
            parent = t.child_frame_id
        assert tip.header.frame_id == parent
        q = to_absolute(js.position)
        assert tip_in_world(msg, tip) == pytest.approx(model_tip_in_world(model, q), abs=1e-9)
    stamps = [stamp_ns(m.transforms[0].header) for m in tfs]
    # paced by tf_rate; the file ends with the final pose
    assert np.diff(stamps[:-1]) == pytest.approx(1e9 / TF_RATE, abs=1e6)
    assert stamps[-1] == max(states) and 0 < stamps[-1] - stamps[-2] <= 1e9 / TF_RATE
    # besides them, three frames per impact (first contact, max compression, separation)
    assert len(by_topic['/tf']) == len(tfs) + 3 * len(result.impacts)


def test_every_impact_is_shown_with_the_tip_on_the_surface_and_the_arrow_at_it(recording):
    """For each impact: a /tf frame inside the contact interval whose tip is on the surface
    where the report says the contact was, and with it a force arrow starting at that tip
    that lives >= 0.3 s."""
    _, scene, result, by_topic = recording
    model = ArmModel(scene)
    ((_, static),) = by_topic['/tf_static']
    tip = next(t for t in static.transforms if t.child_frame_id == 'tip')
    markers = {
        stamp_ns(a.header): ma
        for _, ma in by_topic['/impact_markers']
        for a in ma.markers
        if a.ns == 'contact_force'
    }  # by the arrow's stamp
    reports = [impact_from_json(m.data) for _, m in by_topic['/impact_report']]
    assert len(reports) == len(result.impacts) == 2
    height = scene.surfaces[0].height
    for report in reports:
        t0 = round(report.t_contact * 1e9)
        t1 = round((report.t_contact + report.duration) * 1e9)
        inside = [
            m for _, m in by_topic['/tf'] if t0 - 1 <= stamp_ns(m.transforms[0].header) <= t1 + 1
        ]
        assert len(inside) == 3
        on_surface = [
            (stamp_ns(m.transforms[0].header), tip_in_world(m, tip))
            for m in inside
            if abs(tip_in_world(m, tip)[2] - height) <= 1e-6
        ]
        assert on_surface, 'no frame of the impact shows the tip on the surface'
        stamp, b = on_surface[0]
        q_contact = np.radians(report.q_contact_deg)
        assert b == pytest.approx(model_tip_in_world(model, q_contact), abs=1e-9)
        arrow = next(m for m in markers[stamp].markers if m.ns == 'contact_force')
        assert arrow.action == arrow.ADD and stamp_ns(arrow.header) == stamp
        assert arrow.header.frame_id == 'world'
        start, end = arrow.points
        assert np.array([start.x, start.y, start.z]) == pytest.approx(b, abs=1e-6)
        assert end.x == start.x and end.y == start.y and end.z > start.z  # along the normal
        assert arrow.lifetime.sec + arrow.lifetime.nanosec * 1e-9 >= 0.3
    # the arrow is never deleted: it goes when its lifetime ends
    assert not any(m.action != m.ADD for _, ma in by_topic['/impact_markers'] for m in ma.markers)


def test_every_frame_id_in_the_file_is_a_tf_frame(recording):
    _, scene, _, by_topic = recording
    tf_frames = {'world'}
    for topic in ('/tf', '/tf_static'):
        for _, msg in by_topic[topic]:
            tf_frames |= {t.child_frame_id for t in msg.transforms}
            tf_frames |= {t.header.frame_id for t in msg.transforms}
    used = set()
    for messages in by_topic.values():
        for _, msg in messages:
            for item in getattr(msg, 'markers', []) or getattr(msg, 'transforms', []) or [msg]:
                header = getattr(item, 'header', None)
                if header is not None and header.frame_id:
                    used.add(header.frame_id)
    assert 'surface1' in used  # /contact_wrench and the surface marker
    assert used <= tf_frames
    assert {w.header.frame_id for _, w in by_topic['/contact_wrench']} == {'surface1'}


def test_description_and_static_frames_are_stored_once(recording):
    _, scene, _, by_topic = recording
    ((_, description),) = by_topic['/robot_description']
    assert description.data == robot_description(scene)
    ((_, static),) = by_topic['/tf_static']
    assert {t.child_frame_id for t in static.transforms} == {'tip', 'surface1'}
    surface = next(t for t in static.transforms if t.child_frame_id == 'surface1')
    # z up (REP 103): the surface plane at z = height, its frame's y the normal (world +z)
    v = surface.transform.translation
    assert (v.x, v.y, v.z) == (0.0, 0.0, scene.surfaces[0].height)
    assert rotation(surface.transform.rotation) @ [0, 1, 0] == pytest.approx([0, 0, 1], abs=1e-15)


def test_markers_show_the_surface_the_contact_force_and_every_impact(recording):
    _, scene, result, by_topic = recording
    markers = [m for _, m in by_topic['/impact_markers']]
    assert len(markers) == len(by_topic['/tf'])
    arrows = [a for ma in markers for a in ma.markers if a.ns == 'contact_force']
    # each impact's three event frames, and the paced frames within ARROW_HOLD after it
    paced = {stamp_ns(m.header) for _, m in by_topic['/joint_states']} & {
        stamp_ns(m.transforms[0].header) for _, m in by_topic['/tf']
    }
    contacts = [i.t_contact for i in result.impacts]
    held = [t for t in paced if any(0 <= t * 1e-9 - c < ARROW_HOLD for c in contacts)]
    assert len(result.impacts) == 2 and len(held) > 30
    assert len(arrows) == 3 * len(result.impacts) + len(held)
    height = scene.surfaces[0].height
    for a in arrows:  # the arrow starts on the surface (z up) and points up
        assert a.points[0].z == pytest.approx(height, abs=1e-6)
        assert a.points[1].z > a.points[0].z
    last = markers[-1].markers
    points = [m for m in last if m.ns == 'impact_points']
    assert len(points) == len(result.impacts)
    reach = sum(scene.lengths)
    forces = [i.F_max for i in result.impacts]
    for m, force in zip(points, forces):
        # resting on the surface at the contact point: above the slab's top face, which
        # hid them from below (any zoom); apart from the tip and the arrow by colour
        assert m.pose.position.z - m.scale.z / 2 == pytest.approx(height, abs=1e-9)
        assert m.pose.position.y == 0.0
        # large enough to see in the shipped view (6.5 m away) at 1x: 6 % of the reach
        assert m.scale.x == m.scale.z == pytest.approx(0.06 * reach)
        assert (m.color.r, m.color.g, m.color.b, m.color.a) == pytest.approx(force_colour(force))
        assert arrows[0].color.r > 0.5 > arrows[0].color.b
    surfaces = [m for m in last if m.ns == 'surface']
    # opaque: a translucent slab is drawn after the opaque beads and over them
    assert all(m.color.a == 1.0 for m in surfaces)
    # the slab lies below the plane: its top face at the surface
    assert all(m.pose.position.y + m.scale.y / 2 == pytest.approx(0, abs=1e-12) for m in surfaces)
    assert sum(m.ns == 'surface' for m in last) == len(scene.surfaces)


def test_tf_channels_carry_the_official_type_hash(recording):
    """/tf and /tf_static are written without the tf2_msgs package: their channels must
    still carry TFMessage's RIHS01 hash, the one rosbags computes for its Kilted store."""
    with open(recording[0], 'rb') as f:
        summary = make_reader(f).get_summary()
    expected = get_typestore(Stores.ROS2_KILTED).hash_rihs01('tf2_msgs/msg/TFMessage')
    for channel in summary.channels.values():
        if channel.topic in ('/tf', '/tf_static'):
            assert channel.metadata['topic_type_hash'] == expected


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


class ListWriter:
    """An MCAP writer stand-in keeping (topic, CDR, log time)."""

    def __init__(self):
        self.written = []

    def add_topic(self, *args):
        pass

    def write(self, topic, data, log_time_ns, publish_time_ns):
        self.written.append((topic, data, log_time_ns))


def test_event_frames_of_a_report_come_after_its_state_on_the_recorders_clock():
    """As the recorder node feeds it: states with their log (receive) times and no wrench,
    then the report's text. The event frames are stamped at the events and logged at the
    stamps shifted as the latest state's log time is from its stamp."""
    from rosbags.typesys import Stores, get_typestore
    from impact_arm.io.scene_visuals import VisualsWriter, event_states

    store = get_typestore(Stores.ROS2_KILTED)
    scene = scene_from(cycles=1)
    result = run(scene, control_rate=1000.0)
    report = result.impacts[0]
    writer = ListWriter()
    visuals = VisualsWriter(writer, scene, TF_RATE)
    offset = 1_700_000_000 * 10**9  # wall-clock log times
    for s in result.samples:  # up to the first state after the separation
        t_ns = round(s.t * 1e9)
        visuals.state(t_ns, s.q, (0.0, 0.0), t_ns + offset + 123)
        if s.t > report.t_contact + report.duration:
            break
    before = len(writer.written)
    visuals.impact(json.dumps(report.to_dict()))  # the text of the report, as received
    events = writer.written[before:]
    assert [topic for topic, _, _ in events] == ['/impact_table'] + ['/tf', '/impact_markers'] * 3
    # the table: logged with the contact's frame, so a seek to the impact shows its row
    assert events.pop(0)[2] == events[0][2]
    stamps = [t for _, t, _ in event_states(report)]
    assert stamps[0] <= stamps[1] <= stamps[2] and stamps[0] >= report.t_contact * 1e9
    assert [log for _, _, log in events[::2]] == [t + offset + 123 for t in stamps]
    tf = store.deserialize_cdr(events[0][1], 'tf2_msgs/msg/TFMessage')
    assert [stamp_ns(t.header) for t in tf.transforms] == [stamps[0]] * scene.n_links
    # and a later paced frame within ARROW_HOLD still shows the arrow, with the time left
    t_later = stamps[0] + 100_000_000
    marker_bytes = visuals.visuals.markers(t_later)
    arrow = next(
        m
        for m in store.deserialize_cdr(marker_bytes, 'visualization_msgs/msg/MarkerArray').markers
        if m.ns == 'contact_force'
    )
    left = arrow.lifetime.sec * 10**9 + arrow.lifetime.nanosec
    assert left == stamps[0] + round(ARROW_HOLD * 1e9) - t_later
    after = store.deserialize_cdr(
        visuals.visuals.markers(stamps[0] + round(ARROW_HOLD * 1e9)),
        'visualization_msgs/msg/MarkerArray',
    )
    assert not any(m.ns == 'contact_force' for m in after.markers)  # its time is over


# a whole report of the article's two links, as /impact_report carries one (made-up numbers)
WHOLE_REPORT = {
    'index': 1,
    't_contact': 0.1,
    'q_contact_deg': [1.0, 2.0],
    'joints_contact_deg': [1.0, 1.0],
    'duration': 1.4e-4,
    'delta_m': 3.5e-4,
    'delta_r': 2.8e-4,
    'F_max': 1.0,
    'v_before': [-3.7, -5.5],
    'v_after': [-2.4, 2.2],
    'cor_kinematic': 0.4,
    'T_before': [2.5, 14.0, 16.5],
    'T_after': [4.4, 6.6, 11.0],
    'cor_energetic': [1.3, 0.7, 0.8],
    'phase_durations': [1e-6, 9.9e-5, 4e-5],
    'q_max_compression_deg': [1.0, 2.0],
    'q_separation_deg': [1.0, 2.0],
}


def test_a_whole_report_from_the_wire_is_drawn():
    """The text of a whole report becomes its record once: its point, its three event
    frames and its table row (the malformed ones below differ from it in one thing)."""
    from impact_arm.io.scene_visuals import SceneVisuals

    visuals = SceneVisuals(scene_from())
    visuals.add_impact(json.dumps(WHOLE_REPORT))
    assert len(visuals.impacts) == 1 and len(visuals.take_events()) == 3
    assert [row['impact'] for row in visuals.rows] == [1]


@pytest.mark.parametrize(
    'bad',
    [
        {},
        {'t_contact': 0.1, 'q_contact_deg': [1.0, 2.0], 'F_max': 1.0},  # not the whole record
        {**WHOLE_REPORT, 'F_peak': 1.0},  # a field the record does not have
        {**WHOLE_REPORT, 'q_contact_deg': 'ab'},
        {**WHOLE_REPORT, 't_contact': float('nan')},
        {**WHOLE_REPORT, 'q_contact_deg': [1.0]},
        {**WHOLE_REPORT, 'F_max': None},
        {**WHOLE_REPORT, 'q_contact_deg': [1.0, float('inf')]},
        [1, 2],
    ],
)
def test_a_malformed_report_is_refused_with_a_value_error_and_draws_nothing(bad):
    """The recorder draws reports from the wire: anything malformed must raise ValueError
    (which it catches and logs), never another error, and leave nothing queued."""
    from impact_arm.io.scene_visuals import SceneVisuals

    visuals = SceneVisuals(scene_from())
    with pytest.raises(ValueError, match='impact report'):
        visuals.add_impact(json.dumps(bad))
    assert visuals.impacts == [] and visuals.take_events() == []


def test_impact_points_are_coloured_by_peak_force_on_a_log_scale():
    """Cyan at 1 kN and below, magenta at 100 kN and above, the stops in between exact, and
    each colour channel moving one way between two stops; no colour for a NaN force."""
    from impact_arm.io.scene_visuals import FORCE_COLOURS

    assert force_colour(10.0) == force_colour(1e3) == (*FORCE_COLOURS[0][1], 1.0)
    assert force_colour(1e7) == (*FORCE_COLOURS[-1][1], 1.0)
    for force, rgb in FORCE_COLOURS:
        assert force_colour(force) == pytest.approx((*rgb, 1.0))
    # the article's 27.8 kN and 30.7 kN impacts: between green and yellow, then past yellow
    a, b = force_colour(27.8e3), force_colour(30.7e3)
    assert a != b and a[0] < b[0] <= 1.0
    for bad in (math.nan, math.inf, -1.0):
        with pytest.raises(ValueError):
            force_colour(bad)
