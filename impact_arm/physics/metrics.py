"""Impact metrics (docs/model.md): assembled from the integrator's located events, so every number
comes from the state at an exactly located phase switch, not from a sampled signal."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import math
from dataclasses import dataclass

import numpy as np

from .impact import Impact
from .model import ArmModel

if TYPE_CHECKING:
    from .integrator import Event

PHASE_ORDER = ('contact', 'yield', 'max_compression', 'separation')


class ImpactBuilder:
    """Feed it events in order; it emits one ``Impact`` per completed impact and checks
    that no phase is skipped or repeated."""

    def __init__(self, model: ArmModel) -> None:
        self.model = model
        self.impacts: list[Impact] = []
        self._open: dict[str, Any] | None = None
        # the generated functions' Python originals: two calls per impact cost ~10 us each
        # this way, while their compiled versions would be compiled (a new arm shape: ~1 s
        # each) or loaded (every process: milliseconds) for these calls alone
        eq = model.eq
        self._tip = getattr(eq.tip, 'py_func', eq.tip)
        self._energies = getattr(eq.link_energies, 'py_func', eq.link_energies)
        self._rotors = bool(model.armature.any())

    def _tip_and_energy(self, y):
        y = np.asarray(y, dtype=float)
        model = self.model
        n = model.n
        q, qd = y[:n], y[n : 2 * n]
        _, _, vx, vy = self._tip(q, qd, model.geometry)
        parts = [float(T) for T in self._energies(q, qd, model.geometry, model.m)]
        if self._rotors:  # a joint's rotor turns with its link (numpy: only when there is one)
            parts = [T + float(J) for T, J in zip(parts, model.rotor_energies(qd))]
        return q.tolist(), (float(vx), float(vy)), parts + [math.fsum(parts)]

    def feed(self, event: Event) -> Impact | None:
        """Returns the finished impact record when ``event`` completes one, else None."""
        kind = event.kind
        if kind not in PHASE_ORDER:
            return None
        if kind == 'contact':
            if self._open is not None:
                raise RuntimeError(f'contact at t = {event.t:.9g} s inside an open impact')
            q, v, T = self._tip_and_energy(event.y)
            self._open = {
                't_contact': event.t,
                'q': q,
                'v_before': v,
                'T_before': T,
                'times': {'contact': event.t},
                'surface': event.surface,
            }
            return None
        impact = self._open
        if impact is None or kind in impact['times']:
            raise RuntimeError(
                f'{kind} at t = {event.t:.9g} s out of order (phase repeated or no contact)'
            )
        impact['times'][kind] = event.t
        impact.update(event.info)
        if kind == 'max_compression':  # where a viewer draws the impact (io/scene_visuals)
            impact['q_max'] = np.asarray(event.y[: self.model.n], dtype=float).tolist()
        if kind != 'separation':
            return None
        self._open = None
        record = self._finish(impact, event)
        self.impacts.append(record)
        return record

    def _finish(self, impact: dict[str, Any], event: Event) -> Impact:
        _, v_after, T_after = self._tip_and_energy(event.y)
        times = impact['times']
        t0, t_sep = times['contact'], times['separation']
        t_max = times['max_compression']
        t_yield = times.get('yield', t_max)  # Hertz-only or gentle: no elasto-plastic phase
        v_before, T_before = impact['v_before'], impact['T_before']
        return Impact(
            index=len(self.impacts) + 1,
            t_contact=t0,
            q_contact_deg=tuple(math.degrees(a) for a in impact['q']),
            # the robot's joint angles (its URDF's zero and sign; relative angles for rods)
            joints_contact_deg=tuple(
                math.degrees(a) for a in self.model.scene.joint_coordinates.positions(impact['q'])
            ),
            duration=t_sep - t0,
            delta_m=impact['delta_m'],
            delta_r=impact['delta_r'],
            F_max=impact['F_max'],
            v_before=(v_before[0], v_before[1]),
            v_after=(v_after[0], v_after[1]),
            cor_kinematic=-v_after[1] / v_before[1] if v_before[1] else math.nan,
            T_before=tuple(T_before),
            T_after=tuple(T_after),
            cor_energetic=tuple(
                math.sqrt(a / b) if b > 0 else math.nan for a, b in zip(T_after, T_before)
            ),
            phase_durations=(t_yield - t0, t_max - t_yield, t_sep - t_max),
            q_max_compression_deg=tuple(math.degrees(a) for a in impact['q_max']),
            q_separation_deg=tuple(math.degrees(a) for a in event.y[: self.model.n]),
        )


def settle_index(
    impacts: Sequence[Impact],
    rel_tol: float = 1e-3,
    keys: Sequence[str] = ('q_contact_deg', 'v_before'),
    every: int = 1,
) -> int | None:
    """The number N of the impact (1-based) from which every later impact repeats the one
    ``every`` impacts before it (its predecessor by default) in contact angles and
    velocities to ``rel_tol``: the limit cycle is reached after N impacts. None if the run
    never settles so (or has too few impacts to show one whole repetition). ``keys`` name
    the compared fields of ``Impact`` (sequences of numbers)."""

    def close(a: Impact, b: Impact) -> bool:
        for key in keys:
            for x, y in zip(getattr(a, key), getattr(b, key)):
                if abs(x - y) > rel_tol * max(1.0, abs(y)):
                    return False
        return True

    # one pass from the end: the earliest k from which every pair still repeats
    settled = len(impacts)
    for j in range(len(impacts) - 1, every - 1, -1):
        if not close(impacts[j], impacts[j - every]):
            break
        settled = j - every + 1
    # at least one whole cycle seen repeating: ``every`` pairs
    return settled if settled <= len(impacts) - 2 * every + 1 else None


@dataclass(frozen=True)
class LimitCycle:
    """Where a run's impacts start repeating: after ``settled_after`` impacts, with
    ``impacts_per_cycle`` impacts per repetition (1 for the article's arm; 2 for an arm that
    strikes, rebounds and strikes again in each cycle)."""

    settled_after: int
    impacts_per_cycle: int

    def period(self, impacts: Sequence[Impact]) -> float:
        """The duration of one repetition, the mean over the settled part."""
        times = [i.t_contact for i in impacts[self.settled_after - 1 :]]
        every = self.impacts_per_cycle
        spans = [b - a for a, b in zip(times, times[every:])]
        return sum(spans) / len(spans)

    def text(self) -> str:
        per = f' ({self.impacts_per_cycle} impacts per cycle)' if self.impacts_per_cycle > 1 else ''
        return f'reached after {self.settled_after} impacts{per}'


# a strike and its rebounds: beyond a few, a run that has not settled would be read as a
# long cycle that happens to repeat within the tolerance
MOST_IMPACTS_PER_CYCLE = 4


def limit_cycle(impacts: Sequence[Impact], rel_tol: float = 1e-3) -> LimitCycle | None:
    """The limit cycle with the fewest impacts per repetition (up to
    ``MOST_IMPACTS_PER_CYCLE``) the run settles into, or None."""
    for every in range(1, MOST_IMPACTS_PER_CYCLE + 1):
        settled = settle_index(impacts, rel_tol, every=every)
        if settled is not None:
            return LimitCycle(settled, every)
    return None
