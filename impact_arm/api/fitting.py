"""Fits for the API: ``Param`` bounds and ``fit``, the method of ``calibration.fit`` over a
recording read with its arm's scene."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Union

from ..calibration.fit import FitError, FitOptions, FitResult
from ..calibration.identify import JointRecording
from .recordings import read_recording, recording_scene
from ..physics.scene import Scene
from .scenes import SceneLike


@dataclass(frozen=True)
class Param:
    """The bounds of one fitted parameter, in the key's SI unit.

    Args:
        lo: lower bound.
        hi: upper bound, > ``lo``.
        start: where the search starts; None: the scene's own value.

    Raises:
        FitError: a bound not finite, ``lo >= hi``, or ``start`` outside [lo, hi].
    """

    lo: float
    hi: float
    start: float | None = None

    def __post_init__(self) -> None:
        values = (self.lo, self.hi) + (() if self.start is None else (self.start,))
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise FitError(f'{self}: lo, hi and start must be finite numbers')
        if not self.lo < self.hi:
            raise FitError(f'{self}: lo = {self.lo:g} must be < hi = {self.hi:g}')
        if self.start is not None and not self.lo <= self.start <= self.hi:
            raise FitError(
                f'{self}: start = {self.start:g} is out of range: must be in '
                f'[{self.lo:g}, {self.hi:g}]'
            )

    def bounds(self) -> tuple[float, ...]:
        """(lo, hi) or (lo, hi, start), as ``calibration.fit.fit`` takes them."""
        return (self.lo, self.hi) + (() if self.start is None else (self.start,))


# a parameter's bounds as fit() takes them: a Param, or the tuple (lo, hi[, start])
Bounds = Union[Param, tuple[float, float], tuple[float, float, float]]


def fit(
    recording: JointRecording | str | os.PathLike[str],
    scene: SceneLike | None,
    params: Mapping[str, Bounds],
    *,
    options: FitOptions | None = None,
    progress: Callable[..., Any] | None = None,
) -> FitResult:
    """Fit scene parameters to the impacts of a recording (the method: docs/fit.md).

    Args:
        recording: a ``JointRecording`` (``read_recording``'s), or the path of a recording,
            read with ``scene``.
        scene: the scene fitted (anything ``load_scene`` takes): its fixed values and the
            starting ones; None: the scene the recording (a path) stores.
        params: {scene key path: bounds}, the keys as ``impact-arm fit --param`` spells them
            (``surfaces[0].mu``, ``materials.steel.S_y``, ``links[1].mass``), the bounds a
            ``Param`` or a tuple (lo, hi[, start]).
        options: ``FitOptions`` (impacts left out, wrench used, search effort, ...).
        progress: called as progress(text, done=None, total=None) as the fit goes.

    Returns:
        The ``FitResult``: ``parameters`` ({key: ParameterEstimate with ``value``, ``ci95``,
        ``identifiable``}), ``verdict`` ('fits' or 'does not fit: <why>'), ``verdict_kind``
        (a ``Verdict``), ``scene_overrides`` (the fitted values), residuals and warnings.

    Raises:
        FitError: a key the scene has no number for, or bounds out of range.
        IdentifyError: too few impacts in the recording to fit.
        RecordingInputError: a recording that cannot be read.
        SceneError: a bad scene.
    """
    from ..calibration.fit import fit as fit_impacts

    if isinstance(recording, JointRecording):
        if scene is None:
            raise FitError(
                'scene: None needs a recording path (the scene it stores); give the scene '
                'of a JointRecording'
            )
        rec = recording
        # the core takes a name or path as text (PathLike: its text)
        fitted_scene: str | dict[str, Any] | Scene = (
            os.fspath(scene) if isinstance(scene, os.PathLike) else scene
        )
    else:
        fitted_scene = recording_scene(recording, scene)
        rec = read_recording(recording, fitted_scene)
    bounds = {
        key: value.bounds() if isinstance(value, Param) else tuple(value)
        for key, value in params.items()
    }
    result: FitResult = fit_impacts(rec, fitted_scene, bounds, options, progress)
    return result
