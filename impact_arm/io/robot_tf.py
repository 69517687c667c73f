"""A URDF's forward kinematics, as robot_state_publisher computes it: plain Python and numpy.

``RobotTree(text)`` reads the ``<joint>`` elements of a description (its links need only
their names). For joint values (rad, or m for a prismatic joint) each joint gives the
transform of its child link's frame in its parent's:

    T = origin(xyz, rpy) ∘ motion(value)

where ``origin`` is URDF's ``<origin>`` (translation xyz, then fixed-axis roll, pitch, yaw:
R = Rz(yaw) Ry(pitch) Rx(roll)) and ``motion`` turns about the unit ``<axis>`` by the value
(revolute, continuous) or moves along it (prismatic); a fixed joint, and a floating or planar
one (taken at its zero), is its origin alone. A ``<mimic>`` joint takes
``multiplier * value(joint) + offset``. Fixed joints go on /tf_static, the others on /tf
(``fixed`` / ``moving``); ``poses`` composes every link's frame in the root's.

Quaternions are (x, y, z, w) with w >= 0.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..physics.scene.urdf import joint_motion, rotation_from_rpy


def rpy_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation matrix, the inverse of ``rotation_from_rpy`` (at
    pitch ±90°, where roll and yaw turn about one axis, roll is 0)."""
    pitch = math.atan2(-float(R[2, 0]), math.hypot(float(R[0, 0]), float(R[1, 0])))
    if math.hypot(float(R[0, 0]), float(R[1, 0])) < 1e-12:
        return 0.0, pitch, math.atan2(-float(R[0, 1]), float(R[1, 1]))
    return (
        math.atan2(float(R[2, 1]), float(R[2, 2])),
        pitch,
        math.atan2(float(R[1, 0]), float(R[0, 0])),
    )


def quaternion_from_rotation(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix, w >= 0."""
    m = np.asarray(R, dtype=float)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s)
    sign = -1.0 if q[3] < 0 else 1.0
    x, y, z, w = (sign * float(v) for v in q)
    return x, y, z, w


def homogeneous(R: np.ndarray, p: Sequence[float] | np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def _numbers(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    if text is None:
        return default
    values = tuple(float(v) for v in text.split())
    if len(values) != len(default):
        raise ValueError(f'{text[:60]!r}: expected {len(default)} numbers')
    return values


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>``: its origin, unit axis and, for a mimic joint, (joint, multiplier,
    offset)."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple[float, ...]
    rpy: tuple[float, ...]
    axis: tuple[float, ...]
    mimic: tuple[str, float, float] | None = None

    @property
    def origin(self) -> np.ndarray:
        return homogeneous(rotation_from_rpy(self.rpy), self.xyz)

    def transform(self, value: float = 0.0) -> np.ndarray:
        """4x4 of the child's frame in the parent's at joint ``value``."""
        return homogeneous(*joint_motion(self.kind, self.xyz, self.rpy, self.axis, value))


class RobotTree:
    """The joints of a URDF, in document order, and its root link."""

    def __init__(self, text: str) -> None:
        robot = ET.fromstring(text)
        joints = []
        for element in robot.findall('joint'):
            origin, axis, mimic = (
                element.find('origin'),
                element.find('axis'),
                element.find('mimic'),
            )
            parent, child = element.find('parent'), element.find('child')
            if parent is None or child is None:
                raise ValueError(f'joint {element.get("name")!r}: no parent or child')
            raw = _numbers(None if axis is None else axis.get('xyz'), (1.0, 0.0, 0.0))
            norm = math.sqrt(sum(a * a for a in raw)) or 1.0
            joints.append(
                UrdfJoint(
                    element.get('name', ''),
                    element.get('type', 'fixed'),
                    parent.get('link', ''),
                    child.get('link', ''),
                    _numbers(None if origin is None else origin.get('xyz'), (0.0, 0.0, 0.0)),
                    _numbers(None if origin is None else origin.get('rpy'), (0.0, 0.0, 0.0)),
                    tuple(a / norm for a in raw),
                    None
                    if mimic is None
                    else (
                        mimic.get('joint', ''),
                        float(mimic.get('multiplier', '1')),
                        float(mimic.get('offset', '0')),
                    ),
                )
            )
        self.joints: tuple[UrdfJoint, ...] = tuple(joints)
        children = {j.child for j in joints}
        links = [link.get('name', '') for link in robot.findall('link')]
        roots = [name for name in links if name not in children]
        if len(roots) != 1:
            raise ValueError(f'{len(roots)} root links: not one tree')
        self.root: str = roots[0]
        self.links: tuple[str, ...] = tuple(links)

    @property
    def fixed(self) -> tuple[UrdfJoint, ...]:
        """The joints robot_state_publisher puts on /tf_static."""
        return tuple(j for j in self.joints if j.kind == 'fixed')

    @property
    def moving(self) -> tuple[UrdfJoint, ...]:
        """The joints robot_state_publisher puts on /tf (floating and planar ones too)."""
        return tuple(j for j in self.joints if j.kind != 'fixed')

    def value(self, joint: UrdfJoint, values: Mapping[str, float]) -> float:
        """``joint``'s value: its mimicked joint's, scaled, or its own (0 if not given)."""
        if joint.mimic is not None:
            name, multiplier, offset = joint.mimic
            return multiplier * float(values.get(name, 0.0)) + offset
        return float(values.get(joint.name, 0.0))

    def transforms(self, values: Mapping[str, float]) -> list[tuple[UrdfJoint, np.ndarray]]:
        """(joint, child in parent) of each non-fixed joint at ``values`` (by joint name)."""
        return [(j, j.transform(self.value(j, values))) for j in self.moving]

    def poses(self, values: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Every link's frame in the root's (4x4) at ``values``."""
        by_parent: dict[str, list[UrdfJoint]] = {}
        for j in self.joints:
            by_parent.setdefault(j.parent, []).append(j)
        out = {self.root: np.eye(4)}
        stack = [self.root]
        while stack:
            link = stack.pop()
            for j in by_parent.get(link, []):
                out[j.child] = out[link] @ j.transform(self.value(j, values))
                stack.append(j.child)
        return out
