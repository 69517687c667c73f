"""Impacts whose residual is an outlier: far beyond its own chi-square's tail and beyond what
the other impacts leave (when the scene misfits every impact alike, no single one is
singled out)."""

from __future__ import annotations

from collections.abc import Sequence

import math
from dataclasses import dataclass

import numpy as np

OUTLIER_LEVEL = 1e-3  # an impact's chi-square tail, Bonferroni-corrected over the impacts
OUTLIER_RATIO = 4.0  # ... and its chi-square per output beyond this times the median impact's
MAX_SHARE = 0.1  # at most this share of the impacts (at least one) is called an outlier


@dataclass
class Outlier:
    number: int  # 1-based, in the per-impact table
    t: float  # contact time [s]
    chi2: float
    outputs: int
    p_value: float

    def sentence(self) -> str:
        return (
            f'impact {self.number} at t = {self.t:.4f} s is an outlier (chi2 = {self.chi2:.4g} '
            f'over its {self.outputs} outputs, p = {self.p_value:.2g})'
        )


def find_outliers(per_impact: Sequence[dict]) -> list[Outlier]:
    """The outlier impacts of a fit, worst first."""
    # scipy.special, not scipy.stats: the same tail, without seconds of import in a fresh
    # process
    from scipy.special import chdtrc

    rows = [(k, r) for k, r in enumerate(per_impact) if not r.get('error') and r.get('whitened')]
    if len(rows) < 5:
        return []
    q = np.array([float(np.sum(np.square(r['whitened']))) for _, r in rows])
    dof = np.array([len(r['whitened']) for _, r in rows])
    typical = float(np.median(q / dof))
    level = OUTLIER_LEVEL / len(rows)
    found = []
    for (k, r), qi, di in zip(rows, q, dof):
        p = float(chdtrc(di, qi))
        if p < level and qi / di > OUTLIER_RATIO * max(typical, 1.0):
            found.append(Outlier(k + 1, float(r['t']), float(qi), int(di), p))
    found.sort(key=lambda o: o.p_value)
    return found[: max(1, math.floor(MAX_SHARE * len(rows)))]
