"""What a cycle is (physics/cycle_count.py): CycleCount against transitions counted by hand."""

import numpy as np

from impact_arm.contract import CycleMode
from impact_arm.physics.cycle_count import CycleCount
from impact_arm.physics.integrator import Event
from impact_arm.physics.kinds import EventKind

D, U = CycleMode.DOWN, CycleMode.UP


def tell(count, halves, t0=0.0, dt=0.1):
    """Tell ``count`` the half at each of the consecutive samples ``halves``, the first at
    ``t0``, as the node tells it at each command (each change a switch)."""
    for k in range(1, len(halves)):
        count.turn(halves[k - 1], halves[k], t0 + k * dt)


def test_strikes_completed_cycles_and_the_down_half_start_by_hand():
    count = CycleCount()
    #        0  1  2  3  4  5  6  7  8  9 10 11
    halves = [D, D, U, U, U, D, D, U, D, U, U, D]
    tell(count, halves)
    # down to up at samples 2, 7, 9; up to down at 5, 8, 11 (the last down half's start)
    assert count.strikes == 3
    assert count.completed == 3
    assert count.down_half_start == 11 * 0.1
    assert not count.done  # no cycles asked for: never done


def test_nothing_happens_before_the_first_strike():
    count = CycleCount(1)
    tell(count, [D] * 5)
    assert (count.strikes, count.completed, count.down_half_start, count.done) == (0, 0, 0.0, False)


def test_the_half_as_text_counts_as_the_member():
    count = CycleCount()
    count.turn('down', U, 0.1)
    count.turn(CycleMode.UP, 'down', 0.2)
    count.turn('down', 'down', 0.3)  # no change
    assert (count.strikes, count.completed, count.down_half_start) == (1, 1, 0.2)


def test_done_at_the_cycles_asked_for_and_nothing_counts_after():
    count = CycleCount(2)
    tell(count, [D, U, D, U])  # struck twice, completed once (at sample 2)
    assert (count.strikes, count.completed, count.done) == (2, 1, False)
    assert count.down_half_start == 0.2
    count.turn(U, D, 0.4)  # the second completed: done, no down half of a third cycle begins
    assert count.done
    assert (count.strikes, count.completed, count.down_half_start) == (2, 2, 0.2)
    tell(count, [D, U, D], t0=0.4)  # what the run would do after: not counted
    assert (count.strikes, count.completed, count.down_half_start) == (2, 2, 0.2)


def test_a_rearm_begins_a_down_half_but_completes_no_cycle():
    count = CycleCount(1)
    count.turn(D, U, 0.1)
    count.turn(U, D, 0.05, rearmed=True)  # time went back: the cycle starts again
    assert (count.strikes, count.completed, count.down_half_start, count.done) == (
        1,
        0,
        0.05,
        False,
    )
    count.turn(D, U, 0.2)
    count.turn(U, D, 0.3)
    assert (count.strikes, count.completed, count.done) == (2, 1, True)
    assert count.down_half_start == 0.05  # done: no next down half


def test_an_unknown_time_keeps_the_down_half_start():
    count = CycleCount()
    count.turn(D, U, 0.1)
    count.turn(U, D, 0.2)
    count.turn(D, U, 0.3)
    count.turn(U, D, None)
    assert (count.strikes, count.completed, count.down_half_start) == (2, 2, 0.2)


def test_the_integrators_switch_completes_a_cycle_its_other_events_do_not():
    count = CycleCount(2)
    y = np.zeros(4)
    kinds = [
        EventKind.CONTACT,
        EventKind.MAX_COMPRESSION,
        EventKind.SEPARATION,
        EventKind.SWITCH,  # 0.4: the first cycle completed
        EventKind.CONTACT,
        EventKind.SEPARATION,
        EventKind.CONTACT,  # a bounce in the up half
        EventKind.SEPARATION,
    ]
    for k, kind in enumerate(kinds):
        count.on_event(Event(kind, (k + 1) * 0.1, 0, y))
    assert (count.completed, count.down_half_start, count.done) == (1, 0.4, False)
    count.on_event(Event(EventKind.SWITCH, 0.9, 0, y))
    assert (count.completed, count.done) == (2, True)
    # the event path counts completed cycles only: the kernel's own down-to-up is no event
    assert count.strikes == 0
