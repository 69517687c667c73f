"""The robot description of a scene (URDF) and its frame tree, as plain Python (no rclpy).

Frames (all in the x–y plane of the model, z out of it):

* ``world`` — fixed; the model's origin O, x to the right, y up (gravity along −y);
* ``link1`` … ``linkN`` — one per rod, origin at the rod's proximal joint, x along the rod.
  ``joint1`` (world → link1) turns by q1; ``jointk`` (link(k−1) → linkk, at x = L(k−1)) turns by
  the *relative* angle q_k − q_(k−1), so the joint values are the encoder angles of design.md §3
  and link k's x axis points along the model's absolute angle q_k;
* ``tip`` — fixed to linkN at x = L_N: the centre B of the tip sphere (radius R1);
* ``surface1`` … — fixed to world, one per scene surface, at y = height (the surface plane).

The joints are URDF ``continuous`` joints (revolute about z without position limits): the
model has none, and effort clipping is the simulator's ``max_effort`` parameter.

The ``<ros2_control>`` block names ``topic_based_ros2_control/TopicBasedSystem`` so a
controller_manager can drive the simulator through its topic-hardware interface
(docs/ros2_control.md).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import NamedTuple

from ..contract import joint_names

# topic_based_ros2_control's TopicBasedSystem defaults: the simulator listens and publishes
# there unless told otherwise, so the URDF and the node agree out of the box
JOINT_COMMANDS_TOPIC = '/robot_joint_commands'
JOINT_STATES_TOPIC = '/robot_joint_states'
WORLD = 'world'
TIP = 'tip'
ROD_RADIUS_PER_REACH = 0.015   # visual thickness of the rods (the model's rods are lines)
SURFACE_THICKNESS_PER_REACH = 0.02


def link_names(n_links: int) -> list:
    return [f'link{i + 1}' for i in range(n_links)]


def surface_frames(scene) -> list:
    return [f'surface{i + 1}' for i in range(len(scene.surfaces))]


class Transform(NamedTuple):
    """Parent → child: translation (x, y) [m], then a rotation by ``yaw`` [rad] about z."""
    parent: str
    child: str
    x: float
    y: float
    yaw: float

    def quaternion(self) -> tuple:
        """(x, y, z, w) of the rotation."""
        return 0.0, 0.0, math.sin(self.yaw / 2), math.cos(self.yaw / 2)


def moving_transforms(lengths, q) -> list:
    """The joint transforms for absolute link angles ``q`` (one per link, chain order)."""
    links = link_names(len(lengths))
    out = [Transform(WORLD, links[0], 0.0, 0.0, float(q[0]))]
    for k in range(1, len(lengths)):
        out.append(Transform(links[k - 1], links[k], float(lengths[k - 1]), 0.0,
                             float(q[k]) - float(q[k - 1])))
    return out


def static_transforms(scene) -> list:
    """The fixed transforms: the tip on the last link, each surface on the world."""
    out = [Transform(link_names(scene.n_links)[-1], TIP, float(scene.lengths[-1]), 0.0, 0.0)]
    out += [Transform(WORLD, name, 0.0, float(s.height), 0.0)
            for name, s in zip(surface_frames(scene), scene.surfaces)]
    return out


def _geometry_sizes(scene):
    reach = math.fsum(scene.lengths)
    return reach * ROD_RADIUS_PER_REACH, reach * SURFACE_THICKNESS_PER_REACH, reach


def _sub(parent, tag, **attrs):
    return ET.SubElement(parent, tag, {k: str(v) for k, v in attrs.items()})


def _num(v: float) -> str:
    return repr(float(v))


def _visual_and_collision(link, origin, geometry_tag, material=None, **size):
    for kind in ('visual', 'collision'):
        element = _sub(link, kind)
        _sub(element, 'origin', **origin)
        _sub(_sub(element, 'geometry'), geometry_tag, **size)
        if kind == 'visual' and material:
            _sub(element, 'material', name=material)


def robot_description(scene, *, name: str = 'impact_arm',
                      joint_commands_topic: str = JOINT_COMMANDS_TOPIC,
                      joint_states_topic: str = JOINT_STATES_TOPIC) -> str:
    """URDF text of ``scene`` (see the module docstring for frames and conventions)."""
    rod_radius, thickness, reach = _geometry_sizes(scene)
    robot = ET.Element('robot', name=name)
    for colour, rgba in (('rod', '0.25 0.45 0.85 1'), ('tip', '0.9 0.3 0.2 1'),
                         ('surface', '0.6 0.6 0.6 1')):
        _sub(_sub(robot, 'material', name=colour), 'color', rgba=rgba)
    _sub(robot, 'link', name=WORLD)
    links = link_names(scene.n_links)
    joints = joint_names(scene.n_links)
    for k, (link_name, L, m) in enumerate(zip(links, scene.lengths, scene.masses)):
        link = _sub(robot, 'link', name=link_name)
        inertial = _sub(link, 'inertial')
        _sub(inertial, 'origin', xyz=f'{_num(L / 2)} 0 0', rpy='0 0 0')
        _sub(inertial, 'mass', value=_num(m))
        # a uniform slender rod along x, about its centre: the model's inertia (model.md)
        i_c = m * L * L / 12
        _sub(inertial, 'inertia', ixx='0', ixy='0', ixz='0', iyy=_num(i_c), iyz='0',
             izz=_num(i_c))
        # URDF cylinders lie along z: turn by +90° about y to lay the rod along x
        _visual_and_collision(link, {'xyz': f'{_num(L / 2)} 0 0',
                                     'rpy': f'0 {_num(math.pi / 2)} 0'},
                              'cylinder', 'rod', radius=_num(rod_radius), length=_num(L))
        joint = _sub(robot, 'joint', name=joints[k], type='continuous')
        _sub(joint, 'parent', link=WORLD if k == 0 else links[k - 1])
        _sub(joint, 'child', link=link_name)
        x = 0.0 if k == 0 else scene.lengths[k - 1]
        _sub(joint, 'origin', xyz=f'{_num(x)} 0 0', rpy='0 0 0')
        _sub(joint, 'axis', xyz='0 0 1')
    tip = _sub(robot, 'link', name=TIP)
    _visual_and_collision(tip, {'xyz': '0 0 0', 'rpy': '0 0 0'}, 'sphere', 'tip',
                          radius=_num(scene.tip_radius))
    for t in static_transforms(scene):
        if t.child != TIP:
            surface = _sub(robot, 'link', name=t.child)
            # a thin slab whose top face is the surface plane, wide enough for any reach
            _visual_and_collision(surface, {'xyz': f'0 {_num(-thickness / 2)} 0',
                                            'rpy': '0 0 0'}, 'box', 'surface',
                                  size=f'{_num(2 * reach)} {_num(thickness)} {_num(reach / 2)}')
        joint = _sub(robot, 'joint', name=f'{t.child}_joint', type='fixed')
        _sub(joint, 'parent', link=t.parent)
        _sub(joint, 'child', link=t.child)
        _sub(joint, 'origin', xyz=f'{_num(t.x)} {_num(t.y)} 0', rpy='0 0 0')
    _ros2_control(robot, joints, joint_commands_topic, joint_states_topic)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'


def _ros2_control(robot, joints, commands_topic, states_topic):
    control = _sub(robot, 'ros2_control', name='impact_arm', type='system')
    hardware = _sub(control, 'hardware')
    _sub(hardware, 'plugin').text = 'topic_based_ros2_control/TopicBasedSystem'
    for key, value in (('joint_commands_topic', commands_topic),
                       ('joint_states_topic', states_topic),
                       # TopicBasedSystem skips a write when the *position* commands are
                       # within this of the position states; with effort-only commands that
                       # test means nothing, and a negative threshold sends every command
                       ('trigger_joint_command_threshold', '-1')):
        _sub(hardware, 'param', name=key).text = value
    for joint_name in joints:
        joint = _sub(control, 'joint', name=joint_name)
        _sub(joint, 'command_interface', name='effort')
        for state in ('position', 'velocity', 'effort'):
            _sub(joint, 'state_interface', name=state)
