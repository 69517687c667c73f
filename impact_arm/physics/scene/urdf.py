"""An arm read from its robot description (URDF): the planar chain the model simulates.

Plain XML (no ROS): the scene key ``arm.urdf`` names the file (docs/scene.md, "Your robot's
URDF"). The description is taken as it ships, in its own frames:

* the **moving joints** are ``arm.joints`` (base to tip), or, when the scene does not list
  them, every revolute or continuous joint of the one serial chain the description is. Their
  axes may point anywhere, as long as they are parallel or antiparallel to one another at the
  locked posture (an antiparallel joint turns the other way: its sign is -1);
* every other non-fixed joint between the root and the contact link is **locked** at the value
  ``arm.locked`` gives (the joint's own unit: rad, or m for a prismatic joint); joints that hang
  off the arm (a gripper's fingers) are locked at the value given, else at zero (said once in
  ``UrdfArm.notes``). A locked joint is a fixed joint at that value;
* everything before the first moving joint is **ground**; every link between moving joint k and
  moving joint k+1 (or past the last one) is merged into the k-th rigid body (mass, centre of
  mass, inertia about the joint axis by the parallel-axis theorem);
* the **model's plane** is normal to the first moving joint's axis, through that joint (the
  model's origin O). Its y axis is the world's up (+z) as seen in the plane, its x axis
  completes the frame so that positive angles turn counter-clockwise about the first axis.
  Gravity acts through its component in the plane (``gravity_scale`` of it): the component
  along the axis is carried by the bearings. Offsets along the axis (a link beside the next)
  and a contact point off the plane are taken at their projections;
* each model link runs from its joint to the next (the last: it keeps the direction of the
  previous link at the robot's zero, so that its joint needs no offset). The robot's joint
  angle θ_k (its zero and sign, as its driver reports it) and the model's relative angle
  r_k = q_k - q_(k-1) are related by r_k = sign_k θ_k + offset_k (``JointSpec``).

Joint limits and ``<dynamics damping friction>`` are read and kept (``JointSpec``).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import NoReturn

import numpy as np

from ..errors import SceneError
from .types import JointSpec, PlaneFrame

MAX_URDF_BYTES = 4 << 20  # descriptions with long inline meshes lists run to a few 100 kB
MOVING = ('revolute', 'continuous')
LOCKABLE = ('revolute', 'continuous', 'prismatic')
PLANE_TOLERANCE = 1e-12  # m or rad: what counts as zero in a description's numbers
PARALLEL_TOLERANCE = 1e-9  # rad: two joint axes closer than this are parallel
MIN_LINK_LENGTH = 1e-9  # m: two joints closer in the plane have no link between them
WORLD_UP = np.array([0.0, 0.0, 1.0])  # REP 103: gravity along the world's -z


@dataclass(frozen=True)
class UrdfArm:
    """The chain as the model takes it: per moving link (chain order) its name, length (to
    the next joint; the last link's: the distance of the contact point from its joint),
    mass, centre of mass (along, across) and inertia about it; the contact point (along,
    across) on the last link and the sphere's radius; the moving joints; the locked joints
    of the chain with their values; the plane; what was assumed (``notes``)."""

    link_names: tuple[str, ...]
    lengths: tuple[float, ...]
    masses: tuple[float, ...]
    com: tuple[tuple[float, float], ...]
    inertias: tuple[float, ...]
    tip_point: tuple[float, float]
    tip_radius: float
    joints: tuple[JointSpec, ...]
    locked: tuple[tuple[str, float], ...] = ()
    plane: PlaneFrame | None = None
    gravity_scale: float = 1.0  # the part of the world's gravity that lies in the plane
    notes: tuple[str, ...] = ()


def _vector(
    text: str | None, default: Sequence[float], what: str, fail: Callable[[str], NoReturn]
) -> tuple[float, ...]:
    if text is None:
        return tuple(default)
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        fail(f'{what} = {text[:60]!r} is not a list of numbers')
    if len(values) != len(default) or not all(math.isfinite(v) for v in values):
        fail(f'{what} = {text[:60]!r} must be {len(default)} finite numbers')
    return values


def _number(
    element: ET.Element | None, key: str, what: str, fail: Callable[[str], NoReturn]
) -> float | None:
    if element is None or element.get(key) is None:
        return None
    text = element.get(key, '')
    try:
        value = float(text)
    except ValueError:
        fail(f'{what} = {text[:60]!r} is not a number')
    if not math.isfinite(value):
        fail(f'{what} = {text[:60]!r} is not finite')
    return value


def rotation_from_rpy(rpy: Sequence[float]) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    if r == p == y == 0:
        return np.eye(3)  # exactly: a description in the model's own frames stays exact
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues)."""
    if angle == 0:
        return np.eye(3)
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple[float, ...]
    rpy: tuple[float, ...]
    axis: np.ndarray  # unit, in the joint frame
    element: ET.Element

    def motion(self, value: float) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, translation) of the child frame in the parent's at joint ``value``."""
        return joint_motion(self.kind, self.xyz, self.rpy, self.axis, value)


STILL = ('fixed', 'floating', 'planar')  # taken at their origin: no single value moves them


def joint_motion(
    kind: str,
    xyz: Sequence[float],
    rpy: Sequence[float],
    axis: Sequence[float] | np.ndarray,
    value: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, translation) of a URDF joint's child frame in its parent's at ``value``
    (rad, or m for a prismatic joint; ``axis`` a unit vector): the origin, then the motion
    about or along the axis, as robot_state_publisher composes them."""
    R = rotation_from_rpy(rpy)
    p = np.array(xyz, dtype=float)
    if value == 0 or kind in STILL:
        return R, p
    if kind == 'prismatic':
        return R, p + R @ (np.asarray(axis, dtype=float) * value)
    return R @ axis_rotation(np.asarray(axis, dtype=float), value), p


@dataclass(frozen=True)
class _Inertial:
    mass: float
    com: np.ndarray  # in the link frame
    tensor: np.ndarray  # about the centre of mass, in the link frame


def read_urdf_file(path: str, origin: str) -> str:
    """The text of the description at ``path``, or ``SceneError`` naming ``origin`` (the
    scene key that gave it)."""
    try:
        with open(path, 'rb') as f:
            data = f.read(MAX_URDF_BYTES + 1)
    except OSError as exc:
        raise SceneError(f"{origin} = '{path}': cannot be read: {exc.strerror}") from None
    if len(data) > MAX_URDF_BYTES:
        raise SceneError(f"{origin} = '{path}': larger than {MAX_URDF_BYTES} bytes")
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise SceneError(f"{origin} = '{path}': not UTF-8 text (byte {exc.start})") from None


class _Description:
    """The links and joints of a URDF, checked as a tree."""

    def __init__(self, text: str, fail: Callable[[str], NoReturn]) -> None:
        self.fail = fail
        try:
            root = ET.fromstring(text)
        except ET.ParseError as exc:
            hint = (
                ' (a xacro file? give it as arm.xacro, or expand it first: xacro FILE > FILE.urdf)'
                if 'xacro' in text
                else ''
            )
            fail(f'not valid XML: {exc}{hint}')
        if root.tag != 'robot':
            fail(f'the top element is <{root.tag[:40]}>, not <robot>: not a URDF')
        self.links: dict[str, ET.Element] = {}
        for element in root.findall('link'):
            name = element.get('name')
            if not name:
                fail('a <link> has no name')
            if name in self.links:
                fail(f"link '{name}' is defined twice")
            self.links[name] = element
        self.joints: dict[str, _Joint] = {}
        self.by_child: dict[str, _Joint] = {}
        for element in root.findall('joint'):
            joint = self._joint(element)
            if joint.name in self.joints:
                fail(f"joint '{joint.name}' is defined twice")
            if joint.child in self.by_child:
                fail(
                    f"joint '{joint.name}': link '{joint.child}' is already the child of joint "
                    f"'{self.by_child[joint.child].name}' (not a tree)"
                )
            self.joints[joint.name] = joint
            self.by_child[joint.child] = joint
        roots = [name for name in self.links if name not in self.by_child]
        if len(roots) != 1:
            fail(f'has {len(roots)} root links ({", ".join(roots)[:80]}): must be one tree')
        self.root = roots[0]
        self.children: dict[str, list[_Joint]] = {name: [] for name in self.links}
        for joint in self.joints.values():
            self.children[joint.parent].append(joint)

    def _joint(self, element: ET.Element) -> _Joint:
        fail = self.fail
        name = element.get('name') or ''
        if not name:
            fail('a <joint> has no name')
        where = f"joint '{name}'"
        parent, child = element.find('parent'), element.find('child')
        if parent is None or child is None or not parent.get('link') or not child.get('link'):
            fail(f'{where} needs <parent link=...> and <child link=...>')
        assert parent is not None and child is not None  # for mypy: fail() raised otherwise
        origin_element = element.find('origin')
        axis_element = element.find('axis')
        raw_axis = _vector(
            None if axis_element is None else axis_element.get('xyz'),
            (1.0, 0.0, 0.0),  # URDF's default axis
            f'{where} axis',
            fail,
        )
        kind = element.get('type', '')
        norm = math.sqrt(sum(a * a for a in raw_axis))
        if norm == 0 and kind != 'fixed':
            fail(f'{where} axis = 0 0 0: has no direction')
        joint = _Joint(
            name,
            kind,
            parent.get('link', ''),
            child.get('link', ''),
            _vector(
                None if origin_element is None else origin_element.get('xyz'),
                (0.0, 0.0, 0.0),
                f'{where} origin xyz',
                fail,
            ),
            _vector(
                None if origin_element is None else origin_element.get('rpy'),
                (0.0, 0.0, 0.0),
                f'{where} origin rpy',
                fail,
            ),
            np.array(raw_axis) / (norm or 1.0),
            element,
        )
        for end in (joint.parent, joint.child):
            if end not in self.links:
                fail(f"{where} names link '{end[:60]}', which the description does not define")
        return joint

    def path_to(self, link: str) -> list[_Joint]:
        """The joints from the root to ``link``, root first."""
        path = []
        while link in self.by_child:
            joint = self.by_child[link]
            path.append(joint)
            link = joint.parent
        return path[::-1]

    def inertial(self, name: str) -> _Inertial | None:
        """The link's inertial, or None if it has none."""
        fail = self.fail
        inertial = self.links[name].find('inertial')
        if inertial is None or inertial.find('mass') is None:
            return None
        mass = _number(inertial.find('mass'), 'value', f"link '{name}' mass", fail) or 0.0
        if mass < 0:
            fail(f"link '{name}' mass = {mass:g} is negative")
        origin_element = inertial.find('origin')
        xyz = _vector(
            None if origin_element is None else origin_element.get('xyz'),
            (0.0, 0.0, 0.0),
            f"link '{name}' inertial origin xyz",
            fail,
        )
        rpy = _vector(
            None if origin_element is None else origin_element.get('rpy'),
            (0.0, 0.0, 0.0),
            f"link '{name}' inertial origin rpy",
            fail,
        )
        tensor_element = inertial.find('inertia')
        e = {}
        for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
            value = _number(tensor_element, key, f"link '{name}' inertia {key}", fail)
            e[key] = 0.0 if value is None else value
        tensor = np.array(
            [
                [e['ixx'], e['ixy'], e['ixz']],
                [e['ixy'], e['iyy'], e['iyz']],
                [e['ixz'], e['iyz'], e['izz']],
            ]
        )
        R = rotation_from_rpy(rpy)
        # given in the inertial frame: in the link frame it is R I R^T
        return _Inertial(mass, np.array(xyz, dtype=float), R @ tensor @ R.T)


def _check_kind(joint: _Joint, fail: Callable[[str], NoReturn]) -> None:
    if joint.element.find('mimic') is not None:
        fail(
            f"joint '{joint.name}' mimics another joint: the model's joints move "
            f'independently, each driven by its own torque (lock it: arm.locked)'
        )
    if joint.kind not in LOCKABLE + ('fixed',):
        fail(
            f"joint '{joint.name}' is of type {joint.kind!r}: the model is a planar "
            f'chain of hinges; revolute and continuous joints move or are locked, prismatic '
            f'ones are locked (arm.locked), fixed ones attach frames'
        )


def _moving_joints(
    robot: _Description,
    names: Sequence[str] | None,
    contact_link: str | None,
    fail: Callable[[str], NoReturn],
) -> tuple[list[_Joint], str]:
    """The moving joints (base to tip) and the contact link."""
    if names is not None:
        chain = []
        for k, name in enumerate(names):
            if name not in robot.joints:
                fail(f"arm.joints[{k}] = '{name[:60]}' is not a joint of the description")
            joint = robot.joints[name]
            if joint.kind not in MOVING:
                fail(
                    f"arm.joints[{k}] = '{name}' is a {joint.kind} joint: the model's moving "
                    f'joints are revolute or continuous'
                )
            chain.append(joint)
        if len(set(names)) != len(names):
            fail(f'arm.joints names a joint twice ({", ".join(names)[:80]})')
        link = contact_link or chain[-1].child if chain else ''
        return chain, link
    # no list: the one serial chain of every revolute and continuous joint
    moving = [j for j in robot.joints.values() if j.kind in MOVING]
    if not moving:
        fail('has no revolute or continuous joint: no arm to simulate')
    if contact_link is not None and contact_link in robot.links:
        end = contact_link
    else:
        end = max(moving, key=lambda j: len(robot.path_to(j.child))).child
    on_path = [j for j in robot.path_to(end) if j.kind in MOVING]
    if not on_path:
        fail(f"no revolute or continuous joint lies between the root and link '{end}'")
    deepest = on_path[-1]
    off = [j for j in moving if j not in on_path]
    beyond = [j for j in off if end in [k.child for k in robot.path_to(j.child)]]
    if beyond:
        fail(
            f"joint '{beyond[0].name}' moves beyond the contact link '{end}': the model's "
            f'contact is on the last moving link (or list the moving joints as arm.joints '
            f'and lock the others with arm.locked)'
        )
    if off:
        branch = off[0]
        fail(
            f"joints '{branch.name}' and '{deepest.name}' lie on different branches: the "
            f'model is one serial chain; list the moving joints as arm.joints (base to tip) '
            f'and lock the others (arm.locked)'
        )
    return on_path, contact_link or on_path[-1].child


def parse_urdf_arm(
    text: str,
    origin: str,
    contact_link: str | None = None,
    contact_point: Sequence[float] | None = None,
    contact_radius: float | None = None,
    joints: Sequence[str] | None = None,
    locked: Mapping[str, float] | None = None,
) -> UrdfArm:
    """The planar chain of the description ``text`` (module docstring), or ``SceneError``
    in one line starting with ``origin``. ``joints`` lists the moving joints base to tip
    (default: every revolute and continuous joint of the one chain); ``locked`` gives the
    values of the other joints; ``contact_link`` (default: the last moving link),
    ``contact_point`` (x, y, z in that link's frame) and ``contact_radius`` place the
    contact sphere; a point or radius not given comes from the link's collision sphere."""

    def fail(message: str) -> NoReturn:
        raise SceneError(f'{origin}: {message}')

    robot = _Description(text, fail)
    locked = dict(locked or {})
    chain, contact = _moving_joints(robot, joints, contact_link, fail)
    if contact not in robot.links:
        fail(f"arm.contact.link = '{contact[:60]}' is not a link of the description")
    path = robot.path_to(contact)
    for joint in path:
        _check_kind(joint, fail)
    on_path = {j.name for j in path}
    for k, joint in enumerate(chain):
        if joint.name not in on_path:
            fail(
                f"arm.joints[{k}] = '{joint.name}' is not between the root and the contact "
                f"link '{contact}'"
            )
    order = [j.name for j in path if j.name in {c.name for c in chain}]
    if order != [j.name for j in chain]:
        fail(f'arm.joints must run from the base to the tip: {", ".join(order)}')
    n = len(chain)
    moving_names = {j.name for j in chain}
    missing = [j.name for j in path if j.kind != 'fixed' and j.name not in moving_names]
    missing = [name for name in missing if name not in locked]
    if missing:
        fail(
            f'joints {", ".join(repr(m) for m in missing[:8])} lie between the root and the '
            f'contact link and are not moving (arm.joints): give their values in arm.locked'
        )
    for name, value in locked.items():
        if name not in robot.joints:
            fail(f"arm.locked names '{name[:60]}', which is not a joint of the description")
        joint = robot.joints[name]
        if name in moving_names:
            fail(f"arm.locked names '{name}', which is a moving joint (arm.joints)")
        if joint.kind not in LOCKABLE:
            fail(f"arm.locked names '{name}', a {joint.kind} joint: only a moving joint locks")
        limit = joint.element.find('limit')
        lower = _number(limit, 'lower', f"joint '{name}' limit lower", fail)
        upper = _number(limit, 'upper', f"joint '{name}' limit upper", fail)
        if joint.kind != 'continuous' and lower is not None and upper is not None:
            if lower < upper and not lower <= value <= upper:
                fail(
                    f"arm.locked.{name} = {value:g} is outside the joint's limits "
                    f'[{lower:g}, {upper:g}]'
                )

    # Walk the tree from the root at the robot's zero: each link's pose in the frame of the
    # body it belongs to (-1: the ground, k: the k-th moving joint's), and each body's
    # joint frame in the world. Poses relative to the body's joint frame keep a description
    # written in the model's own frames exact.
    first = chain[0]
    body_of_joint = {j.name: k for k, j in enumerate(chain)}
    pose: dict[str, tuple[int, np.ndarray, np.ndarray]] = {robot.root: (-1, np.eye(3), np.zeros(3))}
    world: dict[int, tuple[np.ndarray, np.ndarray]] = {-1: (np.eye(3), np.zeros(3))}
    at: dict[int, np.ndarray] = {}  # each moving joint's origin in the previous body's frame
    hanging: list[str] = []
    stack = [robot.root]
    while stack:
        name = stack.pop()
        body, R, p = pose[name]
        for joint in robot.children[name]:
            if joint.name in body_of_joint:
                k = body_of_joint[joint.name]
                Rj, pj = joint.motion(0.0)
                Rw, pw = world[body]
                at[k] = p + R @ pj  # in the parent body's joint frame
                world[k] = (Rw @ R @ Rj, pw + Rw @ at[k])
                pose[joint.child] = (k, np.eye(3), np.zeros(3))
            else:
                value = 0.0
                if joint.kind != 'fixed':
                    if joint.name in locked:
                        value = float(locked[joint.name])
                    elif body >= 0:  # hangs off the arm: locked at zero, said once
                        hanging.append(joint.name)
                    if joint.kind not in LOCKABLE and body >= 0:
                        _check_kind(joint, fail)
                Rj, pj = joint.motion(value)
                pose[joint.child] = (body, R @ Rj, p + R @ pj)
            stack.append(joint.child)
    if first.name not in {j.name for j in path} or 0 not in world:
        fail(f"joint '{first.name}' is not on the way to the contact link '{contact}'")
    if n < 2:
        fail(f'has {n} moving joint ({chain[0].name}): an arm needs at least 2 links')

    # the plane: normal to the first axis, y the world's up seen in the plane
    axes = [world[k][0] @ chain[k].axis for k in range(n)]
    normal = axes[0] / np.linalg.norm(axes[0])
    signs = []
    for k in range(1, n) if n > 1 else ():
        cosine = float(axes[k] @ normal)
        # atan2 keeps small angles exact where acos of a cosine near 1 loses half the digits
        angle = math.atan2(float(np.linalg.norm(np.cross(axes[k], normal))), abs(cosine))
        if angle > PARALLEL_TOLERANCE:
            fail(
                f"joint '{chain[k].name}' axis is {math.degrees(angle):.4g} deg from joint "
                f"'{first.name}''s at the locked posture: the moving joints' axes must be "
                f'parallel (the model is planar); lock one of them or change arm.locked'
            )
        signs.append(1.0 if cosine > 0 else -1.0)
    signs.insert(0, 1.0)
    up = WORLD_UP - (WORLD_UP @ normal) * normal
    gravity_scale = float(np.linalg.norm(up))
    if gravity_scale < 1e-12:  # a horizontal plane: gravity acts along the axes only
        up = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
        if np.linalg.norm(up) < 0.5:
            up = np.array([0.0, 1.0, 0.0]) - normal[1] * normal
        gravity_scale = 0.0
    y_axis = up / np.linalg.norm(up)
    x_axis = np.cross(y_axis, normal)
    plane = PlaneFrame(
        tuple(float(v) for v in world[0][1]),  # type: ignore[arg-type]
        tuple(float(v) for v in x_axis),  # type: ignore[arg-type]
        tuple(float(v) for v in y_axis),  # type: ignore[arg-type]
        tuple(float(v) for v in normal),  # type: ignore[arg-type]
    )

    def in_plane(k: int, v: np.ndarray) -> np.ndarray:
        """The in-plane coordinates (model x, y) of a vector given in body k's joint frame."""
        R = world[k][0]
        return np.array([v @ (R.T @ x_axis), v @ (R.T @ y_axis)])

    # each body: its mass, centre of mass and inertia about the axis through it
    members: dict[int, list[tuple[str, _Inertial, np.ndarray, np.ndarray]]] = {}
    for name, (body, R, p) in pose.items():
        inertial = robot.inertial(name)
        if body >= 0 and inertial is not None and inertial.mass > 0:
            members.setdefault(body, []).append((name, inertial, R, p))
    masses, centres, inertias = [], [], []
    for k in range(n):
        parts = members.get(k, [])
        mass = sum(inertial.mass for _, inertial, _, _ in parts)
        if mass <= 0:
            fail(
                f"link '{chain[k].child}' has no <inertial> mass (nor any link merged into it): "
                f'every moving link needs one'
            )
        u = world[k][0].T @ normal  # the axis in body k's joint frame
        if len(parts) == 1:
            _, inertial, R, p = parts[0]
            centre = p + R @ inertial.com
            inertia = float(u @ (R @ inertial.tensor @ R.T) @ u)
        else:
            centre = sum(m.mass * (p + R @ m.com) for _, m, R, p in parts) / mass
            inertia = 0.0
            for _, m, R, p in parts:
                d = p + R @ m.com - centre
                off_axis = d - (d @ u) * u
                inertia += float(u @ (R @ m.tensor @ R.T) @ u) + m.mass * float(off_axis @ off_axis)
        masses.append(mass)
        centres.append(in_plane(k, centre))
        inertias.append(inertia)

    # the links: from each joint to the next; the last keeps the previous one's direction
    lengths, headings = [], []
    for k in range(n - 1):
        d = in_plane(k, at[k + 1])
        length = float(math.hypot(*d))
        if length < MIN_LINK_LENGTH:
            fail(
                f"joints '{chain[k].name}' and '{chain[k + 1].name}' lie on one line along "
                f'their axes: the link between them has no length in the plane'
            )
        lengths.append(length)
        headings.append(math.atan2(d[1], d[0]) if d[1] != 0 else (0.0 if d[0] > 0 else math.pi))
    headings.append(headings[-1])

    def along(k: int, v: np.ndarray) -> tuple[float, float]:
        """In-plane vector ``v`` in link k's own frame (x along the link)."""
        h = headings[k]
        if h == 0:
            return float(v[0]), float(v[1])
        c, s = math.cos(h), math.sin(h)
        return float(c * v[0] + s * v[1]), float(-s * v[0] + c * v[1])

    com = tuple(along(k, centres[k]) for k in range(n))

    # the contact sphere: a point of a link merged into the last body
    body, R_c, p_c = pose[contact]
    if body != n - 1:
        fail(
            f"arm.contact.link = '{contact}' does not move with the last moving joint "
            f"'{chain[-1].name}': the model's contact is on the chain's last link"
        )
    sphere = None
    for collision in robot.links[contact].findall('collision'):
        geometry = collision.find('geometry/sphere')
        if geometry is not None:
            where = f"link '{contact}' collision sphere"
            collision_origin = collision.find('origin')
            radius = _number(geometry, 'radius', f'{where} radius', fail)
            centre = _vector(
                None if collision_origin is None else collision_origin.get('xyz'),
                (0.0, 0.0, 0.0),
                f'{where} origin xyz',
                fail,
            )
            sphere = (centre, radius)
            break
    if contact_point is None:
        point = sphere[0] if sphere else (0.0, 0.0, 0.0)
    else:
        point = tuple(float(v) for v in contact_point)
    radius = contact_radius if contact_radius is not None else (sphere[1] if sphere else None)
    if radius is None:
        return fail(
            f"arm.contact.radius is missing and link '{contact}' has no collision sphere to "
            f'take it from'
        )
    tip = along(n - 1, in_plane(n - 1, p_c + R_c @ np.array(point, dtype=float)))
    lengths.append(math.hypot(*tip))

    joint_specs = []
    notes: list[str] = []
    previous = 0.0
    for k, joint in enumerate(chain):
        limit = joint.element.find('limit')
        dynamics = joint.element.find('dynamics')
        where = f"joint '{joint.name}'"
        lower = upper = None
        if joint.kind == 'revolute':
            lower = _number(limit, 'lower', f'{where} limit lower', fail)
            upper = _number(limit, 'upper', f'{where} limit upper', fail)
            lower, upper = lower or 0.0, upper or 0.0  # URDF's defaults
            if lower > upper:
                fail(f'{where} limit lower = {lower:g} > upper = {upper:g} (rad)')
            if lower == upper:
                notes.append(
                    f"joint '{joint.name}' limit lower = upper = {lower:g} rad: a joint that "
                    f'cannot move; taken as no position limit'
                )
        effort_limit = _number(limit, 'effort', f'{where} limit effort', fail)
        if effort_limit == 0:
            notes.append(
                f"joint '{joint.name}' limit effort = 0: taken as no effort limit (set "
                f'joints[{k}].max_effort to clip)'
            )
        offset = headings[k] - previous
        offset = math.remainder(offset, 2 * math.pi) if offset else 0.0
        previous = headings[k]
        joint_specs.append(
            JointSpec(
                name=joint.name,
                lower=lower,
                upper=upper,
                effort=effort_limit,
                velocity=_number(limit, 'velocity', f'{where} limit velocity', fail),
                damping=_number(dynamics, 'damping', f'{where} dynamics damping', fail) or 0.0,
                friction=_number(dynamics, 'friction', f'{where} dynamics friction', fail) or 0.0,
                sign=signs[k],
                offset=offset,
            )
        )
    if hanging:
        notes.append(
            f'joints {", ".join(hanging[:8])} hang off the arm and are not in arm.locked: '
            f'locked at 0'
        )
    chain_locked = tuple(
        (j.name, float(locked.get(j.name, 0.0)))
        for j in _chain_joints(robot, contact)
        if j.kind in LOCKABLE and j.name not in moving_names
    )
    return UrdfArm(
        link_names=tuple(j.child for j in chain),
        lengths=tuple(lengths),
        masses=tuple(masses),
        com=com,
        inertias=tuple(inertias),
        tip_point=tip,
        tip_radius=float(radius),
        joints=tuple(joint_specs),
        locked=chain_locked,
        plane=plane,
        gravity_scale=gravity_scale,
        notes=tuple(notes),
    )


def _chain_joints(robot: _Description, contact: str) -> list[_Joint]:
    """The joints of the robot the arm carries: from the root to the contact link, and every
    joint below the contact link's path past the first joint that leaves the ground."""
    path = robot.path_to(contact)
    out = list(path)
    seen = {j.name for j in path}
    stack = [j.child for j in path]
    while stack:
        link = stack.pop()
        for joint in robot.children[link]:
            if joint.name not in seen:
                seen.add(joint.name)
                out.append(joint)
                stack.append(joint.child)
    return out


def resolve_urdf_path(path: str, scene_path: str) -> str:
    """A relative ``arm.urdf`` is relative to the scene file's directory (or the working
    directory for a scene given as text)."""
    if os.path.isabs(path) or not scene_path:
        return path
    return os.path.join(os.path.dirname(os.path.abspath(scene_path)), path)
