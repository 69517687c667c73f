"""What a cycle of the down/up striking cycle is, counted in one place, free of ROS: the
controller node and the offline runs (sampled control, the event path, the scipy baseline,
the synthetic driver recording) tell a ``CycleCount`` each change of the cycle's half and
ask it what ran.

A cycle begins with its down half. Down→up is its strike: the impact that ended the down half
(however often the arm bounces in the up half, the cycle is struck once). Up→down by a switch
(the tip back through ``switch_height``) completes it, and the next cycle's down half begins
there. A re-arm that restarts the cycle from its down half (time went back: the arm was
reset) begins a down half but completes no cycle.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..contract import CycleMode
from .kinds import EventKind

if TYPE_CHECKING:
    from .integrator import Event


class CycleCount:
    """The cycles of one run, told each change of the cycle's half (``turn``, or ``on_event``
    for the integrator's located switch): the cycles struck and completed, where the latest
    down half began and whether the ``cycles`` asked for are done (0: never). Once they are
    done no change counts: not one period of the next cycle runs."""

    def __init__(self, cycles: int = 0) -> None:
        self.cycles = cycles  # the cycles after which the run ends (0: it never ends by them)
        self.strikes = 0  # cycles whose down half an impact ended (down→up)
        self.completed = 0  # cycles whose up half ended (up→down by a switch)
        # the time at which the latest down half began [s]: the first's is the start, 0
        self.down_half_start = 0.0

    @property
    def done(self) -> bool:
        """Whether the cycles asked for are completed (never with ``cycles`` 0)."""
        return bool(self.cycles) and self.completed >= self.cycles

    def turn(
        self,
        before: CycleMode | str,
        after: CycleMode | str,
        t: float | None = None,
        *,
        rearmed: bool = False,
    ) -> None:
        """The cycle's half went from ``before`` to ``after`` (the same: nothing happened) at
        time ``t`` [s] (None: unknown, the latest down half's start is kept). ``rearmed``:
        the change is a re-arm's, not a switch: up→down then begins a down half without
        completing a cycle. A change that completes the cycles asked for begins no down half
        (the run ends there: its start stays the previous one's)."""
        if before == after or self.done:
            return
        if after == CycleMode.UP:
            self.strikes += 1
            return
        if not rearmed:
            self.completed += 1
            if self.done:
                return
        if t is not None:
            self.down_half_start = t

    def on_event(self, event: Event) -> None:
        """A located event of the integrator: with continuous control its ``switch`` is the
        cycle's up→down (the kernel's own down→up at a contact is not reported as an event
        kind of its own: the offline runs count completed cycles only)."""
        if event.kind == EventKind.SWITCH:
            self.turn(CycleMode.UP, CycleMode.DOWN, event.t)
