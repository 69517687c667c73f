"""What ``analyze`` writes: the table, the sections, the figures and report.md."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from ...contract import IMPACT_REPORT, IMPACT_TRACE
from ..run_data import Run, _quiet
from ..step_responses import step_metrics
from .impacts import ImpactPoints, trace_missing_reason
from .sections import limit_cycle_text, impact_table, limit_cycle, poincare, tip_velocity

if TYPE_CHECKING:
    from ...physics.contact import ContactConstants
    from ...physics.replay import ElasticCurve
    from ..figures import Style


def no_impact_reason(run: Run) -> str:
    """Why a recording has no impact record: no /impact_report topic at all (a recording
    of joint states only), or the topic is there and the arm never struck."""
    if IMPACT_REPORT in run.topics or IMPACT_TRACE in run.topics:
        return f'the arm struck no surface ({IMPACT_REPORT} was recorded, with no message)'
    return f'it has no {IMPACT_REPORT} topic'


def no_impact_figures(run: Run, path: str) -> str:
    if not run.impacts and not run.traces and IMPACT_REPORT in run.topics:
        return f'Figures 8-11 not drawn: {path} has no impact to show (the arm struck no surface)'
    return (
        f'Figures 8-11 not drawn: {path} has no /impact_trace, and '
        f'{trace_missing_reason(run)}, so the impact cannot be integrated again. '
        f'Record with the trace: impact-arm simulate --scene SCENE --mcap FILE'
    )


def _write(path, text):
    tmp = path + '.tmp'
    with open(tmp, 'w', encoding='utf-8') as f:
        f.write(text)
    os.replace(tmp, path)


def write_outputs(
    run: Run,
    steps: Sequence[Run],
    out: str,
    impact: ImpactPoints | None,
    figures: ModuleType,
    progress: Callable[[str], Any] = _quiet,
    recordings: Sequence[Run] = (),
    constants: ContactConstants | None = None,
    missing: Sequence[str] = (),
    style: Style | None = None,
    elastic: ElasticCurve | None = None,
) -> dict:
    """Tables, CSVs, figures and report.md in ``out``; returns what was written."""
    table = impact_table(run.impacts)
    lc = limit_cycle(run.impacts)
    _write(
        os.path.join(out, 'impacts.json'),
        json.dumps({'impacts': [i.to_dict() for i in run.impacts]}, indent=1),
    )
    _write(os.path.join(out, 'impact_table.txt'), table + '\n')
    sections = {}
    links = range(run.q.shape[1])
    for k in links:  # q̇k = 0 for every link, with every link's angle
        rows = poincare(run.t, run.q, run.qd, k)
        sections[k] = rows
        lines = ['t_s,' + ''.join(f'q{j + 1}_deg,' for j in links) + 'direction'] + [
            f'{r[0]:.9g},' + ''.join(f'{math.degrees(v):.9g},' for v in r[1:-1]) + f'{int(r[-1])}'
            for r in rows
        ]
        _write(os.path.join(out, f'poincare_qd{k + 1}_zero.csv'), '\n'.join(lines) + '\n')
    v_tip = tip_velocity(run)
    made = figures.draw_all(
        run,
        steps,
        sections,
        v_tip,
        impact,
        out,
        progress=progress,
        recordings=recordings,
        constants=constants,
        style=style,
        elastic=elastic,
    )
    _write(
        os.path.join(out, 'report.md'),
        report(run, recordings, table, lc, sections, made, steps, missing),
    )
    return {'table': table, 'limit_cycle': lc, 'figures': made, 'sections': sections}


def recording_origin(info: dict) -> str:
    """Who recorded the file and how: 'offline run, simulate --mcap' for an offline file
    (its node and mode are both 'offline'), else 'NODE, MODE'."""
    node, mode = info.get('node', '?'), info.get('mode', 'live')
    if node == 'offline':
        return 'offline run, impact-arm simulate --mcap'
    return f'{node}, {mode}' if mode != node else node


def _figure_named(made, stem) -> str:
    return next((name for name, _ in made if name.startswith(stem + '.')), stem + '.png')


def report(
    run: Run,
    others: Sequence[Run],
    table: str,
    lc: dict,
    sections: dict[int, np.ndarray],
    made: Sequence[tuple[str, str]],
    steps: Sequence[Run] = (),
    missing: Sequence[str] = (),
) -> str:
    info = run.metadata.get('impact_arm', {})
    nonfinite = int(np.count_nonzero(~np.isfinite(run.q)) + np.count_nonzero(~np.isfinite(run.qd)))
    lines = [
        f'# Analysis of {run.label}',
        '',
        f'Recorded by impact_arm {info.get("version", "?")} ({recording_origin(info)}); scene '
        f'{run.scene.name if run.scene is not None else "not stored"}'
        f'{", law " + run.law if run.law else ""}; {len(run.t)} joint states over '
        f'{run.t[-1] - run.t[0]:.4f} s, {len(run.impacts)} impact reports, '
        f'{len(run.traces)} impact traces.',
        '',
    ]
    if nonfinite:
        lines += [f'**Warning:** {nonfinite} non-finite joint values in /joint_states.', '']
    if run.metadata.get('run', {}).get('error'):
        lines += [f'**The run stopped with an error:** {run.metadata["run"]["error"]}', '']
    lines += [
        '## Impacts',
        '',
        'Units: t [s], angles [deg], duration [µs], δm and δr [µm], '
        'F_max [kN], velocities [m/s], energies [J]; the same table as '
        '`impact-arm simulate` (all fields in `impacts.json`).',
        '',
        '```',
        table,
        '```',
        '',
        '## Limit cycle',
        '',
        limit_cycle_text(lc) + '.',
        '',
    ]
    if lc['periods']:
        lines += ['Times between impacts [s]: ' + ', '.join(f'{p:.5f}' for p in lc['periods']), '']
    lines += ['## Poincaré sections', '']
    for k, rows in sections.items():
        lines.append(
            f'- q̇{k + 1} = 0: {len(rows)} crossings (`poincare_qd{k + 1}_zero.csv`)'
            + (
                '; last: '
                + ', '.join(
                    f'q{j + 1} = {math.degrees(v):.3f}°' for j, v in enumerate(rows[-1][1:-1])
                )
                if len(rows)
                else ''
            )
        )
    lines += ['', '## Figures', '']
    for name, caption in made:
        lines += [f'![{caption}]({name})', '', f'*{caption}*', '']
    if steps:
        lines += [
            'Figure 3 (step responses without impact, settling = staying within 0.1° '
            'of the target):',
            '',
        ]
        for step in steps:
            for k, m in enumerate(step_metrics(step)):
                settle = (
                    f'settles at {m["settle_s"]:.3f} s'
                    if math.isfinite(m['settle_s'])
                    else f'does not settle within {step.t[-1]:g} s'
                )
                lines.append(
                    f'- {step.label}, link {k + 1}: {m["overshoot_deg"]:.3f}° past '
                    f'the target at most, error at the end '
                    f'{round(m["final_error_deg"], 3) + 0.0:+.3f}°, {settle}'
                )
        lines.append('')
    for line in missing:
        lines += [f'**{line}**', '']
    if others:
        lines += [
            f'Recordings compared ({_figure_named(made, "fig3b_recordings")}): '
            + ', '.join([run.label] + [o.label for o in others])
            + '.',
            '',
        ]
    return '\n'.join(lines)
