"""Which periods' states the topic hardware is not sent (driver/state_gaps.py)."""

import pytest

from impact_arm.driver.state_gaps import StateGaps


def gaps(every, quiet, contact):
    """The periods (0-based) left out, given each period's contact."""
    g = StateGaps(every, quiet)
    return [k for k, touching in enumerate(contact) if g.leave_out(touching)], g


def test_one_period_in_every_is_left_out_in_free_flight():
    left, g = gaps(7, 50, [False] * 100)
    assert left == [6, 13, 20, 27, 34, 41, 48, 55, 62, 69, 76, 83, 90, 97]
    assert g.left_out == len(left) and g.postponed == 0


def test_none_in_contact_nor_in_its_rebound_and_the_gap_due_comes_after():
    contact = [False] * 30 + [True] * 5 + [False] * 65  # contact in periods 30..34
    left, g = gaps(10, 20, contact)
    assert not [k for k in left if 30 <= k <= 34 + 20]
    # due at 39 (in contact's rebound): postponed to the first period after it, then every 10
    assert left == [9, 19, 29, 55, 65, 75, 85, 95]
    assert g.postponed == 1


def test_zero_leaves_nothing_out_and_bad_values_are_refused_by_name():
    assert gaps(0, 50, [False] * 100)[0] == []
    with pytest.raises(ValueError, match='every = -1'):
        StateGaps(-1, 0)
    with pytest.raises(ValueError, match='quiet = -2'):
        StateGaps(20, -2)
