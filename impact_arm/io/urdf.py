"""The robot description of a scene (URDF) and its frame tree, as plain Python (no rclpy).

Frames follow REP 103 (z up, gravity along -z); the model's plane is the world's x-z plane
(``contract.plane_to_world``):

* ``world`` — fixed; the model's origin O, x to the right, z up, y out of the screen when
  the arm is seen with x to the right and z up (the model's z is the world's -y);
* ``link1`` … ``linkN`` — one per rod, origin at the rod's proximal joint, x along the rod,
  y = world y. ``joint1`` (world → link1) turns by q1; ``jointk`` (link(k−1) → linkk, at
  x = L(k−1)) turns by the *relative* angle q_k − q_(k−1), so the joint values are the
  encoder angles of the wire and link k's x axis points along the model's absolute angle q_k.
  Every joint axis is ``0 -1 0`` (the model's z): a positive angle lifts the rod towards +z,
  as it lifts it towards the model's +y;
* ``tip`` — fixed to linkN at the contact point (x = L_N for rods): the centre B of the tip
  sphere (radius R1);
* ``surface1`` … — fixed to world, one per scene surface, at z = height (the surface plane),
  with the model's axes (``contract.PLANE_FRAME_ROTATION``): x tangential, y the outward
  normal (world +z). /contact_wrench is given in ``surface1``.

The joints are URDF ``continuous`` joints (revolute without position limits): the model has
none, and effort clipping is the simulator's ``max_effort`` parameter. A scene whose arm came
from a URDF with limits or ``<dynamics>`` (``Scene.joints``) gets them written back
(``revolute`` with its ``<limit>``), though the model does not act on them.

Each link's ``<inertial>`` is the model's: the centre of mass at (along, 0, across) of the link
frame (a rod's: mid-length), ``iyy`` the inertia about it about the joint axis (``izz`` the
same, as for a body slender along x). ``tip`` sits at the scene's contact point on the last
link (a rod's end unless the scene says otherwise); a scene reading this file back with
``arm: {urdf: ..., contact: {link: tip}}`` is the same arm (physics/scene/urdf.py).

Rods are drawn as cylinders of ``rod_radius`` (a visual setting: the model's rods are lines;
default ``ROD_RADIUS_PER_LENGTH`` of the shortest link). The tip sphere's collision radius is
the model's R1; its visual is at least ``TIP_PER_ROD`` rod radii, so it stands out of the rod.

The ``<ros2_control>`` block names ``topic_based_ros2_control/TopicBasedSystem`` so a
controller_manager can drive the simulator through its topic-hardware interface
(docs/ros2_control.md).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..contract import (
    PLANE_AXIS_IN_WORLD,
    PLANE_FRAME_ROTATION,
    WORLD_FRAME,
    plane_rotation,
    surface_frame,
)
from ..physics.errors import ImpactArmError
from .robot_tf import RobotTree, UrdfJoint, homogeneous, quaternion_from_rotation, rpy_from_rotation

from ..physics.scene import JointSpec

if TYPE_CHECKING:
    from ..physics.scene import Scene

# topic_based_ros2_control's TopicBasedSystem defaults: the simulator listens and publishes
# there unless told otherwise, so the URDF and the node agree out of the box
JOINT_COMMANDS_TOPIC = '/robot_joint_commands'
JOINT_STATES_TOPIC = '/robot_joint_states'
WORLD = WORLD_FRAME
TIP = 'tip'
# rods 1 % of the shortest link in radius: 10 mm on the article's 1 m links, thin enough to
# see the joints and the tip, thick enough to see the arm on a screen-sized view
ROD_RADIUS_PER_LENGTH = 0.01
TIP_PER_ROD = 2.5  # the tip sphere's visual radius, at least, in rod radii
SURFACE_THICKNESS_PER_REACH = 0.02


def link_names(n_links: int) -> list:
    return [f'link{i + 1}' for i in range(n_links)]


def scene_link_names(scene: Scene) -> list[str]:
    """The frames of ``scene``'s moving links, base first: a URDF arm's own link names (as
    its joints keep theirs, ``Scene.joint_names``), else link1..N. Refused in one line when a
    URDF link takes the name of a frame the description adds (world, tip, the surfaces)."""
    if not scene.link_names:
        return link_names(scene.n_links)
    reserved = {WORLD, TIP, *surface_frames(scene)}
    taken = [name for name in scene.link_names if name in reserved]
    if taken:
        raise VisualSettingError(
            f"arm.urdf link '{taken[0]}': the name of a frame the description adds "
            f'({", ".join(sorted(reserved))}): rename the link'
        )
    return list(scene.link_names)


def surface_frames(scene: Scene) -> list[str]:
    return [surface_frame(i) for i in range(len(scene.surfaces))]


class VisualSettingError(ImpactArmError, ValueError):
    """A drawing setting out of range."""


def default_rod_radius(scene: Scene) -> float:
    return ROD_RADIUS_PER_LENGTH * min(scene.lengths)


def rod_radius_of(scene: Scene, rod_radius: float | None = None) -> float:
    """``rod_radius`` [m] checked (None or 0: the default for ``scene``)."""
    if rod_radius is None or rod_radius == 0:
        return default_rod_radius(scene)
    rod_radius = float(rod_radius)
    if not (math.isfinite(rod_radius) and 0 < rod_radius <= min(scene.lengths)):
        raise VisualSettingError(
            f'rod_radius = {rod_radius!r}: must be > 0 and <= the '
            f'shortest link ({min(scene.lengths):g} m), or 0 for the '
            f'default'
        )
    return rod_radius


def tip_visual_radius(scene: Scene, rod_radius: float | None = None) -> float:
    return max(float(scene.tip_radius), TIP_PER_ROD * rod_radius_of(scene, rod_radius))


class Transform(NamedTuple):
    """Parent → child in the world's convention: translation (x, y, z) [m], then the rotation
    ``rotation`` (quaternion x, y, z, w)."""

    parent: str
    child: str
    x: float
    y: float
    z: float
    rotation: tuple

    def quaternion(self) -> tuple:
        """(x, y, z, w) of the rotation."""
        return self.rotation


def moving_transforms(
    lengths: Sequence[float], q: Sequence[float], links: Sequence[str] | None = None
) -> list[Transform]:
    """The joint transforms for absolute link angles ``q`` (one per link, chain order), into
    the frames ``links`` (default link1..N; a scene's: ``scene_link_names``)."""
    links = list(links) if links else link_names(len(lengths))
    out = [Transform(WORLD, links[0], 0.0, 0.0, 0.0, plane_rotation(float(q[0])))]
    for k in range(1, len(lengths)):
        out.append(
            Transform(
                links[k - 1],
                links[k],
                float(lengths[k - 1]),
                0.0,
                0.0,
                plane_rotation(float(q[k]) - float(q[k - 1])),
            )
        )
    return out


def static_transforms(scene: Scene) -> list[Transform]:
    """The fixed transforms: the tip on the last link, each surface on the world (a URDF
    arm's: ``WholeRobot.static``)."""
    if scene.plane is not None and scene.urdf_text:
        return WholeRobot(scene).static()
    along, across = scene.contact_point
    out = [
        Transform(
            scene_link_names(scene)[-1],
            TIP,
            float(along),
            0.0,
            float(across),  # the model's across (e⊥) is the link frame's +z
            (0.0, 0.0, 0.0, 1.0),
        )
    ]
    out += [
        Transform(WORLD, name, 0.0, 0.0, float(s.height), PLANE_FRAME_ROTATION)
        for name, s in zip(surface_frames(scene), scene.surfaces)
    ]
    return out


def _geometry_sizes(scene):
    reach = math.fsum(scene.lengths)
    return reach * SURFACE_THICKNESS_PER_REACH, reach


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


def robot_description(
    scene: Scene,
    *,
    name: str = 'impact_arm',
    joint_commands_topic: str = JOINT_COMMANDS_TOPIC,
    joint_states_topic: str = JOINT_STATES_TOPIC,
    rod_radius: float | None = None,
) -> str:
    """URDF text of ``scene``: for a URDF arm the whole robot (``whole_robot_description``),
    else the rods (the module docstring gives frames and conventions)."""
    if scene.plane is not None and scene.urdf_text:
        return whole_robot_description(
            scene,
            joint_commands_topic=joint_commands_topic,
            joint_states_topic=joint_states_topic,
            rod_radius=rod_radius,
        )
    return _rods_description(
        scene,
        name=name,
        joint_commands_topic=joint_commands_topic,
        joint_states_topic=joint_states_topic,
        rod_radius=rod_radius,
    )


def _rods_description(
    scene: Scene,
    *,
    name: str = 'impact_arm',
    joint_commands_topic: str = JOINT_COMMANDS_TOPIC,
    joint_states_topic: str = JOINT_STATES_TOPIC,
    rod_radius: float | None = None,
) -> str:
    """URDF text of ``scene`` (see the module docstring for frames and conventions)."""
    thickness, reach = _geometry_sizes(scene)
    rod_radius = rod_radius_of(scene, rod_radius)
    axis = ' '.join(_num(a) for a in PLANE_AXIS_IN_WORLD)
    robot = ET.Element('robot', name=name)
    for colour, rgba in (
        ('rod', '0.25 0.45 0.85 1'),
        ('tip', '0.9 0.3 0.2 1'),
        ('surface', '0.6 0.6 0.6 1'),
    ):
        _sub(_sub(robot, 'material', name=colour), 'color', rgba=rgba)
    _sub(robot, 'link', name=WORLD)
    links = scene_link_names(scene)
    joints = list(scene.joint_names)
    for k, (link_name, L, m, (cx, cy), i_c) in enumerate(
        zip(links, scene.lengths, scene.masses, scene.link_com, scene.link_inertias)
    ):
        link = _sub(robot, 'link', name=link_name)
        inertial = _sub(link, 'inertial')
        # the model's along / across the link are the link frame's x / z
        _sub(inertial, 'origin', xyz=f'{_num(cx)} 0 {_num(cy) if cy else 0}', rpy='0 0 0')
        _sub(inertial, 'mass', value=_num(m))
        # about the centre, about y (the joint axis) the model's inertia; about z the same,
        # as for a slender body along x (the model does not read it)
        _sub(inertial, 'inertia', ixx='0', ixy='0', ixz='0', iyy=_num(i_c), iyz='0', izz=_num(i_c))
        # URDF cylinders lie along z: turn by +90° about y to lay the rod along x
        _visual_and_collision(
            link,
            {'xyz': f'{_num(L / 2)} 0 0', 'rpy': f'0 {_num(math.pi / 2)} 0'},
            'cylinder',
            'rod',
            radius=_num(rod_radius),
            length=_num(L),
        )
        spec = scene.joints[k] if scene.joints else JointSpec(joints[k])
        limited = spec.lower is not None and spec.upper is not None
        joint = _sub(robot, 'joint', name=joints[k], type='revolute' if limited else 'continuous')
        _sub(joint, 'parent', link=WORLD if k == 0 else links[k - 1])
        _sub(joint, 'child', link=link_name)
        x = 0.0 if k == 0 else scene.lengths[k - 1]
        _sub(joint, 'origin', xyz=f'{_num(x)} 0 0', rpy='0 0 0')
        _sub(joint, 'axis', xyz=axis)
        limit = {
            key: _num(value)
            for key, value in (
                ('lower', spec.lower if limited else None),
                ('upper', spec.upper if limited else None),
                ('effort', spec.effort),
                ('velocity', spec.velocity),
            )
            if value is not None
        }
        if limit:
            if limited:  # URDF requires both on a revolute joint's limit
                limit.setdefault('effort', '0')
                limit.setdefault('velocity', '0')
            _sub(joint, 'limit', **limit)
        if spec.damping or spec.friction:
            _sub(joint, 'dynamics', damping=_num(spec.damping), friction=_num(spec.friction))
    tip = _sub(robot, 'link', name=TIP)
    _visual_and_collision(
        tip, {'xyz': '0 0 0', 'rpy': '0 0 0'}, 'sphere', 'tip', radius=_num(scene.tip_radius)
    )
    # drawn at least TIP_PER_ROD rod radii (R1 is a contact curvature, often far smaller)
    tip.find('visual/geometry/sphere').set('radius', _num(tip_visual_radius(scene, rod_radius)))
    for t in static_transforms(scene):
        if t.child != TIP:
            surface = _sub(robot, 'link', name=t.child)
            # a thin slab whose top face is the surface plane, wide enough for any reach
            _visual_and_collision(
                surface,
                {'xyz': f'0 {_num(-thickness / 2)} 0', 'rpy': '0 0 0'},
                'box',
                'surface',
                size=f'{_num(2 * reach)} {_num(thickness)} {_num(reach / 2)}',
            )
        joint = _sub(robot, 'joint', name=f'{t.child}_joint', type='fixed')
        _sub(joint, 'parent', link=t.parent)
        _sub(joint, 'child', link=t.child)
        roll = 2 * math.atan2(t.rotation[0], t.rotation[3])  # only rotations about x here
        _sub(joint, 'origin', xyz=f'{_num(t.x)} {_num(t.y)} {_num(t.z)}', rpy=f'{_num(roll)} 0 0')
    initial = scene.joint_coordinates.positions(scene.q0)
    _ros2_control(robot, joints, joint_commands_topic, joint_states_topic, initial)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'


def _ros2_control(robot, joints, commands_topic, states_topic, initial_positions):
    control = _sub(robot, 'ros2_control', name='impact_arm', type='system')
    hardware = _sub(control, 'hardware')
    _sub(hardware, 'plugin').text = 'topic_based_ros2_control/TopicBasedSystem'
    for key, value in (
        ('joint_commands_topic', commands_topic),
        ('joint_states_topic', states_topic),
        # TopicBasedSystem skips a write when the *position* commands are
        # within this of the position states; with effort-only commands that
        # test means nothing, and a negative threshold sends every command
        ('trigger_joint_command_threshold', '-1'),
    ):
        _sub(hardware, 'param', name=key).text = value
    for joint_name, position in zip(joints, initial_positions):
        joint = _sub(control, 'joint', name=joint_name)
        _sub(joint, 'command_interface', name='effort')
        for state in ('position', 'velocity', 'effort'):
            interface = _sub(joint, 'state_interface', name=state)
            # what the broadcaster publishes before the hardware's first state: the scene's
            # initial pose (the simulator's, braked until a command with a torque), so a
            # controller started before the simulator computes the torque that holds the
            # arm there, not one for an arm at zero angles
            initial = position if state == 'position' else 0.0
            _sub(interface, 'param', name='initial_value').text = _num(initial)


# ------------------------------------------------------------------ the whole robot
IMPACT_PLANE = 'impact_plane'
TIP_RGBA, SURFACE_RGBA = '0.9 0.3 0.2 1', '0.6 0.6 0.6 1'


def tip_position(
    lengths: Sequence[float], q: Sequence[float], tip_point: Sequence[float] | None = None
) -> tuple[float, float]:
    """(x, y) of the tip centre B in the model's plane for absolute link angles ``q``;
    ``tip_point``: B on the last link (along, across; default: its end)."""
    along, across = (lengths[-1], 0.0) if tip_point is None else tip_point
    x = [L * math.cos(a) for L, a in zip(lengths[:-1], q)]
    y = [L * math.sin(a) for L, a in zip(lengths[:-1], q)]
    c, s = math.cos(q[len(lengths) - 1]), math.sin(q[len(lengths) - 1])
    return math.fsum(x + [along * c - across * s]), math.fsum(y + [along * s + across * c])


def plane_pose(scene: Scene) -> np.ndarray:
    """4x4 of frame ``impact_plane`` in the URDF's root frame: origin O, rotation with the
    columns [x, -axis, y] of the model's plane, so that a point (x, y) of the plane is
    (x, 0, y) in it, as ``contract.plane_to_world`` puts it in ``world`` for the rods."""
    plane = scene.plane
    assert plane is not None
    R = np.column_stack([plane.x, [-a for a in plane.axis], plane.y])
    return homogeneous(R, plane.origin)


def _model_link_rotation(angle: float) -> np.ndarray:
    """A rod frame's rotation in the plane frame at absolute angle ``angle``: about the
    model's z (the frame's -y), as ``contract.plane_rotation``."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


class WholeRobot:
    """A URDF arm's frames as robot_state_publisher gives them (io/robot_tf.py), with the
    frames the project adds: ``impact_plane`` on the root link (``plane_pose``), ``tip`` on
    the last moving link at the model's contact point B (the rods' tip frame: x along the
    last model link, y = the plane's -axis), the surfaces on ``impact_plane``. Locked joints
    sit at ``Scene.locked_joints``, the moving ones at the robot's joint angles."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.element, old_tip = _original_robot(scene)
        self.tree = RobotTree(ET.tostring(self.element, encoding='unicode'))
        self.moving_names = list(scene.joint_names)
        self.locked = dict(scene.locked_joints)
        reserved = {IMPACT_PLANE, TIP, *surface_frames(scene)}
        taken = [name for name in self.tree.links if name in reserved]
        if taken:
            raise VisualSettingError(
                f"arm.urdf link '{taken[0]}': the name of a frame the description adds "
                f'({", ".join(sorted(reserved))}): rename the link'
            )
        joints = {f'{frame}_joint' for frame in reserved}
        taken = [j.name for j in self.tree.joints if j.name in joints]
        if taken:
            raise VisualSettingError(
                f"arm.urdf joint '{taken[0]}': the name of a joint the description adds "
                f'({", ".join(sorted(joints))}): rename the joint'
            )
        self.plane = plane_pose(scene)
        # the tip frame on the last moving link, where the model puts B at the robot's zero
        zero = self.values([0.0] * scene.n_links)
        link = self.tree.poses(zero)[scene.link_names[-1]]
        q = scene.joint_coordinates.absolute([0.0] * scene.n_links)
        # B relative to the last model link's joint, turned into the URDF link's frame, plus
        # the link origin's step onto the plane (its offset along the axis, if any). Numbers
        # within SNAP of 0 or ±1 are taken as exact: a description in the model's own frames
        # gets its contact point back to the last bit
        R = _snap(link[:3, :3].T @ self.plane[:3, :3] @ _model_link_rotation(q[-1]))
        along, across = scene.contact_point
        axis = np.array(scene.plane.axis)  # type: ignore[union-attr]  # a URDF arm's
        off_plane = (link[:3, 3] - self.plane[:3, 3]) @ axis
        step = _snap(link[:3, :3].T @ (-off_plane * axis))
        self.tip = homogeneous(R, R @ np.array([float(along), 0.0, float(across)]) + step)
        self.keep_tip = False
        if old_tip is not None and old_tip.parent == scene.link_names[-1]:
            # a tip a description written here added, where the scene puts it: kept as
            # written, so that the robot read back from it is the same arm to the last bit
            if np.allclose(old_tip.origin, self.tip, rtol=0.0, atol=1e-9):
                self.tip, self.keep_tip = old_tip.origin, True
                self.tip_origin = (old_tip.xyz, old_tip.rpy)

    def values(self, theta: Sequence[float]) -> dict[str, float]:
        """Every joint's value for the robot's joint angles ``theta`` of the moving joints."""
        out = dict(self.locked)
        out.update((name, float(v)) for name, v in zip(self.moving_names, theta))
        return out

    def added_poses(self) -> list[tuple[str, str, np.ndarray | None, float]]:
        """(parent, child, pose, surface height) of the frames the project adds (all fixed):
        impact_plane and tip (pose: 4x4 in the parent), the surfaces (pose None: at their
        height, turned +90 deg about x like the rods' surfaces)."""
        out: list[tuple[str, str, np.ndarray | None, float]] = [
            (self.tree.root, IMPACT_PLANE, self.plane, 0.0),
            (self.scene.link_names[-1], TIP, self.tip, 0.0),
        ]
        out += [
            (IMPACT_PLANE, name, None, float(s.height))
            for name, s in zip(surface_frames(self.scene), self.scene.surfaces)
        ]
        return out

    def added(self) -> list[Transform]:
        """The frames the project adds, as transforms."""
        return [
            Transform(parent, child, 0.0, 0.0, height, PLANE_FRAME_ROTATION)
            if T is None
            else _as_transform(parent, child, T)
            for parent, child, T, height in self.added_poses()
        ]

    def static(self) -> list[Transform]:
        """/tf_static: the URDF's fixed joints, then the added frames."""
        return [_as_transform(j.parent, j.child, j.origin) for j in self.tree.fixed] + self.added()

    def moving(self, q: Sequence[float]) -> list[Transform]:
        """/tf for absolute link angles ``q``: every non-fixed joint of the URDF."""
        values = self.values(self.scene.joint_coordinates.positions(q))
        return [_as_transform(j.parent, j.child, T) for j, T in self.tree.transforms(values)]


SNAP = 1e-12


def _snap(a: np.ndarray) -> np.ndarray:
    """``a`` with its entries within ``SNAP`` of 0, 1 or -1 made exact."""
    out = np.array(a, dtype=float)
    for exact in (0.0, 1.0, -1.0):
        out[np.abs(out - exact) < SNAP] = exact
    return out


def _original_robot(scene: Scene) -> tuple[ET.Element, UrdfJoint | None]:
    """The URDF's ``<robot>`` (its comments kept) without its ``<ros2_control>`` elements
    and without the frames a description written here added (a leaf link named ``tip``,
    ``impact_plane`` or ``surfaceK`` on a fixed joint ``<name>_joint``): a robot read back
    from ``impact-arm urdf`` gets them again, at the scene's values. Also the removed
    ``tip_joint``, if any."""
    robot = ET.fromstring(
        scene.urdf_text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    )
    for element in robot.findall('ros2_control'):
        robot.remove(element)
    old_tip = None
    removed = True
    while removed:  # leaves first: the surfaces, then impact_plane they hang from
        removed = False
        parents = {
            j.find('parent').get('link')  # type: ignore[union-attr]
            for j in robot.findall('joint')
            if j.find('parent') is not None
        }
        for joint in robot.findall('joint'):
            child = joint.find('child')
            name = '' if child is None else child.get('link', '')
            added = name in (TIP, IMPACT_PLANE) or re.fullmatch(r'surface[1-9][0-9]*', name)
            if not (
                added
                and joint.get('type') == 'fixed'
                and joint.get('name') == f'{name}_joint'
                and name not in parents
            ):
                continue
            if name == TIP:
                old_tip = RobotTree(
                    f'<robot><link name="{joint.find("parent").get("link")}"/>'  # type: ignore[union-attr]
                    f'<link name="{TIP}"/>{ET.tostring(joint, encoding="unicode")}</robot>'
                ).joints[0]
            robot.remove(joint)
            for link in robot.findall('link'):
                if link.get('name') == name:
                    robot.remove(link)
            removed = True
    return robot, old_tip


def _as_transform(parent: str, child: str, T: np.ndarray) -> Transform:
    x, y, z = (float(v) for v in T[:3, 3])
    return Transform(parent, child, x, y, z, quaternion_from_rotation(T[:3, :3]))


def whole_robot_description(
    scene: Scene,
    *,
    joint_commands_topic: str = JOINT_COMMANDS_TOPIC,
    joint_states_topic: str = JOINT_STATES_TOPIC,
    rod_radius: float | None = None,
) -> str:
    """A URDF arm's description: the original robot as it ships (its root pose kept, its
    comments too), its ``<ros2_control>`` elements replaced by the project's, naming the
    moving joints; plus ``impact_plane``, ``tip`` and the surfaces (``WholeRobot``)."""
    whole = WholeRobot(scene)
    thickness, reach = _geometry_sizes(scene)
    robot = whole.element
    for parent, child, T, height in whole.added_poses():
        link = _sub(robot, 'link', name=child)
        if child == TIP:
            _visual_and_collision(
                link, {'xyz': '0 0 0', 'rpy': '0 0 0'}, 'sphere', radius=_num(scene.tip_radius)
            )
            # drawn at least TIP_PER_ROD rod radii, as the rods' tip
            link.find('visual/geometry/sphere').set(
                'radius', _num(tip_visual_radius(scene, rod_radius))
            )
        elif child != IMPACT_PLANE:
            # a thin slab whose top face is the surface plane, wide enough for any reach
            _visual_and_collision(
                link,
                {'xyz': f'0 {_num(-thickness / 2)} 0', 'rpy': '0 0 0'},
                'box',
                size=f'{_num(2 * reach)} {_num(thickness)} {_num(reach / 2)}',
            )
        if child != IMPACT_PLANE:  # inline materials: no clash with the robot's names
            material = _sub(link.find('visual'), 'material', name=f'impact_arm_{child}')
            _sub(material, 'color', rgba=TIP_RGBA if child == TIP else SURFACE_RGBA)
        joint = _sub(robot, 'joint', name=f'{child}_joint', type='fixed')
        _sub(joint, 'parent', link=parent)
        _sub(joint, 'child', link=child)
        xyz: Sequence[float]
        rpy: Sequence[float]
        if T is None:
            xyz, rpy = (0.0, 0.0, height), (math.pi / 2, 0.0, 0.0)
        else:
            xyz, rpy = tuple(float(v) for v in T[:3, 3]), rpy_from_rotation(T[:3, :3])
        if child == TIP and whole.keep_tip:
            xyz, rpy = whole.tip_origin
        # (+ 0.0: no '-0.0' in the text)
        _sub(
            joint,
            'origin',
            xyz=' '.join(_num(v + 0.0) for v in xyz),
            rpy=' '.join(_num(v + 0.0) for v in rpy),
        )
    initial = scene.joint_coordinates.positions(scene.q0)
    _ros2_control(robot, whole.moving_names, joint_commands_topic, joint_states_topic, initial)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'
