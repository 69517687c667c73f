"""What the fit knows of each scene key a physical parameter lives at: its unit, the range a
real value can take, and for the
materials, the handbook range of the named material. Any numeric scene key is fittable
(parameters.py reads a key the scene leaves out at the schema's default); an entry of ``KEYS``
adds the range check and makes the key part of the dependence analysis. Nothing else in the
fit names keys."""

from __future__ import annotations

from collections.abc import Iterator

import math
import re
from dataclasses import dataclass

INF = math.inf


@dataclass(frozen=True)
class PhysicalKey:
    pattern: str  # key path; [*] any index, * (after materials.) any material
    what: str
    unit: str
    lo: float  # the range a real value can take (a fitted value outside it is flagged)
    hi: float
    # the amount the dependence analysis moves it by where the scene sets it to 0 (an effect
    # switched off; a relative step of 0 is none): a small real value; None: not moved
    zero_step: float | None = None


KEYS = (
    PhysicalKey('materials.*.E', "Young's modulus", 'Pa', 1e6, 1.2e12),
    PhysicalKey('materials.*.nu', "Poisson's ratio", '', 0.0, 0.5),
    PhysicalKey('materials.*.S_y', 'yield strength', 'Pa', 1e5, 1e10),
    PhysicalKey('surfaces[*].mu', 'friction coefficient', '', 0.0, 1.5, 0.01),
    PhysicalKey('surfaces[*].v_d', 'friction regularisation speed', 'm/s', 0.0, 1.0),
    PhysicalKey('surfaces[*].height', 'surface height', 'm', -INF, INF, 1e-3),
    PhysicalKey('tip_radius', 'tip radius', 'm', 0.0, INF),
    PhysicalKey('links[*].mass', 'link mass', 'kg', 0.0, INF),
    PhysicalKey('links[*].length', 'link length', 'm', 0.0, INF),
    PhysicalKey('joints[*].damping', 'viscous joint friction', 'N m s/rad', 0.0, INF, 0.01),
    PhysicalKey('joints[*].friction', 'Coulomb joint friction', 'N m', 0.0, INF, 0.01),
    PhysicalKey('joints[*].armature', 'reflected rotor inertia', 'kg m^2', 0.0, INF, 1e-4),
    PhysicalKey('surfaces[*].mount.stiffness', 'mount stiffness', 'N/m', 0.0, INF),
    PhysicalKey('surfaces[*].mount.mass', 'mount mass', 'kg', 0.0, INF),
    PhysicalKey('surfaces[*].mount.damping_ratio', 'mount damping ratio', '', 0.0, INF, 0.01),
)

# Handbook ranges over the common alloys of each family (E [Pa], nu, S_y [Pa]): a fitted value
# outside them is either another material than the scene names or a fit gone astray.
MATERIALS = {
    'steel': {'E': (190e9, 215e9), 'nu': (0.26, 0.31), 'S_y': (0.2e9, 2.1e9)},
    'aluminium': {'E': (68e9, 80e9), 'nu': (0.31, 0.35), 'S_y': (0.02e9, 0.7e9)},
    'titanium': {'E': (100e9, 120e9), 'nu': (0.30, 0.37), 'S_y': (0.14e9, 1.4e9)},
    'copper': {'E': (110e9, 130e9), 'nu': (0.33, 0.36), 'S_y': (0.03e9, 0.4e9)},
    'brass': {'E': (95e9, 115e9), 'nu': (0.33, 0.36), 'S_y': (0.07e9, 0.6e9)},
    'bronze': {'E': (95e9, 125e9), 'nu': (0.33, 0.36), 'S_y': (0.1e9, 0.8e9)},
    'cast iron': {'E': (80e9, 175e9), 'nu': (0.20, 0.30), 'S_y': (0.1e9, 0.7e9)},
}
_ALIASES = {
    'steel': 'steel',
    'stainless': 'steel',
    'inox': 'steel',
    'aluminium': 'aluminium',
    'aluminum': 'aluminium',
    'alu': 'aluminium',
    'al': 'aluminium',
    'titanium': 'titanium',
    'ti': 'titanium',
    'copper': 'copper',
    'cu': 'copper',
    'brass': 'brass',
    'bronze': 'bronze',
    'iron': 'cast iron',
}
_PATTERNS = [
    (
        re.compile(
            '^'
            + re.escape(k.pattern).replace(r'\[\*\]', r'\[\d+\]').replace(r'\*', r'[^.\[]+')
            + '$'
        ),
        k,
    )
    for k in KEYS
]


def physical_key(path: str) -> PhysicalKey | None:
    """The entry of ``KEYS`` for a key path (e.g. 'links[1].mass'), or None."""
    for pattern, key in _PATTERNS:
        if pattern.match(path):
            return key
    return None


def material_family(name: str) -> str | None:
    """The handbook family a scene's material name belongs to ('Al 6061' -> 'aluminium')."""
    for token in re.split(r'[^a-z]+', name.lower()):
        if token in _ALIASES:
            return _ALIASES[token]
    return None


def out_of_range(path: str, value: float) -> str:
    """Why ``value`` cannot be the arm's ``path`` ('' when it can): outside what the quantity
    can physically be, or outside the handbook range of the material the key names."""
    key = physical_key(path)
    if key is None:
        return ''
    if not key.lo <= value <= key.hi:
        return (
            f'{path} = {value:.4g} {key.unit} is outside what a {key.what} can be '
            f'({key.lo:g} to {key.hi:g})'
        ).replace('  ', ' ')
    match = re.match(r'^materials\.([^.\[]+)\.(E|nu|S_y)$', path)
    if match:
        family = material_family(match.group(1))
        if family is not None:
            lo, hi = MATERIALS[family][match.group(2)]
            if not lo <= value <= hi:
                return (
                    f'{path} = {value:.4g} {key.unit} is outside the handbook range of '
                    f'{family} ({lo:.3g} to {hi:.3g}): the arm is not of {family}, or the '
                    f'fit is wrong'
                ).replace('  ', ' ')
    return ''


def stated_parameters(data: dict) -> Iterator[tuple[str, float]]:
    """(key path, value) of every physical parameter the scene data state as a number, in
    the data's order: the fixed parameters a fit's values may depend on."""

    def walk(node: object, path: str) -> Iterator[tuple[str, float]]:
        if isinstance(node, dict):
            for k, v in node.items():
                yield from walk(v, f'{path}.{k}' if path else str(k))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                yield from walk(v, f'{path}[{i}]')
        elif isinstance(node, (int, float)) and not isinstance(node, bool):
            if physical_key(path) is not None:
                yield path, float(node)

    yield from walk(data, '')
