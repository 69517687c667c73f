"""``impact-arm analyze FILE.mcap [--out DIR]``: impact table, limit cycle, Poincaré sections,
the article's figures and a markdown report, from a recording alone (no rclpy; CDR is decoded
by ``rosbags``' typestore for ROS 2 Kilted: speed does not matter here, and it is the
reference decoder the tests already trust; ``io/wire.py`` stays the hot path's codec).

What is read (docs/topics.md): ``/joint_states`` (relative joint angles → absolute link angles
q1, q2 = joint1 + joint2 and their rates; time = header stamp), ``/impact_report`` (one JSON
impact record each: the table is exactly the one ``simulate`` prints), ``/impact_trace``
(full-resolution points inside each impact: Figures 8–11), and the scene stored in the file
(link lengths for the tip velocity of Figure 7, the controller law for Figure 3).

Outputs in DIR (default: ``runs/<FILE name without .mcap>_analysis``): ``report.md``,
``impacts.json`` (``{"impacts": [...]}``, the records as published), ``impact_table.txt``,
``poincare_qd1_zero.csv`` … ``poincare_qdN_zero.csv`` (one per link) and the figures
``fig3_controllers.png`` … ``fig11_kinetic_energy.png`` (``figures.FIGURE_SIZE`` pixels
each; ``--format svg|pdf``, ``--dpi``). The impact table and the limit cycle are printed
before any figure is drawn; the animation is a step of its own (``impact-arm animate``, or
``--animation``). Figure 3 is the article's comparison of the control laws (``--laws``,
default q, pd, pid): step responses of the file's scene with its surface taken away,
simulated offline. Figures 8-11 come from ``/impact_trace`` (offline recordings) or, in a
live recording, from the impact integrated again from its ``/impact_report`` contact state
(exact when the actuators are off during contact, as in the article; beyond two links the
joint rates at contact are those that give the reported tip velocity and link energies);
when neither is possible the command says why. Figures 4-6 and 11 draw every link of the
arm.
"""

from __future__ import annotations

import json
import math
import os
from typing import TYPE_CHECKING

import numpy as np

from ..contract import FEEDBACK_LAWS, IMPACT_REPORT, IMPACT_TRACE
from ..physics.metrics import LimitCycle
from ..physics.metrics import limit_cycle as find_limit_cycle
from .run_data import AnalysisError, Run, _quiet, chatter, load
from .step_responses import STEP_LAWS, step_metrics, step_response

if TYPE_CHECKING:
    from ..physics.replay import ElasticCurve


# ------------------------------------------------------------------ impacts of live files
def trace_missing_reason(run: Run) -> str:
    """Why impact ``k``'s points cannot be re-integrated from /impact_report ('' if they
    can): the re-integration starts from the reported contact state and needs the scene."""
    if not run.impacts:
        return 'the recording has no /impact_report'
    if run.scene is None:
        return 'the recording stores no scene'
    if run.scene.n_links > 2 and not all('T_before' in record for record in run.impacts):
        return (
            f'its reports lack the link energies that give the joint rates of '
            f'{run.scene.n_links} links at contact'
        )
    if run.scene.actuators_during_contact:
        return 'its scene keeps the actuators on during contact (their torque is not reported)'
    return ''


def contact_state(model, record: dict, guess=None) -> tuple[np.ndarray, np.ndarray]:
    """(q, q̇) at an impact's contact from its /impact_report: the angles it gives, and the
    joint rates that give its tip velocity (and, beyond two links, every link's kinetic
    energy ``T_before``; ``guess``: the recording's last joint rates before the contact),
    ``physics.replay.contact_rates``. Refused (AnalysisError) when no rates give both."""
    from ..physics.errors import ContactStateError
    from ..physics.replay import contact_rates

    q = np.radians(np.asarray(record['q_contact_deg'], float))
    v = np.asarray(record['v_before'], float)
    energies = np.asarray(record['T_before'][: model.n], float) if model.n > 2 else None
    try:
        return q, contact_rates(model, q, v, energies, guess)
    except ContactStateError as exc:
        raise AnalysisError(f'impact {record.get("index")}: {exc}') from None


def rates_before(run: Run, t: float):
    """The joint rates of ``run``'s last joint state at or before time ``t`` (None if none)."""
    i = int(np.searchsorted(run.t, t, side='right')) - 1
    return run.qd[i] if i >= 0 and np.all(np.isfinite(run.qd[i])) else None


def _contact_replay(scene, record: dict, guess, **kwargs):
    """Impact ``record`` integrated again from its reported contact state
    (``physics.replay.replay_impact``, from a moment before the contact, with the scene's
    integrator options); given up after ten times its reported duration."""
    from ..physics.integrator import IntegratorOptions
    from ..physics.model import ArmModel
    from ..physics.replay import ReplayStart, replay_impact

    model = ArmModel(scene)
    q, qd = contact_state(model, record, guess)
    start = ReplayStart.before_contact(float(record['t_contact']), q, qd)
    horizon = start.t + 10 * max(float(record['duration']), 1e-6)
    options = IntegratorOptions.of_scene(scene.integrator)
    return model, replay_impact(model, start, options, horizon, **kwargs)


def reintegrated_trace(scene, record: dict, guess=None):
    """The points of one impact, integrated again from the state its /impact_report gives at
    contact (``contact_state``; ``guess``: the joint rates just before it, for more than two
    links). With the actuators off during contact (the article's eq. 7) nothing else acts,
    so the impact is the recorded one to the integrator's tolerance. Returns (columns, rows)
    as /impact_trace carries them and the re-integrated record (to compare with the
    reported one)."""
    from ..io.offline_mcap import trace_columns

    model, replay = _contact_replay(scene, record, guess, trace=True)
    if replay.record is None:
        raise AnalysisError(
            f'impact {record.get("index")} did not end when integrated again from '
            f'its reported contact state'
        )
    return (trace_columns(model.n), replay.trace), replay.record


def elastic_curve(scene, record: dict, points: int = 80, guess=None) -> ElasticCurve | None:
    """Integrate impact ``record`` again from its reported contact state (as
    ``reintegrated_trace``, ``guess`` as there) with output on a grid of ``points`` times
    over its elastic phase (the integrator's continuous extension; contact steps end on the
    grid). None when the record cannot be integrated again (``trace_missing_reason``) or has
    no elastic phase."""
    from ..physics.kinds import EventKind
    from ..physics.replay import OutputGrid, elastic_phase

    if scene is None or scene.actuators_during_contact:
        return None
    durations = record.get('phase_durations') or []
    if not durations or not durations[0] > 0 or 'q_contact_deg' not in record:
        return None
    if scene.n_links > 2 and 'T_before' not in record:
        return None
    dt = float(durations[0]) / points
    try:
        model, replay = _contact_replay(
            scene,
            record,
            guess,
            end_at=(EventKind.YIELD, EventKind.MAX_COMPRESSION),
            output=OutputGrid.from_time(dt, float(record['t_contact'])),
        )
    except AnalysisError:
        return None
    return elastic_phase(model, replay)


def with_contact_point(columns, rows, record):
    """The trace with its first point at contact (δ = 0, no force, the velocities and
    energies before impact from the record): the kernel records points at step ends, so the
    phase boundaries it crosses are there, but the contact itself is not."""
    col = {name: i for i, name in enumerate(columns)}
    first = np.zeros(len(columns))
    first[col['t']], first[col['phase']] = record['t_contact'], 1
    first[col['v_x']], first[col['v_y']] = record['v_before'][:2]
    for i, energy in enumerate(record['T_before'][:-1]):
        if f'T{i + 1}' in col:
            first[col[f'T{i + 1}']] = energy
    if len(rows) and rows[0][col['t']] <= record['t_contact']:
        return rows
    return np.vstack([first[None, :], rows])


# ------------------------------------------------------------------------- analysis
def poincare(t, q, qd, k: int) -> np.ndarray:
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


def limit_cycle(impacts) -> dict:
    """Impacts until the motion repeats itself (``metrics.limit_cycle``: every impact, or
    every second one for an arm that strikes twice per cycle, ...) and the period: one
    repetition's duration."""
    times = [i['t_contact'] for i in impacts]
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


def impact_table(impacts) -> str:
    """The impact rows exactly as ``impact-arm simulate`` prints them."""
    from ..physics.simulate import impact_rows

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


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser):
    parser.add_argument('file', help='MCAP recording (live or simulate --mcap)')
    parser.add_argument(
        '--out', metavar='DIR', help='output directory (default: runs/<file name>_analysis)'
    )
    parser.add_argument(
        '--compare',
        nargs='+',
        default=[],
        metavar='FILE',
        help='more recordings (e.g. other controller laws): their link angles '
        "beside this one's (fig3b_recordings.png)",
    )
    parser.add_argument(
        '--laws',
        default=None,
        metavar='LAWS',
        help='the control laws of Figure 3, comma separated (default q,pd,pid; pid '
        'left out when the scene has no integral gains; empty: no Figure 3): step '
        "responses of the file's scene without its surface, simulated offline",
    )
    parser.add_argument(
        '--compare-time',
        type=float,
        default=5.0,
        metavar='S',
        help='simulated seconds of each step response (default 5, (0, 60])',
    )
    parser.add_argument(
        '--impact',
        type=int,
        default=1,
        metavar='K',
        help='impact shown in Figures 8-11 (default 1, the first); from '
        '/impact_trace, or re-integrated from /impact_report in a live '
        'recording',
    )
    parser.add_argument(
        '--animation',
        action='store_true',
        help='also write animation.gif (slow, about a minute; impact-arm animate makes it alone)',
    )
    parser.add_argument(
        '--no-animation',
        action='store_true',
        help='no animation.gif: the default since --animation (accepted for older scripts)',
    )
    figure_options(parser)


def figure_options(parser):
    """--format and --dpi, shared with the commands that draw figures."""
    from .figures import DPI, FORMATS

    parser.add_argument(
        '--format',
        default='png',
        choices=FORMATS,
        help='file format of the figures (default png; svg and pdf are vector graphics)',
    )
    parser.add_argument(
        '--dpi',
        type=float,
        default=DPI,
        metavar='N',
        help=f'resolution of png figures in dots per inch (default {DPI}, [50, 1200]); '
        f'sets the size in pixels, not the layout',
    )


def cli(args) -> int:
    from . import figures
    from .progress import Progress

    line = Progress(prefix='analyze: ')

    def say(text):
        line.show(text, log=True)

    out = args.out or os.path.join(
        'runs', os.path.splitext(os.path.basename(args.file))[0] + '_analysis'
    )
    if not 0 < args.compare_time <= 60:
        raise AnalysisError(f'--compare-time = {args.compare_time}: must be in (0, 60] s')
    if not 50 <= args.dpi <= 1200:
        raise AnalysisError(f'--dpi = {args.dpi:g}: must be in [50, 1200]')
    given = ','.join(STEP_LAWS) if args.laws is None else args.laws
    laws = [w.strip() for w in given.split(',') if w.strip()]
    for law in laws:
        if law not in FEEDBACK_LAWS:
            raise AnalysisError(f'--laws: {law!r} is not one of {", ".join(FEEDBACK_LAWS)}')
    run = load(args.file, progress=say)
    if run.traces and not 1 <= args.impact <= len(run.traces):
        raise AnalysisError(
            f'--impact = {args.impact}: must be in [1, {len(run.traces)}] '
            f'(the impacts with a trace in {args.file})'
        )
    if not run.traces and run.impacts and not 1 <= args.impact <= len(run.impacts):
        raise AnalysisError(
            f'--impact = {args.impact}: must be in [1, {len(run.impacts)}] '
            f'(the impacts reported in {args.file})'
        )
    others = [load(f, progress=say) for f in args.compare]
    # the table first: it needs nothing but the file, the figures take seconds
    table = impact_table(run.impacts)
    lc = limit_cycle(run.impacts)
    line.end()
    if run.impacts:
        print(f'impact table ({len(run.impacts)} impacts):')
        print(table)
    else:
        print(f'no impacts in {args.file}: {no_impact_reason(run)}')
    print(_limit_cycle_text(lc), flush=True)
    for found in chatter(run):
        print(f'CHATTER: {found.text()}: the law is unstable at its rate', flush=True)
    if run.scene is not None:
        from ..physics.limits import limit_excursions

        for excursion in limit_excursions(run.scene, run.q, run.qd):
            print(f'LIMIT: {excursion.text()}', flush=True)
    missing = []
    steps = []
    if laws and run.scene is None:
        missing.append(
            f'Figure 3 not drawn: {args.file} stores no scene to simulate the step responses of'
        )
    elif laws and run.scene is not None:
        if args.laws is None and not any(run.scene.controller.ki):
            # the default asks for every law the scene can run; asked for by name, pid is refused
            laws = [law for law in laws if law != 'pid']
            missing.append('Figure 3 without PID: the scene has no integral gains (controller.ki)')
        steps = [step_response(run.scene, law, args.compare_time, say) for law in laws]
    impact, constants = impact_points(run, args.impact, say)
    if impact is None:
        missing.append(_no_impact_figures(run, args.file))
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise AnalysisError(f'--out {out}: cannot create ({e.strerror})') from None
    written = write_outputs(
        run,
        steps,
        out,
        impact,
        figures,
        progress=say,
        recordings=others,
        constants=constants,
        missing=missing,
        style=figures.Style(args.format, args.dpi),
        elastic=elastic_curve(
            run.scene, impact[2], guess=rates_before(run, float(impact[2]['t_contact']))
        )
        if impact is not None
        else None,
    )
    line.end()
    if impact is not None and impact[3]:
        print(f'Figures 8-11: impact {args.impact} {impact[3]}')
    for line_ in missing:
        print(line_)
    print(
        f'wrote {os.path.join(out, "report.md")} ({len(written["figures"])} figures: '
        + ', '.join(name for name, _ in written['figures'])
        + ')',
        flush=True,
    )
    if args.animation and run.scene is not None:
        from .animation import animate, contact_forces

        gif = os.path.join(out, 'animation.gif')
        say(f'animating to {gif}')
        frames = animate(run, gif, contact_forces(args.file), progress=say)
        line.end()
        print(f'animation: {gif} ({frames} frames)')
    elif args.animation:
        print(f'animation not drawn: {args.file} stores no scene (link lengths)')
    return 0


def no_impact_reason(run: Run) -> str:
    """Why a recording has no impact record: no /impact_report topic at all (a recording
    of joint states only), or the topic is there and the arm never struck."""
    if IMPACT_REPORT in run.topics or IMPACT_TRACE in run.topics:
        return f'the arm struck no surface ({IMPACT_REPORT} was recorded, with no message)'
    return f'it has no {IMPACT_REPORT} topic'


def _no_impact_figures(run: Run, path) -> str:
    if not run.impacts and not run.traces and IMPACT_REPORT in run.topics:
        return f'Figures 8-11 not drawn: {path} has no impact to show (the arm struck no surface)'
    return (
        f'Figures 8-11 not drawn: {path} has no /impact_trace, and '
        f'{trace_missing_reason(run)}, so the impact cannot be integrated again. '
        f'Record with the trace: impact-arm simulate --scene SCENE --mcap FILE'
    )


def impact_points(run: Run, k: int, progress=_quiet):
    """(columns, rows, record, note) of impact ``k`` for Figures 8-11, and the contact
    constants of the surface it struck (None without a scene). From /impact_trace when the
    file has it (offline recordings); otherwise integrated again from /impact_report's
    contact state (live recordings), the note saying so; (None, None) if neither."""
    record = run.impacts[k - 1] if 0 < k <= len(run.impacts) else None
    constants = None
    if run.scene is not None and record is not None:
        constants = _struck_surface(run.scene, record)
    if run.traces and 0 < k <= len(run.traces):
        columns, rows = run.traces[k - 1]
        if record is None:
            record = _record_from_trace(columns, rows, k)
        return (columns, with_contact_point(columns, rows, record), record, ''), constants
    if record is None or trace_missing_reason(run):
        return None, constants
    progress(f'integrating impact {k} again from its /impact_report (no /impact_trace)')
    guess = rates_before(run, float(record['t_contact']))
    (columns, rows), made = reintegrated_trace(run.scene, record, guess)
    worst = max(abs(made[key] / record[key] - 1) for key in ('delta_m', 'F_max', 'duration'))
    note = (
        f're-integrated from /impact_report (no /impact_trace in the file); δm, F_max '
        f'and duration within {max(worst, 1e-12):.0e} of the report'
    )
    return (columns, with_contact_point(columns, rows, record), record, note), constants


def _struck_surface(scene, record):
    """Contact constants of the surface the tip met at contact (the nearest height)."""
    from ..physics.model import ArmModel

    model = ArmModel(scene)
    if not model.surfaces:
        return None
    q = np.radians(np.asarray(record['q_contact_deg'], float))
    y_tip = float(model.tip(q, np.zeros_like(q))[1])
    return min(model.surfaces, key=lambda s: abs(s.height - y_tip)).constants


def _record_from_trace(columns, rows, k):
    """The few record fields the figures need, read off a trace without its report."""
    col = {name: rows[:, i] for i, name in enumerate(columns)}
    energies = [col[c][0] for c in columns if c.startswith('T') and c[1:].isdigit()]
    return {
        'index': k,
        't_contact': float(col['t'][0]),
        'v_before': [col['v_x'][0], col['v_y'][0]],
        'T_before': energies + [sum(energies)],
        'delta_m': float(np.max(col['delta'])),
        'delta_r': float(col['delta'][-1]),
        'F_max': float(np.max(col['F_n'])),
    }


def _limit_cycle_text(lc) -> str:
    if not lc['impacts']:
        return 'no impacts recorded'
    per = lc.get('impacts_per_cycle') or 1
    settled = 'limit cycle ' + (
        LimitCycle(lc['settled_after'], per).text() if lc['settled_after'] else 'not reached'
    )
    period = f'period {lc["period"]:.5f} s' if lc['period'] is not None else 'no period'
    return f'{lc["impacts"]} impacts; {settled}; {period}'


def _write(path, text):
    tmp = path + '.tmp'
    with open(tmp, 'w', encoding='utf-8') as f:
        f.write(text)
    os.replace(tmp, path)


def write_outputs(
    run: Run,
    steps,
    out,
    impact,
    figures,
    progress=_quiet,
    recordings=(),
    constants=None,
    missing=(),
    style=None,
    elastic=None,
) -> dict:
    """Tables, CSVs, figures and report.md in ``out``; returns what was written."""
    table = impact_table(run.impacts)
    lc = limit_cycle(run.impacts)
    _write(os.path.join(out, 'impacts.json'), json.dumps({'impacts': run.impacts}, indent=1))
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


def _origin(info: dict) -> str:
    """Who recorded the file and how: 'offline run, simulate --mcap' for an offline file
    (its node and mode are both 'offline'), else 'NODE, MODE'."""
    node, mode = info.get('node', '?'), info.get('mode', 'live')
    if node == 'offline':
        return 'offline run, impact-arm simulate --mcap'
    return f'{node}, {mode}' if mode != node else node


def _figure_named(made, stem) -> str:
    return next((name for name, _ in made if name.startswith(stem + '.')), stem + '.png')


def report(run: Run, others, table, lc, sections, made, steps=(), missing=()) -> str:
    info = run.metadata.get('impact_arm', {})
    nonfinite = int(np.count_nonzero(~np.isfinite(run.q)) + np.count_nonzero(~np.isfinite(run.qd)))
    lines = [
        f'# Analysis of {run.label}',
        '',
        f'Recorded by impact_arm {info.get("version", "?")} ({_origin(info)}); scene '
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
        _limit_cycle_text(lc) + '.',
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
