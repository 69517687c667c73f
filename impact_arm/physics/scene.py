"""Scene files: load, validate and normalise a YAML scene into a frozen ``Scene``.

Every key is checked against ``SCHEMA``: its type, its allowed range or choices, and whether it
is required. Unknown keys are refused so a typo never silently falls back to a default. Errors
name the key path, the value and the allowed range, e.g.::

    scene 'bad.yaml': links[1].mass = -1.0 is out of range: must be > 0 (kg)

Angles are given in degrees in the file (the user-facing edge) and converted to radians here;
everything after this module is SI.  The schema is documented in ``docs/scene.md``.
"""

from __future__ import annotations

import math
import os
import re
import reprlib
from dataclasses import dataclass, field
from enum import Enum
from collections.abc import Sequence
from typing import Any, NoReturn

import yaml

from ..contract import CONTROL_LAWS, INTEGRATOR_METHODS, INTEGRATOR_PRESETS, PID_SPACES
from .errors import SceneError

CONTACT_LAWS = ('elastoplastic', 'hertz', 'none')
MAX_YIELD_STRAIN = 0.1  # S_y / E* beyond which the Jackson-Green law is meaningless
MAX_FILE_BYTES = 1 << 20  # a scene is a few hundred bytes; /dev/zero must not be read whole
MAX_YAML_NODES = 100_000  # after alias expansion: an alias bomb is refused, not expanded

# shown values are cut short: a refusal never prints an unbounded input
_show = reprlib.Repr()
_show.maxstring = _show.maxother = 60
_show.maxlist = _show.maxtuple = _show.maxdict = 6
_show.maxlevel = 2
_show.maxlong = 40


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
    law: str  # elastoplastic | hertz | none
    mu: float  # Coulomb friction coefficient (0 = no friction force)
    v_d: float  # tanh smoothing velocity [m/s]
    material: Material
    mount: Mount | None = None  # None: rigidly mounted


@dataclass(frozen=True)
class ControllerSpec:
    law: str  # q | pid | pd | none
    space: str  # absolute | joint (angles the PID/PD acts on)
    kp: tuple[float, ...]
    kd: tuple[float, ...]
    ki: tuple[float, ...]
    down_target: tuple[float, ...]  # rad, absolute link angles
    up_target: tuple[float, ...]  # rad
    switch_height: float  # tip height that ends the up phase [m]
    rate: float  # Hz; 0 = continuous (evaluated in the right-hand side)


@dataclass(frozen=True)
class IntegratorSpec:
    preset: str
    rtol: float | None = None
    atol: float | None = None
    max_step: float | None = None
    method: str = 'dopri5'
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
    urdf_text: str = field(default='', compare=False, repr=False)  # the URDF the arm came from
    sensors: SensorSpec = field(default_factory=SensorSpec)
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


# --- schema -----------------------------------------------------------------------------
# A spec is (kind, constraint, unit, default); default REQUIRED means the key must be present.
# Kinds: 'num' (constraint: low, high, low_open, high_open), 'choice' (the allowed values),
# 'str', 'bool', 'int' (low, high), 'vec' (a non-empty list; constraint: its numbers' spec),
# 'dict' (a schema), 'list' (a list of entries of a schema), 'map' (names to such entries).
REQUIRED = object()


def number_spec(
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = '',
    default: Any = REQUIRED,
) -> tuple:
    """The spec of a finite number in [low, high] (either end open or absent)."""
    return ('num', (low, high, low_open, high_open), unit, default)


def choice_spec(options: Sequence[str], default: Any = REQUIRED) -> tuple:
    """The spec of one of ``options``."""
    return ('choice', tuple(options), '', default)


MATERIAL = {
    'E': number_spec(1e5, 1e13, unit='Pa'),
    'nu': number_spec(0, 0.5, high_open=True),
    'S_y': number_spec(1e3, 1e12, unit='Pa'),
}
# Absolute bounds below are physical: the model's tolerances are absolute in metres and
# radians, the contact laws are fitted on lab-scale metal contact, and the numbers must stay far
# from float64's range; docs/scene.md ("Physical ranges") gives each reason.
LINK = {
    'length': number_spec(1e-3, 1e3, unit='m'),
    'mass': number_spec(1e-6, 1e6, unit='kg'),
    # general links; absent: a uniform rod's (centre at length / 2, inertia m L^2 / 12)
    'com_x': number_spec(-1e3, 1e3, unit='m', default=None),
    'com_y': number_spec(-1e3, 1e3, unit='m', default=0.0),
    'inertia': number_spec(1e-12, 1e12, unit='kg m^2', default=None),
}
TIP_RADIUS_RANGE = (1e-6, 1, False, False)  # m
# values of a URDF arm's link that a scene (a fit, a sweep) sets instead of the file's
ARM_LINK = {
    'mass': ('num', LINK['mass'][1], 'kg', None),
    'com_x': ('num', LINK['com_x'][1], 'm', None),
    'com_y': ('num', LINK['com_y'][1], 'm', None),
    'inertia': ('num', LINK['inertia'][1], 'kg m^2', None),
}
ARM: dict[str, Any] = {
    'urdf': ('str', None, '', None),  # a file, or
    'description': ('str', None, '', None),  # its text (recordings store the scene so)
    'links': ('list', ARM_LINK, '', None),  # one per moving link: values instead of the file's
    'contact': (
        'dict',
        {
            'link': ('str', None, '', None),
            'point': ('vec', number_spec(-1e3, 1e3), 'm', None),
            'radius': ('num', TIP_RADIUS_RANGE, 'm', None),
        },
        '',
        {},
    ),
}
JOINT = {  # absent: the URDF's value for damping and friction, else the ideal joint's
    'damping': number_spec(0, 1e6, unit='N m s/rad', default=None),
    'friction': number_spec(0, 1e6, unit='N m', default=None),
    'friction_v_d': number_spec(1e-6, 10, unit='rad/s', default=None),
    'armature': number_spec(0, 1e6, unit='kg m^2', default=None),
}
SURFACE = {
    'height': number_spec(-1e3, 1e3, unit='m'),
    'law': choice_spec(CONTACT_LAWS, 'elastoplastic'),
    'mu': number_spec(0, 10, unit='-', default=0.0),
    'v_d': number_spec(1e-6, 10, unit='m/s', default=0.02),
    'material': ('str', None, '', 'surface'),
    'mount': (
        'dict',
        {
            'mass': number_spec(1e-6, 1e6, unit='kg'),
            'stiffness': number_spec(0, 1e13, unit='N/m'),
            'damping_ratio': number_spec(0, 10, unit='-', default=0.0),
        },
        '',
        None,
    ),
}
CONTROLLER = {
    'law': choice_spec(CONTROL_LAWS, 'q'),
    'space': choice_spec(PID_SPACES, 'absolute'),
    'kp': ('vec', number_spec(0, 1e9), 'N m/rad', REQUIRED),
    'kd': ('vec', number_spec(0, 1e9), 'N m s/rad', REQUIRED),
    'ki': ('vec', number_spec(0, 1e9), 'N m/(rad s)', None),
    'down_target_deg': ('vec', number_spec(-360, 360), 'deg', REQUIRED),
    'up_target_deg': ('vec', number_spec(-360, 360), 'deg', REQUIRED),
    'switch_height': number_spec(-1e3, 1e3, unit='m', default=1.0),
    'rate': number_spec(0, 1e6, unit='Hz', default=0.0),
}
INTEGRATOR = {
    'preset': choice_spec(INTEGRATOR_PRESETS, 'balanced'),
    'rtol': number_spec(1e-14, 1e-1, unit='-', default=None),
    'atol': number_spec(1e-16, 1e-1, unit='-', default=None),
    'max_step': number_spec(1e-5, 10, unit='s', default=None),
    'method': choice_spec(INTEGRATOR_METHODS, 'dopri5'),
    'contact_rtol': number_spec(1e-14, 1e-1, unit='-', default=None),
}
MAX_SENSOR_LATENCY = 1.0  # s: a driver whose samples are older is broken, not slow
SENSORS = {
    'counts_per_revolution': ('int', (1, 2**40), '', None),
    'position_noise': number_spec(0, 1, unit='rad', default=0.0),
    'rate_noise': number_spec(0, 1e3, unit='rad/s', default=0.0),
    'effort_noise': number_spec(0, 1e6, unit='N m', default=0.0),
    'wrench_noise': number_spec(0, 1e9, unit='N', default=0.0),
    'rate': choice_spec([r.value for r in RateReading], RateReading.EXACT.value),
    'rate_cutoff': number_spec(1e-3, 1e6, unit='Hz', default=None),
    'state_latency': number_spec(0, MAX_SENSOR_LATENCY, unit='s', default=0.0),
    'effort_latency': number_spec(0, MAX_SENSOR_LATENCY, unit='s', default=0.0),
    'wrench_latency': number_spec(0, MAX_SENSOR_LATENCY, unit='s', default=0.0),
    'seed': ('int', (0, 2**32 - 1), '', 0),
}
SCHEMA = {
    'name': ('str', None, '', 'scene'),
    'description': ('str', None, '', ''),
    'gravity': number_spec(0, 1000, unit='m/s^2', default=9.81),
    'links': ('list', LINK, '', None),  # this or arm
    'arm': ('dict', ARM, '', None),
    'joints': ('list', JOINT, '', ()),
    'tip_radius': ('num', TIP_RADIUS_RANGE, 'm', None),  # with links
    'materials': ('map', MATERIAL, '', REQUIRED),
    'arm_material': ('str', None, '', 'arm'),
    'surfaces': ('list', SURFACE, '', ()),
    'actuators_during_contact': ('bool', None, '', False),
    'controller': ('dict', CONTROLLER, '', REQUIRED),
    'initial': (
        'dict',
        {
            'q_deg': ('vec', number_spec(-360, 360), 'deg', REQUIRED),
            'qd': ('vec', number_spec(-1e4, 1e4), 'rad/s', None),
        },
        '',
        REQUIRED,
    ),
    'cycles': ('int', (0, 1_000_000), '', 15),
    't_max': number_spec(0, 1e7, low_open=True, unit='s', default=60.0),
    'publish_rate': number_spec(1, 1e6, unit='Hz', default=1000.0),
    'integrator': ('dict', INTEGRATOR, '', {'preset': 'balanced'}),
    'sensors': ('dict', SENSORS, '', {}),
}


def _describe_range(constraint, unit):
    low, high, low_open, high_open = constraint
    unit = f' ({unit})' if unit else ''
    parts = []
    if low is not None:
        parts.append(f'> {low:g}' if low_open else f'>= {low:g}')
    if high is not None:
        parts.append(f'< {high:g}' if high_open else f'<= {high:g}')
    return ('must be ' + ' and '.join(parts) + unit) if parts else f'any finite number{unit}'


class SceneChecker:
    """Checks scene data against a schema of specs (``number_spec``, ``choice_spec``, the
    kinds above), refusing the first bad value with a ``SceneError`` of one line: "scene
    'ORIGIN': KEY.PATH = VALUE ..." and the allowed range. Every scene file uses it: the
    arm's (``parse_scene``) and the free body's (``physics/bodies/scene.py``), so their
    refusals read the same.

    ``leaf(path, value, spec)`` checks one value of any kind and returns it checked (numbers
    as floats, containers as tuples and dicts with their defaults filled in); ``number``
    checks one number against a range, for a value a schema cannot describe; ``fail``
    refuses in the same form, for checks across keys. A scene with container kinds of its
    own subclasses it and overrides ``container``, handing the other kinds to this one.

    With ``checked`` (a dict kept between calls) each container that passes is remembered
    by its key path with its checked value: the very same object met there again is not
    checked again, nor are the entries a copy of a remembered mapping shares with it. A
    subtree's check depends on nothing but the subtree and its key path (which fixes its
    schema), and only what passed is remembered, so the first failure and its message are
    those of a full walk. The objects must not change in place between the calls."""

    def __init__(self, origin: str, checked: dict | None = None) -> None:
        self.origin = origin
        self.checked = checked

    def fail(self, path: str, message: str) -> NoReturn:
        raise SceneError(f"scene '{self.origin}': {path} {message}")

    def number(self, path: str, value: Any, constraint: tuple, unit: str) -> float:
        """``value`` as a float if it is a finite number within ``constraint`` (low, high,
        low_open, high_open; ``number_spec``'s), else refused naming ``path`` and the range."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(
                path, f'= {_show.repr(value)} is not a number; {_describe_range(constraint, unit)}'
            )
        try:
            value = float(value)
        except OverflowError:  # an integer beyond float64 (> ~1.8e308)
            self.fail(
                path,
                f'= an integer of {len(str(abs(value)))} digits is out of range: '
                f'{_describe_range(constraint, unit)}',
            )
        if not math.isfinite(value):
            self.fail(path, f'= {value!r} is not finite; {_describe_range(constraint, unit)}')
        low, high, low_open, high_open = constraint
        bad = (low is not None and (value < low or (low_open and value == low))) or (
            high is not None and (value > high or (high_open and value == high))
        )
        if bad:
            self.fail(path, f'= {value:g} is out of range: {_describe_range(constraint, unit)}')
        return value

    def leaf(self, path: str, value: Any, spec: tuple) -> Any:
        kind, constraint, unit, _ = spec
        if kind == 'num':
            return self.number(path, value, constraint, unit)
        if kind == 'choice':
            if value not in constraint:
                self.fail(
                    path,
                    f'= {_show.repr(value)} is not allowed: choose one of {", ".join(constraint)}',
                )
            return value
        if kind == 'str':
            if not isinstance(value, str):
                self.fail(path, f'= {_show.repr(value)} must be a string')
            try:
                value.encode('utf-8')  # a YAML "\ud800" escape gives a lone surrogate
            except UnicodeEncodeError:
                self.fail(
                    path,
                    f'= {_show.repr(value)} is not valid Unicode text (a lone '
                    f'surrogate): file names, MCAP and JSON cannot hold it',
                )
            return value
        if kind == 'bool':
            if not isinstance(value, bool):
                self.fail(path, f'= {_show.repr(value)} must be true or false')
            return value
        if kind == 'int':
            low, high = constraint
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                self.fail(path, f'= {_show.repr(value)} must be an integer in [{low}, {high}]')
            return value
        if self.checked is None:
            return self.container(path, value, kind, constraint, unit)
        known = self.checked.get(path)
        if known is not None and known[0] is value:
            return known[1]
        result = self.container(path, value, kind, constraint, unit, known)
        self.checked[path] = (value, result)  # holding the object keeps its identity
        return result

    def container(
        self,
        path: str,
        value: Any,
        kind: str,
        constraint: Any,
        unit: str,
        known: tuple | None = None,
    ) -> Any:
        if kind == 'vec':
            if not isinstance(value, (list, tuple)) or not value:
                self.fail(
                    path, f'= {_show.repr(value)} must be a non-empty list of numbers ({unit})'
                )
            return tuple(
                self.number(f'{path}[{i}]', v, constraint[1], unit) for i, v in enumerate(value)
            )
        if kind == 'dict':
            return self.mapping(path, value, constraint, known)
        if kind == 'list':
            if not isinstance(value, (list, tuple)):
                self.fail(path, f'= {_show.repr(value)} must be a list')
            entry = ('dict', constraint, '', REQUIRED)
            return tuple(self.leaf(f'{path}[{i}]', v, entry) for i, v in enumerate(value))
        if kind == 'map':
            if not isinstance(value, dict) or not value:
                self.fail(path, f'= {_show.repr(value)} must be a mapping of names to entries')
            entry = ('dict', constraint, '', REQUIRED)
            return {str(k): self.leaf(f'{path}.{k}', v, entry) for k, v in value.items()}
        raise AssertionError(kind)

    def mapping(self, path: str, value: Any, schema: dict, known: tuple | None = None) -> dict:
        """``known``: (mapping, checked value) remembered at ``path``; the entries that
        ``value`` shares with it (the same objects: a copy with one entry changed) keep
        their checked values."""
        prefix = f'{path}.' if path else ''
        if not isinstance(value, dict):
            self.fail(path or '<top level>', f'must be a mapping, got {type(value).__name__}')
        unknown = (
            () if value.keys() <= schema.keys() else sorted(set(map(str, value)) - set(schema))
        )
        if unknown:
            self.fail(
                f'{prefix}{unknown[0][:60]}',
                f'is not a known key; allowed here: {", ".join(schema)}',
            )
        before, checked = known if known else ({}, None)
        out = {}
        for key, spec in schema.items():
            if key in value:
                entry = value[key]
                if key in before and before[key] is entry:
                    out[key] = checked[key]
                else:
                    out[key] = self.leaf(prefix + key, entry, spec)
            elif spec[3] is REQUIRED:
                self.fail(prefix + key, 'is missing (required)')
            else:
                out[key] = spec[3]
        return out


def parse_scene(
    data: Any,
    origin: str = '<scene>',
    text: str = '',
    path: str = '',
    *,
    checked: dict | None = None,
) -> Scene:
    """Validate a scene already parsed from YAML and build the frozen ``Scene``.

    ``checked``: for many variants of one scene's data that share their unchanged parts
    and are never changed in place (a study's runs, ``study.apply_overrides``), a dict
    kept between the calls: a shared part already checked is not checked again. The
    checks across keys always run; a variant is refused exactly as without it."""
    check = SceneChecker(origin, checked)
    raw = check.leaf('', data, ('dict', SCHEMA, '', REQUIRED))
    links = _arm_links(check, raw, path)
    n = len(links.lengths)

    def vector(path: str, values: Sequence | None, default: Any = None) -> tuple:
        if values is None:
            return tuple(default for _ in range(n))
        if len(values) != n:
            check.fail(path, f'has {len(values)} entries: must have one per link ({n})')
        return tuple(values)

    materials = {k: Material(**v) for k, v in raw['materials'].items()}

    def material(path: str, name: str) -> Material:
        if name not in materials:
            check.fail(path, f"= {name!r} names no entry of 'materials' ({', '.join(materials)})")
        return materials[name]

    arm = material('arm_material', raw['arm_material'])
    surfaces = tuple(
        Surface(
            height=s['height'],
            law=s['law'],
            mu=s['mu'],
            v_d=s['v_d'],
            material=material(f'surfaces[{i}].material', s['material']),
            mount=Mount(**s['mount']) if s['mount'] is not None else None,
        )
        for i, s in enumerate(raw['surfaces'])
    )
    heights = [s.height for s in surfaces]
    if len(set(heights)) != len(heights):
        check.fail('surfaces', f'= heights {heights}: two surfaces at the same height')

    c = raw['controller']
    controller = ControllerSpec(
        law=c['law'],
        space=c['space'],
        kp=vector('controller.kp', c['kp']),
        kd=vector('controller.kd', c['kd']),
        ki=vector('controller.ki', c['ki'], 0.0),
        down_target=tuple(
            map(math.radians, vector('controller.down_target_deg', c['down_target_deg']))
        ),
        up_target=tuple(map(math.radians, vector('controller.up_target_deg', c['up_target_deg']))),
        switch_height=c['switch_height'],
        rate=c['rate'],
    )
    if controller.law == 'pid' and not any(controller.ki):
        check.fail('controller.ki', '= all zero with law pid: use law pd, or give integral gains')

    q0 = tuple(map(math.radians, vector('initial.q_deg', raw['initial']['q_deg'])))
    qd0 = vector('initial.qd', raw['initial']['qd'], 0.0)
    reach = sum(links.lengths[:-1]) + math.hypot(*links.tip_point)
    for i, s in enumerate(surfaces):
        if s.law != 'none' and abs(s.height) >= reach:
            check.fail(
                f'surfaces[{i}].height',
                f'= {s.height:g} is out of reach: must satisfy |height| < {reach:g} (m)',
            )
    for i, s in enumerate(surfaces):
        if s.law != 'elastoplastic':
            continue
        # the Jackson-Green fit (B = 0.14 exp(23 S_y/E)) holds for metals-like yield strains;
        # far beyond it B overflows and the force law means nothing
        strain = min(arm.S_y, s.material.S_y) / reduced_modulus(arm, s.material)
        if strain > MAX_YIELD_STRAIN:
            check.fail(
                f'surfaces[{i}].material',
                f'= {raw["surfaces"][i]["material"]!r}: yield strain S_y/E* = '
                f'{strain:.3g} is out of range: must be <= {MAX_YIELD_STRAIN:g} for the '
                f'elasto-plastic (Jackson-Green) law; use law hertz, or a consistent '
                f'E and S_y',
            )
    joints = _joint_values(check, links, raw['joints'])
    _check_physics(check, raw, links, surfaces, arm)
    _check_joints(check, links, joints)
    integ = IntegratorSpec(**raw['integrator'])
    sensors = _sensor_spec(check, raw['sensors'])
    return Scene(
        name=raw['name'],
        lengths=links.lengths,
        masses=links.masses,
        gravity=raw['gravity'],
        tip_radius=links.tip_radius,
        arm_material=arm,
        surfaces=surfaces,
        actuators_during_contact=raw['actuators_during_contact'],
        controller=controller,
        q0=q0,
        qd0=qd0,
        cycles=raw['cycles'],
        t_max=raw['t_max'],
        publish_rate=raw['publish_rate'],
        integrator=integ,
        com=links.com,
        inertias=links.inertias,
        tip_point=links.tip_point,
        joints=joints,
        link_names=links.link_names,
        urdf_path=links.urdf_path,
        urdf_text=links.urdf_text,
        sensors=sensors,
        source_text=text,
        source_path=path,
    )


@dataclass(frozen=True)
class _ArmLinks:
    """The arm's links from the scene's ``links`` or its ``arm.urdf``."""

    lengths: tuple[float, ...]
    masses: tuple[float, ...]
    com: tuple[tuple[float, float], ...]
    inertias: tuple[float, ...]
    tip_point: tuple[float, float]
    tip_radius: float
    joints: tuple[JointSpec, ...]
    link_names: tuple[str, ...]
    urdf_path: str
    key: str  # the scene key the links come from, for refusals
    urdf_text: str = ''


def _arm_links(check: SceneChecker, raw: dict, scene_path: str) -> _ArmLinks:
    from ..contract import joint_names

    if raw['arm'] is not None:
        for key, instead in (
            ('links', 'the links'),
            ('tip_radius', "the contact sphere's radius (arm.contact.radius)"),
        ):
            if raw[key] is not None:
                check.fail(key, f'is given with arm.urdf, which gives {instead}: give one of them')
        contact = raw['arm'].get('contact') or {}
        point = contact.get('point')
        if point is not None and len(point) != 3:
            check.fail(
                'arm.contact.point',
                f"has {len(point)} entries: must be x y z (m) in the contact link's frame",
            )
        given = [key for key in ('urdf', 'description') if raw['arm'][key] is not None]
        if len(given) != 1:
            check.fail(
                'arm',
                'gives both urdf and description: give one of them'
                if given
                else 'needs urdf (a URDF file) or description (its text)',
            )
        urdf, urdf_text = _urdf_arm(
            check.origin,
            raw['arm']['urdf'],
            raw['arm']['description'],
            scene_path,
            contact.get('link'),
            point,
            contact.get('radius'),
        )
        urdf = _with_link_values(check, urdf, raw['arm']['links'])
        for k, name in enumerate(urdf.link_names):
            where = f"arm.{given[0]} link '{name}'"
            length = 'contact point distance' if k == len(urdf.link_names) - 1 else 'length'
            for what, value, spec in (
                (length, urdf.lengths[k], LINK['length']),
                ('mass', urdf.masses[k], LINK['mass']),
                ('centre of mass x', urdf.com[k][0], LINK['com_x']),
                ('centre of mass z', urdf.com[k][1], LINK['com_y']),
                ('inertia', urdf.inertias[k], LINK['inertia']),
            ):
                check.number(f'{where} {what}', value, spec[1], spec[2])
        check.number('arm.contact.radius', urdf.tip_radius, TIP_RADIUS_RANGE, 'm')
        return _ArmLinks(
            urdf.lengths,
            urdf.masses,
            urdf.com,
            urdf.inertias,
            urdf.tip_point,
            urdf.tip_radius,
            urdf.joints,
            urdf.link_names,
            raw['arm']['urdf'] or '',
            f'arm.{given[0]}',
            urdf_text,
        )
    for key in ('links', 'tip_radius'):
        if raw[key] is None:
            check.fail(key, 'is missing (required unless arm.urdf gives the arm)')
    entries = raw['links']
    n = len(entries)
    if n < 2:
        check.fail('links', f'has {n} entries: an arm needs at least 2 links')
    lengths = tuple(entry['length'] for entry in entries)
    masses = tuple(entry['mass'] for entry in entries)
    rod_c, rod_i = rod_centres(lengths), rod_inertias(lengths, masses)
    return _ArmLinks(
        lengths,
        masses,
        tuple(
            (rod_c[k][0] if entry['com_x'] is None else entry['com_x'], entry['com_y'])
            for k, entry in enumerate(entries)
        ),
        tuple(
            rod_i[k] if entry['inertia'] is None else entry['inertia']
            for k, entry in enumerate(entries)
        ),
        (lengths[-1], 0.0),
        raw['tip_radius'],
        tuple(JointSpec(name) for name in joint_names(n)),
        (),
        '',
        'links',
    )


def _with_link_values(check: SceneChecker, urdf: Any, values: Sequence[dict] | None) -> Any:
    """The URDF's arm with the values ``arm.links`` states instead of the file's."""
    from dataclasses import replace

    if values is None:
        return urdf
    n = len(urdf.link_names)
    if len(values) != n:
        check.fail(
            'arm.links',
            f'has {len(values)} entries: must have one per moving link of the URDF ({n}: '
            f'{", ".join(urdf.link_names)})',
        )
    masses, com, inertias = list(urdf.masses), list(urdf.com), list(urdf.inertias)
    for k, entry in enumerate(values):
        if entry['mass'] is not None:
            masses[k] = entry['mass']
        com[k] = (
            com[k][0] if entry['com_x'] is None else entry['com_x'],
            com[k][1] if entry['com_y'] is None else entry['com_y'],
        )
        if entry['inertia'] is not None:
            inertias[k] = entry['inertia']
    return replace(urdf, masses=tuple(masses), com=tuple(com), inertias=tuple(inertias))


_URDF_CACHE: dict[tuple, Any] = {}  # a study loads one scene many times: read its URDF once


def _urdf_arm(origin, path, description, scene_path, link, point, radius):
    """(the parsed arm, the URDF text) of ``arm.urdf`` (a file) or ``arm.description``."""
    from .urdf_arm import parse_urdf_arm, read_urdf_file, resolve_urdf_path

    if path is None:
        key: tuple = (hash(description), description, link, point, radius)
    else:
        full = resolve_urdf_path(path, scene_path)
        try:
            info = os.stat(full)
            stamp: tuple = (info.st_mtime_ns, info.st_size)
        except OSError:
            stamp = ()
        key = (os.path.abspath(full), stamp, link, point, radius)
    if key not in _URDF_CACHE:
        if path is None:
            text, where = description, f"scene '{origin}': arm.description"
        else:
            text = read_urdf_file(full, f"scene '{origin}': arm.urdf")
            where = f"scene '{origin}': arm.urdf '{path}'"
        if len(_URDF_CACHE) > 64:
            _URDF_CACHE.clear()
        _URDF_CACHE[key] = (parse_urdf_arm(text, where, link, point, radius), text)
    return _URDF_CACHE[key]


def self_contained_text(scene: Scene) -> str:
    """The scene's YAML text as a recording stores it: unchanged, but for an arm read from
    a URDF file, whose text it carries as ``arm.description`` instead of the file's path, so
    that the recording's scene loads wherever the file is not."""
    if not scene.urdf_path or not scene.source_text:
        return scene.source_text
    data = scene_data(scene.source_text, scene.source_path or scene.name)
    arm = dict(data['arm'])
    del arm['urdf']
    arm['description'] = scene.urdf_text
    data['arm'] = arm
    header = (
        f'# {scene.name}: the arm of {scene.urdf_path} inlined as arm.description (docs/scene.md)\n'
    )
    return header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)


def _sensor_spec(check: SceneChecker, raw: dict) -> SensorSpec:
    """The checked ``sensors`` section; a key that the chosen rate reading would ignore is
    refused rather than silently dropped."""
    if not raw:  # the section left out: ideal sensors
        return SensorSpec()
    rate = RateReading(raw['rate'])
    if raw['rate_noise'] and rate is not RateReading.EXACT:
        check.fail(
            'sensors.rate_noise',
            f'= {raw["rate_noise"]:g} applies to rate: exact only; rate: {rate.value} '
            f'derives the rates from the published positions and carries their noise',
        )
    if rate is RateReading.FILTERED and raw['rate_cutoff'] is None:
        check.fail('sensors.rate_cutoff', 'is missing: rate: filtered needs a cut-off (Hz)')
    if rate is not RateReading.FILTERED and raw['rate_cutoff'] is not None:
        check.fail(
            'sensors.rate_cutoff',
            f'= {raw["rate_cutoff"]:g} applies to rate: filtered only (rate is {rate.value})',
        )
    return SensorSpec(**{**raw, 'rate': rate})


MAX_LENGTH_RATIO = 1e3  # longest / shortest link
MAX_MASS_RATIO = 1e4  # heaviest / lightest link
MIN_CONTACT_TIME = 1e-6  # s, Hertz contact duration at 1 m/s
MAX_LOOP_RATE = 1e5  # 1/s, the control loop's fastest eigenvalue (kd/I, sqrt(kp/I))
# a link's inertia about its joint, at least, in m L^2 (a rod has 1/3): below it the link
# turns almost freely about its joint and the mass matrix is near singular
MIN_JOINT_INERTIA = 1e-6
MAX_COM_DISTANCE = 10.0  # a link's centre of mass from its joint, at most, in link lengths


def _joint_inertias(check: SceneChecker, links: _ArmLinks) -> list[float]:
    """Each link's inertia about its joint, refused when too small; a rod's m L² / 3."""
    out = []
    for k, (length, mass, (cx, cy), inertia) in enumerate(
        zip(links.lengths, links.masses, links.com, links.inertias)
    ):
        rod = (cx, cy) == (length / 2, 0.0) and inertia == mass * length * length / 12
        where = (
            f'links[{k}]' if links.key == 'links' else f"{links.key} link '{links.link_names[k]}'"
        )
        if math.hypot(cx, cy) > MAX_COM_DISTANCE * length:
            check.fail(
                f'{where}.com_x' if links.key == 'links' else f'{where} centre of mass',
                f'= ({cx:g}, {cy:g}) m is out of range: must lie within '
                f'{MAX_COM_DISTANCE:g} link lengths ({MAX_COM_DISTANCE * length:g} m) of the '
                f"link's joint (a link's mass lies on or near the link)",
            )
        about_joint = mass * length**2 / 3 if rod else inertia + mass * (cx * cx + cy * cy)
        if about_joint < MIN_JOINT_INERTIA * mass * length**2:
            check.fail(
                f'{where}.inertia' if links.key == 'links' else f'{where} inertia',
                f'= {inertia:g} with the centre of mass at ({cx:g}, {cy:g}) m: the inertia '
                f'about the joint, {about_joint:.3g} kg m^2, is out of range: must be >= '
                f'{MIN_JOINT_INERTIA:g} m L^2 = {MIN_JOINT_INERTIA * mass * length**2:.3g} '
                f'(the link would turn almost freely: mass matrix near singular)',
            )
        out.append(about_joint)
    return out


def _joint_values(check: SceneChecker, links: _ArmLinks, entries: Sequence[dict]) -> tuple:
    """The arm's joints (names and limits from ``links``) with the values the scene's
    ``joints`` states: one entry per link, or none."""
    from dataclasses import replace

    if not entries:
        return links.joints
    n = len(links.lengths)
    if len(entries) != n:
        check.fail('joints', f'has {len(entries)} entries: must have one per link ({n}) or none')
    return tuple(
        replace(joint, **{k: v for k, v in entry.items() if v is not None})
        for joint, entry in zip(links.joints, entries)
    )


def _check_joints(check: SceneChecker, links: _ArmLinks, joints: Sequence[JointSpec]) -> None:
    """Joint friction and armature within what the numerics can follow."""
    for k, joint in enumerate(joints):
        cx, cy = links.com[k]
        own = links.inertias[k]  # the link about its centre of mass
        inertia = own + links.masses[k] * (cx * cx + cy * cy) + joint.armature
        # near ω = 0 smoothed Coulomb friction is a damper of slope friction / friction_v_d
        for key, value, rate in (
            ('damping', joint.damping, joint.damping / inertia),
            ('friction', joint.friction, joint.friction / joint.friction_v_d / inertia),
        ):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'joints[{k}].{key}',
                    f'= {value:g} is out of range: gives a decay rate of {rate:.3g} 1/s '
                    f'on link {k + 1} (inertia {inertia:.3g} kg m^2'
                    + (f', friction_v_d {joint.friction_v_d:g} rad/s' if key == 'friction' else '')
                    + f'); must be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: '
                    f'beyond the run budget)',
                )
        if joint.armature > MAX_MASS_RATIO * own:
            check.fail(
                f'joints[{k}].armature',
                f'= {joint.armature:g} is out of range: must be <= {MAX_MASS_RATIO:g} times '
                f"link {k + 1}'s own inertia ({MAX_MASS_RATIO * own:.3g} kg m^2: the mass "
                f'matrix becomes too ill-conditioned to solve)',
            )


def _check_physics(check, raw, links, surfaces, arm):
    """Ranges that involve several keys: each bounds what the model or the numerics can do."""
    lengths, masses = links.lengths, links.masses
    joint_inertias = _joint_inertias(check, links)
    if max(lengths) / min(lengths) > MAX_LENGTH_RATIO:
        check.fail(
            links.key,
            f'= lengths {min(lengths):g} .. {max(lengths):g} m: ratio '
            f'{max(lengths) / min(lengths):.3g} is out of range: must be <= '
            f'{MAX_LENGTH_RATIO:g} (the absolute tolerances, in m and rad, cannot suit '
            f'both ends of the arm)',
        )
    if max(masses) / min(masses) > MAX_MASS_RATIO:
        check.fail(
            links.key,
            f'= masses {min(masses):g} .. {max(masses):g} kg: ratio '
            f'{max(masses) / min(masses):.3g} is out of range: must be <= '
            f'{MAX_MASS_RATIO:g} (the mass matrix becomes too ill-conditioned to solve)',
        )
    if links.tip_radius > min(lengths):
        check.fail(
            'tip_radius' if links.key == 'links' else 'arm.contact.radius',
            f'= {links.tip_radius:g} is out of range: must be <= the '
            f'shortest link ({min(lengths):g} m): the tip is a sphere on a slender rod',
        )
    # Hertz contact duration of the lightest link's mass striking at 1 m/s:
    # t_c = 2.87 (m^2 / (R E*^2 v))^(1/5); the contact phases need steps well below it
    for i, sfc in enumerate(surfaces):
        if sfc.law == 'none':
            continue
        e_red = reduced_modulus(arm, sfc.material)
        t_c = 2.87 * (min(masses) ** 2 / (links.tip_radius * e_red**2)) ** 0.2
        if t_c < MIN_CONTACT_TIME:
            check.fail(
                f'surfaces[{i}].material',
                f'= {raw["surfaces"][i]["material"]!r}: contact lasts ~{t_c:.2g} s '
                f'(Hertz, lightest link at 1 m/s), out of range: must be >= '
                f'{MIN_CONTACT_TIME:g} s (stiffness E* = {e_red:.3g} Pa against link '
                f'masses down to {min(masses):g} kg: steps would fall under the '
                f'resolution of t)',
            )
    for i, sfc in enumerate(surfaces):
        if sfc.mount is None or sfc.law == 'none':
            continue
        mount = sfc.mount
        omega = math.sqrt(mount.stiffness / mount.mass)
        for key, rate in (('stiffness', omega), ('damping_ratio', 2 * mount.damping_ratio * omega)):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'surfaces[{i}].mount.{key}',
                    f'= {getattr(mount, key):g} is out of range: gives the plate a rate of '
                    f'{rate:.3g} 1/s (mass {mount.mass:g} kg, stiffness {mount.stiffness:g} '
                    f'N/m); must be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: beyond '
                    f'the run budget)',
                )
        e_red = reduced_modulus(arm, sfc.material)
        t_c = 2.87 * (mount.mass**2 / (links.tip_radius * e_red**2)) ** 0.2
        if t_c < MIN_CONTACT_TIME:
            check.fail(
                f'surfaces[{i}].mount.mass',
                f'= {mount.mass:g} is out of range: the tip would bounce off the plate in '
                f'~{t_c:.2g} s (Hertz at 1 m/s); must be >= {MIN_CONTACT_TIME:g} s: steps '
                f'would fall under the resolution of t',
            )
    c = raw['controller']
    for k, inertia in enumerate(joint_inertias):
        for key, rate in (
            ('kd', c['kd'][k] / inertia if k < len(c['kd']) else 0.0),
            ('kp', math.sqrt(c['kp'][k] / inertia) if k < len(c['kp']) else 0.0),
        ):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'controller.{key}[{k}]',
                    f'= {c[key][k]:g} is out of range: gives a closed-loop rate of '
                    f'{rate:.3g} 1/s on link {k + 1} (inertia {inertia:.3g} kg m^2); must '
                    f'be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: beyond the run budget)',
                )
    if 0 < c['rate'] < 1:
        check.fail(
            'controller.rate',
            f'= {c["rate"]:g} is out of range: must be 0 '
            f'(continuous) or >= 1 (Hz): a slower sampled controller holds one torque '
            f'for more than a second',
        )


def read_scene_file(name: str | os.PathLike) -> tuple[str, str]:
    """(text, path) of a scene file given by path or installed name; at most
    ``MAX_FILE_BYTES`` are read (``--scene /dev/zero`` is refused at once)."""
    path = str(resolve_scene_path(name))
    try:
        with open(path, 'rb') as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        hint = ''
        if isinstance(exc, FileNotFoundError) and not os.path.dirname(path):
            names = installed_scenes()
            hint = (
                f'; installed scenes: {", ".join(names)} (or give a path to a scene file)'
                if names
                else ''
            )
        raise SceneError(f"scene '{path}': cannot be read: {exc.strerror}{hint}") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"scene '{path}': larger than {MAX_FILE_BYTES} bytes: not a scene file")
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise SceneError(f"scene '{path}': not UTF-8 text (byte {exc.start})") from None
    return text, path


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a scene file; raises ``SceneError`` with a user-facing message."""
    text, path = read_scene_file(path)
    return scene_from_text(text, origin=path, path=path)


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that reads numbers as YAML 1.2 does, refuses what YAML 1.1 and 1.2 read
    differently, and refuses duplicate keys.

    PyYAML implements YAML 1.1: ``210e9`` would be a string, ``1:30`` the number 90
    (sexagesimal), ``017`` the number 15 (octal), ``on``/``no`` booleans. A scene means one
    thing under either reading or is refused, naming the value."""

    yaml_implicit_resolvers = {
        first: [
            (tag, regexp)
            for tag, regexp in resolvers
            if tag
            not in ('tag:yaml.org,2002:int', 'tag:yaml.org,2002:float', 'tag:yaml.org,2002:bool')
        ]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            if key is not None and key in seen:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f'duplicate key {key[:60]!r} (the file would mean only its last value)',
                    key_node.start_mark,
                )
            seen.add(key)
        return super().construct_mapping(node, deep)

    def construct_ambiguous(self, node: yaml.ScalarNode) -> NoReturn:
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f'{node.value[:60]!r} reads differently in YAML 1.1 and 1.2 '
            f'(sexagesimal, octal, yes/no/on/off, digit separators): write a plain decimal '
            f'number, true/false, or quote it as a string',
            node.start_mark,
        )


_AMBIGUOUS = 'tag:impact_arm,2026:ambiguous'
_SceneLoader.add_constructor(_AMBIGUOUS, _SceneLoader.construct_ambiguous)
for _tag, _pattern, _first in (
    (
        _AMBIGUOUS,
        r'^(?:[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?'
        r'|[-+]?0[0-9_]+|[-+]?0b[01_]+|[-+]?[0-9][0-9_]*_[0-9_]*(?:\.[0-9_]*)?'
        r'|yes|Yes|YES|no|No|NO|on|On|ON|off|Off|OFF|y|Y|n|N)$',
        list('-+0123456789yYnNoO'),
    ),
    ('tag:yaml.org,2002:bool', r'^(?:true|True|TRUE|false|False|FALSE)$', list('tTfF')),
    (
        'tag:yaml.org,2002:int',
        r'^(?:[-+]?(?:0|[1-9][0-9]*)|0x[0-9a-fA-F]+|0o[0-7]+)$',
        list('-+0123456789'),
    ),
    (
        'tag:yaml.org,2002:float',
        r'^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?'
        r'|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$',
        list('-+0123456789.'),
    ),
):
    _SceneLoader.add_implicit_resolver(_tag, re.compile(_pattern), _first)


def _construct_int(loader, node):
    """YAML 1.2 integers: decimal, 0x hex, 0o octal (PyYAML's reader would take 0o as text)."""
    value = node.value
    if value.startswith('0x'):
        return int(value[2:], 16)
    if value.startswith('0o'):
        return int(value[2:], 8)
    return int(value)


_SceneLoader.add_constructor('tag:yaml.org,2002:int', _construct_int)


def _expanded_size(node, sizes) -> int:
    """Nodes the document becomes once aliases are expanded (shared nodes counted each time)."""
    key = id(node)
    if key not in sizes:
        sizes[key] = 0  # a recursive alias counts as one node here; it is refused later
        if isinstance(node, yaml.SequenceNode):
            total = 1 + sum(_expanded_size(child, sizes) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            total = 1 + sum(
                _expanded_size(k, sizes) + _expanded_size(v, sizes) for k, v in node.value
            )
        else:
            total = 1
        sizes[key] = min(total, MAX_YAML_NODES + 1)
    return sizes[key]


def _near_key(text: str, line: int) -> str:
    """The key being written at (or just before) a 0-based line, for the one-line message."""
    lines = text.splitlines()
    for k in range(min(line, len(lines) - 1), -1, -1):
        m = re.match(r'\s*(?:-\s*)?\{?\s*([A-Za-z_][\w]*)\s*:', lines[k])
        if m:
            return f", near key '{m.group(1)}'"
    return ''


def scene_data(text: str, origin: str = '<scene>', what: str = 'scene') -> Any:
    """The scene's YAML as plain data, not yet validated (studies change values in it), or
    ``SceneError`` in one line with line, column and key. Also reads sweep specs (``what``)."""
    loader = None
    try:
        # the reader checks the characters as it is built: a NUL byte fails here already
        loader = _SceneLoader(text)
        node = loader.get_single_node()
        if node is not None and _expanded_size(node, {}) > MAX_YAML_NODES:
            raise SceneError(
                f"{what} '{origin}': more than {MAX_YAML_NODES} YAML nodes once "
                f'aliases are expanded: not a scene file'
            )
        return loader.construct_document(node) if node is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = (
            (f' at line {mark.line + 1}, column {mark.column + 1}{_near_key(text, mark.line)}')
            if mark
            else ''
        )
        problem = ' '.join(str(exc.problem or exc.context or 'unreadable').split())
        raise SceneError(f"{what} '{origin}': not valid YAML{where}: {problem[:200]}") from None
    except (yaml.YAMLError, RecursionError, ValueError) as exc:
        problem = ' '.join(str(exc).split()) or type(exc).__name__
        raise SceneError(f"{what} '{origin}': not valid YAML: {problem[:200]}") from None
    finally:
        if loader is not None:
            loader.dispose()


def scene_from_text(text: str, origin: str = '<scene>', path: str = '') -> Scene:
    return parse_scene(scene_data(text, origin), origin=origin, text=text, path=path)


def resolve_scene_path(name: str | os.PathLike) -> str:
    """Accept a path, or a bare scene name ('paper') found in the installed config directory."""
    name = os.fspath(name)
    if os.path.exists(name):
        return name
    for directory in config_dirs():
        for candidate in (name, name + '.yaml'):
            full = os.path.join(directory, candidate)
            if os.path.exists(full):
                return full
    return name  # load_scene reports it as unreadable


def installed_scenes() -> list[str]:
    """Names of the scene files in the installed config directories (the node parameter
    files there are not scenes: a scene has a top-level ``links:`` or ``arm:``)."""
    names = set()
    for directory in config_dirs():
        for entry in os.listdir(directory):
            if not entry.endswith('.yaml'):
                continue
            try:
                with open(os.path.join(directory, entry), encoding='utf-8') as f:
                    if any(line.startswith(('links:', 'arm:')) for line in f):
                        names.add(entry[: -len('.yaml')])
            except (OSError, UnicodeDecodeError):
                continue
    return sorted(names)


def config_dirs() -> list[str]:
    """Where scene files live: the source tree, the install prefix, the ament share dir."""
    import sys

    here = os.path.dirname(os.path.abspath(__file__))
    dirs = [
        os.path.join(os.path.dirname(os.path.dirname(here)), 'config'),
        os.path.join(sys.prefix, 'share', 'impact_arm', 'config'),
    ]
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(os.path.join(get_package_share_directory('impact_arm'), 'config'))
    except Exception:  # no ament index (plain venv): the other places suffice
        pass
    return [d for d in dirs if os.path.isdir(d)]
