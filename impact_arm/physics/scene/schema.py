"""The scene schema: every key's type, allowed range or choices and default, and the
checker that walks scene data against it, refusing the first bad value in one line."""

from __future__ import annotations

import math
import reprlib
from collections.abc import Sequence
from typing import Any, NoReturn

from ...contract import CONTROL_LAWS, INTEGRATOR_METHODS, INTEGRATOR_PRESETS, PID_SPACES
from ..errors import SceneError
from .types import CONTACT_LAWS, RateReading

# shown values are cut short: a refusal never prints an unbounded input
_show = reprlib.Repr()
_show.maxstring = _show.maxother = 60
_show.maxlist = _show.maxtuple = _show.maxdict = 6
_show.maxlevel = 2
_show.maxlong = 40

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
    'xacro': ('str', None, '', None),  # a xacro file (expanded in-process), or
    'args': ('args', None, '', None),  # its xacro args: name -> string, number or boolean
    'package_paths': ('names', None, '', None),  # where $(find pkg) looks first
    'joints': ('names', None, '', None),  # the moving joints, base to tip
    'locked': ('values', number_spec(-1e3, 1e3), 'rad or m', None),  # the others' values
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
    # absent: the URDF's <limit effort> (none for the scene's rods)
    'max_effort': number_spec(0, 1e9, low_open=True, unit='N m', default=None),
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
    'allow_unstable': ('bool', None, '', False),
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
    # a URDF arm's position and velocity limits: reported, or a protective stop
    'joint_limits': choice_spec(('report', 'stop'), 'report'),
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
        if kind == 'names':
            if (
                not isinstance(value, (list, tuple))
                or not value
                or not all(isinstance(v, str) and v for v in value)
            ):
                self.fail(path, f'= {_show.repr(value)} must be a non-empty list of names')
            return tuple(
                self.leaf(f'{path}[{i}]', v, ('str', None, '', None)) for i, v in enumerate(value)
            )
        if kind == 'args':
            if not isinstance(value, dict) or not all(
                isinstance(v, (str, int, float)) and isinstance(k, str) for k, v in value.items()
            ):
                self.fail(
                    path, f'= {_show.repr(value)} must map names to strings, numbers or booleans'
                )
            return dict(value)
        if kind == 'values':
            if not isinstance(value, dict):
                self.fail(
                    path, f'= {_show.repr(value)} must be a mapping of names to numbers ({unit})'
                )
            return {
                str(k): self.number(f'{path}.{k}', v, constraint[1], unit) for k, v in value.items()
            }
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
