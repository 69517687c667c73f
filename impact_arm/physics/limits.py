"""The robot's position and velocity limits, watched: how many periods a run spends beyond
each joint's ``<limit lower upper velocity>`` (the URDF's, in the robot's own joint angles).

The simulated arm does not stop at them (a driver's limit handling is its own choice); a run
says where its motion went past what the robot is rated for, in its summary, on the
simulator's /diagnostics and in ``impact-arm analyze``. Plain Python, no ROS.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

from .errors import SimulationError
from .scene import Scene

if TYPE_CHECKING:
    import numpy as np


class JointLimitStop(SimulationError):
    """A joint went beyond its position or velocity limit under ``joint_limits: stop``: the
    run stops there, as a driver's protective stop halts the arm."""


class LimitKind(str, Enum):
    POSITION = 'position'
    VELOCITY = 'velocity'


@dataclass(frozen=True)
class LimitExcursion:
    """A joint's periods beyond one of its limits, and how far beyond it went at most."""

    joint: str
    kind: LimitKind
    periods: int
    worst: float  # the farthest value reached [rad or rad/s]
    limit: float  # the bound passed [rad or rad/s]

    def text(self) -> str:
        position = self.kind is LimitKind.POSITION
        unit = 'rad' if position else 'rad/s'
        bound = f'{self.limit:g}' if position else f'±{abs(self.limit):g}'
        return (
            f"joint '{self.joint}' beyond its {self.kind.value} limit {bound} {unit} "
            f'in {self.periods} periods (up to {self.worst:.4g} {unit})'
        )

    def to_json(self) -> dict:
        return {
            'joint': self.joint,
            'kind': self.kind.value,
            'periods': self.periods,
            'worst': self.worst,
            'limit': self.limit,
        }


class LimitWatch:
    """Counts the samples (periods) beyond each joint's limits. ``add(θ, θ̇)`` takes the
    robot's joint angles and rates of one period. A revolute joint without a range (its
    URDF's ``lower = upper``, e.g. both 0) and a continuous joint have no position limit;
    a velocity limit of 0 (not given) is none."""

    def __init__(self, scene: Scene) -> None:
        specs = scene.joint_specs
        self.stop = scene.joint_limits == 'stop'
        self.names = [j.name for j in specs]
        self.ranges = [
            (j.lower, j.upper)
            if j.lower is not None and j.upper is not None and j.lower < j.upper
            else None
            for j in specs
        ]
        self.speeds = [j.velocity if j.velocity else None for j in specs]
        n = len(specs)
        self._count = {kind: [0] * n for kind in LimitKind}
        self._worst: dict[LimitKind, list[float]] = {kind: [0.0] * n for kind in LimitKind}
        self._bound: dict[LimitKind, list[float]] = {kind: [0.0] * n for kind in LimitKind}
        self.active = any(self.ranges) or any(self.speeds)

    def add(self, theta: Sequence[float], theta_d: Sequence[float]) -> None:
        if not self.active:
            return
        for k, (a, w) in enumerate(zip(theta, theta_d)):
            bounds = self.ranges[k]
            if bounds is not None and not bounds[0] <= a <= bounds[1]:
                self._note(LimitKind.POSITION, k, a, bounds[0] if a < bounds[0] else bounds[1])
            speed = self.speeds[k]
            if speed is not None and abs(w) > speed:
                self._note(LimitKind.VELOCITY, k, w, math.copysign(speed, w))

    def _note(self, kind: LimitKind, k: int, value: float, bound: float) -> None:
        self._count[kind][k] += 1
        if abs(value - bound) >= abs(self._worst[kind][k] - self._bound[kind][k]):
            self._worst[kind][k], self._bound[kind][k] = float(value), float(bound)
        if self.stop:
            unit = 'rad' if kind is LimitKind.POSITION else 'rad/s'
            shown = f'{bound:g}' if kind is LimitKind.POSITION else f'±{abs(bound):g}'
            raise JointLimitStop(
                f"joint '{self.names[k]}' at {value:.4g} {unit}, beyond its {kind.value} "
                f'limit {shown} {unit}: protective stop (joint_limits: stop)'
            )

    @property
    def found(self) -> list[LimitExcursion]:
        return [
            LimitExcursion(self.names[k], kind, count, self._worst[kind][k], self._bound[kind][k])
            for kind in LimitKind
            for k, count in enumerate(self._count[kind])
            if count
        ]


def limit_excursions(
    scene: Scene,
    q: Sequence[Sequence[float]] | np.ndarray,
    qd: Sequence[Sequence[float]] | np.ndarray,
) -> list[LimitExcursion]:
    """The excursions of a run given as the model's absolute link angles and rates, one row
    per period (a recording's, ``tools/analysis``)."""
    watch = LimitWatch(scene)
    if watch.active:
        coordinates = scene.joint_coordinates
        for a, w in zip(q, qd):
            watch.add(coordinates.positions(a), coordinates.rates(w))
    return watch.found
