"""Which periods' states a driver stack that reads one queued state per update is not sent.

TopicBasedSystem (topic_based_ros2_control 0.3) takes one state per update, the oldest
queued: a state delivered after the read it was meant for stays queued, and every later
read is a period late, until an update finds no new state (docs/ros2_control.md, "The queue
of states"). Leaving out one period's state in ``every`` drains that queue. An update that
finds it empty repeats its previous state instead; the controller computes that update's
command on its latest state predicted a period further (before it did, it held its previous
command a period longer, which in an impact's rebound can turn the arm back into the
surface: docs/benchmarks.md, "The queue of states"). Its prediction does not model the
contact, so no state is left out while the arm is in contact nor for ``quiet`` periods
after: the gap that falls due then waits until they have passed.
"""

from __future__ import annotations

# the rebound after an impact, in which a command held a period longer can turn the arm
# back into the surface (the controller's implicit window is as long)
REBOUND_QUIET_S = 0.05


class StateGaps:
    """``leave_out(in_contact)``, once per period: whether this period's state is left out.
    ``every`` = 0: never."""

    def __init__(self, every: int, quiet: int) -> None:
        if every < 0:
            raise ValueError(f'every = {every}: must be >= 0 (0: no gaps)')
        if quiet < 0:
            raise ValueError(f'quiet = {quiet}: must be >= 0')
        self.every = every
        self.quiet = quiet
        self._until_gap = every
        self._quiet_left = 0
        self.left_out = 0  # periods left out so far
        self.postponed = 0  # gaps that fell due in contact or in a rebound

    def leave_out(self, in_contact: bool) -> bool:
        if not self.every:
            return False
        quiet = in_contact or self._quiet_left > 0
        if in_contact:
            self._quiet_left = self.quiet
        elif self._quiet_left:
            self._quiet_left -= 1
        if self._until_gap > 1:
            self._until_gap -= 1
            return False
        if quiet:
            if self._until_gap == 1:
                self.postponed += 1
                self._until_gap = 0  # due: the first period after the quiet
            return False
        self._until_gap = self.every
        self.left_out += 1
        return True
