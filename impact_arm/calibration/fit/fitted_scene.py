"""The fitted scene as a file: the starting scene with the fitted values written in, which
``impact-arm simulate --scene`` runs and ``impact_arm.load_scene`` reads."""

from __future__ import annotations

import os
from typing import Any

from ...physics.scene import Scene
from ..study import Study, apply_overrides
from .parameters import state_fit_keys


def write_fitted_scene(
    scene: str | os.PathLike | Scene | dict,
    values: dict[str, Any],
    path: str | os.PathLike,
    recording: str | os.PathLike = '',
) -> None:
    """Write ``scene`` with ``values`` ({key path: value}, e.g. ``FitResult.scene_overrides``)
    to ``path``, named ``<name>_fitted``; a header says which values came from
    ``recording``. Raises ``SceneError`` (before writing) when the values make it invalid."""
    import yaml

    from ...physics.scene import parse_scene

    path = os.fspath(path)
    study = Study(os.fspath(scene) if isinstance(scene, os.PathLike) else scene)
    state_fit_keys(study, list(values))  # arm.links / joints the scene leaves to its URDF
    data = apply_overrides(study.data, values)
    _keep_urdf_reachable(data, study.path, path)
    parse_scene(data, origin=path, path=path)  # refuse now rather than hand out a broken file
    if isinstance(data.get('name'), str):
        data['name'] = data['name'] + '_fitted'
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    head = (
        f'# {os.path.basename(path)}: {study.origin} with values fitted to '
        f'{os.fspath(recording)} by impact-arm fit\n'
    )
    with open(path, 'w', encoding='utf-8') as f:
        f.write(head + ''.join(f'#   {k} = {v:.6g}\n' for k, v in values.items()) + text)


def _keep_urdf_reachable(data: dict, scene_path: str, fitted_path: str) -> None:
    """A relative ``arm.urdf`` is relative to its scene file's directory: written into
    another directory (runs/fit_<name>/), it is rewritten relative to the new file's
    directory so that the fitted scene reads the same description."""
    from ...physics.scene.urdf import resolve_urdf_path

    arm = data.get('arm')
    if not isinstance(arm, dict):
        return
    urdf = arm.get('urdf')
    if not isinstance(urdf, str) or os.path.isabs(urdf):
        return
    full = os.path.abspath(resolve_urdf_path(urdf, scene_path))
    arm['urdf'] = os.path.relpath(full, os.path.dirname(os.path.abspath(fitted_path)))
