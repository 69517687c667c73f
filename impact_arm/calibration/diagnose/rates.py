"""Joint rates that are no measured rates: exact finite differences of the positions
(``DIFFERENCE_RATES``) or those differences through a first-order low-pass
(``FILTERED_RATES``); the rates at the stamps computed from the positions."""

from __future__ import annotations

import math

import numpy as np

from ..identify import JointRecording
from .findings import Finding, FindingKind
from .stamps import consecutive

# relative agreement of a rate with a finite difference that no measured rate reaches by
# chance (the difference and the rate at the stamp differ by ~ period x acceleration)
DIFFERENCE_TOLERANCE = 1e-9
DIFFERENCE_SHARE = 0.9  # of the moving samples


def check_difference_rates(rec: JointRecording) -> Finding | None:
    """Rates equal to (q[k] - q[k-1]) / period (or the stamps' difference), or to central
    differences, at nearly every sample where the arm moves."""
    k, period = consecutive(rec)
    k = k[(k >= 1) & (k < len(rec.t) - 1)]
    q, v, t = rec.position, rec.velocity, rec.t
    moving = np.any(q[k] != q[k - 1], axis=1)
    k = k[moving]
    if len(k) < 20:
        return None
    scale = np.maximum(np.abs(v[k]), 1e-12)
    candidates = {
        'backward': ((q[k] - q[k - 1]) / period, (q[k] - q[k - 1]) / (t[k] - t[k - 1])[:, None]),
        'central': (
            (q[k + 1] - q[k - 1]) / (2 * period),
            (q[k + 1] - q[k - 1]) / (t[k + 1] - t[k - 1])[:, None],
        ),
    }
    for name, guesses in candidates.items():
        share = max(
            float(np.mean(np.all(np.abs(g - v[k]) <= DIFFERENCE_TOLERANCE * scale, axis=1)))
            for g in guesses
        )
        if share >= DIFFERENCE_SHARE:
            lag = ' half a period late and' if name == 'backward' else ''
            return Finding(
                FindingKind.DIFFERENCE_RATES,
                share,
                '-',
                f'the joint rates are exact {name} differences of the positions at '
                f'{share:.0%} of the moving samples: each is the mean rate over '
                f'{"the period before" if name == "backward" else "two periods around"} '
                f'its stamp,{lag} smeared across an impact, not a measured rate',
                "record the drive's own velocity if it has one"
                + (
                    ', or fit with --difference-rates (each rate read as the mean over its period)'
                    if name == 'backward'
                    else ''
                )
                + '; contact parameters fitted from these rates as measured ones are biased',
            )
    return None


def check_filtered_rates(rec: JointRecording) -> Finding | None:
    """Rates that are the backward differences d[k] = (q[k] - q[k-1]) / period through a
    discrete first-order low-pass, v[k] = v[k-1] + alpha (d[k] - v[k-1]), with one alpha
    (0 < alpha < 1) at nearly every sample where the arm moves."""
    k, period = consecutive(rec)
    k = k[k >= 1]
    q, v = rec.position, rec.velocity
    x = (q[k] - q[k - 1]) / period - v[k - 1]
    y = v[k] - v[k - 1]
    moving = np.any(x != 0, axis=1)
    x, y = x[moving], y[moving]
    if len(x) < 20 or not np.any(x):
        return None
    alpha = float(np.sum(x * y) / np.sum(x * x))
    if not 0.0 < alpha < 1.0 - 1e-9:
        return None
    scale = np.abs(v[k][moving]) + np.abs(x) + 1e-12
    share = float(
        np.mean(np.all(np.abs(y - alpha * x) <= 1e3 * DIFFERENCE_TOLERANCE * scale, axis=1))
    )
    if share < DIFFERENCE_SHARE:
        return None
    cutoff = -math.log(1.0 - alpha) / (2.0 * math.pi * period)
    return Finding(
        FindingKind.FILTERED_RATES,
        cutoff,
        'Hz',
        f'the joint rates are backward differences of the positions through a first-order '
        f'low-pass (cut-off {cutoff:.4g} Hz, alpha {alpha:.4g}) at {share:.0%} of the moving '
        f'samples: late and smoothed across every impact, not a measured rate',
        "record the drive's own velocity if it has one, or fit with --difference-rates (the "
        'rates recomputed from the positions and read as mean rates over their periods); '
        'contact parameters fitted from these rates as measured ones are biased',
    )


def central_rates(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The rate at each stamp from the positions: the derivative of the parabola through the
    sample and its two neighbours (central difference on any stamps; one-sided at the ends)."""
    return np.gradient(q, t, axis=0, edge_order=2)


def _parabola_at(t: np.ndarray, q: np.ndarray, nodes: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Per row i, the parabola through the samples ``nodes[i]`` (three indices) at ``at[i]``
    (Lagrange's form)."""
    x = t[nodes]
    w = np.empty_like(x)
    for j in range(3):
        o1, o2 = (j + 1) % 3, (j + 2) % 3
        w[:, j] = (at - x[:, o1]) * (at - x[:, o2]) / ((x[:, j] - x[:, o1]) * (x[:, j] - x[:, o2]))
    return np.einsum('ij,ijk->ik', w, q[nodes])
