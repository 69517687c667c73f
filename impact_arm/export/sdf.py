"""The arm as Drake and Gazebo load it (SDFormat 1.9): one link per body at the joints'
zero, revolute joints about the plane's normal in the robot's coordinates, the tip sphere
(collision ``tip``) and the struck surfaces (collisions ``surface1``, ...) on a link welded
to the world. Each peer's contact parameters go where that peer reads them: Drake's
``drake:proximity_properties``, Gazebo's ``<surface>`` (ODE)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .arm import PlanarArm, hinge_axis, in_world


@dataclass(frozen=True)
class DrakeContact:
    """Drake's compliant point contact (Hunt-Crossley), the same on the tip and on every
    surface: Drake combines two geometries' stiffnesses in series, so the pair's is half
    the value written on each; dissipation and friction combine to the value written."""

    stiffness: float  # drake:point_contact_stiffness of each geometry [N/m]
    dissipation: float  # drake:hunt_crossley_dissipation [s/m]
    mu: float  # drake:mu_dynamic and mu_static [-]
    timestep: float  # the plant's discrete time step [s]

    def __post_init__(self) -> None:
        for name, value in (('stiffness', self.stiffness), ('timestep', self.timestep)):
            if not 0.0 < value < math.inf:
                raise ValueError(f'Drake {name} = {value}: must be in (0, inf)')
        for name, value in (('dissipation', self.dissipation), ('mu', self.mu)):
            if not 0.0 <= value < math.inf:
                raise ValueError(f'Drake {name} = {value}: must be in [0, inf)')


@dataclass(frozen=True)
class GazeboContact:
    """Gazebo's ODE contact: a spring-damper turned into ERP and CFM at each step, a
    velocity-level restitution, and a cap on the speed penetration is corrected at."""

    kp: float  # contact stiffness [N/m]
    kd: float  # contact damping [N s/m]
    restitution: float  # <bounce restitution_coefficient> [-]
    mu: float  # <friction><ode><mu>, <mu2> [-]
    max_vel: float  # fastest correction of penetration [m/s]
    min_depth: float  # penetration left uncorrected [m]
    timestep: float  # the world's max_step_size [s]
    bounce_threshold: float = 0.01  # [m/s] slower impacts do not bounce

    def __post_init__(self) -> None:
        for name, value in (('kp', self.kp), ('timestep', self.timestep)):
            if not 0.0 < value < math.inf:
                raise ValueError(f'Gazebo {name} = {value}: must be in (0, inf)')
        for name, value in (
            ('kd', self.kd),
            ('mu', self.mu),
            ('max_vel', self.max_vel),
            ('min_depth', self.min_depth),
        ):
            if not 0.0 <= value < math.inf:
                raise ValueError(f'Gazebo {name} = {value}: must be in [0, inf)')
        if not 0.0 <= self.restitution <= 1.0:
            raise ValueError(f'Gazebo restitution = {self.restitution}: must be in [0, 1]')


def gazebo_defaults(timestep: float) -> GazeboContact:
    """Gazebo's (SDFormat's) defaults: kp 1e12, kd 1, max_vel 0.01, min_depth 0, no bounce,
    mu 1."""
    return GazeboContact(1e12, 1.0, 0.0, 1.0, 0.01, 0.0, timestep)


def _xyz(values: tuple[float, ...]) -> str:
    return ' '.join(f'{v:.10g}' for v in values)


def _drake_properties(contact: DrakeContact, indent: str) -> list[str]:
    return [
        f'{indent}<drake:proximity_properties>',
        f'{indent}  <drake:point_contact_stiffness>{contact.stiffness:.10g}'
        '</drake:point_contact_stiffness>',
        f'{indent}  <drake:hunt_crossley_dissipation>{contact.dissipation:.10g}'
        '</drake:hunt_crossley_dissipation>',
        f'{indent}  <drake:mu_dynamic>{contact.mu:.10g}</drake:mu_dynamic>',
        f'{indent}  <drake:mu_static>{contact.mu:.10g}</drake:mu_static>',
        f'{indent}</drake:proximity_properties>',
    ]


def _gazebo_surface(contact: GazeboContact, indent: str) -> list[str]:
    i = indent
    return [
        f'{i}<surface>',
        f'{i}  <bounce><restitution_coefficient>{contact.restitution:.10g}'
        f'</restitution_coefficient><threshold>{contact.bounce_threshold:.10g}</threshold>'
        '</bounce>',
        f'{i}  <friction><ode><mu>{contact.mu:.10g}</mu><mu2>{contact.mu:.10g}</mu2></ode>'
        '</friction>',
        f'{i}  <contact><ode><kp>{contact.kp:.10g}</kp><kd>{contact.kd:.10g}</kd>'
        f'<max_vel>{contact.max_vel:.10g}</max_vel><min_depth>{contact.min_depth:.10g}'
        '</min_depth></ode></contact>',
        f'{i}</surface>',
    ]


def _contact(contact: DrakeContact | GazeboContact | None, indent: str) -> list[str]:
    if isinstance(contact, DrakeContact):
        return _drake_properties(contact, indent)
    if isinstance(contact, GazeboContact):
        return _gazebo_surface(contact, indent)
    return []  # the peer's defaults


def sdf_model(arm: PlanarArm, contact: DrakeContact | GazeboContact | None) -> list[str]:
    """The <model> element's lines (``contact`` None: the peer's default contact)."""
    lines = [f'  <model name="{arm.name}">']
    lines += ['    <link name="surfaces">', '      <inertial><mass>1</mass></inertial>']
    for surface in arm.surfaces:
        geometry = '<geometry><plane><normal>0 0 1</normal><size>4 4</size></plane></geometry>'
        lines += [
            f'      <collision name="{surface.name}">',
            f'        <pose>0 0 {surface.plane_height:.10g} 0 0 0</pose>',
            f'        {geometry}',
            *_contact(contact, '        '),
            '      </collision>',
            f'      <visual name="{surface.name}_visual">',
            f'        <pose>0 0 {surface.plane_height:.10g} 0 0 0</pose>',
            f'        {geometry}',
            '      </visual>',
        ]
    lines += [
        '    </link>',
        '    <joint name="surfaces_weld" type="fixed">',
        '      <parent>world</parent><child>surfaces</child>',
        '    </joint>',
    ]
    x = y = heading = 0.0  # the link's joint and heading in the plane at the joints' zero
    parent = 'world'
    last = len(arm.links) - 1
    for i, link in enumerate(arm.links):
        if i:
            x += arm.links[i - 1].length * math.cos(heading)
            y += arm.links[i - 1].length * math.sin(heading)
        heading += link.offset
        j = link.inertia
        # a turn about -y by the heading is a pitch of -heading
        lines += [
            f'    <link name="{link.name}">',
            f'      <pose>{x:.10g} 0 {y:.10g} 0 {-heading:.10g} 0</pose>',
            '      <inertial>',
            f'        <pose>{_xyz(in_world(*link.com))} 0 0 0</pose>',
            f'        <mass>{link.mass:.10g}</mass>',
            f'        <inertia><ixx>{1e-3 * j:.10g}</ixx><iyy>{j:.10g}</iyy><izz>{j:.10g}</izz>'
            '<ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>',
            '      </inertial>',
        ]
        end = arm.tip if i == last else (link.length, 0.0)
        half = 0.5 * end[0]
        rod = 0.01 * min(k.length for k in arm.links)
        lines += [
            f'      <visual name="{link.name}_rod">',
            f'        <pose>{half:.10g} 0 0 0 1.5707963267949 0</pose>',
            f'        <geometry><cylinder><radius>{rod:.10g}</radius>'
            f'<length>{max(end[0], rod):.10g}</length></cylinder></geometry>',
            '      </visual>',
        ]
        if i == last:
            tip = _xyz(in_world(*arm.tip))
            lines += [
                '      <collision name="tip">',
                f'        <pose>{tip} 0 0 0</pose>',
                f'        <geometry><sphere><radius>{arm.tip_radius:.10g}</radius></sphere>'
                '</geometry>',
                *_contact(contact, '        '),
                '      </collision>',
            ]
        lines.append('    </link>')
        effort = link.effort_limit if math.isfinite(link.effort_limit) else -1.0  # -1: none
        lines += [
            f'    <joint name="{link.joint}" type="revolute">',
            f'      <parent>{parent}</parent><child>{link.name}</child>',
            '      <axis>',
            f'        <xyz>{_xyz(hinge_axis(link.sign))}</xyz>',
            # the scene reports excursions beyond its limits and does not stop the joint
            '        <limit><lower>-1e16</lower><upper>1e16</upper>'
            f'<effort>{effort:.10g}</effort></limit>',
            f'        <dynamics><damping>{link.damping:.10g}</damping>'
            f'<friction>{link.friction:.10g}</friction></dynamics>',
            '      </axis>',
        ]
        if isinstance(contact, DrakeContact) or contact is None:
            # Drake's reflected rotor inertia is rotor_inertia * gear_ratio^2
            lines += [
                f'      <drake:rotor_inertia>{link.armature:.10g}</drake:rotor_inertia>',
                '      <drake:gear_ratio>1</drake:gear_ratio>',
            ]
        lines.append('    </joint>')
        parent = link.name
    lines.append(
        f'    <frame name="tip" attached_to="{arm.links[-1].name}">'
        f'<pose>{_xyz(in_world(*arm.tip))} 0 0 0</pose></frame>'
    )
    lines.append('  </model>')
    return lines


def drake_sdf(arm: PlanarArm, contact: DrakeContact | None) -> str:
    lines = ['<?xml version="1.0"?>', '<sdf version="1.9" xmlns:drake="drake.mit.edu">']
    return '\n'.join([*lines, *sdf_model(arm, contact), '</sdf>']) + '\n'


def gazebo_world(arm: PlanarArm, contact: GazeboContact) -> str:
    """A world with the ODE engine at the fitted step, the scene's gravity and the arm."""
    lines = [
        '<?xml version="1.0"?>',
        '<sdf version="1.9">',
        f'<world name="{arm.name}_world">',
        f'  <gravity>0 0 {-arm.gravity:.10g}</gravity>',
        '  <physics name="fitted_step" type="ode">',
        f'    <max_step_size>{contact.timestep:.10g}</max_step_size>',
        '    <real_time_factor>1</real_time_factor>',
        '  </physics>',
        *sdf_model(arm, contact),
        '</world>',
        '</sdf>',
    ]
    return '\n'.join(lines) + '\n'
