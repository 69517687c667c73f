"""A URDF arm shown as the whole robot: /robot_description is the robot as it ships with the
project's frames added (``impact_plane``, ``tip``, the surfaces), /tf moves every joint as
robot_state_publisher would (checked against Pinocchio on example-robot-data's UR5), the model's
markers land on the robot, /joint_states carries the locked joints after the moving ones, and
``impact-arm urdf`` keeps the robot's root pose (RRBot's 1.95 m base) with a ``<ros2_control>``
block naming the moving joints only."""

import copy
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from impact_arm.io.robot_tf import (
    RobotTree,
    quaternion_from_rotation,
    rotation_from_rpy,
    rpy_from_rotation,
)
from impact_arm.physics.model import ArmModel
from scenes import impact_at, paper_dict
from repo_paths import TEST_DATA
from robots import UR5_ARM, UR5_JOINTS, robots_dir

pin = pytest.importorskip('pinocchio')
SURFACES = [
    {'height': -0.3, 'material': 'steel'},
    {'height': 0.5, 'law': 'none', 'material': 'steel'},
]


def ur5_path():
    return os.path.join(robots_dir(), 'ur_description', 'urdf', 'ur5_robot.urdf')


def scene_data(arm, n, q_deg):
    data = copy.deepcopy(paper_dict())
    del data['links'], data['tip_radius']
    data['arm'] = arm
    c = data['controller']
    c.update(kp=[1.0] * n, kd=[0.1] * n, down_target_deg=[0.0] * n, up_target_deg=[0.0] * n)
    c.pop('ki', None)
    data['initial'] = {'q_deg': list(q_deg)}
    data['surfaces'] = copy.deepcopy(SURFACES)
    return data


def ur5_scene(q_deg=(-60.0, 80.0, -40.0)):
    from impact_arm.physics.scene import parse_scene

    return parse_scene(scene_data({'urdf': ur5_path(), **UR5_ARM}, 3, q_deg), origin='ur5')


def matrix(t):
    """4x4 of a geometry_msgs Transform (or io.urdf.Transform)."""
    if hasattr(t, 'transform'):
        p, r = t.transform.translation, t.transform.rotation
        xyz, (x, y, z, w) = (p.x, p.y, p.z), (r.x, r.y, r.z, r.w)
    else:
        xyz, (x, y, z, w) = (t.x, t.y, t.z), t.rotation
    T = np.eye(4)
    T[:3, :3] = pin.Quaternion(w, x, y, z).toRotationMatrix()  # an independent conversion
    T[:3, 3] = xyz
    return T


def compose(transforms, frame, root):
    """The pose of ``frame`` in ``root`` from TransformStamped messages (parent -> child)."""
    by_child = {t.child_frame_id: t for t in transforms}
    T = np.eye(4)
    while frame != root:
        t = by_child[frame]
        T = matrix(t) @ T
        frame = t.header.frame_id
    return T


def pinocchio_config(model, values):
    config = pin.neutral(model)
    for jid in range(1, model.njoints):
        joint, value = model.joints[jid], values.get(model.names[jid], 0.0)
        if joint.nq == 1:
            config[joint.idx_q] = value
        else:  # continuous: (cos, sin)
            config[joint.idx_q : joint.idx_q + 2] = math.cos(value), math.sin(value)
    return config


def test_rpy_and_quaternion_conversions_invert_each_other():
    rng = np.random.default_rng(3)
    for rpy in list(rng.uniform(-3, 3, (50, 3))) + [(0.2, math.pi / 2, 0.4), (0, 0, math.pi)]:
        R = rotation_from_rpy(rpy)
        assert rotation_from_rpy(rpy_from_rotation(R)) == pytest.approx(R, abs=1e-12)
        x, y, z, w = quaternion_from_rotation(R)
        assert w >= 0 and math.isclose(x * x + y * y + z * z + w * w, 1.0, rel_tol=1e-14)
        assert pin.Quaternion(w, x, y, z).toRotationMatrix() == pytest.approx(R, abs=1e-14)


def test_forward_kinematics_equals_pinocchio_on_the_ur5():
    text = Path(ur5_path()).read_text()
    tree = RobotTree(text)
    model = pin.buildModelFromXML(text)
    data = model.createData()
    rng = np.random.default_rng(7)
    for _ in range(20):
        values = dict(zip(UR5_JOINTS, rng.uniform(-math.pi, math.pi, 6)))
        poses = tree.poses(values)
        pin.framesForwardKinematics(model, data, pinocchio_config(model, values))
        for frame in ('ee_link', 'tool0', 'wrist_2_link', 'base'):
            want = data.oMf[model.getFrameId(frame)].homogeneous
            assert poses[frame] == pytest.approx(want, abs=1e-12), frame
        # the per-joint transforms compose to the same poses
        chain = {j.child: (j.parent, T) for j, T in tree.transforms(values)}
        chain.update({j.child: (j.parent, j.origin) for j in tree.fixed})
        T, link = np.eye(4), 'ee_link'
        while link != tree.root:
            parent, step = chain[link]
            T, link = step @ T, parent
        assert T == pytest.approx(poses['ee_link'], abs=1e-12)


def test_the_ur5_description_is_the_whole_robot_with_the_projects_frames():
    from impact_arm.io.scene_visuals import SceneVisuals

    scene = ur5_scene()
    text = SceneVisuals(scene).description().data
    model = pin.buildModelFromXML(text)
    assert [model.names[j] for j in range(1, model.njoints)] == UR5_JOINTS
    for frame in ('world', 'base_link', 'ee_link', 'tool0', 'impact_plane', 'tip', 'surface1'):
        assert model.existFrame(frame), frame
    yourdfpy = pytest.importorskip('yourdfpy')
    import io

    robot = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False, build_scene_graph=False)
    assert set(UR5_JOINTS) <= set(robot.joint_map)
    assert {'impact_plane', 'surface1', 'surface2', 'tip'} <= set(robot.link_map)
    root = ET.fromstring(text)
    (control,) = root.findall('ros2_control')
    assert [j.get('name') for j in control.findall('joint')] == list(scene.joint_names)
    assert control.find('hardware/plugin').text == 'topic_based_ros2_control/TopicBasedSystem'
    # the impact_plane's frame: a point (x, y) of the model's plane is (x, 0, y) in it
    data = model.createData()
    values = dict(scene.locked_joints)
    pin.framesForwardKinematics(model, data, pinocchio_config(model, values))
    plane = data.oMf[model.getFrameId('impact_plane')]
    p = scene.plane
    for x, y in [(0.3, 0.0), (0.0, 0.2), (-0.4, 0.7)]:
        want = np.array(p.origin) + x * np.array(p.x) + y * np.array(p.y)
        assert plane.act(np.array([x, 0.0, y])) == pytest.approx(want, abs=1e-12)
    # the surfaces lie in the plane frame at their heights, their y the plane's up
    surface = data.oMf[model.getFrameId('surface2')]
    assert surface.translation == pytest.approx(np.array(p.origin) + 0.5 * np.array(p.y))
    assert surface.rotation[:, 1] == pytest.approx(p.y, abs=1e-12)


def test_tf_for_a_joint_state_is_pinocchios_robot_and_the_markers_land_on_it():
    from impact_arm.io.scene_visuals import SceneVisuals

    scene = ur5_scene()
    visuals = SceneVisuals(scene)
    model = pin.buildModelFromUrdf(ur5_path())  # the robot as it ships
    data = model.createData()
    arm = ArmModel(scene)
    static = visuals.tf_static().transforms
    rng = np.random.default_rng(11)
    for _ in range(10):
        theta = rng.uniform(-2.0, 2.0, 3)
        q = scene.joint_coordinates.absolute(theta)
        msg = visuals.tf(q, 1_000_000)
        moving = {t.child_frame_id: t for t in msg.transforms}
        # every non-fixed joint is on /tf: the moving ones at θ, the locked at their values
        assert set(moving) == {
            'shoulder_link',
            'upper_arm_link',
            'forearm_link',
            'wrist_1_link',
            'wrist_2_link',
            'wrist_3_link',
        }
        values = {**dict(scene.locked_joints), **dict(zip(scene.joint_names, theta))}
        pin.framesForwardKinematics(model, data, pinocchio_config(model, values))
        transforms = list(static) + list(msg.transforms)
        for frame in ('ee_link', 'tool0'):
            want = data.oMf[model.getFrameId(frame)].homogeneous
            assert compose(transforms, frame, 'world') == pytest.approx(want, abs=1e-12)
        # the model's tip B, a point of the plane, through impact_plane: the contact point
        # (ee_link's origin) projected onto the plane
        x, y = arm.tip(np.array(q), np.zeros(3))[:2]
        plane = compose(transforms, 'impact_plane', 'world')
        tip_world = plane @ np.array([x, 0.0, y, 1.0])
        contact = data.oMf[model.getFrameId('ee_link')].translation
        p = scene.plane
        projected = contact - (contact - np.array(p.origin)) @ np.array(p.axis) * np.array(p.axis)
        assert tip_world[:3] == pytest.approx(projected, abs=1e-9)
        # ... and frame 'tip' of the description sits there too
        assert compose(transforms, 'tip', 'world')[:3, 3] == pytest.approx(projected, abs=1e-9)
    # impact points and the force arrow are drawn in impact_plane
    visuals.add_impact(impact_at(np.degrees(q)))
    from impact_arm.io.msgdefs import typestore

    markers = typestore().deserialize_cdr(
        visuals.markers(2_000_000), 'visualization_msgs/msg/MarkerArray'
    )
    frames = {m.ns: m.header.frame_id for m in markers.markers}
    assert frames['impact_points'] == frames['contact_force'] == 'impact_plane'
    assert frames['surface'] == 'surface2'


def test_rod_scenes_keep_the_world_frame_and_their_joint_states():
    from impact_arm.io.scene_visuals import SceneVisuals
    from impact_arm.physics.scene import load_scene

    scene = load_scene('paper')
    assert scene.plane is None and scene.locked_joints == ()
    visuals = SceneVisuals(scene)
    assert visuals.robot is None and visuals.frame == 'world'
    assert 'impact_plane' not in visuals.description().data


@pytest.fixture(scope='module')
def ur5_recording(tmp_path_factory):
    from impact_arm.tools.cli import main

    tmp = tmp_path_factory.mktemp('ur5')
    data = scene_data({'urdf': ur5_path(), **UR5_ARM}, 3, (-60.0, 80.0, -40.0))
    data['cycles'] = 1
    data['t_max'] = 0.05
    (tmp / 'ur5.yaml').write_text(yaml.safe_dump(data))
    path = tmp / 'ur5.mcap'
    assert main(['simulate', '--scene', str(tmp / 'ur5.yaml'), '--mcap', str(path)]) == 0
    return path


def test_an_offline_recording_names_every_joint_and_reads_back(ur5_recording):
    from rosbags.highlevel import AnyReader

    from impact_arm.tools.analysis import load

    scene = ur5_scene()
    locked = dict(scene.locked_joints)
    with AnyReader([ur5_recording]) as reader:
        states = [
            reader.deserialize(raw, conn.msgtype)
            for conn, _, raw in reader.messages()
            if conn.topic == '/joint_states'
        ]
        description = [
            reader.deserialize(raw, conn.msgtype).data
            for conn, _, raw in reader.messages()
            if conn.topic == '/robot_description'
        ]
    assert len(states) > 10
    for msg in states[:: len(states) // 10]:
        assert list(msg.name) == list(scene.joint_names) + list(locked)
        assert list(msg.position[3:]) == list(locked.values())
        assert not any(msg.velocity[3:]) and not any(msg.effort[3:])
    (text,) = description
    assert 'impact_plane' in text and 'shoulder_pan_joint' in text
    run = load(ur5_recording)
    assert np.asarray(run.q).shape[1] == 3
    q0 = scene.joint_coordinates.absolute(states[0].position[:3])
    assert run.q[0] == pytest.approx(q0, abs=1e-12)


def test_impact_arm_urdf_keeps_rrbots_base_height_and_names_its_moving_joints(tmp_path, capsys):
    from impact_arm.tools.cli import main

    data = scene_data(
        {
            'xacro': os.path.join(TEST_DATA, 'rrbot', 'urdf', 'rrbot.urdf.xacro'),
            'package_paths': [TEST_DATA],
            'contact': {'link': 'tool_link'},
        },
        2,
        (-30.0, 20.0),
    )
    (tmp_path / 'rrbot.yaml').write_text(yaml.safe_dump(data))
    assert main(['urdf', '--scene', str(tmp_path / 'rrbot.yaml')]) == 0
    root = ET.fromstring(capsys.readouterr().out)
    base = next(j for j in root.findall('joint') if j.get('name') == 'base_joint')
    assert float(base.find('origin').get('xyz').split()[2]) == 1.95
    (control,) = root.findall('ros2_control')  # the original's mock block is gone
    assert [j.get('name') for j in control.findall('joint')] == ['joint1', 'joint2']
    initial = [
        float(j.find("state_interface[@name='position']/param").text)
        for j in control.findall('joint')
    ]
    assert initial == pytest.approx([math.radians(-30.0), math.radians(20.0)], abs=1e-12)
    links = {link.get('name') for link in root.findall('link')}
    assert {'world', 'base_link', 'impact_plane', 'surface1', 'tip'} <= links
    model = pin.buildModelFromXML(ET.tostring(root, encoding='unicode'))
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    # the plane's origin is RRBot's first joint, up on its base
    assert data.oMf[model.getFrameId('impact_plane')].translation[2] >= 1.95
