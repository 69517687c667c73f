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
from dataclasses import dataclass, field
from typing import Any

import yaml

from ..contract import CONTROL_LAWS, INTEGRATOR_METHODS, INTEGRATOR_PRESETS, PID_SPACES
from .errors import SceneError

CONTACT_LAWS = ('elastoplastic', 'hertz', 'none')
MAX_YIELD_STRAIN = 0.1   # S_y / E* beyond which the Jackson-Green law is meaningless


@dataclass(frozen=True)
class Material:
    E: float      # Young's modulus [Pa]
    nu: float     # Poisson's ratio [-]
    S_y: float    # yield strength [Pa]


@dataclass(frozen=True)
class Surface:
    height: float            # y of the horizontal surface [m]; the tip strikes it from above
    law: str                 # elastoplastic | hertz | none
    mu: float                # Coulomb friction coefficient (0 = no friction term)
    v_d: float               # tanh smoothing velocity [m/s]
    material: Material


@dataclass(frozen=True)
class ControllerSpec:
    law: str                       # q | pid | pd | none
    space: str                     # absolute | joint (angles the PID/PD acts on)
    kp: tuple[float, ...]
    kd: tuple[float, ...]
    ki: tuple[float, ...]
    down_target: tuple[float, ...]  # rad, absolute link angles
    up_target: tuple[float, ...]    # rad
    switch_height: float            # tip height that ends the up phase [m]
    rate: float                     # Hz; 0 = continuous (evaluated in the right-hand side)


@dataclass(frozen=True)
class IntegratorSpec:
    preset: str
    rtol: float | None = None
    atol: float | None = None
    max_step: float | None = None
    method: str = 'dopri5'
    contact_rtol: float | None = None


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
    q0: tuple[float, ...]           # rad, absolute link angles
    qd0: tuple[float, ...]          # rad/s
    cycles: int
    t_max: float                    # hard stop of a run [s]
    publish_rate: float             # Hz of sampled output (joint states)
    integrator: IntegratorSpec
    source_text: str = field(default='', compare=False, repr=False)
    source_path: str = field(default='', compare=False, repr=False)

    @property
    def n_links(self) -> int:
        return len(self.lengths)


# --- schema -----------------------------------------------------------------------------
# A leaf is (kind, constraint, unit, default); default REQUIRED means the key must be present.
REQUIRED = object()


def _num(low=None, high=None, low_open=False, high_open=False, unit='', default=REQUIRED):
    return ('num', (low, high, low_open, high_open), unit, default)


def _choice(options, default=REQUIRED):
    return ('choice', tuple(options), '', default)


MATERIAL = {
    'E': _num(0, None, low_open=True, unit='Pa'),
    'nu': _num(0, 0.5, high_open=True),
    'S_y': _num(0, None, low_open=True, unit='Pa'),
}
LINK = {'length': _num(0, None, low_open=True, unit='m'),
        'mass': _num(0, None, low_open=True, unit='kg')}
SURFACE = {
    'height': _num(unit='m'),
    'law': _choice(CONTACT_LAWS, 'elastoplastic'),
    'mu': _num(0, 10, unit='-', default=0.0),
    'v_d': _num(0, None, low_open=True, unit='m/s', default=0.02),
    'material': ('str', None, '', 'surface'),
}
CONTROLLER = {
    'law': _choice(CONTROL_LAWS, 'q'),
    'space': _choice(PID_SPACES, 'absolute'),
    'kp': ('vec', _num(0, None), 'N m/rad', REQUIRED),
    'kd': ('vec', _num(0, None), 'N m s/rad', REQUIRED),
    'ki': ('vec', _num(0, None), 'N m/(rad s)', None),
    'down_target_deg': ('vec', _num(-360, 360), 'deg', REQUIRED),
    'up_target_deg': ('vec', _num(-360, 360), 'deg', REQUIRED),
    'switch_height': _num(unit='m', default=1.0),
    'rate': _num(0, 1e6, unit='Hz', default=0.0),
}
INTEGRATOR = {
    'preset': _choice(INTEGRATOR_PRESETS, 'balanced'),
    'rtol': _num(1e-14, 1e-1, unit='-', default=None),
    'atol': _num(1e-16, 1e-1, unit='-', default=None),
    'max_step': _num(0, 10, low_open=True, unit='s', default=None),
    'method': _choice(INTEGRATOR_METHODS, 'dopri5'),
    'contact_rtol': _num(1e-14, 1e-1, unit='-', default=None),
}
SCHEMA = {
    'name': ('str', None, '', 'scene'),
    'description': ('str', None, '', ''),
    'gravity': _num(0, 1000, unit='m/s^2', default=9.81),
    'links': ('list', LINK, '', REQUIRED),
    'tip_radius': _num(0, None, low_open=True, unit='m'),
    'materials': ('map', MATERIAL, '', REQUIRED),
    'arm_material': ('str', None, '', 'arm'),
    'surfaces': ('list', SURFACE, '', ()),
    'actuators_during_contact': ('bool', None, '', False),
    'controller': ('dict', CONTROLLER, '', REQUIRED),
    'initial': ('dict', {'q_deg': ('vec', _num(-360, 360), 'deg', REQUIRED),
                         'qd': ('vec', _num(-1e4, 1e4), 'rad/s', None)}, '', REQUIRED),
    'cycles': ('int', (0, 1_000_000), '', 15),
    't_max': _num(0, 1e7, low_open=True, unit='s', default=60.0),
    'publish_rate': _num(1, 1e6, unit='Hz', default=1000.0),
    'integrator': ('dict', INTEGRATOR, '', {'preset': 'balanced'}),
}


def _describe_range(constraint, unit):
    low, high, low_open, high_open = constraint
    unit = f' ({unit})' if unit else ''
    parts = []
    if low is not None:
        parts.append(f"> {low:g}" if low_open else f">= {low:g}")
    if high is not None:
        parts.append(f"< {high:g}" if high_open else f"<= {high:g}")
    return ('must be ' + ' and '.join(parts) + unit) if parts else f'any finite number{unit}'


class _Checker:
    def __init__(self, origin):
        self.origin = origin

    def fail(self, path, message):
        raise SceneError(f"scene '{self.origin}': {path} {message}")

    def number(self, path, value, constraint, unit):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(path, f"= {value!r} is not a number; {_describe_range(constraint, unit)}")
        value = float(value)
        if not math.isfinite(value):
            self.fail(path, f"= {value!r} is not finite; {_describe_range(constraint, unit)}")
        low, high, low_open, high_open = constraint
        bad = ((low is not None and (value < low or (low_open and value == low)))
               or (high is not None and (value > high or (high_open and value == high))))
        if bad:
            self.fail(path, f"= {value:g} is out of range: {_describe_range(constraint, unit)}")
        return value

    def leaf(self, path, value, spec):
        kind, constraint, unit, _ = spec
        if kind == 'num':
            return self.number(path, value, constraint, unit)
        if kind == 'choice':
            if value not in constraint:
                self.fail(path, f"= {value!r} is not allowed: choose one of {', '.join(constraint)}")
            return value
        if kind == 'str':
            if not isinstance(value, str):
                self.fail(path, f"= {value!r} must be a string")
            return value
        if kind == 'bool':
            if not isinstance(value, bool):
                self.fail(path, f"= {value!r} must be true or false")
            return value
        if kind == 'int':
            low, high = constraint
            if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
                self.fail(path, f"= {value!r} must be an integer in [{low}, {high}]")
            return value
        if kind == 'vec':
            if not isinstance(value, (list, tuple)) or not value:
                self.fail(path, f"= {value!r} must be a non-empty list of numbers ({unit})")
            return tuple(self.number(f'{path}[{i}]', v, constraint[1], unit)
                         for i, v in enumerate(value))
        if kind == 'dict':
            return self.mapping(path, value, constraint)
        if kind == 'list':
            if not isinstance(value, (list, tuple)):
                self.fail(path, f"= {value!r} must be a list")
            return tuple(self.mapping(f'{path}[{i}]', v, constraint) for i, v in enumerate(value))
        if kind == 'map':
            if not isinstance(value, dict) or not value:
                self.fail(path, f"= {value!r} must be a mapping of names to entries")
            return {str(k): self.mapping(f'{path}.{k}', v, constraint) for k, v in value.items()}
        raise AssertionError(kind)

    def mapping(self, path, value, schema):
        prefix = f'{path}.' if path else ''
        if not isinstance(value, dict):
            self.fail(path or '<top level>', f"must be a mapping, got {type(value).__name__}")
        unknown = sorted(set(map(str, value)) - set(schema))
        if unknown:
            self.fail(f'{prefix}{unknown[0]}', f"is not a known key; allowed here: {', '.join(schema)}")
        out = {}
        for key, spec in schema.items():
            if key in value:
                out[key] = self.leaf(prefix + key, value[key], spec)
            elif spec[3] is REQUIRED:
                self.fail(prefix + key, 'is missing (required)')
            else:
                out[key] = spec[3]
        return out


def parse_scene(data: Any, origin: str = '<scene>', text: str = '', path: str = '') -> Scene:
    """Validate a scene already parsed from YAML and build the frozen ``Scene``."""
    check = _Checker(origin)
    raw = check.mapping('', data, SCHEMA)
    n = len(raw['links'])
    if n < 2:
        check.fail('links', f'has {n} entries: an arm needs at least 2 links')

    def vector(path, values, default=None):
        if values is None:
            return tuple(default for _ in range(n))
        if len(values) != n:
            check.fail(path, f'has {len(values)} entries: must have one per link ({n})')
        return tuple(values)

    materials = {k: Material(**v) for k, v in raw['materials'].items()}

    def material(path, name):
        if name not in materials:
            check.fail(path, f"= {name!r} names no entry of 'materials' ({', '.join(materials)})")
        return materials[name]

    arm = material('arm_material', raw['arm_material'])
    surfaces = tuple(
        Surface(height=s['height'], law=s['law'], mu=s['mu'], v_d=s['v_d'],
                material=material(f'surfaces[{i}].material', s['material']))
        for i, s in enumerate(raw['surfaces']))
    heights = [s.height for s in surfaces]
    if len(set(heights)) != len(heights):
        check.fail('surfaces', f'= heights {heights}: two surfaces at the same height')

    c = raw['controller']
    controller = ControllerSpec(
        law=c['law'], space=c['space'],
        kp=vector('controller.kp', c['kp']), kd=vector('controller.kd', c['kd']),
        ki=vector('controller.ki', c['ki'], 0.0),
        down_target=tuple(map(math.radians, vector('controller.down_target_deg',
                                                   c['down_target_deg']))),
        up_target=tuple(map(math.radians, vector('controller.up_target_deg', c['up_target_deg']))),
        switch_height=c['switch_height'], rate=c['rate'])
    if controller.law == 'pid' and not any(controller.ki):
        check.fail('controller.ki', '= all zero with law pid: use law pd, or give integral gains')

    q0 = tuple(map(math.radians, vector('initial.q_deg', raw['initial']['q_deg'])))
    qd0 = vector('initial.qd', raw['initial']['qd'], 0.0)
    reach = sum(l['length'] for l in raw['links'])
    for i, s in enumerate(surfaces):
        if s.law != 'none' and abs(s.height) >= reach:
            check.fail(f'surfaces[{i}].height',
                       f'= {s.height:g} is out of reach: must satisfy |height| < {reach:g} (m)')
    for i, s in enumerate(surfaces):
        if s.law != 'elastoplastic':
            continue
        # the Jackson-Green fit (B = 0.14 exp(23 S_y/E)) holds for metals-like yield strains;
        # far beyond it B overflows and the force law means nothing
        a, b = arm, s.material
        e_red = a.E * b.E / (b.E * (1 - a.nu ** 2) + a.E * (1 - b.nu ** 2))
        strain = min(a.S_y, b.S_y) / e_red
        if strain > MAX_YIELD_STRAIN:
            check.fail(f'surfaces[{i}].material',
                       f'= {raw["surfaces"][i]["material"]!r}: yield strain S_y/E* = '
                       f'{strain:.3g} is out of range: must be <= {MAX_YIELD_STRAIN:g} for the '
                       f'elasto-plastic (Jackson-Green) law; use law hertz, or a consistent '
                       f'E and S_y')
    integ = IntegratorSpec(**raw['integrator'])
    return Scene(
        name=raw['name'], lengths=tuple(l['length'] for l in raw['links']),
        masses=tuple(l['mass'] for l in raw['links']), gravity=raw['gravity'],
        tip_radius=raw['tip_radius'], arm_material=arm, surfaces=surfaces,
        actuators_during_contact=raw['actuators_during_contact'], controller=controller,
        q0=q0, qd0=qd0, cycles=raw['cycles'], t_max=raw['t_max'],
        publish_rate=raw['publish_rate'], integrator=integ, source_text=text, source_path=path)


def read_scene_file(name: str | os.PathLike) -> tuple[str, str]:
    """(text, path) of a scene file given by path or installed name."""
    path = str(resolve_scene_path(name))
    try:
        with open(path, encoding='utf-8') as f:
            return f.read(), path
    except OSError as exc:
        raise SceneError(f"scene '{path}': cannot be read: {exc.strerror}") from None


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a scene file; raises ``SceneError`` with a user-facing message."""
    text, path = read_scene_file(path)
    return scene_from_text(text, origin=path, path=path)


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that also reads ``210e9`` / ``1.12e9`` as floats.

    YAML 1.1 (PyYAML) demands a dot and a signed exponent, so ``210e9`` would otherwise arrive
    as a string and be refused as non-numeric, which surprises every user."""


_SceneLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?(?:[eE][-+]?[0-9]+)$'),
    list('-+0123456789'))


def scene_data(text: str, origin: str = '<scene>', what: str = 'scene'):
    """The scene's YAML as plain data, not yet validated (studies change values in it).
    Also reads sweep specs (``what``), with the same reading of 210e9 as a number."""
    try:
        return yaml.load(text, Loader=_SceneLoader)
    except yaml.YAMLError as exc:
        raise SceneError(f"{what} '{origin}': not valid YAML: {exc}") from None


def scene_from_text(text: str, origin: str = '<scene>', path: str = '') -> Scene:
    return parse_scene(scene_data(text, origin), origin=origin, text=text, path=path)


def with_overrides(scene: Scene, **changes) -> Scene:
    """A copy of ``scene`` with top-level fields replaced (used by benchmarks and tests)."""
    from dataclasses import replace
    return replace(scene, **changes)


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


def config_dirs() -> list[str]:
    """Where scene files live: the source tree, the install prefix, the ament share dir."""
    import sys
    here = os.path.dirname(os.path.abspath(__file__))
    dirs = [os.path.join(os.path.dirname(os.path.dirname(here)), 'config'),
            os.path.join(sys.prefix, 'share', 'impact_arm', 'config')]
    try:
        from ament_index_python.packages import get_package_share_directory
        dirs.append(os.path.join(get_package_share_directory('impact_arm'), 'config'))
    except Exception:  # no ament index (plain venv): the other places suffice
        pass
    return [d for d in dirs if os.path.isdir(d)]
