"""``impact-arm analyze FILE.mcap [--out DIR]``: impact table, limit cycle, Poincaré sections,
the article's figures and a markdown report, from a recording alone (no rclpy; CDR is decoded
by ``rosbags``' typestore for ROS 2 Kilted: speed does not matter here, and it is the
reference decoder the tests already trust; ``io/wire.py`` stays the hot path's codec).

What is read (docs/topics.md): ``/joint_states`` (relative joint angles → absolute link angles
q1, q2 = joint1 + joint2 and their rates; time = header stamp), ``/impact_report`` (one JSON
impact record each: the table is exactly the one ``simulate`` prints), ``/impact_trace``
(full-resolution points inside each impact: Figures 8–11), and the scene stored in the file
(link lengths for the tip velocity of Figure 7, the controller law for Figure 3).

Outputs in DIR (default: ``<FILE without .mcap>_analysis``): ``report.md``, ``impacts.json``
(``{"impacts": [...]}``, the records as published), ``impact_table.txt``,
``poincare_qd1_zero.csv`` / ``poincare_qd2_zero.csv`` and the figures ``fig3_controllers.png``
… ``fig11_kinetic_energy.png`` (``figures.FIGURE_SIZE`` pixels each). Figure 3 compares
controller laws: it shows every recording given (FILE and ``--compare`` files), plus offline
runs of the file's scene for the laws given with ``--laws`` (e.g. ``--laws q,pd,pid``).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from ..contract import FEEDBACK_LAWS, IMPACT_REPORT, IMPACT_TRACE, JOINT_STATES, to_absolute
from ..core.errors import ImpactArmError
from ..core.metrics import settle_index


class AnalysisError(ImpactArmError):
    """The recording cannot be analysed (missing file, topic or data)."""


@dataclass
class Run:
    """One recording (or an offline run) reduced to arrays. Angles in rad, SI units."""
    label: str
    t: np.ndarray                      # joint state times [s] (header stamps)
    q: np.ndarray                      # (N, n) absolute link angles
    qd: np.ndarray                     # (N, n) absolute link rates
    impacts: list = field(default_factory=list)
    traces: list = field(default_factory=list)   # [(columns, (rows, cols) array)]
    scene: object = None
    metadata: dict = field(default_factory=dict)
    law: str = ''


def _quiet(text):
    pass


def load(path, progress=_quiet) -> Run:
    """Read a recording. ``progress(text)`` is told what is being read."""
    from ..io.mcap_ros2 import iter_raw, read_metadata, topics_info
    from ..io.msgdefs import typestore
    deserialize_cdr = typestore().deserialize_cdr
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise AnalysisError(f'{path}: no such file')
    try:
        info = topics_info(path)
        metadata = read_metadata(path)
    except Exception as e:  # noqa: BLE001 - any reader failure: not an MCAP file we can use
        raise AnalysisError(f'{path}: not a readable MCAP file ({e})') from None
    if JOINT_STATES not in info:
        raise AnalysisError(f'{path}: no /joint_states recorded (topics: {sorted(info)})')
    total = sum(i.message_count for i in info.values()) or 1
    progress(f'reading {path} ({total} messages)')
    t, pos, vel, impacts, traces = [], [], [], [], []
    wanted = [JOINT_STATES, IMPACT_REPORT, IMPACT_TRACE]
    for k, m in enumerate(iter_raw(path, [w for w in wanted if w in info])):
        if k and k % 20000 == 0:
            progress(f'  {100 * k // total} %')
        msg = deserialize_cdr(m.data, m.type_name)
        if m.topic == JOINT_STATES:
            t.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            pos.append(to_absolute(msg.position))
            vel.append(to_absolute(msg.velocity) if len(msg.velocity) else
                       [math.nan] * len(msg.position))
        elif m.topic == IMPACT_REPORT:
            try:
                impacts.append(json.loads(msg.data))
            except ValueError as e:
                raise AnalysisError(f'{path}: /impact_report message {len(impacts) + 1} is not '
                                    f'JSON ({e})') from None
        else:
            dims = msg.layout.dim
            if len(dims) != 2:
                raise AnalysisError(f'{path}: {IMPACT_TRACE} message {len(traces) + 1} has '
                                    f'{len(dims)} dimensions, expected 2')
            columns = dims[1].label.split(',')
            data = np.asarray(msg.data, float)[msg.layout.data_offset:]
            traces.append((columns, data.reshape(dims[0].size, dims[1].size)))
    if not t:
        raise AnalysisError(f'{path}: /joint_states has no messages')
    # stamp order, never file order: a recorder that stalled writes what it received late
    # after newer messages (impact reports by their contact time, joint states by stamp)
    impacts.sort(key=lambda record: _number(record.get('t_contact')))
    order = np.argsort(t, kind='stable')
    scene = _scene(metadata)
    law = scene.controller.law if scene is not None else ''
    return Run(os.path.basename(path), np.asarray(t)[order], np.asarray(pos, float)[order],
               np.asarray(vel, float)[order], impacts, traces, scene, metadata, law)


def _number(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.inf


def _scene(metadata):
    text = metadata.get('scene', {}).get('yaml')
    if not text:
        return None
    from ..core.scene import scene_from_text
    try:
        return scene_from_text(text, origin='scene stored in the recording')
    except ImpactArmError:
        return None


def simulated(scene, law: str, t_max: float, progress=_quiet) -> Run:
    """An offline run of ``scene`` with controller ``law`` (for Figure 3)."""
    from ..core.simulate import run
    if law not in FEEDBACK_LAWS:
        raise AnalysisError(f'--laws: {law!r} is not one of {", ".join(FEEDBACK_LAWS)}')
    sc = replace(scene, controller=replace(scene.controller, law=law))
    if law == 'pid' and not any(sc.controller.ki):
        raise AnalysisError('--laws pid: the scene has no integral gains (controller.ki)')
    progress(f'simulating law {law} for {t_max:g} s')
    result = run(sc, t_max=t_max)
    samples = result.samples
    return Run(f'law {law} (offline)', np.array([s.t for s in samples]),
               np.array([s.q for s in samples]), np.array([s.qd for s in samples]),
               result.impacts, scene=sc, law=law)


# ------------------------------------------------------------------------- analysis
def poincare(t, q, qd, k: int) -> np.ndarray:
    """Rows (t, q1, q2, direction) where q̇_k crosses zero (linear interpolation between
    samples; direction +1 rising, -1 falling). Samples with a non-finite rate are skipped."""
    v = qd[:, k]
    a, b = v[:-1], v[1:]
    ok = np.isfinite(a) & np.isfinite(b)
    idx = np.nonzero(ok & (((a < 0) & (b >= 0)) | ((a > 0) & (b <= 0))))[0]
    rows = []
    for i in idx:
        s = a[i] / (a[i] - b[i])
        rows.append([t[i] + s * (t[i + 1] - t[i]), *(q[i] + s * (q[i + 1] - q[i]))[:2],
                     1.0 if b[i] > a[i] else -1.0])
    return np.array(rows).reshape(-1, 4)


def limit_cycle(impacts) -> dict:
    """Impacts until the motion repeats itself (``metrics.settle_index``) and the period."""
    times = [i['t_contact'] for i in impacts]
    periods = np.diff(times)
    settled = settle_index(impacts) if len(impacts) > 1 else None
    after = periods[settled - 1:] if settled else periods[-1:]
    return {'impacts': len(impacts), 'settled_after': settled,
            'period': float(np.mean(after)) if len(after) else None,
            'period_last': float(periods[-1]) if len(periods) else None,
            'periods': [float(p) for p in periods]}


def impact_table(impacts) -> str:
    """The impact rows exactly as ``impact-arm simulate`` prints them."""
    from ..core.simulate import RunResult, format_table
    return format_table(RunResult(scene=None, impacts=impacts)).split('\n\n')[0]


def tip_velocity(run: Run) -> np.ndarray | None:
    """(N, 2) tip velocity (vx, vy) from the joint states and the link lengths of the stored
    scene (absolute angles from the x axis: v = Σ L_i q̇_i (−sin q_i, cos q_i)), or None."""
    if run.scene is None or len(run.scene.lengths) != run.q.shape[1]:
        return None
    L = np.asarray(run.scene.lengths, float)
    vx = -(L * np.sin(run.q) * run.qd).sum(axis=1)
    vy = (L * np.cos(run.q) * run.qd).sum(axis=1)
    return np.stack([vx, vy], axis=1)


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser):
    parser.add_argument('file', help='MCAP recording (live or simulate --mcap)')
    parser.add_argument('--out', metavar='DIR',
                        help='output directory (default: <file without .mcap>_analysis)')
    parser.add_argument('--compare', nargs='+', default=[], metavar='FILE',
                        help='more recordings (e.g. other controller laws) for Figure 3')
    parser.add_argument('--laws', default='', metavar='LAWS',
                        help='also simulate the file\'s scene with these controller laws for '
                             'Figure 3, comma separated (q, pd, pid)')
    parser.add_argument('--compare-time', type=float, default=1.0, metavar='S',
                        help='simulated seconds per law for --laws (default 1.0, (0, 60])')
    parser.add_argument('--impact', type=int, default=1, metavar='K',
                        help='impact shown in Figures 8-11 (default 1, the first)')
    parser.add_argument('--no-animation', action='store_true',
                        help='skip animation.gif (impact-arm animate makes it alone)')


def cli(args) -> int:
    from . import figures
    from .progress import Progress
    line = Progress(prefix='analyze: ')

    def say(text):
        line.show(text, log=True)
    out = args.out or (os.path.splitext(args.file)[0] + '_analysis')
    if not 0 < args.compare_time <= 60:
        raise AnalysisError(f'--compare-time = {args.compare_time}: must be in (0, 60] s')
    laws = [w.strip() for w in args.laws.split(',') if w.strip()]
    for law in laws:
        if law not in FEEDBACK_LAWS:
            raise AnalysisError(f'--laws: {law!r} is not one of {", ".join(FEEDBACK_LAWS)}')
    run = load(args.file, progress=say)
    if run.traces and not 1 <= args.impact <= len(run.traces):
        raise AnalysisError(f'--impact = {args.impact}: must be in [1, {len(run.traces)}] '
                            f'(the impacts with a trace in {args.file})')
    others = [load(f, progress=say) for f in args.compare]
    if laws and run.scene is None:
        raise AnalysisError(f'--laws: {args.file} holds no scene to simulate')
    others += [simulated(run.scene, law, args.compare_time, say) for law in laws]
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise AnalysisError(f'--out {out}: cannot create ({e.strerror})') from None
    written = write_outputs(run, others, out, args.impact, figures, progress=say)
    if not args.no_animation and run.scene is not None:
        from .animation import animate, contact_forces
        gif = os.path.join(out, 'animation.gif')
        say(f'animating to {gif}')
        frames = animate(run, gif, contact_forces(args.file), progress=say)
        line.end()
        print(f'animation: {gif} ({frames} frames)')
    line.end()
    print(f'impact table ({len(run.impacts)} impacts):')
    print(written['table'])
    lc = written['limit_cycle']
    print(_limit_cycle_text(lc))
    print(f'report: {os.path.join(out, "report.md")} ({len(written["figures"])} figures)')
    return 0


def _limit_cycle_text(lc) -> str:
    if not lc['impacts']:
        return 'no impacts recorded'
    settled = (f'limit cycle reached after {lc["settled_after"]} impacts'
               if lc['settled_after'] else 'limit cycle not reached')
    period = f'period {lc["period"]:.5f} s' if lc['period'] is not None else 'no period'
    return f'{lc["impacts"]} impacts; {settled}; {period}'


def _write(path, text):
    tmp = path + '.tmp'
    with open(tmp, 'w', encoding='utf-8') as f:
        f.write(text)
    os.replace(tmp, path)


def write_outputs(run: Run, others, out, impact_k, figures, progress=_quiet) -> dict:
    """Tables, CSVs, figures and report.md in ``out``; returns what was written."""
    table = impact_table(run.impacts)
    lc = limit_cycle(run.impacts)
    _write(os.path.join(out, 'impacts.json'), json.dumps({'impacts': run.impacts}, indent=1))
    _write(os.path.join(out, 'impact_table.txt'), table + '\n')
    sections = {}
    for k in (0, 1):
        rows = poincare(run.t, run.q, run.qd, k)
        sections[k] = rows
        lines = ['t_s,q1_deg,q2_deg,direction'] + [
            f'{r[0]:.9g},{math.degrees(r[1]):.9g},{math.degrees(r[2]):.9g},{int(r[3])}'
            for r in rows]
        _write(os.path.join(out, f'poincare_qd{k + 1}_zero.csv'), '\n'.join(lines) + '\n')
    v_tip = tip_velocity(run)
    made = figures.draw_all(run, others, sections, v_tip, impact_k, out, progress=progress)
    _write(os.path.join(out, 'report.md'), report(run, others, table, lc, sections, made,
                                                  impact_k))
    return {'table': table, 'limit_cycle': lc, 'figures': made, 'sections': sections}


def report(run: Run, others, table, lc, sections, made, impact_k) -> str:
    info = run.metadata.get('impact_arm', {})
    nonfinite = int(np.count_nonzero(~np.isfinite(run.q)) + np.count_nonzero(
        ~np.isfinite(run.qd)))
    lines = [f'# Analysis of {run.label}', '',
             f'Recorded by impact_arm {info.get("version", "?")} ({info.get("node", "?")}'
             f', {info.get("mode", "live")}); scene '
             f'{run.scene.name if run.scene is not None else "not stored"}'
             f'{", law " + run.law if run.law else ""}; {len(run.t)} joint states over '
             f'{run.t[-1] - run.t[0]:.4f} s, {len(run.impacts)} impact reports, '
             f'{len(run.traces)} impact traces.', '']
    if nonfinite:
        lines += [f'**Warning:** {nonfinite} non-finite joint values in /joint_states.', '']
    if run.metadata.get('run', {}).get('error'):
        lines += [f'**The run stopped with an error:** {run.metadata["run"]["error"]}', '']
    lines += ['## Impacts', '', 'Units: t [s], angles [deg], duration [µs], δm and δr [µm], '
              'F_max [kN], velocities [m/s], energies [J]; the same table as '
              '`impact-arm simulate` (all fields in `impacts.json`).', '', '```', table, '```',
              '', '## Limit cycle', '', _limit_cycle_text(lc) + '.', '']
    if lc['periods']:
        lines += ['Times between impacts [s]: ' + ', '.join(f'{p:.5f}' for p in lc['periods']),
                  '']
    lines += ['## Poincaré sections', '']
    for k, rows in sections.items():
        lines.append(f'- q̇{k + 1} = 0: {len(rows)} crossings (`poincare_qd{k + 1}_zero.csv`)'
                     + (f'; last: q1 = {math.degrees(rows[-1][1]):.3f}°, '
                        f'q2 = {math.degrees(rows[-1][2]):.3f}°' if len(rows) else ''))
    lines += ['', '## Figures', '']
    for name, caption in made:
        lines += [f'![{caption}]({name})', '', f'*{caption}*', '']
    if others:
        lines += ['Figure 3 compares: ' + ', '.join([run.label] + [o.label for o in others])
                  + '.', '']
    return '\n'.join(lines)
