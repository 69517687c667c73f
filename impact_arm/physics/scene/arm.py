"""The arm's links as the model takes them: from the scene's ``links`` or its URDF
(``arm.urdf`` or ``arm.description``), with the values the scene states instead of the file's."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

from .schema import LINK, TIP_RADIUS_RANGE, SceneChecker
from .types import JointSpec, rod_centres, rod_inertias
from .urdf import UrdfArm, parse_urdf_arm, read_urdf_file, resolve_urdf_path
from .xacro import expand_xacro


@dataclass(frozen=True)
class _ArmLinks(UrdfArm):
    """The arm's links as the model takes them (``UrdfArm``'s record, which the scene's rods
    fill too), and where they come from: the scene key, for refusals, and the URDF."""

    key: str = 'links'
    urdf_path: str = ''
    urdf_text: str = ''


def _arm_links(check: SceneChecker, raw: dict, scene_path: str) -> _ArmLinks:
    from ...contract import joint_names

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
        given = [key for key in ('urdf', 'xacro', 'description') if raw['arm'][key] is not None]
        if len(given) != 1:
            check.fail(
                'arm',
                f'gives both {" and ".join(given)}: give one of them'
                if given
                else 'needs urdf (a URDF file), xacro (a xacro file) or description (its text)',
            )
        for key in ('args', 'package_paths'):
            if raw['arm'][key] is not None and given != ['xacro']:
                check.fail(f'arm.{key}', 'applies to arm.xacro only')
        locked = raw['arm']['locked']
        urdf, urdf_text = _urdf_arm(
            check.origin,
            raw['arm']['urdf'],
            raw['arm']['description']
            if given != ['xacro']
            else _xacro_text(check, raw, scene_path),
            scene_path,
            contact.get('link'),
            point,
            contact.get('radius'),
            raw['arm']['joints'],
            None if locked is None else tuple(sorted(locked.items())),
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
            **{f.name: getattr(urdf, f.name) for f in fields(urdf)},
            key=f'arm.{given[0]}',
            urdf_path=raw['arm']['urdf'] or raw['arm']['xacro'] or '',
            urdf_text=urdf_text,
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
        link_names=(),
        lengths=lengths,
        masses=masses,
        com=tuple(
            (rod_c[k][0] if entry['com_x'] is None else entry['com_x'], entry['com_y'])
            for k, entry in enumerate(entries)
        ),
        inertias=tuple(
            rod_i[k] if entry['inertia'] is None else entry['inertia']
            for k, entry in enumerate(entries)
        ),
        tip_point=(lengths[-1], 0.0),
        tip_radius=raw['tip_radius'],
        joints=tuple(JointSpec(name) for name in joint_names(n)),
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


def _xacro_text(check: SceneChecker, raw: dict, scene_path: str) -> str:
    """The URDF text of ``arm.xacro``, expanded with its args and package paths."""
    arm = raw['arm']
    base = os.path.dirname(os.path.abspath(scene_path)) if scene_path else ''
    key: tuple = (
        arm['xacro'],
        base,
        tuple(sorted((arm['args'] or {}).items())),
        tuple(arm['package_paths'] or ()),
    )
    try:
        info = os.stat(os.path.join(base, arm['xacro']))
        key += (info.st_mtime_ns, info.st_size)
    except OSError:
        pass
    if key not in _XACRO_CACHE:
        if len(_XACRO_CACHE) > 16:
            _XACRO_CACHE.clear()
        _XACRO_CACHE[key] = expand_xacro(
            arm['xacro'],
            arm['args'],
            arm['package_paths'] or (),
            f"scene '{check.origin}': arm.xacro '{arm['xacro']}'",
            base,
        )
    return _XACRO_CACHE[key]


_XACRO_CACHE: dict[tuple, str] = {}  # a study loads one scene many times: expand it once
_URDF_CACHE: dict[tuple, Any] = {}  # a study loads one scene many times: read its URDF once


def _urdf_arm(origin, path, description, scene_path, link, point, radius, joints, locked):
    """(the parsed arm, the URDF text) of ``arm.urdf`` (a file) or ``arm.description``;
    ``joints``: the moving joints or None, ``locked``: sorted (name, value) pairs or None."""
    choice = (link, point, radius, joints, locked)
    if path is None:
        key: tuple = (hash(description), description, *choice)
    else:
        full = resolve_urdf_path(path, scene_path)
        try:
            info = os.stat(full)
            stamp: tuple = (info.st_mtime_ns, info.st_size)
        except OSError:
            stamp = ()
        key = (os.path.abspath(full), stamp, *choice)
    if key not in _URDF_CACHE:
        if path is None:
            text, where = description, f"scene '{origin}': arm.description"
        else:
            text = read_urdf_file(full, f"scene '{origin}': arm.urdf")
            where = f"scene '{origin}': arm.urdf '{path}'"
        if len(_URDF_CACHE) > 64:
            _URDF_CACHE.clear()
        arm = parse_urdf_arm(text, where, link, point, radius, joints, dict(locked or ()))
        _URDF_CACHE[key] = (arm, text)
    return _URDF_CACHE[key]
