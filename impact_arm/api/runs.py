"""Runs for the API: ``simulate`` and its ``RunResult``, whose impacts are ``Impact`` records."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..physics.errors import SceneError, SimulationError
from ..physics.impact import Impact
from ..physics.scene import Scene
from ..physics.simulate import Sample, StopReason
from .scenes import SceneLike, load_scene

if TYPE_CHECKING:
    from ..physics.metrics import LimitCycle
    from ..physics.simulate import RunResult as Run


@dataclass(frozen=True)
class RunResult:
    """What ``simulate`` returns: the impacts as ``Impact`` records, the samples if kept, and
    why the run ended. A simulation error never raises: it ends the run early, with the
    impacts before it kept, ``error`` saying why and ``exception`` to re-raise."""

    scene: Scene
    impacts: tuple[Impact, ...]
    samples: tuple[Sample, ...]  # empty for simulate(samples=False)
    t_end: float  # simulated time at the end [s]
    stop_reason: StopReason | None
    stopped: str  # why it ended, in words ('15 cycles completed')
    error: str  # '' when the run completed
    exception: SimulationError | None
    wall_time: float  # the integration and its bookkeeping [s]
    mcap: str | None  # the MCAP file written, if asked for
    run: Run  # the physics' own result (the same records, integrator, chatter, limits)

    @property
    def ok(self) -> bool:
        """True when no simulation error ended the run."""
        return not self.error

    @property
    def limit_cycle(self) -> LimitCycle | None:
        """Where the impacts start repeating, or None."""
        return self.run.limit_cycle

    def to_json(self) -> dict[str, Any]:
        """The JSON of ``impact-arm simulate --json``: {'impacts': [...], 'run': {...}}."""
        result: dict[str, Any] = self.run.to_json()
        return result


def simulate(
    scene: SceneLike,
    *,
    control_rate: float | None = None,
    samples: bool = True,
    mcap: str | os.PathLike[str] | None = None,
) -> RunResult:
    """Simulate ``scene`` for its cycles (or until its ``t_max``), as ``impact-arm simulate``.

    Args:
        scene: anything ``load_scene`` takes (name, path, YAML data, ``Scene``).
        control_rate: the controller's sampling rate [Hz]; None: the scene's
            ``controller.rate``; 0: continuous control, as in the article.
        samples: keep the sampled output (``RunResult.samples``, at the scene's
            ``publish_rate``); False runs from event to event (continuous control only),
            the fastest path to the impacts.
        mcap: write the run to this MCAP file as the live simulator's topics, with the
            scene stored in it (``read_recording`` reads it back); needs ``samples``.

    Returns:
        The ``RunResult``.

    Raises:
        SceneError: a bad scene, a control rate out of range, ``mcap`` without samples, or
            too many samples to keep in memory.
    """
    sc = load_scene(scene)
    rate = sc.controller.rate if control_rate is None else control_rate
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate >= 0):
        raise SceneError(f'control_rate = {control_rate!r} is out of range: must be >= 0 Hz')
    if not samples and (rate or mcap is not None):
        raise SceneError(
            'samples = False runs continuous control without output: '
            + (f'control_rate = {rate:g} Hz must be 0' if rate else 'no mcap can be written')
        )
    from ..physics.simulate import run

    observer = None
    if mcap is not None:
        from ..io.offline_mcap import OfflineRecorder

        observer = OfflineRecorder(mcap, sc, control_rate=control_rate)
    result = None
    try:
        result = run(sc, samples=samples, control_rate=control_rate, observer=observer)
    finally:
        if observer is not None:
            observer.close(result)  # with the result: its summary is stored in the file
    return RunResult(
        scene=sc,
        impacts=tuple(result.impacts),
        samples=tuple(result.samples),
        t_end=result.t_end,
        stop_reason=result.stop_reason,
        stopped=result.stopped,
        error=result.error,
        exception=result.exception,
        wall_time=result.wall_time,
        mcap=None if mcap is None else os.fspath(mcap),
        run=result,
    )
