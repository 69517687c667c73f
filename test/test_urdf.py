"""The generated robot description, read by an independent URDF parser (yourdfpy)."""
import io
import math

import numpy as np
import pytest

from impact_arm.core.model import ArmModel
from impact_arm.io.urdf import moving_transforms, robot_description, static_transforms
from scenes import scene_from

yourdfpy = pytest.importorskip('yourdfpy')

THREE_LINKS = {('links',): [{'length': 0.7, 'mass': 1.3}, {'length': 0.5, 'mass': 0.8},
                            {'length': 0.4, 'mass': 0.35}],
               ('controller', 'kp'): [600.0, 300.0, 100.0],
               ('controller', 'kd'): [100.0, 100.0, 50.0],
               ('controller', 'ki'): [0.0, 0.0, 0.0],
               ('controller', 'down_target_deg'): [-80.0, -70.0, -60.0],
               ('controller', 'up_target_deg'): [80.0, 70.0, 60.0],
               ('initial', 'q_deg'): [60.0, 45.0, 30.0], ('initial', 'qd'): [0.0, 0.0, 0.0]}


def scenes():
    return [scene_from(), scene_from(THREE_LINKS,
                                     surfaces=[{'height': -1.2, 'material': 'steel'},
                                               {'height': 1.3, 'material': 'steel',
                                                'law': 'none'}])]


def parse(scene):
    return yourdfpy.URDF.load(io.StringIO(robot_description(scene)), load_meshes=False,
                              build_scene_graph=True, build_collision_scene_graph=False)


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
        assert np.diag(link.inertial.inertia) == pytest.approx([0, m * L * L / 12,
                                                               m * L * L / 12], rel=1e-15)
        assert link.visuals[0].geometry.cylinder.length == pytest.approx(L, rel=1e-15)
        joint = urdf.joint_map[f'joint{k + 1}']
        assert list(joint.axis) == [0, 0, 1]
        assert joint.parent == ('world' if k == 0 else f'link{k}')
        assert joint.origin[:3, 3] == pytest.approx([scene.lengths[k - 1] if k else 0, 0, 0])
    assert urdf.link_map['tip'].visuals[0].geometry.sphere.radius == scene.tip_radius
    for i, surface in enumerate(scene.surfaces):
        name = f'surface{i + 1}'
        assert urdf.get_transform(name, 'world')[1, 3] == pytest.approx(surface.height)
        box = urdf.link_map[name].visuals[0]
        top = box.origin[1, 3] + box.geometry.box.size[1] / 2   # the slab's top face
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
        x, y = urdf.get_transform('tip', 'world')[:2, 3]
        xb, yb = model.tip(q, np.zeros_like(q))[:2]
        assert (x, y) == pytest.approx((xb, yb), abs=1e-12)


def test_ros2_control_block_names_topic_hardware_with_effort_commands():
    import xml.etree.ElementTree as ET
    root = ET.fromstring(robot_description(scene_from()))
    control = root.find('ros2_control')
    assert control.find('hardware/plugin').text == 'topic_based_ros2_control/TopicBasedSystem'
    params = {p.get('name'): p.text for p in control.findall('hardware/param')}
    assert params['joint_states_topic'] != '/joint_states'
    assert set(params) >= {'joint_commands_topic', 'joint_states_topic'}
    for joint in control.findall('joint'):
        assert [c.get('name') for c in joint.findall('command_interface')] == ['effort']
        assert [s.get('name') for s in joint.findall('state_interface')] == [
            'position', 'velocity', 'effort']


def test_frame_functions_compose_to_the_tip():
    scene = scenes()[1]
    q = [0.3, -1.1, 2.0]
    chain = moving_transforms(scene.lengths, q) + static_transforms(scene)[:1]
    x = y = yaw = 0.0
    for t in chain:   # compose planar transforms world -> ... -> tip
        x, y = x + math.cos(yaw) * t.x - math.sin(yaw) * t.y, y + math.sin(yaw) * t.x + \
            math.cos(yaw) * t.y
        yaw += t.yaw
    xb, yb = ArmModel(scene).tip(q, [0, 0, 0])[:2]
    assert (x, y) == pytest.approx((xb, yb), abs=1e-12)
