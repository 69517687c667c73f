"""``impact-arm compare A B``: the impacts of two recordings, or of a recording and a scene.

    impact-arm compare runs/second.mcap runs/fit_first/fitted.yaml  # scene driven by A's efforts
    impact-arm compare runs/second.mcap fitted.yaml --controller    # scene, its own controller
    impact-arm compare runs/a.mcap runs/b_bag/ --scene paper            # two recordings

Each side becomes a table of impacts (time from the first impact, impact speed, kinematic CoR,
impulse, joint rates just after); the impacts are matched one to one by time and the
differences printed and written with overlay plots. A scene "driven by the recording's
efforts" replays each recorded impact from its recorded pre-impact state (as ``fit`` does):
this is how a fitted scene is checked against a recording it was not fitted on.
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..physics.errors import ImpactArmError

COLUMNS = ('t', 'impact_speed', 'cor', 'impulse_n', 'impulse_t', 'qd_after')


def _is_recording(path) -> bool:
    p = os.fspath(path)
    return os.path.isdir(p) or (os.path.isfile(p) and p.endswith('.mcap'))


def recorded_impacts(rec, study, timing=None) -> tuple:
    """Rows of the impacts of a recording; the scene gives the kinematics and the free flight
    that carries the first sample after an impact back to its separation (for the CoR)."""
    from ..calibration.fit import predict_impact, read_impacts, recorded_cor
    from ..calibration.identify import joint_to_absolute_matrix, tip_normal_speed
    from ..physics.model import ArmModel

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


def replayed_impacts(preds, model) -> list:
    """Rows of the scene's predictions of each recorded impact (from the recorded state)."""
    from ..calibration.identify import joint_to_absolute_matrix, tip_normal_speed

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


def match(a_rows, b_rows) -> list:
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
    used_a, used_b, out = set(), set(), []
    for _, i, j in pairs:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            out.append((i, j))
    return sorted(out)


def compare(
    a, b, *, scene=None, joints=None, controller=False, states_topic=None, wrench_topic=None
) -> dict:
    """Python API: {'a': rows, 'b': rows, 'pairs': [(i, j)], 'table': [...], 'what': text}."""
    from ..contract import JOINT_STATES
    from ..calibration.study import Study
    from ..io.recording import read_recording

    from .fit import scene_of

    b_is_recording = _is_recording(b)
    kin_scene = scene_of(a, scene)[0] if b_is_recording else b
    study = Study(kin_scene)
    kin = study.scene()
    n, names = kin.n_links, kin.joint_names
    coordinates = kin.joint_coordinates
    rec_a = read_recording(
        a,
        joints,
        n,
        states_topic or JOINT_STATES,
        wrench_topic,
        scene_joints=names,
        coordinates=coordinates,
    )
    a_rows, preds, _ = recorded_impacts(rec_a, study)
    a_origin = a_rows[0]['t'] if a_rows else 0.0
    if b_is_recording:
        rec_b = read_recording(
            b,
            joints,
            n,
            states_topic or JOINT_STATES,
            wrench_topic,
            scene_joints=names,
            coordinates=coordinates,
        )
        b_rows = recorded_impacts(rec_b, study)[0]
        what = f'recording {b}'
    elif controller:
        from .synthetic import synthetic_recording

        rec_b = synthetic_recording(b, noise={}, publish_rate=1.0 / rec_a.period)
        b_rows = recorded_impacts(rec_b, study)[0]
        what = f'scene {b} with its own controller'
    else:
        from ..physics.model import ArmModel

        b_rows = replayed_impacts(preds, ArmModel(study.scene()))
        what = f'scene {b} replaying each impact of {a} from its recorded state and efforts'
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


def format_table(result) -> str:
    lines = [
        (
            f'{"#":>3} {"t A [s]":>8} {"t B [s]":>8} {"v A":>6} {"v B":>6} {"e A":>7} '
            f'{"e B":>7} {"de":>8} {"Pn A":>7} {"Pn B":>7} {"dPn":>8}  dqd after [rad/s]'
        )
    ]
    for k, r in enumerate(result['table']):
        lines.append(
            f'{k + 1:>3} {r["a_t"]:>8.4f} {r["b_t"]:>8.4f} {r["impact_speed_a"]:>6.3f} '
            f'{r["impact_speed_b"]:>6.3f} {r["cor_a"]:>7.4f} {r["cor_b"]:>7.4f} '
            f'{r["d_cor"]:>+8.4f} {r["impulse_n_a"]:>7.4f} {r["impulse_n_b"]:>7.4f} '
            f'{r["d_impulse_n"]:>+8.4f}  {", ".join(f"{x:+.3e}" for x in r["d_qd_after"])}'
        )
    d = np.array([r['d_cor'] for r in result['table']])
    if len(d):
        lines.append(
            f'\n{len(d)} impacts matched ({result["unmatched_a"]} of A and '
            f'{result["unmatched_b"]} of B unmatched); CoR difference mean '
            f'{d.mean():+.4f}, rms {math.sqrt(np.mean(d**2)):.4f}'
        )
    return '\n'.join(lines)


def write_plot(result, path, a_name, b_name):
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for rows, mark, name in ((result['a'], 'o', a_name), (result['b'], 'x', b_name)):
        axes[0].plot([r['impact_speed'] for r in rows], [r['cor'] for r in rows], mark, label=name)
        t0 = rows[0]['t'] if rows else 0.0
        axes[1].plot([r['t'] - t0 for r in rows], [r['cor'] for r in rows], mark, label=name)
    axes[0].set_xlabel('impact speed (tip, normal) [m/s]')
    axes[0].set_ylabel('kinematic coefficient of restitution [-]')
    axes[1].set_xlabel('time from the first impact [s]')
    axes[1].set_ylabel('kinematic coefficient of restitution [-]')
    for ax in axes:
        ax.legend(fontsize=8)
    fig.suptitle('Impacts of A and B', fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def default_out(a, b) -> str:
    """runs/compare_<A>_vs_<B>: one directory per pair, so comparing A with another B
    does not land on the first result."""

    def name(path):
        return os.path.splitext(os.path.basename(os.path.normpath(path)))[0]

    return os.path.join('runs', f'compare_{name(a)}_vs_{name(b)}')


def add_arguments(parser):
    from .recording_options import add_recording_arguments

    parser.add_argument('a', help='recording (rosbag2 folder or MCAP file)')
    parser.add_argument('b', help='second recording, or a scene (file or installed name)')
    parser.add_argument(
        '--scene',
        default=None,
        help='scene for the kinematics when both are recordings (default: the scene A '
        'stores, else paper)',
    )
    parser.add_argument(
        '--controller',
        action='store_true',
        help='B a scene: simulate it with its own controller instead of '
        "replaying A's impacts with A's efforts",
    )
    add_recording_arguments(parser, states_of=' of the recordings')
    parser.add_argument(
        '--out',
        default=None,
        metavar='DIR',
        help='write table.json and compare.png here (default runs/compare_<A>_vs_<B>/)',
    )
    parser.add_argument(
        '--force',
        action='store_true',
        help='replace an earlier comparison in the output directory (refused without)',
    )


def cli(args) -> int:
    from .cli import write_json

    joints = [j.strip() for j in args.joints.split(',')] if args.joints else None
    out = args.out or default_out(args.a, args.b)
    earlier = [n for n in ('table.json', 'compare.png') if os.path.exists(os.path.join(out, n))]
    if earlier and not args.force:  # refused before the work, not after
        raise ImpactArmError(
            f'--out {out}: holds an earlier comparison ({", ".join(earlier)}); pass --force '
            f'to replace it, or another --out'
        )
    result = compare(
        args.a,
        args.b,
        scene=args.scene,
        joints=joints,
        controller=args.controller,
        states_topic=args.states_topic,
        wrench_topic=args.wrench_topic,
    )
    print(f'A: {args.a}\nB: {result["what"]}')
    print(format_table(result))
    os.makedirs(out, exist_ok=True)
    write_json(os.path.join(out, 'table.json'), result)
    print(f'wrote {os.path.join(out, "table.json")}')
    png = os.path.join(out, 'compare.png')
    write_plot(
        result,
        png,
        'A ' + os.path.basename(os.path.normpath(args.a)),
        'B ' + os.path.basename(os.path.normpath(args.b)),
    )
    print(f'wrote {png}')
    if not result['pairs']:
        raise ImpactArmError('no impact of A matches one of B')
    return 0
