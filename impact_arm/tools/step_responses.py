"""The article's Figure 3: offline step responses of a scene under each control law, as
``Run``s like a recording's. ``step_response`` drives the arm to its down target with the
surfaces taken away; ``step_metrics`` gives each link's overshoot, final error and settling
time."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..contract import FEEDBACK_LAWS, ControlLaw
from .run_data import AnalysisError, Run, _quiet

if TYPE_CHECKING:
    from ..physics.scene import Scene, Surface
    from ..physics.simulate import RunResult


STEP_LAWS = ('q', 'pd', 'pid')
LAW_NAMES = {'q': 'Q controller (eq. 9)', 'pd': 'PD (eq. 10, Ki = 0)', 'pid': 'PID (eq. 10)'}


def step_response(
    scene: Scene, law: str, t_max: float = 5.0, progress: Callable[[str], Any] = _quiet
) -> Run:
    """The article's Figure 3 for one law: the arm driven from the scene's initial position
    to its down target with the surfaces taken away (no impact: a step response), the
    controller evaluated continuously. ``run.target`` holds the target (rad)."""
    from ..physics.simulate import run

    if law not in FEEDBACK_LAWS:
        raise AnalysisError(f'--laws: {law!r} is not one of {", ".join(FEEDBACK_LAWS)}')
    controller = replace(scene.controller, law=ControlLaw(law), rate=0.0)
    if law == 'pid' and not any(controller.ki):
        raise AnalysisError('--laws pid: the scene has no integral gains (controller.ki)')
    sc = replace(scene, controller=controller, surfaces=surfaces_out_of_reach(scene), cycles=0)
    progress(f'step response of law {law} for {t_max:g} s (no surface)')
    result = run(sc, t_max=t_max)
    if result.error:
        raise AnalysisError(f'step response of law {law}: {result.error}')
    out = _offline_run(LAW_NAMES.get(law, law), result, sc, law)
    out.target = np.asarray(scene.controller.down_target, float)
    return out


def surfaces_out_of_reach(scene: Scene) -> tuple[Surface, ...]:
    """The surfaces a step response keeps: none but each mounted one, moved below the arm's
    reach. A mounted plate adds its state to the compiled kernel's shape, so taking it away
    would compile another kernel; out of reach and unloaded, its plate stays at rest and the
    arm moves as with no surface."""
    tip = math.hypot(*scene.tip_point) if scene.tip_point else 0.0
    below = -(sum(scene.lengths) + tip + scene.tip_radius + 1.0)  # farther than any link reaches
    return tuple(
        replace(s, height=below) for s in scene.surfaces if s.mount is not None and s.law != 'none'
    )


def step_metrics(run: Run, band_deg: float = 0.1) -> list[dict[str, float]]:
    """Per link, in degrees and seconds: the overshoot past the target (0 if none), the error
    at the end, and the time after which the angle stays within ``band_deg`` of the target
    (NaN if it never does)."""
    target = run.target
    if target is None:
        raise AnalysisError(f'{run.label}: not a step response (no target)')
    out = []
    for k in range(len(target)):
        e = np.degrees(run.q[:, k] - target[k])
        direction = np.sign(e[0])
        overshoot = max(0.0, float(-np.min(e * direction)))
        outside = np.nonzero(np.abs(e) > band_deg)[0]
        if not len(outside):
            settle = float(run.t[0])
        elif outside[-1] + 1 < len(e):
            settle = float(run.t[outside[-1] + 1])
        else:
            settle = math.nan
        out.append(
            {'overshoot_deg': overshoot, 'final_error_deg': float(e[-1]), 'settle_s': settle}
        )
    return out


def _offline_run(label: str, result: RunResult, scene: Scene, law: str) -> Run:
    """An offline run's samples as a Run (like a recording's)."""
    samples = result.samples
    return Run(
        label,
        np.array([s.t for s in samples]),
        np.array([s.q for s in samples]),
        np.array([s.qd for s in samples]),
        result.impacts,
        scene=scene,
        law=law,
    )
