"""The scene of a free planar rigid body: a YAML file with a ``body`` section instead of the
arm's ``links`` (docs/scene.md, "Free bodies"). Checked with the arm scene's checker, so a
refusal reads the same: the key path, the value and the allowed range, in one line.

The body moves in the x-z plane (z up, gravity along -z). Its corners are spheres of radius
``corner_radius`` centred at body-frame points; each surface is a line through ``point`` with
``normal`` pointing into free space, at any angle. Angles are degrees in the file, radians
after loading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..scene import (
    MATERIAL,
    MAX_YIELD_STRAIN,
    REQUIRED,
    Material,
    SceneChecker,
    choice_spec,
    number_spec,
    read_scene_file,
    reduced_modulus,
    scene_data,
)

BODY_CONTACT_LAWS = ('elastoplastic', 'hertz', 'constant_cor', 'none')
MIN_NORMAL_LENGTH = 1e-9  # a surface normal shorter than this has no direction
MAX_CORNERS = 64
MAX_SURFACES = 16
MIN_CONTACT_TIME = 1e-7  # s, Hertz contact time of the body's mass at 1 m/s


@dataclass(frozen=True)
class BodySpec:
    mass: float  # [kg]
    inertia: float  # about the centre of mass [kg m²]
    corners: tuple[tuple[float, float], ...]  # body-frame centres of the corner spheres [m]
    corner_radius: float  # [m]
    material: Material


@dataclass(frozen=True)
class BodyState:
    """Pose and velocity of the centre of mass: x, z [m], θ [rad] and their rates."""

    x: float
    z: float
    theta: float
    vx: float
    vz: float
    omega: float

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        return (self.x, self.z, self.theta, self.vx, self.vz, self.omega)


@dataclass(frozen=True)
class LineSurface:
    point: tuple[float, float]  # a point of the line [m]
    normal: tuple[float, float]  # unit normal into free space
    law: str  # elastoplastic | hertz | constant_cor | none
    mu: float
    v_d: float
    cor: float  # the constant_cor law's restitution coefficient
    material: Material


@dataclass(frozen=True)
class BodyIntegratorSpec:
    rtol: float
    atol: float
    max_step: float


@dataclass(frozen=True)
class BodyScene:
    name: str
    gravity: float
    body: BodySpec
    initial: BodyState
    surfaces: tuple[LineSurface, ...]
    t_max: float
    integrator: BodyIntegratorSpec


_COORDINATE = number_spec(-1e3, 1e3, unit='m')  # of a point [x, z]
BODY = {
    'mass': number_spec(1e-6, 1e6, unit='kg'),
    'inertia': number_spec(1e-12, 1e9, unit='kg m^2'),
    'corners': ('list_of_points', None, 'm', REQUIRED),
    'corner_radius': number_spec(1e-6, 1, unit='m'),
    'material': ('str', None, '', 'body'),
}
INITIAL = {
    'x': number_spec(-1e3, 1e3, unit='m', default=0.0),
    'z': number_spec(-1e3, 1e3, unit='m'),
    'theta_deg': number_spec(-3600, 3600, unit='deg', default=0.0),
    'vx': number_spec(-1e3, 1e3, unit='m/s', default=0.0),
    'vz': number_spec(-1e3, 1e3, unit='m/s', default=0.0),
    'omega': number_spec(-1e4, 1e4, unit='rad/s', default=0.0),
}
LINE_SURFACE = {
    'point': ('vec', number_spec(-1e3, 1e3), 'm', (0.0, 0.0)),
    'normal': ('vec', number_spec(-1e3, 1e3), '-', (0.0, 1.0)),
    'law': choice_spec(BODY_CONTACT_LAWS, 'elastoplastic'),
    'mu': number_spec(0, 10, unit='-', default=0.0),
    'v_d': number_spec(1e-6, 10, unit='m/s', default=0.02),
    'cor': number_spec(0, 1, low_open=True, unit='-', default=None),
    'material': ('str', None, '', 'surface'),
}
BODY_INTEGRATOR = {
    'rtol': number_spec(1e-13, 1e-3, unit='-', default=1e-9),
    'atol': number_spec(1e-16, 1e-6, unit='-', default=1e-13),
    'max_step': number_spec(1e-6, 1, unit='s', default=1e-3),
}
BODY_SCHEMA = {
    'name': ('str', None, '', 'body'),
    'description': ('str', None, '', ''),
    'gravity': number_spec(0, 1000, unit='m/s^2', default=9.81),
    'materials': ('map', MATERIAL, '', REQUIRED),
    'body': ('dict', BODY, '', REQUIRED),
    'initial': ('dict', INITIAL, '', REQUIRED),
    'surfaces': ('list', LINE_SURFACE, '', REQUIRED),
    't_max': number_spec(0, 1e4, low_open=True, unit='s', default=1.0),
    'integrator': ('dict', BODY_INTEGRATOR, '', {}),
}


class _BodyChecker(SceneChecker):
    """The arm scene's checker plus one container kind, a list of 2-D points, and the
    check of one point."""

    def container(
        self,
        path: str,
        value: Any,
        kind: str,
        constraint: Any,
        unit: str,
        known: tuple | None = None,
    ) -> Any:
        if kind != 'list_of_points':
            return super().container(path, value, kind, constraint, unit, known)
        if not isinstance(value, (list, tuple)) or not value:
            self.fail(path, f'= {value!r:.60} must be a non-empty list of [x, z] points ({unit})')
        if len(value) > MAX_CORNERS:
            self.fail(path, f'has {len(value)} entries: at most {MAX_CORNERS}')
        return tuple(self.point(f'{path}[{i}]', v) for i, v in enumerate(value))

    def point(self, path: str, value: Any) -> tuple[float, float]:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            self.fail(path, f'= {value!r:.60} must be a point [x, z] (m)')
        x, z = (self.leaf(f'{path}[{i}]', v, _COORDINATE) for i, v in enumerate(value))
        return (x, z)


def parse_body_scene(data: Any, origin: str = '<scene>') -> BodyScene:
    """Validate a free-body scene already read from YAML; ``SceneError`` in one line."""
    check = _BodyChecker(origin)
    raw = check.leaf('', data, ('dict', BODY_SCHEMA, '', REQUIRED))
    materials = {k: Material(**v) for k, v in raw['materials'].items()}

    def material(path: str, name: str) -> Material:
        if name not in materials:
            check.fail(path, f"= {name!r} names no entry of 'materials' ({', '.join(materials)})")
        return materials[name]

    b = raw['body']
    body = BodySpec(
        mass=b['mass'],
        inertia=b['inertia'],
        corners=b['corners'],
        corner_radius=b['corner_radius'],
        material=material('body.material', b['material']),
    )
    if len(raw['surfaces']) > MAX_SURFACES:
        check.fail('surfaces', f'has {len(raw["surfaces"])} entries: at most {MAX_SURFACES}')
    surfaces = []
    for i, s in enumerate(raw['surfaces']):
        path = f'surfaces[{i}]'
        point = check.point(f'{path}.point', s['point'])
        normal = check.point(f'{path}.normal', s['normal'])
        length = math.hypot(*normal)
        if not length >= MIN_NORMAL_LENGTH:
            check.fail(
                f'{path}.normal',
                f'= {list(normal)} has length {length:.3g}: must be >= {MIN_NORMAL_LENGTH:g}',
            )
        if s['law'] == 'constant_cor' and s['cor'] is None:
            check.fail(f'{path}.cor', 'is missing (required by law constant_cor): 0 < cor <= 1')
        if s['law'] != 'constant_cor' and s['cor'] is not None:
            check.fail(f'{path}.cor', f'= {s["cor"]:g} is only used by law constant_cor')
        surface = LineSurface(
            point=point,
            normal=(normal[0] / length, normal[1] / length),
            law=s['law'],
            mu=s['mu'],
            v_d=s['v_d'],
            cor=s['cor'] if s['cor'] is not None else 1.0,
            material=material(f'{path}.material', s['material']),
        )
        _check_pairing(check, path, body, surface)
        surfaces.append(surface)
    i0 = raw['initial']
    initial = BodyState(
        i0['x'], i0['z'], math.radians(i0['theta_deg']), i0['vx'], i0['vz'], i0['omega']
    )
    for i, s in enumerate(surfaces):
        if s.law == 'none':
            continue
        for j, depth in enumerate(corner_depths(body, initial, s)):
            if depth >= 0:
                check.fail(
                    'initial',
                    f'places corner {j} {depth:.3g} m inside surfaces[{i}]: every corner '
                    f'must start clear of every surface',
                )
    spec = BodyIntegratorSpec(
        **{**{k: v[3] for k, v in BODY_INTEGRATOR.items()}, **raw['integrator']}
    )
    return BodyScene(
        name=raw['name'],
        gravity=raw['gravity'],
        body=body,
        initial=initial,
        surfaces=tuple(surfaces),
        t_max=raw['t_max'],
        integrator=spec,
    )


def _check_pairing(check: SceneChecker, path: str, body: BodySpec, s: LineSurface) -> None:
    if s.law == 'none':
        return
    E = reduced_modulus(body.material, s.material)
    strain = min(body.material.S_y, s.material.S_y) / E
    if s.law == 'elastoplastic' and strain > MAX_YIELD_STRAIN:
        check.fail(
            f'{path}.material',
            f'gives a yield strain S_y/E* = {strain:.3g}: must be <= {MAX_YIELD_STRAIN:g} for '
            f'the elasto-plastic (Jackson-Green) law; use law hertz or constant_cor',
        )
    # Hertz contact time at 1 m/s of the whole mass on one corner (the shortest it can be)
    delta_m = (15 * body.mass / (16 * E * math.sqrt(body.corner_radius))) ** 0.4
    duration = 2.9432 * delta_m
    if duration < MIN_CONTACT_TIME:
        check.fail(
            f'{path}.material',
            f'gives a Hertz contact time of {duration:.3g} s at 1 m/s: must be >= '
            f'{MIN_CONTACT_TIME:g} s (lighter or stiffer cannot be stepped)',
        )


def corner_depths(body: BodySpec, state: BodyState, surface: LineSurface) -> list[float]:
    """How deep each corner sphere reaches past the surface line (negative: clear of it)."""
    c, s = math.cos(state.theta), math.sin(state.theta)
    nx, nz = surface.normal
    px, pz = surface.point
    return [
        body.corner_radius
        - (nx * (state.x + c * bx - s * bz - px) + nz * (state.z + s * bx + c * bz - pz))
        for bx, bz in body.corners
    ]


def body_scene_from_text(text: str, origin: str = '<scene>') -> BodyScene:
    return parse_body_scene(scene_data(text, origin), origin)


def load_body_scene(path: str) -> BodyScene:
    """Read and validate a free-body scene file; ``SceneError`` in one line."""
    text, resolved = read_scene_file(path)
    return body_scene_from_text(text, resolved)
