"""``impact-arm export --check DIR``: the export's peer rerun on the scene's cycles in closed
loop with the scene's controller, its impact table beside the package's own.

Our side is the offline sampled loop (``simulate.run`` at the control rate: the
``CycleController`` held for a period, the mean normal contact force of the period ended
given to it); the peer's is the same law on the exported model (``closed_loop`` with
``mujoco_loop`` or ``drake_loop``). Both run
until ``cycles + 1`` impacts: the strike of each cycle and the one that starts the next, as
the article's 15 cycles give 16 impacts. The scene is the one the export wrote into DIR
(``scene.yaml``), with its surfaces rigid as the export writes them."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass
from typing import Any

from ..physics.errors import ImpactArmError
from ..physics.scene import Scene, scene_from_text
from ..physics.simulate import run
from .exporter import SCENE_FILE
from .files import MODEL_FILES
from .impacts import Column, ColumnSummary, ImpactRow, summarise
from .peers import Peer, require
from .strike import rigid

# the controller node's default rate [Hz]: a scene with continuous control is checked at it
DEFAULT_RATE = 1000.0
# Contact times agree within this many control periods. Each cycle's two switches (down to
# up at the impact, up to down at the switch height) are taken at control samples: a contact
# that begins just after a sample on one side and just before it on the other moves the
# switch, and the rest of the cycle, by one period; the two switches: two periods.
TOLERANCE_PERIODS = 2.0
# where the peer's normal contact force comes from, for the controller input's description
FORCE_SOURCE = {
    Peer.MUJOCO: "MuJoCo's mj_contactForce",
    Peer.DRAKE: "Drake's point-pair contact results",
}
CHECKED_PEERS = (Peer.MUJOCO, Peer.DRAKE)


def controller_input(peer: Peer) -> str:
    """What the controller sees on the peer's side, in words."""
    return (
        'the mean normal contact force of each control period (as the offline loop gives '
        f"it; {FORCE_SOURCE[peer]}), and the joint state sampled at the period's start"
    )


class CheckRefused(ImpactArmError):
    """DIR is not an export, or one of a peer ``--check`` does not run."""


@dataclass(frozen=True)
class ExportedDir:
    directory: str
    peer: Peer
    scene: Scene
    timestep: float  # the export's recommended time step [s]
    model_path: str


@dataclass(frozen=True)
class CheckResult:
    directory: str
    scene: str
    peer: Peer
    timestep: float  # [s]
    rate: float  # the control rate both sides ran at [Hz]
    cycles: int
    ours: tuple[ImpactRow, ...]
    theirs: tuple[ImpactRow, ...]
    our_stopped: str
    peer_stopped: str
    our_seconds: float  # wall clock of our run
    peer_seconds: float  # of the peer's
    peer_steps: int

    @property
    def impacts_wanted(self) -> int:
        return self.cycles + 1

    @property
    def tolerance(self) -> float:
        """The contact times' tolerance [s]."""
        return TOLERANCE_PERIODS / self.rate

    @property
    def summary(self) -> list[ColumnSummary]:
        return summarise(self.ours, self.theirs)

    @property
    def failures(self) -> list[str]:
        """Why the peer's impacts do not agree with ours, in words (empty: they agree)."""
        out = []
        for side, rows in (('ours', self.ours), (self.peer.value, self.theirs)):
            if len(rows) != self.impacts_wanted:
                out.append(f'{side}: {len(rows)} impacts of {self.impacts_wanted}')
        for side, rows in (('ours', self.ours), (self.peer.value, self.theirs)):
            out += [
                f'{side}: {c.value} is {getattr(r, c.value)} at impact {k + 1}'
                for k, r in enumerate(rows)
                for c in Column
                if not math.isfinite(getattr(r, c.value))
            ]
        worst = self.summary[0]
        if not worst.worst <= self.tolerance:  # NaN fails too
            out.append(
                f'contact time {worst.worst * 1e3:.3f} ms apart at impact {worst.at} '
                f'(tolerance {self.tolerance * 1e3:g} ms)'
            )
        return out


def _refuse(directory: str, why: str) -> CheckRefused:
    return CheckRefused(f'--check {directory}: {why}')


def read_export(directory: str) -> ExportedDir:
    """The peer, scene and time step an export wrote into ``directory``; a one-line refusal
    for a directory that is not an export or one of a peer not checked."""
    report_path = os.path.join(directory, 'report.json')
    if not os.path.isdir(directory):
        raise _refuse(directory, 'not a directory')
    if not os.path.isfile(report_path):
        raise _refuse(directory, 'not an export of impact-arm export (no report.json)')
    try:
        with open(report_path, encoding='utf-8') as f:
            data = json.load(f)
        peer = Peer(data['peer'])
        timestep = float(data['timestep'])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise _refuse(directory, f'report.json is not an export report ({exc})') from None
    if peer not in CHECKED_PEERS:
        raise _refuse(
            directory,
            f'an export to {peer.value}; --check runs '
            f'{" and ".join(p.value for p in CHECKED_PEERS)} ({peer.value}: not run here)',
        )
    if not (math.isfinite(timestep) and timestep > 0.0):
        raise _refuse(directory, f'report.json timestep = {timestep}: must be > 0 s')
    scene_path = os.path.join(directory, SCENE_FILE)
    if not os.path.isfile(scene_path):
        raise _refuse(
            directory,
            f'no {SCENE_FILE} (written by exports since --check exists): export the scene again',
        )
    with open(scene_path, encoding='utf-8') as f:
        scene = scene_from_text(f.read(), origin=scene_path, path=scene_path)
    model_path = os.path.join(directory, MODEL_FILES[peer])
    if not os.path.isfile(model_path):
        raise _refuse(directory, f'no {MODEL_FILES[peer]}, the {peer.value} model')
    return ExportedDir(directory, peer, scene, timestep, model_path)


def control_rate(scene: Scene, timestep: float, rate: float | None = None) -> float:
    """The rate both sides run the controller at: ``rate``, else the scene's, else (a scene
    with continuous control) the controller node's default; a whole number of steps."""
    chosen = rate if rate is not None else (scene.controller.rate or DEFAULT_RATE)
    steps = 1.0 / (chosen * timestep) if chosen > 0 and math.isfinite(chosen) else math.nan
    if not (steps >= 1.0 and abs(steps - round(steps)) < 1e-6 * steps):
        raise CheckRefused(
            f'--rate {chosen:g}: the control period must be a whole number (>= 1) of the '
            f"export's time steps ({timestep:g} s), e.g. {DEFAULT_RATE:g} Hz"
        )
    return float(chosen)


def our_impacts(scene: Scene, impacts: int, rate: float) -> tuple[list[ImpactRow], str]:
    """The first ``impacts`` impacts of our offline sampled loop, and why it stopped."""
    # a cycle ends at the up-to-down switch after its impact: ``impacts`` cycles hold them
    result = run(
        dataclasses.replace(rigid(scene), cycles=impacts), control_rate=rate, keep_samples=False
    )
    rows = [
        ImpactRow(
            float(r.t_contact),
            -float(r.v_before[1]),
            float(r.cor_kinematic),
            float(r.duration),
            float(r.F_max),
        )
        for r in result.impacts[:impacts]
    ]
    return rows, result.stopped + (f': {result.error}' if result.error else '')


def _peer_loop(exported: ExportedDir, rate: float) -> Any:
    """The peer's closed loop (its package is imported only here)."""
    if exported.peer is Peer.DRAKE:
        from .drake_loop import DrakeLoop

        return DrakeLoop(exported.model_path, exported.scene, exported.timestep, rate)
    from .mujoco_loop import MujocoLoop

    return MujocoLoop(exported.model_path, exported.scene, exported.timestep, rate)


def check(directory: str, cycles: int | None = None, rate: float | None = None) -> CheckResult:
    """Run both sides of the export in ``directory`` for ``cycles`` cycles (the scene's by
    default) at the control ``rate`` (see ``control_rate``)."""
    exported = read_export(directory)
    require(exported.peer)
    scene = exported.scene
    cycles = scene.cycles if cycles is None else cycles
    if cycles < 1:
        raise CheckRefused(
            f'--cycles {cycles}: must be >= 1 (the scene runs until t_max: give --cycles N)'
        )
    rate = control_rate(scene, exported.timestep, rate)
    wanted = cycles + 1
    started = time.perf_counter()
    ours, our_stopped = our_impacts(scene, wanted, rate)
    our_seconds = time.perf_counter() - started
    started = time.perf_counter()
    peer = _peer_loop(exported, rate).run(wanted, scene.t_max)
    return CheckResult(
        directory,
        scene.name,
        exported.peer,
        exported.timestep,
        rate,
        cycles,
        tuple(ours),
        peer.impacts,
        our_stopped,
        peer.stopped,
        our_seconds,
        time.perf_counter() - started,
        peer.steps,
    )
