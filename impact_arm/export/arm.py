"""The planar arm as the peers' model files describe it: one body per link, hinged about
the plane's normal, in the robot's joint coordinates (same zero, same sign as the scene's
/joint_states), with the tip sphere and the struck surfaces.

The plane x-y of the model (y up) is the peers' world x-z (z up); the model's z (positive
angles) is the world's -y (contract.PLANE_AXIS_IN_WORLD), so a hinge of sign s turns about
(0, -s, 0)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..contract import PLANE_AXIS_IN_WORLD
from ..physics.model import ArmModel
from ..physics.scene import Scene


@dataclass(frozen=True)
class LinkBody:
    name: str  # the URDF's link name, or link1..N
    joint: str  # the scene's joint name
    sign: float  # the joint angle turns the link by sign * angle about the plane's normal
    offset: float  # the link's heading against the previous one at the joint's zero [rad]
    parent_length: float  # distance from the previous joint to this one [m] (0: the base)
    length: float  # joint to the next joint (or to the tip's joint for the last) [m]
    mass: float  # [kg]
    com: tuple[float, float]  # centre of mass (along, across) from the joint [m]
    inertia: float  # about the centre of mass, about the plane's normal [kg m^2]
    damping: float  # viscous joint friction [N m s/rad]
    friction: float  # Coulomb joint friction [N m]
    armature: float  # reflected rotor inertia [kg m^2]
    effort_limit: float  # [N m], inf when the scene has none
    lower: float | None  # joint limits [rad] (the robot's angle), None: continuous
    upper: float | None


@dataclass(frozen=True)
class StruckSurface:
    name: str  # surface1, surface2, ... (the peers' geometry names)
    height: float  # the scene's height h [m]: the tip's centre touches it
    plane_height: float  # the peers' plane, h - R: the sphere's bottom touches it [m]
    mu: float
    mounted: bool  # on a compliant mount in the scene (exported rigid)


@dataclass(frozen=True)
class PlanarArm:
    name: str
    links: tuple[LinkBody, ...]
    tip: tuple[float, float]  # the tip sphere's centre on the last link (along, across) [m]
    tip_radius: float  # [m]
    gravity: float  # in the plane, along -y [m/s^2]
    surfaces: tuple[StruckSurface, ...]
    from_urdf: bool

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(link.joint for link in self.links)


def planar_arm(scene: Scene) -> PlanarArm:
    """The scene's arm and surfaces as the peers' files describe them."""
    model = ArmModel(scene)
    coordinates = scene.joint_coordinates
    specs = scene.joint_specs
    names = scene.link_names or tuple(f'link{i + 1}' for i in range(scene.n_links))
    links = tuple(
        LinkBody(
            name=names[i],
            joint=spec.name,
            sign=float(coordinates.signs[i]),
            offset=float(coordinates.offsets[i]),
            parent_length=float(scene.lengths[i - 1]) if i else 0.0,
            length=float(scene.lengths[i]),
            mass=float(scene.masses[i]),
            com=(float(scene.link_com[i][0]), float(scene.link_com[i][1])),
            inertia=float(scene.link_inertias[i]),
            damping=float(spec.damping),
            friction=float(spec.friction),
            armature=float(spec.armature),
            effort_limit=float(spec.effort_limit),
            lower=spec.lower,
            upper=spec.upper,
        )
        for i, spec in enumerate(specs)
    )
    struck = [s for s in scene.surfaces if s.law != 'none']
    surfaces = tuple(
        StruckSurface(
            f'surface{i + 1}',
            float(s.height),
            float(s.height - scene.tip_radius),
            float(s.mu),
            s.mount is not None,
        )
        for i, s in enumerate(struck)
    )
    tip = scene.contact_point
    return PlanarArm(
        scene.name,
        links,
        (float(tip[0]), float(tip[1])),
        float(scene.tip_radius),
        float(model.g),
        surfaces,
        bool(scene.urdf_path or scene.urdf_text),
    )


def hinge_axis(sign: float) -> tuple[float, float, float]:
    """The world axis a joint of this sign turns about (positive angle: counter-clockwise
    in the model's plane)."""
    return tuple(sign * a + 0.0 for a in PLANE_AXIS_IN_WORLD)  # type: ignore[return-value]


def heading_quaternion(angle: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a turn by ``angle`` counter-clockwise in the model's plane."""
    half = 0.5 * angle
    ax = PLANE_AXIS_IN_WORLD
    return (math.cos(half), ax[0] * math.sin(half), ax[1] * math.sin(half), ax[2] * math.sin(half))


def in_world(along: float, across: float) -> tuple[float, float, float]:
    """A point (along, across) of a link's plane frame in the body's 3-D frame."""
    return (along, 0.0, across)
