"""An arm read from its robot description (URDF): the planar chain the model can simulate.

Plain XML (no ROS): the scene key ``arm.urdf`` names the file (docs/scene.md, "The arm from
its URDF"). What the model is, and therefore what a description must be:

* a serial chain of ``revolute`` or ``continuous`` joints from the ground (the root link and
  every link fixed to it) to the last moving link; prismatic, planar and floating joints,
  two moving joints on one link (a branch) and mass fixed to a moving link through a
  ``fixed`` joint are refused, naming the joint and why;
* all joint axes ``0 -1 0`` and joint origins without rotation, so that the arm moves in the
  world's x-z plane as the model's plane (``contract.plane_to_world``) and each joint's value
  is the relative angle q_k − q_(k−1) the model's encoders read; each joint lies on its
  parent link's x axis (origin ``x 0 0``: that x is the parent link's length). The first
  joint is the model's origin O wherever the description puts it;
* of each link: its mass, the centre of mass in the x-z plane of its frame (x along the link,
  z across it: the model's along / across), and the inertia about the centre of mass about
  the joint axis (the y-y entry of the inertia tensor turned into the link's axes; the other
  entries act across the plane only, on the joints' bearings, and are not part of the
  planar model);
* the contact: a sphere of given radius at a point of a named link, the last moving link or
  a link fixed to it (the description's collision sphere of that link gives the point and
  radius unless the scene gives them).

Joint limits and ``<dynamics damping friction>`` are read and kept (``JointSpec``).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NoReturn

from ..errors import SceneError
from .types import JointSpec

MAX_URDF_BYTES = 4 << 20  # descriptions with long inline meshes lists run to a few 100 kB
MOVING = ('revolute', 'continuous')
AXIS = (0.0, -1.0, 0.0)  # contract.PLANE_AXIS_IN_WORLD: positive angles lift x towards +z
PLANE_TOLERANCE = 1e-12  # m or rad: what counts as zero in a description's numbers


@dataclass(frozen=True)
class UrdfArm:
    """The chain as the model takes it: per moving link (chain order) its name, length (to
    the next joint; the last link's: the distance of the contact point from its joint),
    mass, centre of mass (along, across) and inertia about it; the contact point (along,
    across) on the last link and the sphere's radius; the joints."""

    link_names: tuple[str, ...]
    lengths: tuple[float, ...]
    masses: tuple[float, ...]
    com: tuple[tuple[float, float], ...]
    inertias: tuple[float, ...]
    tip_point: tuple[float, float]
    tip_radius: float
    joints: tuple[JointSpec, ...]


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


def _rotation(rpy: Sequence[float]) -> list[list[float]]:
    """URDF's fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]


def _apply(R: list[list[float]], v: Sequence[float]) -> tuple[float, ...]:
    return tuple(sum(R[i][k] * v[k] for k in range(3)) for i in range(3))


def _compose(A: list[list[float]], B: list[list[float]]) -> list[list[float]]:
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple[float, ...]
    rpy: tuple[float, ...]
    axis: tuple[float, ...]
    element: ET.Element


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


def parse_urdf_arm(
    text: str,
    origin: str,
    contact_link: str | None = None,
    contact_point: Sequence[float] | None = None,
    contact_radius: float | None = None,
) -> UrdfArm:
    """The planar chain of the description ``text`` (module docstring), or ``SceneError``
    in one line starting with ``origin``. ``contact_link`` (default: the last moving link),
    ``contact_point`` (x, y, z in that link's frame) and ``contact_radius`` place the
    contact sphere; a point or radius not given comes from the link's collision sphere."""

    def fail(message: str) -> NoReturn:
        raise SceneError(f'{origin}: {message}')

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        hint = ' (a xacro file? expand it first: xacro FILE > FILE.urdf)' if 'xacro' in text else ''
        fail(f'not valid XML: {exc}{hint}')
    if root.tag != 'robot':
        fail(f'the top element is <{root.tag[:40]}>, not <robot>: not a URDF')
    links: dict[str, ET.Element] = {}
    for element in root.findall('link'):
        name = element.get('name')
        if not name:
            fail('a <link> has no name')
        if name in links:
            fail(f"link '{name}' is defined twice")
        links[name] = element
    joints: dict[str, _Joint] = {}
    by_child: dict[str, _Joint] = {}
    for element in root.findall('joint'):
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
        joint = _Joint(
            name,
            element.get('type', ''),
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
            _vector(
                None if axis_element is None else axis_element.get('xyz'),
                (1.0, 0.0, 0.0),  # URDF's default axis
                f'{where} axis',
                fail,
            ),
            element,
        )
        for end in (joint.parent, joint.child):
            if end not in links:
                fail(f"{where} names link '{end[:60]}', which the description does not define")
        if name in joints:
            fail(f'{where} is defined twice')
        if joint.child in by_child:
            fail(
                f"{where}: link '{joint.child}' is already the child of joint "
                f"'{by_child[joint.child].name}' (not a tree)"
            )
        joints[name] = joint
        by_child[joint.child] = joint
    roots = [name for name in links if name not in by_child]
    if len(roots) != 1:
        fail(f'has {len(roots)} root links ({", ".join(roots)[:80]}): must be one tree')
    children: dict[str, list[_Joint]] = {name: [] for name in links}
    for joint in joints.values():
        children[joint.parent].append(joint)

    def mass_of(name: str) -> float:
        inertial = links[name].find('inertial')
        mass = None if inertial is None else inertial.find('mass')
        value = _number(mass, 'value', f"link '{name}' mass", fail)
        return 0.0 if value is None else value

    def subtree_mass(name: str) -> float:
        return mass_of(name) + sum(subtree_mass(j.child) for j in children[name])

    def check_kind(joint: _Joint) -> None:
        if joint.element.find('mimic') is not None:
            fail(
                f"joint '{joint.name}' mimics another joint: the model's joints move "
                f'independently, each driven by its own torque'
            )
        if joint.kind not in MOVING + ('fixed',):
            fail(
                f"joint '{joint.name}' is of type {joint.kind!r}: the model is a planar "
                f'chain of hinges; only revolute or continuous joints move (fixed ones '
                f'attach massless frames)'
            )

    def check_unrotated(joint: _Joint) -> None:
        if any(abs(a) > PLANE_TOLERANCE for a in joint.rpy):
            fail(
                f"joint '{joint.name}' origin rpy = {' '.join(f'{a:g}' for a in joint.rpy)}: "
                f'must be 0 0 0 (the model measures each joint angle from its parent '
                f"link's x axis, in the x-z plane; a turned joint frame would offset the "
                f'angles)'
            )

    # the ground: the root and every link fixed to it; exactly one moving joint leaves it
    ground: list[tuple[str, _Joint | None]] = [(roots[0], None)]  # (link, a turning joint)
    first_moving = []
    for name, turned in ground:
        for joint in children[name]:
            check_kind(joint)
            if joint.kind == 'fixed':
                rotated = any(abs(a) > PLANE_TOLERANCE for a in joint.rpy)
                ground.append((joint.child, joint if rotated else turned))
            else:
                if turned is not None:
                    check_unrotated(turned)  # a turned ground would turn the plane
                first_moving.append(joint)
    if not first_moving:
        fail('has no revolute or continuous joint: no arm to simulate')
    if len(first_moving) > 1:
        fail(
            f'joints {", ".join(repr(j.name) for j in first_moving[:4])} all move links of '
            f'the ground: the model is one serial chain (a branch is not)'
        )
    chain: list[_Joint] = []  # the moving joints, in order
    # link fixed to a moving one -> (that moving link, rotation and origin in its frame)
    fixed_on: dict[str, tuple[str, list[list[float]], tuple[float, ...]]] = {}
    joint = first_moving[0]
    while True:
        check_kind(joint)
        check_unrotated(joint)
        where = f"joint '{joint.name}'"
        norm = math.sqrt(sum(a * a for a in joint.axis))
        axis = tuple(a / norm for a in joint.axis) if norm > 0 else joint.axis
        if norm == 0 or any(abs(a - b) > 1e-9 for a, b in zip(axis, AXIS)):
            parallel = norm > 0 and abs(abs(axis[1]) - 1) <= 1e-9
            why = (
                'turns the other way: the model counts angles counter-clockwise seen with '
                'x right and z up, about 0 -1 0; write axis 0 -1 0 and negate its angles'
                if parallel
                else 'must be 0 -1 0 for every joint: the model is a planar chain in the '
                "world's x-z plane, all axes parallel and along the world's -y"
            )
            fail(f'{where} axis = {" ".join(f"{a:g}" for a in joint.axis)}: {why}')
        if chain:
            x, y, z = joint.xyz
            if abs(y) > PLANE_TOLERANCE or abs(z) > PLANE_TOLERANCE:
                fail(
                    f'{where} origin xyz = {x:g} {y:g} {z:g}: must be x 0 0 (each joint on '
                    f"its parent link's x axis; the model's links run from joint to joint)"
                )
        chain.append(joint)
        moving = [j for j in children[joint.child] if j.kind != 'fixed']
        for j in children[joint.child]:
            check_kind(j)
        if len(moving) > 1:
            fail(
                f'joints {", ".join(repr(j.name) for j in moving[:4])} all move link '
                f"'{joint.child}': the model is one serial chain (a branch is not)"
            )
        # frames fixed to this link: possible contact links; their mass would need merging
        identity = _rotation((0.0, 0.0, 0.0))
        stack: list[tuple[_Joint, list[list[float]], tuple[float, ...]]] = [
            (j, identity, (0.0, 0.0, 0.0)) for j in children[joint.child] if j.kind == 'fixed'
        ]
        while stack:
            fixed, frame_turn, frame_offset = stack.pop()
            mass = subtree_mass(fixed.child)
            if mass > 0:
                fail(
                    f"fixed joint '{fixed.name}' carries link '{fixed.child}' of mass "
                    f'{mass:g} kg: merge its inertial into link {joint.child!r} (the model '
                    f'has one rigid body per moving joint)'
                )
            at = tuple(o + d for o, d in zip(frame_offset, _apply(frame_turn, fixed.xyz)))
            frame = _compose(frame_turn, _rotation(fixed.rpy))
            fixed_on[fixed.child] = (joint.child, frame, at)
            stack += [(j, frame, at) for j in children[fixed.child]]
        if not moving:
            break
        joint = moving[0]
    moving_links = [j.child for j in chain]
    n = len(chain)
    if n < 2:
        fail(f'has {n} moving joint ({chain[0].name}): an arm needs at least 2 links')
    masses, com, inertias = [], [], []
    for name in moving_links:
        inertial = links[name].find('inertial')
        if inertial is None or inertial.find('mass') is None:
            fail(f"link '{name}' has no <inertial> mass: every moving link needs one")
        masses.append(mass_of(name))
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
        entries = {}
        for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
            value = _number(tensor_element, key, f"link '{name}' inertia {key}", fail)
            entries[key] = 0.0 if value is None else value
        tensor = [
            [entries['ixx'], entries['ixy'], entries['ixz']],
            [entries['ixy'], entries['iyy'], entries['iyz']],
            [entries['ixz'], entries['iyz'], entries['izz']],
        ]
        # the tensor is given in the inertial frame: about the link's y axis (the joint
        # axis, up to its sign) it is row y of R I R^T
        R = _rotation(rpy)
        about_axis = sum(R[1][a] * tensor[a][b] * R[1][b] for a in range(3) for b in range(3))
        com.append((xyz[0], xyz[2]))  # x along the link, z across it (the model's along, across)
        inertias.append(about_axis)
    joint_specs = []
    for joint in chain:
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
        joint_specs.append(
            JointSpec(
                name=joint.name,
                lower=lower,
                upper=upper,
                effort=_number(limit, 'effort', f'{where} limit effort', fail),
                velocity=_number(limit, 'velocity', f'{where} limit velocity', fail),
                damping=_number(dynamics, 'damping', f'{where} dynamics damping', fail) or 0.0,
                friction=_number(dynamics, 'friction', f'{where} dynamics friction', fail) or 0.0,
            )
        )
    last = moving_links[-1]
    name = last if contact_link is None else contact_link
    turn = _rotation((0.0, 0.0, 0.0))
    offset: tuple[float, ...] = (0.0, 0.0, 0.0)
    if name == last:
        pass
    elif name in fixed_on:
        carrier, turn, offset = fixed_on[name]
        if carrier != last:
            fail(
                f"arm.contact.link = '{name}' is fixed to '{carrier}', not to the last moving "
                f"link '{last}': the model's contact is on the chain's last link"
            )
    elif name in moving_links:
        fail(
            f"arm.contact.link = '{name}' is not the last moving link '{last}': the model's "
            f"contact is on the chain's last link"
        )
    else:
        fail(
            f"arm.contact.link = '{name[:60]}' is not a link of the chain's last link "
            f"('{last}' or a link fixed to it)"
        )
    sphere = None
    for collision in links[name].findall('collision'):
        geometry = collision.find('geometry/sphere')
        if geometry is not None:
            where = f"link '{name}' collision sphere"
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
            f"arm.contact.radius is missing and link '{name}' has no collision sphere to "
            f'take it from'
        )
    x, y, z = (o + p for o, p in zip(offset, _apply(turn, point)))
    if abs(y) > PLANE_TOLERANCE:
        fail(f'the contact point is {y:g} m off the x-z plane (y): the model is planar')
    lengths = [chain[k + 1].xyz[0] for k in range(n - 1)] + [math.hypot(x, z)]
    return UrdfArm(
        link_names=tuple(moving_links),
        lengths=tuple(lengths),
        masses=tuple(masses),
        com=tuple(com),
        inertias=tuple(inertias),
        tip_point=(x, z),
        tip_radius=float(radius),
        joints=tuple(joint_specs),
    )


def resolve_urdf_path(path: str, scene_path: str) -> str:
    """A relative ``arm.urdf`` is relative to the scene file's directory (or the working
    directory for a scene given as text)."""
    if os.path.isabs(path) or not scene_path:
        return path
    return os.path.join(os.path.dirname(os.path.abspath(scene_path)), path)
