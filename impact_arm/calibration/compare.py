"""The impacts of two sources side by side: a recording's impacts as a scene reads them, a
scene's replays of them, one-to-one matching by time and the table of differences.

A scene "driven by the recording's efforts" replays each recorded impact from its recorded
pre-impact state (as the fit does): how a fitted scene is checked against a recording it was
not fitted on. Reading the recordings is the caller's (``impact_arm.compare`` reads them).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import math

import numpy as np

from ..physics.model import ArmModel
from .identify import JointRecording
from .study import Study

COLUMNS = ('t', 'impact_speed', 'cor', 'impulse_n', 'impulse_t', 'qd_after')


def recorded_impacts(
    rec: JointRecording, study: Study
) -> tuple[list[dict], list[tuple[Any, Any]], Any]:
    """Rows of the impacts of a recording; the scene gives the kinematics and the free flight
    that carries the first sample after an impact back to its separation (for the CoR).
    Returns (rows, (window, prediction) per impact, the ``RecordedImpacts``)."""
    from .fit import predict_impact, read_impacts, recorded_cor
    from .identify import joint_to_absolute_matrix, tip_normal_speed

    model = ArmModel(study.scene())
    impacts = read_impacts(rec, study)
    T = joint_to_absolute_matrix(rec.n)
    rows, preds = [], []
    for w in impacts.windows:
        p = predict_impact(model, w, impacts.timing)
        q, qd_pre, _ = w.pre.state(w.t_c)
        v_in = tip_normal_speed(model, T @ q, T @ qd_pre)
        imp = w.impulse if w.impulse is not None else [math.nan, math.nan]
        rows.append(
            {
                't': w.t_c,
                'impact_speed': -v_in,
                'cor': recorded_cor(model, w, p, impacts.timing, v_in),
                'impulse_n': float(imp[1]),
                'impulse_t': float(imp[0]),
                'qd_after': w.post_qd[0].tolist(),
            }
        )
        preds.append((w, p))
    return rows, preds, impacts


def replayed_impacts(preds: Sequence[tuple[Any, Any]], model: ArmModel) -> list[dict]:
    """Rows of the scene's predictions of each recorded impact (from the recorded state)."""
    from .identify import joint_to_absolute_matrix, tip_normal_speed

    rows = []
    for w, p in preds:
        if p.error:
            continue
        T = joint_to_absolute_matrix(model.n)
        q, qd_pre, _ = w.pre.state(w.t_c)
        rows.append(
            {
                't': w.t_c,
                'impact_speed': -tip_normal_speed(model, T @ q, T @ qd_pre),
                'cor': -p.v_out / p.v_in,
                'impulse_n': float(p.impulse[1]),
                'impulse_t': float(p.impulse[0]),
                'qd_after': p.qd[0].tolist(),
            }
        )
    return rows


def match(a_rows: Sequence[dict], b_rows: Sequence[dict]) -> list[tuple[int, int]]:
    """Pairs (i, j) one to one: times from each side's first impact, nearest first, within
    half the typical interval between impacts."""
    if not a_rows or not b_rows:
        return []
    ta = np.array([r['t'] for r in a_rows]) - a_rows[0]['t']
    tb = np.array([r['t'] for r in b_rows]) - b_rows[0]['t']
    gaps = np.diff(ta) if len(ta) > 1 else np.array([1.0])
    tol = 0.5 * float(np.median(gaps))
    pairs = sorted(
        ((abs(x - y), i, j) for i, x in enumerate(ta) for j, y in enumerate(tb) if abs(x - y) < tol)
    )
    used_a: set[int] = set()
    used_b: set[int] = set()
    out = []
    for _, i, j in pairs:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            out.append((i, j))
    return sorted(out)


def impact_table(a_rows: list[dict], b_rows: list[dict], what: str) -> dict:
    """The comparison of two sides' rows: {'a': rows, 'b': rows, 'pairs': [(i, j)], 'table':
    [...], 'what': text, 'unmatched_a', 'unmatched_b'} (written as ``table.json``)."""
    a_origin = a_rows[0]['t'] if a_rows else 0.0
    b_origin = b_rows[0]['t'] if b_rows else 0.0
    pairs = match(a_rows, b_rows)
    table = []
    for i, j in pairs:
        ra, rb = a_rows[i], b_rows[j]
        table.append(
            {
                'a_t': ra['t'] - a_origin,
                'b_t': rb['t'] - b_origin,
                **{
                    f'{k}_{side}': r[k]
                    for k in ('impact_speed', 'cor', 'impulse_n', 'impulse_t')
                    for side, r in (('a', ra), ('b', rb))
                },
                'qd_after_a': ra['qd_after'],
                'qd_after_b': rb['qd_after'],
                'd_cor': rb['cor'] - ra['cor'],
                'd_impulse_n': rb['impulse_n'] - ra['impulse_n'],
                'd_qd_after': (np.array(rb['qd_after']) - np.array(ra['qd_after'])).tolist(),
            }
        )
    return {
        'a': a_rows,
        'b': b_rows,
        'pairs': pairs,
        'table': table,
        'what': what,
        'unmatched_a': len(a_rows) - len(pairs),
        'unmatched_b': len(b_rows) - len(pairs),
    }
