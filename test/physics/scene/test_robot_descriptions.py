"""Robots as they ship: public descriptions loaded unmodified, checked against Pinocchio on
the original file, in the robot's own joint coordinates.

* example-robot-data's UR5 (``ur5_robot.urdf``): a planar sub-chain (shoulder lift, elbow,
  wrist 1) with the pan and the other wrists locked; axes along ``0 1 0`` in frames turned
  by ``rpy``, offsets along the axis, a root turned by pi;
* example-robot-data's ``double_pendulum_simple.urdf``: axes ``1 0 0``, links along z,
  offsets along the axis;
* a RRBot-like xacro (test/data/rrbot, written here in ros2_control_demos' style): links
  along z, axes ``0 1 0``, 0.1 m offsets along the axis, a base raised 1.95 m.

For each, at random postures θ (the robot's joint angles), Pinocchio (``buildReducedModel``
for the locked joints, gravity -9.81 along the world's z) gives the mass matrix, the
free-fall acceleration and the contact point; the model gives them through its absolute
angles q(θ) = T (S θ + c): M_θ = (T S)ᵀ M_q (T S), θ̈ = (T S)⁻¹ M_q⁻¹ Q(q, 0)."""

import copy
import math

import numpy as np
import pytest

from impact_arm.physics.errors import SceneError
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import parse_scene
from scenes import paper_dict
from robots import cases, robot_scene

pin = pytest.importorskip('pinocchio')


def reduced(model, scene):
    """Pinocchio's model with every joint but the scene's moving ones locked at the scene's
    values (zero for those it does not name)."""
    moving = set(scene.joint_names)
    locked = dict(scene.locked_joints)
    config = pin.neutral(model)
    lock = []
    for jid in range(1, model.njoints):
        if model.names[jid] in moving:
            continue
        lock.append(jid)
        value, idx = locked.get(model.names[jid], 0.0), model.joints[jid].idx_q
        if model.joints[jid].nq == 1:
            config[idx] = value
        else:
            config[idx : idx + 2] = math.cos(value), math.sin(value)
    return pin.buildReducedModel(model, lock, config)


@pytest.mark.parametrize('robot', ['ur5', 'pendulum', 'rrbot'])
def test_dynamics_and_contact_point_equal_pinocchio_in_the_robots_joint_angles(robot):
    path, arm, n, contact = cases()[robot]
    scene = robot_scene(arm, n, [0.0] * n)
    assert scene.n_links == n
    model = pin.buildModelFromUrdf(path) if path else pin.buildModelFromXML(scene.urdf_text)
    if robot == 'ur5':
        model = reduced(model, scene)
    assert [model.names[j] for j in range(1, model.njoints)] == list(scene.joint_names)
    data = model.createData()
    arm_model = ArmModel(scene)
    S = np.diag([j.sign for j in scene.joints])
    c = np.array([j.offset for j in scene.joints])
    J = np.tril(np.ones((n, n))) @ S  # dq / dθ
    frame = model.getFrameId(contact)
    rng = np.random.default_rng(len(robot))
    for _ in range(10):
        theta = rng.uniform(-2.5, 2.5, n)
        config = np.concatenate(
            [
                [a] if model.joints[k + 1].nq == 1 else [math.cos(a), math.sin(a)]
                for k, a in enumerate(theta)
            ]
        )
        q = np.tril(np.ones((n, n))) @ (S @ theta + c)
        M = pin.crba(model, data, config)
        M = np.triu(M) + np.triu(M, 1).T
        want = J.T @ arm_model.mass_matrix(q) @ J
        assert np.max(np.abs(M - want)) <= 1e-12 * np.max(np.abs(M))
        fall = pin.aba(model, data, config, np.zeros(n), np.zeros(n))
        ours = np.linalg.solve(
            J, np.linalg.solve(arm_model.mass_matrix(q), arm_model.free_forces(q, np.zeros(n)))
        )
        assert np.max(np.abs(fall - ours)) <= 1e-12 * max(1.0, np.max(np.abs(fall)))
        pin.framesForwardKinematics(model, data, config)
        tip = scene.plane.to_plane(data.oMf[frame].translation)
        assert arm_model.tip(q, np.zeros(n))[:2] == pytest.approx(tip, abs=1e-12)


def test_the_ur5_keeps_its_joint_angles_limits_and_locked_joints():
    path, arm, n, _ = cases()['ur5']
    scene = robot_scene(arm, n, [-90.0, 90.0, -90.0])
    # the initial posture is the robot's joint angles: what its driver would report
    assert scene.joint_coordinates.positions(scene.q0) == pytest.approx(
        [math.radians(v) for v in (-90.0, 90.0, -90.0)], abs=1e-12
    )
    assert [j.effort for j in scene.joints] == [150.0, 150.0, 28.0]
    assert scene.effort_limits == (150.0, 150.0, 28.0)
    assert [j.velocity for j in scene.joints] == [3.15, 3.15, 3.2]
    assert dict(scene.locked_joints) == {
        'shoulder_pan_joint': 0.3,
        'wrist_2_joint': 0.0,
        'wrist_3_joint': 0.7,
    }
    # the wrist bodies merged into wrist 1's: 1.219 + 1.219 + 0.1879 kg
    assert scene.masses[2] == pytest.approx(2.6259, rel=1e-12)


def test_the_rrbot_keeps_its_base_height_and_its_zero_upright():
    """Joint 1 stays where the description puts it (1.95 m up, 0.1 m along the axis); at the
    robot's zero both links point up, so the model's first link angle is +90 deg there."""
    _, arm, n, _ = cases()['rrbot']
    scene = robot_scene(arm, n, [0.0, 0.0])
    assert scene.plane.origin == pytest.approx((0.0, 0.1, 1.95), abs=1e-15)
    assert scene.plane.axis == (0.0, 1.0, 0.0) and scene.plane.y == (0.0, 0.0, 1.0)
    assert scene.lengths == pytest.approx((1.0, 1.0), abs=1e-15)
    assert scene.q0 == pytest.approx((math.pi / 2, math.pi / 2), abs=1e-15)
    assert scene.gravity == 9.81  # the axis is horizontal: all of gravity is in the plane


@pytest.mark.parametrize(
    'change, message',
    [
        ({'locked': {'shoulder_pan_joint': 0.0}}, "joints 'wrist_2_joint', 'wrist_3_joint' lie"),
        (
            {'locked': {'shoulder_pan_joint': 0.0, 'wrist_2_joint': 0.0, 'wrist_3_joint': 9.0}},
            'arm.locked.wrist_3_joint = 9 is outside the joint',
        ),
        (
            {'joints': ['shoulder_lift_joint', 'elbow_joint', 'wrist_2_joint']},
            "joint 'wrist_2_joint' axis is 90 deg from joint 'shoulder_lift_joint''s",
        ),
        (
            {'joints': ['elbow_joint', 'shoulder_lift_joint', 'wrist_1_joint']},
            'arm.joints must run from the base to the tip',
        ),
        ({'joints': ['shoulder_lift_joint', 'nope', 'wrist_1_joint']}, "arm.joints[1] = 'nope'"),
    ],
)
def test_a_sub_chain_that_is_not_planar_is_refused_naming_the_joints(change, message):
    _, arm, n, _ = cases()['ur5']
    arm = {**arm, **change}
    if 'joints' in change and 'wrist_2_joint' in change['joints']:
        arm['locked'] = {'shoulder_pan_joint': 0.0, 'wrist_1_joint': 0.0, 'wrist_3_joint': 0.0}
    with pytest.raises(SceneError) as refused:
        robot_scene(arm, n, [0.0] * n)
    assert message in str(refused.value) and '\n' not in str(refused.value)


STRIKES = {  # gains, targets (the robot's joint angles) and a surface each one strikes
    'pendulum': dict(
        kp=[2.0, 1.0],
        kd=[0.1, 0.05],
        down=[170.0, 10.0],
        up=[120.0, 0.0],
        start=[150.0, 0.0],
        switch=-0.15,
        height=-0.25,
    ),
    'rrbot': dict(
        kp=[800.0, 300.0],
        kd=[80.0, 30.0],
        down=[130.0, 60.0],
        up=[60.0, 0.0],
        start=[60.0, 0.0],
        switch=-0.5,
        height=-1.2,
    ),
}


@pytest.mark.parametrize('robot', ['pendulum', 'rrbot'])
def test_each_robot_runs_through_simulate_analyze_urdf_and_compare(robot, tmp_path, monkeypatch):
    """The pendulum and the RRBot as they ship, offline: a sampled run recorded to MCAP
    (read back with rosbags under the robot's joint names, in its joint angles), analyzed,
    written as a URDF and compared with their scene."""
    import yaml
    from rosbags.highlevel import AnyReader
    from pathlib import Path

    from impact_arm.tools.analysis import load
    from impact_arm.tools.cli import main

    _, arm, n, _ = cases()[robot]
    s = STRIKES[robot]
    data = copy.deepcopy(paper_dict())
    del data['links'], data['tip_radius']
    data['arm'] = arm
    data['controller'] = {
        'law': 'q',
        'kp': s['kp'],
        'kd': s['kd'],
        'down_target_deg': s['down'],
        'up_target_deg': s['up'],
        'switch_height': s['switch'],
        'rate': 1000.0,
    }
    data['initial'] = {'q_deg': s['start']}
    data['surfaces'] = [{'height': s['height'], 'material': 'steel'}]
    data['cycles'], data['t_max'] = 3, 10.0
    (tmp_path / 'robot.yaml').write_text(yaml.safe_dump(data))
    monkeypatch.chdir(tmp_path)
    assert main(['simulate', '--scene', 'robot.yaml', '--mcap', 'run.mcap']) == 0
    scene = parse_scene(data, origin='robot')
    with AnyReader([Path('run.mcap')]) as reader:
        states = [
            reader.deserialize(raw, conn.msgtype)
            for conn, _, raw in reader.messages()
            if conn.topic == '/joint_states'
        ]
    assert all(list(m.name[:n]) == list(scene.joint_names) for m in states)
    assert np.degrees(states[0].position[:n]) == pytest.approx(s['start'], abs=1e-9)
    run = load('run.mcap')
    assert len(run.impacts) >= 2 and run.q.shape[1] == n
    # analyze's absolute angles are the scene's: the first row is the scene's start
    assert run.q[0] == pytest.approx(scene.q0, abs=1e-9)
    assert main(['analyze', 'run.mcap', '--out', 'analysis', '--no-animation', '--laws', '']) == 0
    assert main(['urdf', '--scene', 'robot.yaml']) == 0
    assert main(['compare', 'run.mcap', 'robot.yaml', '--out', 'compare']) == 0
