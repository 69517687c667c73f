"""What a 3D viewer gets from the live simulator over DDS: each impact's force arrow and
impact point, stamped at the impact's first contact and anchored where the report says the
tip touched the surface (real node processes, random domain)."""

import json
import math

import pytest

from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import load_scene
from ros_helpers import controller, simulator, start_process, wait_for


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def test_live_markers_show_every_impact_at_its_contact_point(probe, ros_env, tmp_path):
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    reports = probe.listen(String, '/impact_report', transient=True)
    markers = probe.listen(MarkerArray, '/impact_markers')
    tables = probe.listen(String, '/impact_table', transient=True)
    wrenches = probe.listen(WrenchStamped, '/contact_wrench')
    peaks = probe.listen(WrenchStamped, '/contact_force_peak')
    # at 1x: unpaced, the lockstep loop published a period's peak faster than a loaded
    # probe took them, and once none of three impacts' peaks reached it
    with (
        start_process(
            simulator('mode:=lockstep', 'rate_factor:=1.0'), ros_env, tmp_path, 'sim'
        ) as sim,
        start_process(controller(), ros_env, tmp_path, 'ctl') as ctl,
    ):
        assert wait_for(
            lambda: len(reports) >= 3 or not sim.alive() or not ctl.alive(), timeout=120
        ), sim.stderr[-2000:] + ctl.stderr[-2000:]
        # the event frames of the last report go out with the next visual tick (10 ms)
        assert wait_for(
            lambda: any(
                m.ns == 'impact_points' and m.id == 2 for _, ma in markers for m in ma.markers
            ),
            timeout=10,
        )
    probe.forget(reports, markers, tables, wrenches, peaks)
    # the table a viewer shows: each message holds every impact so far, rounded
    rows = json.loads(tables[-1][1].data)['rows']
    assert [r['impact'] for r in rows] == list(range(1, len(rows) + 1)) and len(rows) >= 3
    first = json.loads(reports[0][1].data)
    assert rows[0]['F max [kN]'] == pytest.approx(first['F_max'] / 1e3, rel=5e-4)
    scene = load_scene('paper')
    model, height = ArmModel(scene), scene.surfaces[0].height
    arrows = {
        stamp_ns(m.header): m for _, ma in markers for m in ma.markers if m.ns == 'contact_force'
    }
    for _, msg in reports[:3]:
        report = json.loads(msg.data)
        t_contact = math.ceil(report['t_contact'] * 1e9 - 1e-6)
        arrow = arrows.get(t_contact)
        assert arrow is not None, f'no arrow stamped at the contact of impact {report["index"]}'
        x_b, y_b = model.tip([math.radians(a) for a in report['q_contact_deg']], [0, 0])[:2]
        start = arrow.points[0]
        assert (start.x, start.y, start.z) == pytest.approx((x_b, 0.0, y_b), abs=1e-6)
        assert start.z == pytest.approx(height, abs=1e-6)  # on the surface, z up
        assert arrow.lifetime.sec + arrow.lifetime.nanosec * 1e-9 >= 0.3
    assert {w.header.frame_id for _, w in wrenches} == {'surface1'}
    # each period's peak force: the impacts' F_max among them (the probe may miss a period)
    assert {w.header.frame_id for _, w in peaks} == {'surface1'}
    assert all(w.wrench.force.x == 0.0 and w.wrench.force.y >= 0.0 for _, w in peaks)
    f_max = {round(json.loads(msg.data)['F_max'], 3) for _, msg in reports}
    assert f_max & {round(w.wrench.force.y, 3) for _, w in peaks}


def test_listeners_that_come_late_get_the_view_and_the_topic_hardware_states(
    probe, ros_env, tmp_path
):
    """With nobody listening to /tf or /impact_markers the simulator stops their timer and
    only looks for listeners now and then: a viewer, and topic hardware on
    /robot_joint_states, that subscribe seconds after the start still get their messages."""
    import time

    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    states = probe.listen(JointState, '/joint_states', depth=10)
    with start_process(
        simulator('publish_rate:=100.0', 'tf_rate:=50.0'), ros_env, tmp_path, 'sim'
    ) as sim:
        assert wait_for(lambda: states or not sim.alive(), timeout=60), sim.stderr[-2000:]
        time.sleep(1.5)  # several looks for a listener: the view's timer has stopped
        # topic hardware alone first: the view's timer stays stopped meanwhile
        hw_states = probe.listen(JointState, '/robot_joint_states', depth=10)
        assert wait_for(lambda: hw_states or not sim.alive(), timeout=15), (
            'no topic hardware states\n' + sim.stderr[-2000:]
        )
        markers = probe.listen(MarkerArray, '/impact_markers', depth=10)
        assert wait_for(lambda: markers or not sim.alive(), timeout=15), (
            'no markers\n' + sim.stderr[-2000:]
        )
    probe.forget(states, markers, hw_states)
    assert any(m.ns == 'surface' for _, ma in markers for m in ma.markers)
