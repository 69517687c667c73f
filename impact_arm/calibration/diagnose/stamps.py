"""The recording's clock: which samples follow their predecessor by one period, and stamps
that scatter about a regular grid the values follow (``STAMP_JITTER``)."""

from __future__ import annotations

import math
from enum import Enum

import numpy as np

from ..identify import JointRecording
from .findings import Finding, FindingKind

# stamp jitter reported above this share of the period (rms) and this absolute floor
JITTER_SHARE = 0.01
JITTER_FLOOR = 1e-6  # s


def consecutive(rec: JointRecording) -> tuple[np.ndarray, float]:
    """Indices k of the samples that follow their predecessor by one period (no sample lost
    between), and the period."""
    dt = np.diff(rec.t)
    period = float(np.median(dt))
    return np.flatnonzero((dt > 0.5 * period) & (dt < 1.5 * period)) + 1, period


class SampleTimes(str, Enum):
    """What the values of a recording follow in time."""

    GRID = 'grid'  # a regular grid: the stamps' scatter is the stamps' own error
    STAMPS = 'stamps'  # the stamps: irregular sampling, truly stamped
    EITHER = 'either'  # the data cannot tell (noise above what the jitter moves)


def stamp_jitter(rec: JointRecording) -> tuple[float, SampleTimes]:
    """(rms of the stamps about a regular grid [s], what the values follow). The values
    follow the grid when the positions advance by the rates times the period rather than
    times the stamps' difference."""
    k, period = consecutive(rec)
    dev = np.diff(rec.t)[k - 1] - period
    # difference of two stamps' errors: sqrt(2) times one stamp's
    jitter = float(np.sqrt(np.mean(dev**2)) / math.sqrt(2)) if len(k) else 0.0
    dq = rec.position[k] - rec.position[k - 1]
    mean_rate = 0.5 * (rec.velocity[k] + rec.velocity[k - 1])
    dt = np.diff(rec.t)[k - 1][:, None]
    e_stamps = float(np.sum((dq - mean_rate * dt) ** 2))
    e_grid = float(np.sum((dq - mean_rate * period) ** 2))
    if e_grid < 0.5 * e_stamps:
        return jitter, SampleTimes.GRID
    return jitter, SampleTimes.STAMPS if e_stamps < 0.5 * e_grid else SampleTimes.EITHER


def check_stamp_jitter(rec: JointRecording) -> tuple[Finding | None, float]:
    jitter, follows = stamp_jitter(rec)
    period = rec.period
    if jitter <= max(JITTER_SHARE * period, JITTER_FLOOR) or follows is SampleTimes.STAMPS:
        # a regular clock, or irregular sampling stamped truly: nothing to correct
        return None, jitter
    values = (
        'the positions advance with the regular period, not with the stamps'
        if follows is SampleTimes.GRID
        else 'the data cannot tell whether the values follow the stamps or a regular grid'
    )
    return (
        Finding(
            FindingKind.STAMP_JITTER,
            jitter,
            's',
            f'the stamps scatter by {jitter * 1e6:.3g} us rms ({jitter / period:.1%} of the '
            f'{period * 1e3:.4g} ms period) about a regular grid, and {values}',
            "stamp the samples where they are taken (the driver's header stamp or its "
            'sample counter), or fit with --regular-stamps',
        ),
        jitter,
    )
