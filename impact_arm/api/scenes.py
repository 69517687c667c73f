"""Scenes for the API: one loader for every way a scene is given."""

from __future__ import annotations

import os
from typing import Any, Union

from ..physics.errors import SceneError
from ..physics.scene import Scene, installed_scenes, load_scene as load_scene_file, parse_scene

# a scene as the API takes it: an installed name ('paper'), a file, YAML data or a Scene
SceneLike = Union[str, 'os.PathLike[str]', dict[str, Any], Scene]


def load_scene(scene: SceneLike) -> Scene:
    """The validated, frozen scene ``scene`` names.

    Args:
        scene: an installed scene's name (``'paper'``, ``'three_link'``), the path of a scene
            file, the scene's YAML data as a dict, or a ``Scene`` (returned as it is).

    Returns:
        The ``Scene`` (SI units, radians), which keeps its YAML text: studies, fits and
        recordings made from it can rebuild it.

    Raises:
        SceneError: no such scene, or a key out of its range (one line naming the key path,
            the value and the allowed range).
    """
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, dict):
        import yaml

        # kept as text too, as a file's scene is: what a study or a recording rebuilds it from
        text = yaml.safe_dump(scene, sort_keys=False)
        return parse_scene(scene, origin='<scene data>', text=text)
    if isinstance(scene, (str, os.PathLike)):
        return load_scene_file(scene)
    raise SceneError(
        f'scene {scene!r}: expected a scene name ({", ".join(installed_scenes())}), a file '
        f'path, YAML data (dict) or a Scene'
    )
