"""The robot's limits: effort limits clip every command, position and velocity limits are
watched and reported. The UR5 of example-robot-data as it ships (150 / 150 / 28 N m,
3.15 / 3.15 / 3.2 rad/s)."""

import math

import numpy as np
import pytest

from impact_arm.physics.limits import LimitKind, LimitWatch, limit_excursions
from impact_arm.physics.scene import load_scene
from impact_arm.physics.simulate import format_table, run
from robots import UR5_ARM, cases, robot_scene

pytest.importorskip('pinocchio')  # test_robot_descriptions' module needs it

STEEL = {'height': -0.15, 'law': 'elastoplastic', 'mu': 0.2, 'material': 'steel'}


def ur5(**controller):
    path, arm, n, _ = cases()['ur5']
    scene = robot_scene(
        {**arm, 'locked': {k: 0.0 for k in UR5_ARM['locked']}},
        n,
        [-90.0, 60.0, -30.0],
        kp=controller.get('kp', 400.0),
        kd=controller.get('kd', 40.0),
        surfaces=[STEEL],
    )
    return scene


def test_a_watch_counts_the_periods_beyond_each_limit_and_the_worst_value():
    scene = ur5()
    watch = LimitWatch(scene)
    assert watch.active
    watch.add([0.0, 0.0, 0.0], [1.0, -3.0, 3.0])  # inside
    watch.add([0.0, 0.0, 0.0], [4.0, -3.0, -5.0])
    watch.add([0.0, 3.5, 0.0], [5.0, 0.0, -4.0])  # elbow beyond its +pi
    found = {(e.joint, e.kind): e for e in watch.found}
    assert set(found) == {
        ('shoulder_lift_joint', LimitKind.VELOCITY),
        ('wrist_1_joint', LimitKind.VELOCITY),
        ('elbow_joint', LimitKind.POSITION),
    }
    lift = found['shoulder_lift_joint', LimitKind.VELOCITY]
    assert (lift.periods, lift.worst, lift.limit) == (2, 5.0, 3.15)
    wrist = found['wrist_1_joint', LimitKind.VELOCITY]
    assert (wrist.periods, wrist.worst, wrist.limit) == (2, -5.0, -3.2)
    elbow = found['elbow_joint', LimitKind.POSITION]
    assert elbow.periods == 1 and elbow.limit == pytest.approx(math.pi, abs=1e-9)
    assert "joint 'wrist_1_joint' beyond its velocity limit ±3.2 rad/s in 2 periods" in wrist.text()


def test_the_scenes_rods_have_no_limits_to_watch():
    assert not LimitWatch(load_scene('paper')).active
    assert limit_excursions(load_scene('paper'), [[9.0, 9.0]], [[99.0, 99.0]]) == []


def test_a_ur5_run_never_commands_beyond_its_effort_limits_and_reports_its_speeds():
    """Gains that would ask ~500 N m of the shoulder: every torque the arm is driven with is
    within 150 / 150 / 28 N m, the limit is reached, and the run reports the periods beyond
    the velocity limits with the same count the samples give."""
    scene = ur5(kp=2000.0, kd=60.0)
    result = run(scene, control_rate=1000.0)
    assert not result.error and result.impacts
    coordinates = scene.joint_coordinates
    efforts = np.array([coordinates.efforts(s.tau) for s in result.samples])
    limits = np.array(scene.effort_limits)
    assert np.all(np.abs(efforts) <= limits * (1 + 1e-12))
    assert np.any(np.abs(efforts) >= limits * (1 - 1e-9), axis=0).all()  # each joint saturates
    rates = np.array([coordinates.rates(s.qd) for s in result.samples])
    speeds = np.array([j.velocity for j in scene.joints])
    want = {
        name: int(count)
        for name, count in zip(scene.joint_names, (np.abs(rates) > speeds).sum(axis=0))
        if count
    }
    got = {e.joint: e.periods for e in result.limits if e.kind is LimitKind.VELOCITY}
    assert got == want and got  # this swing is faster than a UR5 is rated for
    table = format_table(result)
    assert "LIMIT: joint 'elbow_joint' beyond its velocity limit ±3.15 rad/s" in table
    assert result.summary()['limits'][0]['kind'] == 'velocity'


def test_a_description_s_empty_limits_are_said_not_enforced():
    _, arm, n, _ = cases()['pendulum']
    scene = robot_scene(arm, n, [0.0, 0.0])
    assert scene.effort_limits == (math.inf, math.inf)  # effort="0": not given
    assert not LimitWatch(scene).active  # lower = upper = 0, velocity 0: none
    assert any('limit effort = 0: taken as no effort limit' in note for note in scene.notes)
    assert any('lower = upper = 0 rad' in note for note in scene.notes)


def test_joint_limits_stop_ends_a_run_at_the_first_period_beyond_a_limit():
    """``joint_limits: stop``: offline, the run stops at the first sample beyond a limit
    with the joint, the value and the limit; the simulated driver's period raises the same
    stop (the simulator node then stops stepping and says so)."""
    import dataclasses

    from impact_arm.driver.arm import SimulatedArm
    from impact_arm.physics.limits import JointLimitStop

    scene = dataclasses.replace(ur5(), joint_limits='stop')
    result = run(scene, control_rate=1000.0)
    assert isinstance(result.exception, JointLimitStop)
    assert 'beyond its velocity limit ±3.15 rad/s: protective stop' in result.error
    reported = run(ur5(), control_rate=1000.0)
    first = min(
        k
        for k, s in enumerate(reported.samples)
        if np.any(np.abs(scene.joint_coordinates.rates(s.qd)) > [3.15, 3.15, 3.2])
    )
    assert result.samples[-1].t < reported.samples[first].t + 1e-12
    arm = SimulatedArm(scene, 1000.0)
    with pytest.raises(JointLimitStop):
        for _ in range(2000):
            arm.apply([150.0, 150.0, 28.0])
            arm.step()
