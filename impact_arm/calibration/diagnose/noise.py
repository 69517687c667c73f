"""Positions that scatter far more than the encoder's resolution (``POSITION_NOISE``): the
resolution read from the steps of the positions, the noise from the free flight."""

from __future__ import annotations

import numpy as np

from ..identify import IdentifyError, JointRecording, estimate_noise
from .findings import Finding, FindingKind

NOISE_PER_STEP = 3.0  # position noise (rms) beyond this many encoder steps is "far above"
# the smallest step of a joint may be several counts: a joint that never turns slower than
# a few counts per period (a fine encoder on a fast arm) never shows a single count
MAX_COUNTS_IN_SMALLEST_STEP = 1000


def encoder_resolution(rec: JointRecording) -> np.ndarray | None:
    """Per joint, the largest step of which every step of the positions is a whole number
    (an encoder's count), looked for among whole fractions of the smallest step; None when
    the positions are not on such a grid."""
    steps = np.diff(rec.position, axis=0)
    out = []
    for j in range(rec.n):
        d = np.abs(steps[:, j])
        d = d[d > 0]
        if len(d) < 10 or float(np.min(d)) > 0.1:
            return None
        count = _grid_step(d)
        if count is None:
            return None
        out.append(count)
    return np.array(out)


def _grid_step(d: np.ndarray) -> float | None:
    smallest = float(np.min(d))
    for k in range(1, MAX_COUNTS_IN_SMALLEST_STEP + 1):
        counts = d * (k / smallest)
        if np.max(np.abs(counts - np.round(counts))) <= 1e-4:
            return smallest / k
    return None


def check_position_noise(
    rec: JointRecording, impacts: list[int]
) -> tuple[Finding | None, float | None, str]:
    """(finding, worst noise / step, why not checked)."""
    steps = encoder_resolution(rec)
    if steps is None:
        return None, None, 'the positions are not on an encoder grid: resolution unknown'
    try:
        noise = estimate_noise(rec, impacts).position
    except IdentifyError as exc:
        return None, None, str(exc)
    ratio = noise / steps
    j = int(np.argmax(ratio))
    if ratio[j] <= NOISE_PER_STEP:
        return None, float(ratio[j]), ''
    name = rec.joints[j] if j < len(rec.joints) else f'joint {j + 1}'
    return (
        Finding(
            FindingKind.POSITION_NOISE,
            float(noise[j]),
            'rad',
            f'{name}: the positions scatter by {noise[j]:.3g} rad rms, {ratio[j]:.3g} times '
            f'the encoder resolution of {steps[j]:.3g} rad (one count)',
            'look for electrical noise, a loose coupling or backlash, or a position that is '
            "an estimate rather than the encoder's count; the fit weights the samples by "
            'this noise, so its intervals widen',
        ),
        float(ratio[j]),
        '',
    )
