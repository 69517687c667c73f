"""The generated robot description, read by an independent URDF parser (yourdfpy) and an
independent dynamics library (Pinocchio), both in REP 103's world (z up, gravity along -z)."""

import io
import math

import numpy as np
import pytest

from impact_arm.contract import to_joint_space

from impact_arm.physics.model import ArmModel
from impact_arm.io.urdf import moving_transforms, robot_description, static_transforms
from scenes import scene_from

yourdfpy = pytest.importorskip('yourdfpy')

THREE_LINKS = {
    ('links',): [
        {'length': 0.7, 'mass': 1.3},
        {'length': 0.5, 'mass': 0.8},
        {'length': 0.4, 'mass': 0.35},
    ],
    ('controller', 'kp'): [600.0, 300.0, 100.0],
    ('controller', 'kd'): [100.0, 100.0, 50.0],
    ('controller', 'ki'): [0.0, 0.0, 0.0],
    ('controller', 'down_target_deg'): [-80.0, -70.0, -60.0],
    ('controller', 'up_target_deg'): [80.0, 70.0, 60.0],
    ('initial', 'q_deg'): [60.0, 45.0, 30.0],
    ('initial', 'qd'): [0.0, 0.0, 0.0],
}


def scenes():
    return [
        scene_from(),
        scene_from(
            THREE_LINKS,
            surfaces=[
                {'height': -1.2, 'material': 'steel'},
                {'height': 1.3, 'material': 'steel', 'law': 'none'},
            ],
        ),
    ]


def parse(scene):
    return yourdfpy.URDF.load(
        io.StringIO(robot_description(scene)),
        load_meshes=False,
        build_scene_graph=True,
        build_collision_scene_graph=False,
    )


@pytest.mark.parametrize('scene', scenes(), ids=['2 links', '3 links'])
def test_links_masses_inertias_and_joints_match_the_scene(scene):
    urdf = parse(scene)
    n = scene.n_links
    assert urdf.actuated_joint_names == [f'joint{i + 1}' for i in range(n)]
    for k in range(n):
        L, m = scene.lengths[k], scene.masses[k]
        link = urdf.link_map[f'link{k + 1}']
        assert link.inertial.mass == pytest.approx(m, rel=1e-15)
        # inertial frame at the rod's centre, slender-rod inertia m L^2 / 12 about z (and y)
        assert link.inertial.origin[:3, 3] == pytest.approx([L / 2, 0, 0], abs=1e-15)
        assert np.diag(link.inertial.inertia) == pytest.approx(
            [0, m * L * L / 12, m * L * L / 12], rel=1e-15
        )
        assert link.visuals[0].geometry.cylinder.length == pytest.approx(L, rel=1e-15)
        joint = urdf.joint_map[f'joint{k + 1}']
        assert list(joint.axis) == [0, -1, 0]  # the model's z axis in the z-up world
        assert joint.parent == ('world' if k == 0 else f'link{k}')
        assert joint.origin[:3, 3] == pytest.approx([scene.lengths[k - 1] if k else 0, 0, 0])
    assert urdf.link_map['tip'].collisions[0].geometry.sphere.radius == scene.tip_radius
    for i, surface in enumerate(scene.surfaces):
        name = f'surface{i + 1}'
        pose = urdf.get_transform(name, 'world')
        assert pose[:3, 3] == pytest.approx([0, 0, surface.height])  # z up
        assert pose[:3, 1] == pytest.approx([0, 0, 1])  # the surface frame's y: the normal
        box = urdf.link_map[name].visuals[0]
        top = box.origin[1, 3] + box.geometry.box.size[1] / 2  # the slab's top face
        assert top == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize('scene', scenes(), ids=['2 links', '3 links'])
def test_joint_values_are_relative_angles_and_put_the_tip_where_the_model_does(scene):
    """Set the URDF's joints to the encoder angles (joint1 = q1, jointk = qk - q(k-1)) and the
    parser's forward kinematics must put frame 'tip' at the model's tip B."""
    urdf = parse(scene)
    model = ArmModel(scene)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-math.pi, math.pi, scene.n_links)
        urdf.update_cfg(np.concatenate([[q[0]], np.diff(q)]))
        xb, yb = model.tip(q, np.zeros_like(q))[:2]
        # the model's plane is the world's x-z plane: B = (x, 0, y)
        assert urdf.get_transform('tip', 'world')[:3, 3] == pytest.approx([xb, 0, yb], abs=1e-12)


def test_ros2_control_block_names_topic_hardware_with_effort_commands():
    import xml.etree.ElementTree as ET

    scene = scene_from()
    root = ET.fromstring(robot_description(scene))
    control = root.find('ros2_control')
    assert control.find('hardware/plugin').text == 'topic_based_ros2_control/TopicBasedSystem'
    params = {p.get('name'): p.text for p in control.findall('hardware/param')}
    assert params['joint_states_topic'] != '/joint_states'
    assert set(params) >= {'joint_commands_topic', 'joint_states_topic'}
    for joint in control.findall('joint'):
        assert [c.get('name') for c in joint.findall('command_interface')] == ['effort']
        assert [s.get('name') for s in joint.findall('state_interface')] == [
            'position',
            'velocity',
            'effort',
        ]
    # before the hardware's first state the broadcaster publishes the scene's initial pose
    initial = [
        [float(s.find("param[@name='initial_value']").text) for s in j.findall('state_interface')]
        for j in control.findall('joint')
    ]
    relative = to_joint_space(scene.q0)
    assert [i[0] for i in initial] == pytest.approx(relative, abs=1e-12)
    assert all(i[1:] == [0.0, 0.0] for i in initial) and relative[1] != 0.0


def test_frame_functions_compose_to_the_tip():
    from scipy.spatial.transform import Rotation

    scene = scenes()[1]
    q = [0.3, -1.1, 2.0]
    chain = moving_transforms(scene.lengths, q) + static_transforms(scene)[:1]
    R, p = np.eye(3), np.zeros(3)
    for t in chain:  # compose world -> ... -> tip
        p = p + R @ [t.x, t.y, t.z]
        R = R @ Rotation.from_quat(t.quaternion()).as_matrix()
    xb, yb = ArmModel(scene).tip(q, [0, 0, 0])[:2]
    assert p == pytest.approx([xb, 0, yb], abs=1e-12)


@pytest.mark.parametrize('scene', scenes(), ids=['2 links', '3 links'])
def test_an_independent_dynamics_library_finds_the_models_gravity_torques(scene):
    """Pinocchio builds the arm from the URDF with its own default gravity (-9.81 along -z):
    at random states its gravity torques must be the model's. Pinocchio's g(q) is dV/dq in
    joint (relative) angles; the model's gravity_forces are -dV/dq in absolute angles, and
    q_abs = S q_rel with S lower-triangular ones, so g = -S^T gravity_forces."""
    pin = pytest.importorskip('pinocchio')
    model = pin.buildModelFromXML(robot_description(scene))
    assert model.gravity.linear == pytest.approx([0, 0, -9.81])
    data = model.createData()
    arm = ArmModel(scene)
    n = scene.n_links
    S = np.tril(np.ones((n, n)))
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, n)
        relative = np.concatenate([[q[0]], np.diff(q)])
        # continuous joints are (cos, sin) pairs in Pinocchio's configuration
        config = np.concatenate([[math.cos(a), math.sin(a)] for a in relative])
        expected = -S.T @ np.asarray(arm.gravity_forces(q)) * 9.81 / scene.gravity
        torques = pin.computeGeneralizedGravity(model, data, config)
        assert torques == pytest.approx(expected, rel=1e-12, abs=1e-12)
        assert np.abs(torques).max() > 1.0  # not all zero: gravity is not along an axis


def test_rod_radius_is_a_visual_setting_and_the_tip_stands_out_of_the_rod():
    from impact_arm.io.urdf import default_rod_radius

    scene = scene_from()
    urdf = parse(scene)
    rod = urdf.link_map['link1'].visuals[0].geometry.cylinder.radius
    assert rod == default_rod_radius(scene) == pytest.approx(0.01 * min(scene.lengths))
    tip = urdf.link_map['tip']
    assert tip.visuals[0].geometry.sphere.radius >= 2 * rod  # visible around the rod
    assert tip.collisions[0].geometry.sphere.radius == scene.tip_radius
    assert tip.visuals[0].material.name != urdf.link_map['link1'].visuals[0].material.name
    thick = yourdfpy.URDF.load(
        io.StringIO(robot_description(scene, rod_radius=0.05)), load_meshes=False
    )
    assert thick.link_map['link2'].visuals[0].geometry.cylinder.radius == 0.05
    for bad in (-0.01, math.nan, 10 * max(scene.lengths)):
        with pytest.raises(ValueError, match='rod_radius'):
            robot_description(scene, rod_radius=bad)
