"""A sweep spec: base scene, fixed overrides, swept parameters by key path, tables wanted."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
from collections.abc import Callable
from typing import NoReturn

from ...physics.errors import ImpactArmError
from ...calibration.study import Study, load_scene_data, parse_key_path


KINDS = ('grid', 'list', 'random', 'lhs')


TABLES = ('runs', 'impacts')


SPEC_KEYS = ('scene', 'set', 'parameters', 'samples', 'seed', 'outputs')


class SpecError(ImpactArmError):
    """A sweep spec with a missing, unknown or out-of-range entry."""


class Spec:
    """A validated sweep spec: base scene data, fixed overrides, parameters and their runs."""

    def __init__(self, data: dict, origin: str = '<spec>', base_dir: str = '.') -> None:
        def fail(key: str, message: str) -> NoReturn:
            raise SpecError(f"sweep '{origin}': {key} {message}")

        if not isinstance(data, dict):
            fail('<top level>', 'must be a mapping')
        unknown = sorted(set(data) - set(SPEC_KEYS))
        if unknown:
            fail(unknown[0], f'is not a known key; allowed: {", ".join(SPEC_KEYS)}')
        scene = data.get('scene', 'paper')
        if isinstance(scene, str) and os.path.exists(os.path.join(base_dir, scene)):
            scene = os.path.join(base_dir, scene)
        self.scene_data, self.scene_origin = load_scene_data(scene)
        self.fixed = dict(data.get('set') or {})
        for key in self.fixed:
            parse_key_path(key)
        self.seed = data.get('seed', 0)
        self.samples = data.get('samples', 1)
        for key, value in (('seed', self.seed), ('samples', self.samples)):
            if isinstance(value, bool) or not isinstance(value, int) or value < (key == 'samples'):
                fail(key, f'= {value!r} must be an integer >= {int(key == "samples")}')
        self.outputs = tuple(data.get('outputs', TABLES))
        if not self.outputs or set(self.outputs) - set(TABLES):
            fail('outputs', f'= {list(self.outputs)!r}: choose from {", ".join(TABLES)}')
        self.parameters = {}
        for key, entry in (data.get('parameters') or {}).items():
            parse_key_path(key)
            self.parameters[key] = _parameter(
                key, entry, lambda m, k=key: fail(f'parameters.{k}', m)
            )
        self.hash = hashlib.sha256(
            json.dumps(
                {
                    'scene': self.scene_data,
                    'set': self.fixed,
                    'parameters': self.parameters,
                    'samples': self.samples,
                    'seed': self.seed,
                    'outputs': self.outputs,
                },
                sort_keys=True,
                default=str,
            ).encode()
        ).hexdigest()[:12]
        self.runs = self._expand()
        self._check_key_paths(origin)

    def _check_key_paths(self, origin: str) -> None:
        """Refuse a key path the scene does not have (``surfaces[0].muu``, an index past the
        end) now, before any run: otherwise every run fails with the same error. Each path is
        tried alone with its first run's value; out-of-range values are the runs' business
        (a sweep may cross the schema's limits on purpose)."""
        from ...physics.errors import SceneError

        first = self.runs[0] if self.runs else {}
        errors = []

        def check(base: dict, key: str, value: object) -> None:
            try:
                Study(self.scene_data, base).scene({key: value})
            except SceneError as exc:
                text = str(exc)
                if 'is not a known key' in text or text.startswith('override '):
                    errors.append(f'{key}: {text}')

        # the fixed overrides alone first (a parameter's path may need one of them, e.g. a
        # second surface), then each parameter on top of them
        for key, value in self.fixed.items():
            check({}, key, value)
        if not errors:
            for key in self.parameters:
                check(self.fixed, key, first.get(key))
        if errors:
            raise SpecError(
                f"sweep '{origin}': {len(errors)} key path(s) the scene does not "
                f'have, nothing was run:\n  ' + '\n  '.join(errors)
            )

    def _expand(self) -> list[dict]:
        """Each run's overrides, in run order: grid/list product (first parameter slowest)
        times the samples of the random/LHS parameters (seeded)."""
        import numpy as np

        fixed = {k: v for k, v in self.parameters.items() if v['kind'] in ('grid', 'list')}
        drawn = {k: v for k, v in self.parameters.items() if v['kind'] in ('random', 'lhs')}
        samples = self.samples if drawn else 1
        rng = np.random.default_rng(self.seed)
        columns = {}
        for key, p in drawn.items():
            u = rng.random(samples)
            if p['kind'] == 'lhs':  # one draw in each of `samples` equal strata
                u = (rng.permutation(samples) + u) / samples
            low, high = p['range']
            values = low * (high / low) ** u if p['scale'] == 'log' else low + (high - low) * u
            columns[key] = values.tolist()
        runs = []
        for point in itertools.product(*(p['values'] for p in fixed.values())):
            for s in range(samples):
                overrides = dict(zip(fixed, point))
                overrides.update({k: column[s] for k, column in columns.items()})
                runs.append(overrides)
        return runs

    @classmethod
    def load(cls, path: str) -> 'Spec':
        from ...physics.scene import scene_data

        try:
            with open(path, encoding='utf-8') as f:
                text = f.read()
        except OSError as exc:
            raise SpecError(f"sweep '{path}': cannot be read: {exc.strerror}") from None
        return cls(
            scene_data(text, path, 'sweep'),
            origin=path,
            base_dir=os.path.dirname(os.path.abspath(path)),
        )


def _parameter(key: str, entry: object, fail: Callable[..., NoReturn]) -> dict:
    if (
        not isinstance(entry, dict)
        or len(set(entry) & set(KINDS)) != 1
        or set(entry) - set(KINDS) - {'scale'}
    ):
        fail(
            f'= {entry!r} must be a mapping with one of {", ".join(KINDS)} (and scale for '
            f'random/lhs)'
        )
    kind = next(k for k in KINDS if k in entry)
    value = entry[kind]
    scale = entry.get('scale', 'linear')
    if scale not in ('linear', 'log'):
        fail(f'scale = {scale!r} is not allowed: choose linear or log')
    if kind == 'list':
        if not isinstance(value, list) or not value:
            fail(f'list = {value!r} must be a non-empty list of values')
        return {'kind': kind, 'values': value}
    numbers = isinstance(value, list) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
    )
    if kind == 'grid':
        if not numbers or len(value) != 3 or value[2] < 1 or int(value[2]) != value[2]:
            fail(f'grid = {value!r} must be [start, stop, count] with count an integer >= 1')
        start, stop, count = float(value[0]), float(value[1]), int(value[2])
        values = (
            [start + (stop - start) * i / (count - 1) for i in range(count)]
            if count > 1
            else [start]
        )
        return {'kind': kind, 'values': values}
    if (
        not numbers
        or len(value) != 2
        or not value[0] < value[1]
        or (scale == 'log' and value[0] <= 0)
    ):
        fail(f'{kind} = {value!r} must be [low, high] with low < high (low > 0 for scale log)')
    return {'kind': kind, 'range': (float(value[0]), float(value[1])), 'scale': scale}
