"""The limit cycle, Poincaré sections, the impact table and the tip velocity of a run."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...physics.impact import Impact
from ...physics.metrics import LimitCycle
from ...physics.metrics import limit_cycle as find_limit_cycle
from ..run_data import Run


def poincare(t: np.ndarray, q: np.ndarray, qd: np.ndarray, k: int) -> np.ndarray:
    """Rows (t, q1, ..., qn, direction) where q̇_k crosses zero (linear interpolation
    between samples; direction +1 rising, -1 falling): every link's angle, the article's
    (t, q1, q2, direction) for two links. Samples with a non-finite rate are skipped."""
    v = qd[:, k]
    a, b = v[:-1], v[1:]
    ok = np.isfinite(a) & np.isfinite(b)
    idx = np.nonzero(ok & (((a < 0) & (b >= 0)) | ((a > 0) & (b <= 0))))[0]
    rows = []
    for i in idx:
        s = a[i] / (a[i] - b[i])
        rows.append(
            [
                t[i] + s * (t[i + 1] - t[i]),
                *(q[i] + s * (q[i + 1] - q[i])),
                1.0 if b[i] > a[i] else -1.0,
            ]
        )
    return np.array(rows).reshape(-1, q.shape[1] + 2)


def limit_cycle(impacts: Sequence[Impact]) -> dict:
    """Impacts until the motion repeats itself (``metrics.limit_cycle``: every impact, or
    every second one for an arm that strikes twice per cycle, ...) and the period: one
    repetition's duration."""
    times = [i.t_contact for i in impacts]
    periods = np.diff(times)
    cycle = find_limit_cycle(impacts)
    if cycle is not None:
        period: float | None = cycle.period(impacts)
    else:
        period = float(periods[-1]) if len(periods) else None
    return {
        'impacts': len(impacts),
        'settled_after': cycle.settled_after if cycle else None,
        'impacts_per_cycle': cycle.impacts_per_cycle if cycle else None,
        'period': period,
        'period_last': float(periods[-1]) if len(periods) else None,
        'periods': [float(p) for p in periods],
    }


def impact_table(impacts: Sequence[Impact]) -> str:
    """The impact rows exactly as ``impact-arm simulate`` prints them."""
    from ...physics.simulate import impact_rows

    return impact_rows(impacts)


def tip_velocity(run: Run) -> np.ndarray | None:
    """(N, 2) tip velocity (vx, vy) from the joint states and the link lengths of the stored
    scene (absolute angles from the x axis: v = Σ L_i q̇_i (−sin q_i, cos q_i)), or None."""
    if run.scene is None or len(run.scene.lengths) != run.q.shape[1]:
        return None
    L = np.asarray(run.scene.lengths, dtype=np.float64)
    if run.scene.general_links:  # the tip B off the last link's end: its point's velocity
        along, across = run.scene.contact_point
        q, w = run.q[:, -1], run.qd[:, -1]
        vx = -(L[:-1] * np.sin(run.q[:, :-1]) * run.qd[:, :-1]).sum(axis=1)
        vy = (L[:-1] * np.cos(run.q[:, :-1]) * run.qd[:, :-1]).sum(axis=1)
        vx -= (along * np.sin(q) + across * np.cos(q)) * w
        vy += (along * np.cos(q) - across * np.sin(q)) * w
        return np.stack([vx, vy], axis=1)
    vx = -(L * np.sin(run.q) * run.qd).sum(axis=1)
    vy = (L * np.cos(run.q) * run.qd).sum(axis=1)
    return np.stack([vx, vy], axis=1)


def limit_cycle_text(lc: dict) -> str:
    if not lc['impacts']:
        return 'no impacts recorded'
    per = lc.get('impacts_per_cycle') or 1
    settled = 'limit cycle ' + (
        LimitCycle(lc['settled_after'], per).text() if lc['settled_after'] else 'not reached'
    )
    period = f'period {lc["period"]:.5f} s' if lc['period'] is not None else 'no period'
    return f'{lc["impacts"]} impacts; {settled}; {period}'
