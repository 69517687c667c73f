"""``impact-arm compare A B``: the impacts of two recordings, or of a recording and a scene.

    impact-arm compare runs/second.mcap runs/fit_first/fitted.yaml  # scene driven by A's efforts
    impact-arm compare runs/second.mcap fitted.yaml --controller    # scene, its own controller
    impact-arm compare runs/a.mcap runs/b_bag/ --scene paper            # two recordings

Each side becomes a table of impacts (time from the first impact, impact speed, kinematic CoR,
impulse, joint rates just after); the impacts are matched one to one by time and the
differences printed and written with overlay plots. A scene "driven by the recording's
efforts" replays each recorded impact from its recorded pre-impact state (as ``fit`` does):
this is how a fitted scene is checked against a recording it was not fitted on.

The comparison is ``impact_arm.compare`` (the method: calibration/compare.py); this module
is the command over it: the recording's scene or the article's, the table, the files.
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Any

import numpy as np

from ..contract import JOINT_STATES
from ..physics.errors import ImpactArmError


def format_table(result: dict[str, Any]) -> str:
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


def write_plot(result: dict[str, Any], path: str, a_name: str, b_name: str) -> None:
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


def default_out(a: str, b: str) -> str:
    """runs/compare_<A>_vs_<B>: one directory per pair, so comparing A with another B
    does not land on the first result."""

    def name(path: str) -> str:
        return os.path.splitext(os.path.basename(os.path.normpath(path)))[0]

    return os.path.join('runs', f'compare_{name(a)}_vs_{name(b)}')


def add_arguments(parser: argparse.ArgumentParser) -> None:
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


def cli(args: argparse.Namespace) -> int:
    from .cli import write_json

    joints = [j.strip() for j in args.joints.split(',')] if args.joints else None
    out = args.out or default_out(args.a, args.b)
    earlier = [n for n in ('table.json', 'compare.png') if os.path.exists(os.path.join(out, n))]
    if earlier and not args.force:  # refused before the work, not after
        raise ImpactArmError(
            f'--out {out}: holds an earlier comparison ({", ".join(earlier)}); pass --force '
            f'to replace it, or another --out'
        )
    from ..api.comparing import compare, is_recording
    from .fit import scene_of

    # both recordings: read with the scene given, else the one A stores, else the article's
    scene = scene_of(args.a, args.scene)[0] if is_recording(args.b) else None
    result = compare(
        args.a,
        args.b,
        scene=scene,
        joints=joints,
        controller=args.controller,
        states_topic=args.states_topic or JOINT_STATES,
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
