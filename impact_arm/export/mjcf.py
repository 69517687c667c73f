"""The arm as MuJoCo loads it (MJCF): one body per link hinged about the plane's normal in
the robot's joint coordinates, the tip sphere as geom ``tip``, the struck surfaces as
planes ``surface1``, ``surface2``, ..., one motor per joint for ros2_control, and the
contact as an explicit tip/surface ``<pair>`` (so no default of either geom mixes in)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from .arm import PlanarArm, heading_quaternion, hinge_axis, in_world


@dataclass(frozen=True)
class MujocoContact:
    """The tip/surface pair's parameters and the time step they were fitted at."""

    timeconst: float  # solref[0]: the contact's time constant [s]
    dampratio: float  # solref[1]: its damping ratio [-]
    dmin: float  # solimp[0]: impedance at zero penetration [-]
    dmax: float  # solimp[1]: impedance at ``width`` and beyond [-]
    width: float  # solimp[2]: penetration over which the impedance rises [m]
    mu: float  # sliding friction coefficient [-]
    timestep: float  # [s]

    def __post_init__(self) -> None:
        checks = (
            ('timeconst', self.timeconst, 0.0, math.inf),
            ('dampratio', self.dampratio, 0.0, math.inf),
            ('dmin', self.dmin, 0.0, 1.0),
            ('dmax', self.dmax, 0.0, 1.0),
            ('width', self.width, 0.0, math.inf),
            ('mu', self.mu, 0.0, math.inf),
            ('timestep', self.timestep, 0.0, math.inf),
        )
        for name, value, low, high in checks:
            if not low < value < high:
                raise ValueError(f'MuJoCo {name} = {value}: must be in ({low}, {high})')

    @property
    def solref(self) -> tuple[float, float]:
        return (self.timeconst, self.dampratio)

    @property
    def solimp(self) -> tuple[float, float, float, float, float]:
        return (self.dmin, self.dmax, self.width, 0.5, 2.0)  # midpoint, power: MuJoCo's


def mujoco_defaults(timestep: float) -> MujocoContact:
    """MuJoCo's own contact parameters (solref, solimp, friction) at ``timestep``."""
    return MujocoContact(0.02, 1.0, 0.9, 0.95, 0.001, 1.0, timestep)


def _numbers(values: tuple[float, ...] | list[float]) -> str:
    return ' '.join(f'{v:.10g}' for v in values)


def mjcf(arm: PlanarArm, contact: MujocoContact) -> str:
    """The MJCF text of ``arm`` with the contact ``contact`` on every surface."""
    lines = [
        f'<mujoco model={quoteattr(arm.name)}>',
        '  <compiler angle="radian"/>',
        # elliptic cone: Coulomb's circle of friction, as the package's law; implicitfast:
        # the joints' damping integrated implicitly
        f'  <option timestep="{contact.timestep:.10g}" gravity="0 0 {-arm.gravity:.10g}" '
        'integrator="implicitfast" cone="elliptic"/>',
        '  <worldbody>',
    ]
    for surface in arm.surfaces:
        lines.append(
            f'    <geom name="{surface.name}" type="plane" pos="0 0 {surface.plane_height:.10g}" '
            'size="0 0 0.1" contype="0" conaffinity="1" rgba="0.6 0.6 0.65 1"/>'
        )
    rod = 0.01 * min(link.length for link in arm.links)  # drawn only
    indent = '    '
    last = len(arm.links) - 1
    for i, link in enumerate(arm.links):
        quat = _numbers(heading_quaternion(link.offset))
        lines.append(
            f'{indent}<body name={quoteattr(link.name)} pos="{link.parent_length:.10g} 0 0" '
            f'quat="{quat}">'
        )
        inner = indent + '  '
        limits = ''
        if link.lower is not None and link.upper is not None:
            # the scene reports excursions and does not stop the joint: not enforced here
            limits = f' range="{link.lower:.10g} {link.upper:.10g}" limited="false"'
        effort = ''
        if math.isfinite(link.effort_limit):
            effort = f' actuatorfrcrange="{-link.effort_limit:.10g} {link.effort_limit:.10g}"'
        lines.append(
            f'{inner}<joint name={quoteattr(link.joint)} type="hinge" '
            f'axis="{_numbers(hinge_axis(link.sign))}" damping="{link.damping:.10g}" '
            f'frictionloss="{link.friction:.10g}" armature="{link.armature:.10g}"'
            f'{limits}{effort}/>'
        )
        # a planar link: only the inertia about the hinge moves the arm; the other two
        # principal values are those of a thin rod along the link (MuJoCo checks them)
        j = link.inertia
        lines.append(
            f'{inner}<inertial pos="{_numbers(in_world(*link.com))}" mass="{link.mass:.10g}" '
            f'diaginertia="{1e-3 * j:.10g} {j:.10g} {j:.10g}"/>'
        )
        end = arm.tip if i == last else (link.length, 0.0)
        lines.append(
            f'{inner}<geom name="{link.name}_rod" type="capsule" '
            f'fromto="0 0 0 {_numbers(in_world(*end))}" size="{rod:.10g}" '
            'contype="0" conaffinity="0" group="1" mass="0"/>'
        )
        if i == last:
            lines.append(
                f'{inner}<geom name="tip" type="sphere" pos="{_numbers(in_world(*arm.tip))}" '
                f'size="{arm.tip_radius:.10g}" contype="1" conaffinity="0" mass="0"/>'
            )
            lines.append(f'{inner}<site name="tip" pos="{_numbers(in_world(*arm.tip))}"/>')
        indent = inner
    for i in range(len(arm.links), 0, -1):
        lines.append('  ' * (i + 1) + '</body>')
    lines.append('  </worldbody>')
    lines.append('  <contact>')
    friction = f'{contact.mu:.10g} {contact.mu:.10g} 0 0 0'
    for surface in arm.surfaces:
        lines.append(
            f'    <pair name="tip_{surface.name}" geom1="tip" geom2="{surface.name}" condim="3" '
            f'friction="{friction}" solref="{_numbers(contact.solref)}" '
            f'solimp="{_numbers(contact.solimp)}"/>'
        )
    lines.append('  </contact>')
    lines.append('  <actuator>')
    for link in arm.links:
        limit = ''
        if math.isfinite(link.effort_limit):
            limit = f' ctrlrange="{-link.effort_limit:.10g} {link.effort_limit:.10g}"'
        lines.append(
            f'    <motor name={quoteattr(link.joint)} joint={quoteattr(link.joint)} gear="1"'
            f'{limit}/>'
        )
    lines.append('  </actuator>')
    lines.append('</mujoco>')
    return '\n'.join(lines) + '\n'
