"""The peer's side of ``export --check``, whatever the peer: the scene's ``CycleController``
held (zero-order hold) for one control period over the peer's steps, as in the package's
offline sampled loop (``simulate.run`` with a control rate). The controller reads the
peer's joint angles in the scene's joint coordinates (the export keeps their names, zero
and sign) and, as the offline loop gives it, the mean normal contact force of the period
just ended. The motors are off while the tip touches a surface when the scene's
``actuators_during_contact`` is false (the article's contact), as the package's are.

An impact lasts from the first step whose tip/surface contact carries a normal force to the
first step without one (the contact's extent the export was tuned on). It is measured on
the peer's state: the contact time interpolated back from the first penetrating state to
zero penetration, the tip velocity at that state (before any contact force acted) and at
the first state after the last force, the peak of the steps' forces.

A peer is a ``PeerStepper`` (``mujoco_loop``, ``drake_loop``): how it starts, reads its
joints, steps a whole period far from the surface and one step near it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from ..physics.control import CycleController
from ..physics.errors import SimulationError
from ..physics.model import ArmModel
from ..physics.scene import Scene
from .impacts import ImpactRow

# far from the surface the steps of a control period run in one call: the tip could not
# reach the surface within this many periods at its speed, nor within this distance [m]
FAR_PERIODS = 2.0
FAR_MARGIN = 1e-3


@dataclass(frozen=True)
class PeerRun:
    impacts: tuple[ImpactRow, ...]
    t_end: float  # [s] simulated
    steps: int
    stopped: str  # why the run ended, in words


@dataclass(frozen=True)
class TipState:
    """The tip at the state a step starts from."""

    t: float
    depth: float  # deepest penetration of a tip/surface contact [m] (0: none)
    vx: float  # world x, along the surface [m/s]
    vz: float  # world z, the surface's normal [m/s]


@dataclass(frozen=True)
class Step:
    """One peer step near the surface: the state it started from and what it applied."""

    before: TipState
    touching: bool  # a tip/surface contact at that state (the motors were off if so)
    force: float  # the normal force the step applied [N]


class PeerStepper(Protocol):
    name: str
    timestep: float  # [s]

    def start(self, joints: list[float], rates: list[float]) -> None:
        """The peer at time 0 with the robot's joint angles and rates."""

    def time(self) -> float:
        """The peer's time [s]."""

    def joints(self) -> tuple[list[float], list[float]]:
        """The robot's joint angles and rates (finite: the stepper raises otherwise)."""

    def advance(self, efforts: list[float], steps: int) -> bool:
        """``steps`` steps with the robot's joint efforts held; whether the tip touches a
        surface at the end (it should not: the loop asks this only far from it)."""

    def step(self, efforts: list[float], motors_in_contact: bool) -> Step:
        """One step with the efforts held, zero while the tip touches unless
        ``motors_in_contact``."""


@dataclass
class _OpenImpact:
    start: TipState
    steps: int = 0
    peak: float = 0.0


def run(peer: PeerStepper, scene: Scene, rate: float, impacts: int, t_max: float) -> PeerRun:
    """Step ``peer`` under the scene's controller at ``rate`` until ``impacts`` impacts have
    ended or ``t_max`` simulated seconds."""
    coordinates = scene.joint_coordinates
    peer.start(list(coordinates.positions(scene.q0)), list(coordinates.rates(scene.qd0)))
    arm = ArmModel(scene)
    highest = max(s.height for s in scene.surfaces if s.law != 'none')
    ctrl = CycleController.for_scene(arm, scene.controller)
    limits = scene.effort_limits
    motors_in_contact = scene.actuators_during_contact
    dt = peer.timestep
    steps_per_period = round(1.0 / (rate * dt))
    period = 1.0 / rate
    found: list[ImpactRow] = []
    open_impact: _OpenImpact | None = None
    impulse = 0.0  # normal impulse over the control period [N s]
    steps = k = 0
    while len(found) < impacts:
        t_ctl = k * period
        if t_ctl > t_max:
            return PeerRun(tuple(found), peer.time(), steps, f't_max = {t_max:g} s reached')
        theta, theta_d = peer.joints()
        q, qd = coordinates.absolute(theta), coordinates.absolute_rates(theta_d)
        tau = ctrl.update(t_ctl, q, qd, normal_force=impulse / period)
        tau = [min(max(v, -lim), lim) for v, lim in zip(tau, limits)]  # the drive clips
        held = list(coordinates.efforts(tau))
        impulse = 0.0
        k += 1
        _, y, vx, vy = arm.tip(q, qd)
        reach = FAR_PERIODS * math.hypot(vx, vy) * period + FAR_MARGIN
        if open_impact is None and y - highest > reach:
            steps += steps_per_period
            if peer.advance(held, steps_per_period):
                raise SimulationError(
                    f'{peer.name}: the tip reached a surface within a period stepped as far '
                    f'from it (t = {peer.time():.6f} s): FAR_PERIODS too small'
                )
            continue
        for _ in range(steps_per_period):
            step = peer.step(held, motors_in_contact)
            steps += 1
            impulse += step.force * dt
            if step.force > 0.0:
                if open_impact is None:
                    open_impact = _OpenImpact(step.before)
                open_impact.steps += 1
                open_impact.peak = max(open_impact.peak, step.force)
            elif open_impact is not None:
                found.append(_impact(open_impact, step.before, dt))
                open_impact = None
                if len(found) == impacts:
                    break
    return PeerRun(tuple(found), peer.time(), steps, f'{impacts} impacts')


def _impact(impact: _OpenImpact, after: TipState, dt: float) -> ImpactRow:
    """The impact from its first penetrating state and the state after its last force."""
    start = impact.start
    # back from the first penetrating state to zero penetration, at the approach speed
    t_contact = start.t - start.depth / -start.vz if start.vz < 0.0 else start.t
    cor = -after.vz / start.vz if start.vz != 0.0 else math.nan
    return ImpactRow(t_contact, -start.vz, cor, impact.steps * dt, impact.peak)
