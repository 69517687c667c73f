"""The scene's frozen records: what a validated scene is (``Scene``) and its parts.

Everything here is SI: angles in radians, lengths in metres. Nothing here reads or checks
a file (``files.py``, ``parse.py``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

from ...contract import (
    ControlLaw,
    IntegratorPreset,
    JointCoordinates,
    PidSpace,
    StepMethod,
    TextEnum,
)


class ContactLaw(TextEnum):
    """The normal contact law of a surface: Jackson-Green elasto-plastic compression with its
    restitution, Hertz (elastic) throughout, or no contact (the tip passes through)."""

    ELASTOPLASTIC = 'elastoplastic'
    HERTZ = 'hertz'
    NONE = 'none'


CONTACT_LAWS = tuple(m.value for m in ContactLaw)


@dataclass(frozen=True)
class Material:
    E: float  # Young's modulus [Pa]
    nu: float  # Poisson's ratio [-]
    S_y: float  # yield strength [Pa]


def reduced_modulus(a: Material, b: Material) -> float:
    """E* of a contact pairing: 1/E* = (1 - ν_a²)/E_a + (1 - ν_b²)/E_b (docs/model.md)."""
    return a.E * b.E / (b.E * (1 - a.nu**2) + a.E * (1 - b.nu**2))


@dataclass(frozen=True)
class Mount:
    """A surface's compliant mount: the surface is a plate of ``mass`` on a spring-damper
    along its normal, at rest at its height at t = 0 (docs/model.md)."""

    mass: float  # [kg]
    stiffness: float  # [N/m]
    damping_ratio: float = 0.0  # c = 2 damping_ratio sqrt(stiffness mass)

    @property
    def damping(self) -> float:
        """The damping coefficient c [N s/m]."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * self.mass)


@dataclass(frozen=True)
class Surface:
    height: float  # y of the horizontal surface [m]; the tip strikes it from above
    law: ContactLaw
    mu: float  # Coulomb friction coefficient (0 = no friction force)
    v_d: float  # tanh smoothing velocity [m/s]
    material: Material
    mount: Mount | None = None  # None: rigidly mounted


@dataclass(frozen=True)
class ControllerSpec:
    law: ControlLaw
    space: PidSpace  # the angles the PID/PD acts on
    kp: tuple[float, ...]
    kd: tuple[float, ...]
    ki: tuple[float, ...]
    down_target: tuple[float, ...]  # rad, absolute link angles
    up_target: tuple[float, ...]  # rad
    switch_height: float  # tip height that ends the up phase [m]
    rate: float  # Hz; 0 = continuous (evaluated in the right-hand side)
    allow_unstable: bool = False  # run a law unstable at its sampled rate (warned), not refuse it


@dataclass(frozen=True)
class IntegratorSpec:
    preset: IntegratorPreset
    rtol: float | None = None
    atol: float | None = None
    max_step: float | None = None
    method: StepMethod = StepMethod.DOPRI5
    contact_rtol: float | None = None


class RateReading(str, Enum):
    """How the driver obtains the joint rates it publishes."""

    EXACT = 'exact'  # the drive's own velocity measurement (the state's rate, plus rate_noise)
    DIFFERENCE = 'difference'  # (published position - previous one) x publish rate
    FILTERED = 'filtered'  # that difference through a first-order low-pass at rate_cutoff


@dataclass(frozen=True)
class SensorSpec:
    """How the simulated driver reports the state (``driver/sensors.py``): the physics is
    untouched. The defaults are ideal sensors: the exact state, at once."""

    counts_per_revolution: int | None = None  # encoder resolution; None: not quantised
    position_noise: float = 0.0  # [rad] standard deviation, before quantisation
    rate_noise: float = 0.0  # [rad/s] on the exact rate only
    effort_noise: float = 0.0  # [N m]
    wrench_noise: float = 0.0  # [N]
    rate: RateReading = RateReading.EXACT
    rate_cutoff: float | None = None  # [Hz] of the filtered rate
    state_latency: float = 0.0  # [s] age of the published joint states
    effort_latency: float = 0.0  # [s] age of the reported efforts
    wrench_latency: float = 0.0  # [s] age of the published wrench
    seed: int = 0  # of the noise: a run's readings are reproducible

    @property
    def ideal(self) -> bool:
        return self == SensorSpec()


@dataclass(frozen=True)
class JointSpec:
    """A joint of the arm: its name and limits as its URDF describes them (limits are not
    enforced: the article's arm has none), and what a real joint adds to the ideal one (all
    zero: the article's frictionless joint), each acting on the joint's relative rate
    ω_i = q̇_i - q̇_(i-1) (docs/model.md). ``damping`` / ``friction`` are the URDF's
    ``<dynamics>`` values unless the scene's ``joints`` states them."""

    name: str
    lower: float | None = None  # rad, relative joint angle; None: continuous (no limits)
    upper: float | None = None
    effort: float | None = None  # N m, the URDF's <limit effort>
    velocity: float | None = None  # rad/s, the URDF's <limit velocity>
    damping: float = 0.0  # N m s/rad, viscous (URDF <dynamics damping>)
    friction: float = 0.0  # N m, Coulomb (URDF <dynamics friction>), smoothed as
    # friction tanh(ω / friction_v_d)
    friction_v_d: float = 0.01  # rad/s, the Coulomb law's smoothing rate
    armature: float = 0.0  # kg m^2, rotor inertia reflected to the joint
    # the robot's joint angle θ (its zero and sign, as its driver reports it) against the
    # model's relative angle r = q_k - q_(k-1): r = sign θ + offset (docs/scene.md)
    sign: float = 1.0
    offset: float = 0.0  # rad
    max_effort: float | None = None  # N m, the scene's limit instead of the URDF's

    @property
    def effort_limit(self) -> float:
        """The torque the joint's drive clips to [N m] (inf: none). A URDF effort of 0 is
        taken as not given: no drive is rated for nothing."""
        if self.max_effort is not None:
            return self.max_effort
        return self.effort if self.effort else math.inf


@dataclass(frozen=True)
class PlaneFrame:
    """Where the model's plane lies in the description's world (at the robot's zero of the
    moving joints, locked joints at their values): its origin O (the first moving joint),
    its x and y axes and its normal (the first moving joint's axis), all in the world."""

    origin: tuple[float, float, float]
    x: tuple[float, float, float]
    y: tuple[float, float, float]
    axis: tuple[float, float, float]

    def to_plane(self, point: Sequence[float]) -> tuple[float, float]:
        """A world point's coordinates in the plane (its projection)."""
        d = [p - o for p, o in zip(point, self.origin)]
        return (sum(a * b for a, b in zip(d, self.x)), sum(a * b for a, b in zip(d, self.y)))


@dataclass(frozen=True)
class Scene:
    name: str
    lengths: tuple[float, ...]
    masses: tuple[float, ...]
    gravity: float
    tip_radius: float
    arm_material: Material
    surfaces: tuple[Surface, ...]
    actuators_during_contact: bool
    controller: ControllerSpec
    q0: tuple[float, ...]  # rad, absolute link angles
    qd0: tuple[float, ...]  # rad/s
    cycles: int
    t_max: float  # hard stop of a run [s]
    publish_rate: float  # Hz of sampled output (joint states)
    integrator: IntegratorSpec
    # General links (docs/scene.md): per link its centre of mass (along, across the link from
    # its joint) [m] and inertia about it [kg m²], the contact point on the last link (along,
    # across) [m]; empty or None: uniform rods struck at the last link's end
    com: tuple[tuple[float, float], ...] = ()
    inertias: tuple[float, ...] = ()
    tip_point: tuple[float, float] | None = None
    joints: tuple[JointSpec, ...] = ()  # empty: joint1..N, continuous, no dynamics
    link_names: tuple[str, ...] = ()  # the URDF's names of the moving links
    urdf_path: str = ''  # the file the arm came from ('' : the scene's links or arm.description)
    # a URDF arm's other joints of the chain, locked at these values (rad, m), published so
    # that the whole robot shows; and where the model's plane lies in the URDF's world
    locked_joints: tuple[tuple[str, float], ...] = ()
    plane: PlaneFrame | None = None
    urdf_text: str = field(default='', compare=False, repr=False)  # the URDF the arm came from
    sensors: SensorSpec = field(default_factory=SensorSpec)
    joint_limits: str = 'report'  # report | stop: what a run does beyond a joint's limits
    # what loading assumed of the description (said once: the CLI prints them)
    notes: tuple[str, ...] = field(default=(), compare=False)
    source_text: str = field(default='', compare=False, repr=False)
    source_path: str = field(default='', compare=False, repr=False)

    @property
    def n_links(self) -> int:
        return len(self.lengths)

    @property
    def joint_specs(self) -> tuple[JointSpec, ...]:
        """One ``JointSpec`` per joint (ideal ones, joint1..N, when the scene has none)."""
        return self.joints or tuple(JointSpec(f'joint{i + 1}') for i in range(len(self.lengths)))

    @property
    def joint_coordinates(self) -> JointCoordinates:
        """The robot's joint coordinates (what the wire carries) against the model's
        absolute angles: identity for the scene's rods and a URDF in the model's convention."""
        specs = self.joint_specs
        return JointCoordinates(tuple(j.sign for j in specs), tuple(j.offset for j in specs))

    @property
    def effort_limits(self) -> tuple[float, ...]:
        """Each joint's effort limit [N m]: the scene's ``joints[i].max_effort``, else the
        URDF's ``<limit effort>``, else none (inf)."""
        return tuple(j.effort_limit for j in self.joint_specs)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The arm's joint names, base first: a URDF arm's own (its ``<joint name>``), joint1..N
        for the scene's ``links``. Every node, topic, description and recording names the
        joints by this."""
        return tuple(spec.name for spec in self.joint_specs)

    @property
    def link_com(self) -> tuple[tuple[float, float], ...]:
        """Each link's centre of mass (along, across) from its joint [m]."""
        return self.com or rod_centres(self.lengths)

    @property
    def link_inertias(self) -> tuple[float, ...]:
        """Each link's inertia about its centre of mass, about the joint axis [kg m²]."""
        return self.inertias or rod_inertias(self.lengths, self.masses)

    @property
    def contact_point(self) -> tuple[float, float]:
        """The tip sphere's centre B on the last link (along, across) from its joint [m]."""
        return self.tip_point or (self.lengths[-1], 0.0)

    @property
    def general_links(self) -> bool:
        """False when every link is a uniform rod (centre mid-length, inertia m L²/12) and
        the tip at the last link's end: the article's equations, generated as before."""
        return (
            self.link_com != rod_centres(self.lengths)
            or self.link_inertias != rod_inertias(self.lengths, self.masses)
            or self.contact_point != (self.lengths[-1], 0.0)
        )


def rod_centres(lengths: Sequence[float]) -> tuple[tuple[float, float], ...]:
    """Centres of mass of uniform rods: mid-length, on the axis."""
    return tuple((length / 2, 0.0) for length in lengths)


def rod_inertias(lengths: Sequence[float], masses: Sequence[float]) -> tuple[float, ...]:
    """Inertias of uniform slender rods about their centres: m L² / 12."""
    return tuple(m * length * length / 12 for length, m in zip(lengths, masses))
