"""The fitted parameters: scene key paths with bounds, checked against the scene, and the
unit-cube / log coordinates the search and the covariance use."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...physics.errors import ImpactArmError, SceneError
from ..study import Study, parse_key_path


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


def parameter_specs(study: Study, bounds: dict) -> list:
    """Check each key against the scene (it must exist and hold a number) and its bounds
    (finite, lo < hi, containing the scene's value, which is the starting point)."""
    if not bounds:
        raise FitError('no parameter to fit: give at least one --param KEY=LO:HI')
    specs: list[Parameter] = []
    for key, (lo, hi) in bounds.items():
        try:
            parts = parse_key_path(key)
        except SceneError as exc:
            raise FitError(f'--param {key}: {exc}') from None
        node = study.data
        for depth, part in enumerate(parts):
            ok = (
                (isinstance(node, dict) and part in node)
                if isinstance(part, str)
                else (isinstance(node, list) and part < len(node))
            )
            if not ok:
                where = (
                    ''.join(
                        f'[{p}]' if isinstance(p, int) else f'.{p}' for p in parts[:depth]
                    ).lstrip('.')
                    or 'the scene'
                )
                raise FitError(
                    f'--param {key}: the scene {study.origin} has no {part!r} in '
                    f'{where} (fit keys the scene states, e.g. surfaces[0].mu, '
                    f'materials.steel.S_y)'
                )
            node = node[part]
        if isinstance(node, bool) or not isinstance(node, (int, float)):
            raise FitError(f"--param {key}: the scene's value {node!r} is not a number")
        lo, hi, start = float(lo), float(hi), float(node)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise FitError(f'--param {key}={lo:g}:{hi:g}: bounds must be finite with LO < HI')
        if not lo <= start <= hi:
            raise FitError(
                f"--param {key}={lo:g}:{hi:g}: the bounds exclude the scene's value "
                f'{start:g}, the starting point; widen them or edit the scene'
            )
        specs.append(Parameter(key, lo, hi, start, log=lo > 0))
    return specs
