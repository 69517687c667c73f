"""Studies: many runs of one scene with a few values changed, on the event-only path.

A run is a base scene plus *overrides* addressed by key path, the way the scene file spells
them: ``surfaces[0].mu``, ``controller.kp`` (a whole list), ``controller.kp[0]`` (one entry),
``materials.steel.E``, ``integrator.rtol``. Overrides are written into the scene's YAML data
before validation, so a refused value is named by its key path like any scene error. Runs
integrate from event to event (no samples, no traces) and return ``Impact`` records and a summary;
a refused scene or a simulation error is part of the result, never an exception::

    from impact_arm.calibration.study import Study

    study = Study('paper', {'integrator.rtol': 1e-2, 'integrator.contact_rtol': 3e-4,
                            'integrator.method': 'rosenbrock'})
    result = study.run({'surfaces[0].mu': 0.5, 'controller.kp': [800, 300]})
    result.summary['cor_kinematic'], result.impacts[0].F_max, result.error

The YAML is parsed once per study, and what a run's overrides leave alone is validated once
(``parse_scene(checked=...)``; the checks across keys run for every run); the compiled kernel
of a scene shape is loaded once per process (``equations.load_equations``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import copy
import functools
import math
import os
import re
import time
from dataclasses import dataclass, field

from ..physics.errors import SceneError
from ..physics.impact import Impact
from ..physics.metrics import limit_cycle
from ..physics.scene import Scene, parse_scene, read_scene_file, scene_data
from ..physics.simulate import run as run_scene

if TYPE_CHECKING:
    from ..physics.integrator import Stats

_TOKEN = re.compile(r'\.?([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]')


def parse_key_path(path: str) -> list:
    """'surfaces[0].mu' -> ['surfaces', 0, 'mu']."""
    return list(_key_path(path))


@functools.lru_cache(maxsize=1024)
def _key_path(path: str) -> tuple:
    # a sweep applies the same few paths to every run: parsed once per process
    parts, pos = [], 0
    while pos < len(path):
        match = _TOKEN.match(path, pos)
        if not match or (pos == 0 and path.startswith('.')):
            raise SceneError(
                f'override key {path!r}: not a key path (e.g. surfaces[0].mu, controller.kp[1])'
            )
        name, index = match.groups()
        parts.append(name if name is not None else int(index))
        pos = match.end()
    if not parts:
        raise SceneError("override key '': empty key path")
    return tuple(parts)


def _plain(value):
    """numpy numbers and arrays as the Python numbers and lists the schema checks; lists and
    mappings copied, so that a study's data never changes in place (the caller may change
    its own after a run: the study remembers what it has validated)."""
    if hasattr(value, 'tolist'):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


# top-level lists of the scene with one entry per link, each entry all defaults when absent
PER_LINK_LISTS = ('joints',)


def apply_overrides(data: dict, overrides: dict) -> dict:
    """A copy of scene ``data`` with each key path set to its value (containers along a path
    are copied, the rest shared). A path through a missing mapping creates it, and one through
    a missing per-link list (``joints[1].damping``) creates it with an empty entry per link;
    the schema then refuses keys it does not know."""
    out = dict(data)
    for path, value in overrides.items():
        parts = _key_path(path)
        node: Any = out  # a mapping or a list of the data, one level deeper each step
        for depth, key in enumerate(parts):
            last = depth == len(parts) - 1
            if isinstance(key, int):
                if not isinstance(node, list):
                    raise SceneError(
                        f'override {path!r}: {_where(path, parts, depth)} is not a list'
                    )
                if key >= len(node):
                    raise SceneError(
                        f'override {path!r}: {_where(path, parts, depth)} has {len(node)} entries'
                    )
            elif not isinstance(node, dict):
                raise SceneError(
                    f'override {path!r}: {_where(path, parts, depth)} is not a mapping'
                )
            if last:
                node[key] = _plain(value)
                break
            child = node.get(key) if isinstance(node, dict) else node[key]
            if child is None and key in PER_LINK_LISTS and isinstance(parts[depth + 1], int):
                # 'joints[1].damping' on a scene with ideal joints: one default entry per link
                links = out.get('links')
                child = [{} for _ in links] if isinstance(links, list) else []
            child = {} if child is None else child
            child = (
                list(child)
                if isinstance(child, (list, tuple))
                else dict(child)
                if isinstance(child, dict)
                else child
            )
            node[key] = child
            node = child
    return out


def _where(path, parts, depth) -> str:
    """The container an override failed at, for its error message (rendered only then)."""
    return path if depth == 0 else _render(parts[:depth])


def _render(parts) -> str:
    return ''.join(
        f'[{p}]' if isinstance(p, int) else (f'.{p}' if i else p) for i, p in enumerate(parts)
    )


def load_scene_data(scene: str | Scene | dict) -> tuple[dict, str]:
    """(YAML data, origin) of a scene given as a path or installed name, a ``Scene`` loaded
    from text, or data already parsed."""
    if isinstance(scene, dict):
        return copy.deepcopy(scene), '<scene data>'
    if isinstance(scene, Scene):
        if not scene.source_text:
            raise SceneError(
                f"scene '{scene.name}' was built without its YAML text: pass its file or data"
            )
        return scene_data(
            scene.source_text, scene.source_path or scene.name
        ), scene.source_path or scene.name
    text, path = read_scene_file(scene)
    return scene_data(text, path), path


@dataclass
class StudyRun:
    overrides: dict
    impacts: list[Impact] = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    error: str = ''  # the refusal or simulation error, '' if the run completed
    error_kind: str = ''  # 'scene' | 'simulation' | ''


def summarize(
    impacts: Sequence[Impact],
    t_end: float = math.nan,
    stats: Stats | None = None,
    wall: float = math.nan,
) -> dict:
    """The per-run numbers of a study: impacts, the last period (the time the last
    repetition took: between the last two contacts, or the last few for an arm that strikes
    more than once per cycle), the impact from which the motion repeats and how many impacts
    make one repetition, the final CoRs."""
    last = impacts[-1] if impacts else None
    cycle = limit_cycle(impacts)
    every = cycle.impacts_per_cycle if cycle else 1
    return {
        'impacts': len(impacts),
        't_end': t_end,
        'period': impacts[-1].t_contact - impacts[-1 - every].t_contact
        if len(impacts) > every
        else math.nan,
        'settled_after': cycle.settled_after if cycle else 0,
        'impacts_per_cycle': every if cycle else 0,
        'cor_kinematic': last.cor_kinematic if last else math.nan,
        'cor_energetic': last.cor_energetic[-1] if last else math.nan,
        'rhs_evaluations': stats.rhs_evaluations if stats else 0,
        'steps': stats.steps if stats else 0,
        'wall_time': wall,
    }


class Study:
    """A base scene (path, installed name, ``Scene`` or YAML data) and fixed overrides; each
    ``run(overrides)`` integrates one variant on the event-only path. ``data`` is the base's
    YAML data, a copy of the caller's: change it through overrides, never in place."""

    def __init__(self, scene='paper', overrides: dict | None = None):
        self.data, self.origin = load_scene_data(scene)
        self.path = self.origin if os.path.exists(self.origin) else ''
        if overrides:
            self.data = apply_overrides(self.data, overrides)
        # the parts of the data a run's overrides leave alone are checked once per study
        self._checked: dict = {}

    def scene(self, overrides: dict | None = None) -> Scene:
        data = apply_overrides(self.data, overrides) if overrides else self.data
        origin = self.origin if not overrides else f'{self.origin} with overrides'
        return parse_scene(data, origin=origin, path=self.path, checked=self._checked)

    def run(self, overrides: dict | None = None) -> StudyRun:
        overrides = dict(overrides or {})
        wall0 = time.perf_counter()
        try:
            scene = self.scene(overrides)
        except SceneError as exc:
            return StudyRun(
                overrides,
                summary=summarize([], wall=time.perf_counter() - wall0),
                error=str(exc),
                error_kind='scene',
            )
        result = run_scene(scene, samples=False)
        summary = summarize(
            result.impacts,
            result.t_end,
            result.integrator.stats,  # type: ignore[union-attr]  # run() always sets it
            time.perf_counter() - wall0,
        )
        return StudyRun(
            overrides, result.impacts, summary, result.error, 'simulation' if result.error else ''
        )


def run(scene: str | Scene | dict = 'paper', overrides: dict | None = None) -> StudyRun:
    """One run of ``scene`` with ``overrides`` (see the module's docstring)."""
    return Study(scene).run(overrides)
