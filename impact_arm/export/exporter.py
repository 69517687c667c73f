"""``export``: the scene's arm and contact written for one peer, tuned by running the peer
through the strikes (``strike``), with the residual report. The one entry point of the
CLI and of Python users."""

from __future__ import annotations

import json
import math
import os
import time
from typing import Any

import numpy as np

from ..physics.model import ArmModel
from ..physics.scene import Scene, load_scene, self_contained_text
from .arm import planar_arm
from .files import MODEL_FILES, model_text, readme, write
from .peers import Peer, require
from .report import PeerReport, to_json, to_markdown
from .strike import SPEED_RATIOS, Outcome, Strike, limit_cycle_impact, our_outcome, strikes
from .tuning import tune

BUDGET = 400  # peer evaluations (each: every strike) of the CLI's search
SCENE_FILE = 'scene.yaml'  # the exported scene's YAML, in the export's directory
STEPS_PER_CONTACT = 25  # the recommended time step resolves our shortest contact this finely


def recommended_timestep(ours: list[Outcome]) -> float:
    """The largest of 1, 2, 5 x 10^k seconds that gives our shortest contact
    ``STEPS_PER_CONTACT`` steps."""
    longest = min(o.duration for o in ours) / STEPS_PER_CONTACT
    exponent = math.floor(math.log10(longest))
    for mantissa in (5.0, 2.0, 1.0):
        step = mantissa * 10.0**exponent
        if step <= longest:
            return float(f'{step:.3g}')
    return float(f'{10.0 ** (exponent - 1) * 5.0:.3g}')


def fitted_scene(path: str) -> str:
    """The fitted scene a ``--fitted`` file names: the fitted scene YAML itself, or the
    fit.json of ``impact-arm fit`` (its ``scene`` entry: the fitted.yaml it wrote)."""
    if not path.endswith('.json'):
        return path
    with open(path, encoding='utf-8') as f:
        data = json.load(f)
    scene = data.get('scene') if isinstance(data, dict) else None
    if not isinstance(scene, str) or not scene:
        raise ValueError(f'--fitted {path}: no "scene" entry (the fitted scene fit wrote)')
    if not os.path.isabs(scene):
        scene = os.path.join(os.path.dirname(os.path.abspath(path)), scene)
    return scene


def linear_stiffness(scene: Scene, strike: Strike, duration: float) -> float:
    """The spring that makes a half period of ``duration`` with the tip's effective mass
    along the normal: the start of the stiffness searches [N/m]."""
    model = ArmModel(scene)
    q = np.asarray(strike.q)
    jacobian = np.asarray(model.tip_jacobian(q), float).reshape(2, model.n)
    w_nn = float(jacobian[1] @ np.linalg.solve(model.mass_matrix(q), jacobian[1]))
    return (math.pi / duration) ** 2 / w_nn


def _problem(peer: Peer, scene: Scene, chosen: list[Strike], ours: list[Outcome], dt: float) -> Any:
    arm = planar_arm(scene)
    struck = scene.surfaces[chosen[0].surface]
    cycle = next((k for k, s in enumerate(chosen) if s.speed_ratio == 1.0), 0)
    k = linear_stiffness(scene, chosen[cycle], ours[cycle].duration)
    if peer is Peer.MUJOCO:
        from .mujoco_strike import mujoco_problem

        return mujoco_problem(arm, dt, min(o.duration for o in ours), struck.mu)
    if peer is Peer.DRAKE:
        from .drake_strike import drake_problem

        return drake_problem(arm, dt, 2.0 * k, struck.mu)  # each of the pair: twice the pair's
    from .gazebo_model import gazebo_problem

    return gazebo_problem(scene, dt, k, chosen, struck.mu)


def _defaults(peer: Peer, dt: float) -> Any:
    if peer is Peer.MUJOCO:
        from .mjcf import mujoco_defaults

        return mujoco_defaults(dt)
    if peer is Peer.GAZEBO:
        from .sdf import gazebo_defaults

        return gazebo_defaults(dt)
    return None  # Drake's: no proximity properties (the plant's penetration allowance)


def _default_outcomes(peer: Peer, scene: Scene, chosen: list[Strike], dt: float) -> list[Outcome]:
    arm = planar_arm(scene)
    if peer is Peer.DRAKE:
        from .drake_strike import drake_outcomes

        return drake_outcomes(arm, None, dt, chosen)
    if peer is Peer.MUJOCO:
        from .mujoco_strike import mujoco_outcomes

        return mujoco_outcomes(arm, _defaults(peer, dt), chosen)
    from .gazebo_model import ode_outcome, tip_inverse_mass

    contact = _defaults(peer, dt)
    return [ode_outcome(contact, s, tip_inverse_mass(scene, s)) for s in chosen]


def export(
    scene: str,
    peer: Peer | str,
    out: str,
    fitted: str | None = None,
    budget: int = BUDGET,
    ratios: tuple[float, ...] = SPEED_RATIOS,
) -> PeerReport:
    """Write ``peer``'s model of ``scene`` (or of the ``fitted`` scene) with its contact
    tuned on the strikes at ``ratios`` of the limit-cycle speed, the README, the report
    and the scene's YAML (``SCENE_FILE``) into ``out``; returns the report."""
    started = time.perf_counter()
    peer = Peer(peer)
    require(peer)
    the_scene = load_scene(fitted_scene(fitted) if fitted else scene)
    chosen = strikes(the_scene, ratios, limit_cycle_impact(the_scene))
    ours = [our_outcome(the_scene, s) for s in chosen]
    dt = recommended_timestep(ours)
    tuned = tune(_problem(peer, the_scene, chosen, ours, dt), chosen, ours, budget)
    defaults = _defaults(peer, dt)
    report = PeerReport(
        peer,
        the_scene.name,
        dt,
        tuned.contact,
        defaults if defaults is not None else 'Drake plant defaults (no proximity properties)',
        chosen,
        ours,
        tuned.outcomes,
        _default_outcomes(peer, the_scene, chosen, dt),
        tuned.cost,
        tuned.evaluations,
        0.0,
    )
    arm = planar_arm(the_scene)
    write(out, MODEL_FILES[peer], model_text(arm, peer, tuned.contact))
    write(out, 'README.md', readme(arm, peer, tuned.contact, dt))
    # the scene itself (a URDF arm's description inlined), so that ``--check`` rebuilds our
    # side of the comparison from DIR alone, wherever the scene's own files are
    write(out, SCENE_FILE, self_contained_text(the_scene))
    import dataclasses

    report = dataclasses.replace(report, seconds=time.perf_counter() - started)
    write(out, 'report.md', to_markdown(report))
    write(out, 'report.json', json.dumps(to_json(report), indent=1) + '\n')
    return report
