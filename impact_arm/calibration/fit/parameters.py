"""The fitted parameters: scene key paths with bounds, checked against the scene, and the
unit-cube / log coordinates the search and the covariance use."""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ...physics.errors import ImpactArmError, SceneError
from ..study import Study, apply_overrides, parse_key_path
from ...physics.scene import SCHEMA, Scene


class FitError(ImpactArmError):
    """Bad fit input (parameter keys, bounds, options): one line naming what is wrong."""


@dataclass
class Parameter:
    key: str
    lo: float
    hi: float
    start: float
    log: bool  # fitted in log space (positive bounds)

    def to_unit(self, value: float) -> float:
        if self.log:
            return (math.log(value) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (value - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        if self.log:
            return math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + u * (self.hi - self.lo)

    def to_native(self, value: float) -> float:
        """The coordinate the covariance is stated in: log(value) or value."""
        return math.log(value) if self.log else value


# link keys with a default that follows from the others (docs/scene.md): a fit may start
# from it without the scene stating it (a rod's centre and inertia; a URDF arm's values)
_LINK_DEFAULTS: dict[str, Callable[[Scene, int], float]] = {
    'com_x': lambda scene, k: scene.link_com[k][0],
    'com_y': lambda scene, k: scene.link_com[k][1],
    'inertia': lambda scene, k: scene.link_inertias[k],
    'mass': lambda scene, k: scene.masses[k],  # a URDF arm's: the file's
}


def _link_default_key(parts: Sequence) -> bool:
    """``links[i].KEY`` left to a rod's default, or ``arm.links[i].KEY`` to the URDF's."""
    head = ('links',) if parts[0] == 'links' else ('arm', 'links')
    return (
        tuple(parts[: len(head)]) == head
        and len(parts) == len(head) + 2
        and isinstance(parts[-2], int)
        and parts[-1] in _LINK_DEFAULTS
        and (head == ('arm', 'links') or parts[-1] != 'mass')
    )


def _link_default(study: Study, key: str, parts: Sequence) -> float | None:
    """The value a link key the scene leaves out stands at, None if ``key`` is no such key."""
    if not _link_default_key(parts):
        return None
    try:
        scene = study.scene()
    except SceneError as exc:
        raise FitError(f'--param {key}: {exc}') from None
    if parts[-2] >= scene.n_links:
        return None
    return float(_LINK_DEFAULTS[parts[-1]](scene, parts[-2]))


def _state_entries(study: Study, parts: Sequence) -> None:
    """A fit of ``arm.links[i].KEY`` or ``joints[i].KEY`` of a scene that states no such
    list: the study's data gets one empty entry per link (the URDF's, or the ideal joint's,
    values stand), for the fit to set."""
    data = study.data if isinstance(study.data, dict) else {}
    arm = data.get('arm')
    if tuple(parts[:2]) == ('arm', 'links'):
        if not isinstance(arm, dict) or 'links' in arm:
            return
        key = 'arm.links'
    elif parts[0] == 'joints' and not data.get('joints'):
        key = 'joints'
    else:
        return
    try:
        n = study.scene().n_links
    except SceneError as exc:
        raise FitError(f'--param {key}: {exc}') from None
    study.data = apply_overrides(study.data, {key: [{} for _ in range(n)]})


_NAMED = re.compile(r'^(links|joints)\[([A-Za-z_][A-Za-z0-9_\-/]*)\]\.([A-Za-z_]+)$')
_JOINT_DEFAULTS = ('damping', 'friction', 'friction_v_d', 'armature', 'max_effort')


def resolve_named_keys(study: Study, bounds: dict) -> dict:
    """Keys that name a URDF arm's links and joints by their URDF names (``links[NAME].KEY``,
    ``joints[NAME].KEY``) as the scene's key paths (``arm.links[k].KEY``, ``joints[k].KEY``);
    a name the arm does not have is refused naming the ones it has. A ``joints[k]`` key of a
    scene that states no ``joints`` gets one empty entry per joint (the URDF's values stand)."""
    out = {}
    for key, given in bounds.items():
        match = _NAMED.match(key)
        if match is None:
            out[key] = given
            continue
        kind, name, leaf = match.groups()
        try:
            scene = study.scene()
        except SceneError as exc:
            raise FitError(f'--param {key}: {exc}') from None
        names = scene.link_names if kind == 'links' else scene.joint_names
        allowed = _LINK_DEFAULTS if kind == 'links' else _JOINT_DEFAULTS
        if kind == 'links' and not scene.link_names:
            raise FitError(
                f"--param {key}: the scene's links have no names (give links[INDEX].{leaf})"
            )
        if name not in names:
            raise FitError(
                f'--param {key}: the arm has no {kind[:-1]} {name!r}; its {kind}: '
                f'{", ".join(names)}'
            )
        if leaf not in allowed:
            raise FitError(
                f'--param {key}: {leaf!r} is not a fit key of a {kind[:-1]}; '
                f'allowed: {", ".join(allowed)}'
            )
        k = names.index(name)
        out[f'arm.links[{k}].{leaf}' if kind == 'links' else f'joints[{k}].{leaf}'] = given
    return out


def _joint_default(study: Study, parts: Sequence) -> float | None:
    """The value a ``joints[i].KEY`` the scene leaves out stands at (the URDF's damping or
    friction, the ideal joint's), None if ``parts`` is no such key."""
    if len(parts) != 3 or parts[0] != 'joints' or not isinstance(parts[1], int):
        return None
    if parts[2] not in _JOINT_DEFAULTS:
        return None
    scene = study.scene()
    if parts[1] >= scene.n_links:
        return None
    value = getattr(scene.joint_specs[parts[1]], parts[2])
    if parts[2] == 'max_effort' and value is None:
        value = scene.joint_specs[parts[1]].effort_limit
    return float(value) if value is not None and math.isfinite(value) else None


def state_fit_keys(study: Study, keys: Sequence[str]) -> None:
    """Give ``study``'s data the entries the fitted keys need where the scene leaves them to
    the URDF (``arm.links``, ``joints``): a fitted scene is written from the same data."""
    for key in keys:
        try:
            parts = parse_key_path(key)
        except SceneError as exc:
            raise FitError(f'--param {key}: {exc}') from None
        _state_entries(study, parts)


def parameter_specs(study: Study, bounds: dict) -> list:
    """Check each key against the scene and its bounds ({key: (lo, hi)} or (lo, hi, start)):
    the key holds a number in the scene, or is one the scene may leave out (its value is then
    the schema's default, e.g. no joint damping) and the scene accepts it there;
    the bounds are finite, lo < hi, and contain the start (by default the scene's value)."""
    if not bounds:
        raise FitError('no parameter to fit: give at least one --param KEY=LO:HI')
    specs: list[Parameter] = []
    bounds = resolve_named_keys(study, bounds)
    for key, given in bounds.items():
        if len(given) not in (2, 3):
            raise FitError(f'--param {key}: expected (lo, hi) or (lo, hi, start), got {given!r}')
        lo, hi = float(given[0]), float(given[1])
        try:
            parts = parse_key_path(key)
        except SceneError as exc:
            raise FitError(f'--param {key}: {exc}') from None
        _state_entries(study, parts)
        stated = _scene_value(study, key)
        if stated is None:  # a link key left to its default (a rod's, the URDF's)
            stated = _link_default(study, key, parts)
        if stated is None:  # a joint key left to the URDF's or the ideal joint's value
            stated = _joint_default(study, parts)
        if stated is None:  # a key the scene leaves out: the schema's default, if it has one
            stated = schema_default(key)
            if stated is None:
                raise FitError(_missing(study, key))
            try:
                study.scene({key: stated})
            except SceneError as exc:
                raise FitError(f'--param {key}: the scene refuses it: {exc}') from None
        start = float(given[2]) if len(given) == 3 else stated
        text = f'{lo:g}:{hi:g}' + (f'@{start:g}' if len(given) == 3 else '')
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise FitError(f'--param {key}={text}: bounds must be finite with LO < HI')
        if not lo <= start <= hi:
            what = 'the start' if len(given) == 3 else f"the scene's value {start:g}, the start"
            raise FitError(
                f'--param {key}={text}: the bounds exclude {what}; widen them, or give a start '
                f'inside them (KEY=LO:HI@START)'
            )
        specs.append(Parameter(key, lo, hi, start, log=lo > 0))
    return specs


def _scene_value(study: Study, key: str) -> float | None:
    """The number the scene states at ``key``, None if it states nothing there."""
    try:
        parts = parse_key_path(key)
    except SceneError as exc:
        raise FitError(f'--param {key}: {exc}') from None
    node = study.data
    for part in parts:
        ok = (
            (isinstance(node, dict) and part in node)
            if isinstance(part, str)
            else (isinstance(node, list) and part < len(node))
        )
        if not ok:
            return None
        node = node[part]
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise FitError(f"--param {key}: the scene's value {node!r} is not a number")
    return float(node)


def _missing(study: Study, key: str) -> str:
    """The refusal of a key the scene does not state and that has no 'absent' value."""
    parts = parse_key_path(key)
    node = study.data
    for depth, part in enumerate(parts):
        ok = (
            (isinstance(node, dict) and part in node)
            if isinstance(part, str)
            else (isinstance(node, list) and part < len(node))
        )
        if not ok:
            where = (
                ''.join(f'[{p}]' if isinstance(p, int) else f'.{p}' for p in parts[:depth]).lstrip(
                    '.'
                )
                or 'the scene'
            )
            return (
                f'--param {key}: the scene {study.origin} has no {part!r} in {where} (fit keys '
                f'the scene states, e.g. surfaces[0].mu, materials.steel.S_y)'
            )
        node = node[part]
    return f'--param {key}: not in the scene {study.origin}'


def _schema_leaf(key: str) -> tuple | None:
    """The scene schema's entry (kind, constraint, unit, default) along a key's path, or None
    when the schema has no such path."""
    node: tuple = ('dict', SCHEMA, '', None)
    for part in parse_key_path(key):
        kind, inner = node[0], node[1]
        if (kind == 'list' and isinstance(part, int)) or (kind == 'map' and isinstance(part, str)):
            node = ('dict', inner, '', None)  # a list item or a named entry: its schema
        elif kind == 'dict' and isinstance(part, str) and part in inner:
            node = inner[part]
        else:
            return None
    return node


def schema_default(key: str) -> float | None:
    """The number the scene schema gives a key the scene leaves out (None: required, not a
    number, or not in the schema), read from the schema along the key's path."""
    node = _schema_leaf(key)
    if node is None or node[0] != 'num':
        return None
    default = node[3]
    if isinstance(default, (int, float)) and not isinstance(default, bool):
        return float(default)
    return None


def schema_unit(key: str) -> str:
    """The unit the scene schema states for a number key ('' for none, a pure number or a
    key the schema does not have)."""
    node = _schema_leaf(key)
    if node is None or node[0] != 'num' or node[2] == '-':
        return ''
    return str(node[2])
