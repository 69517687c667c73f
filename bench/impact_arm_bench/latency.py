"""``impact-arm bench latency``: the article's limit cycle against the command latency a driver
stack adds, with and without the controller's prediction (its ``latency_periods``).

1. offline (tools/latency_study.py): the simulator's lockstep session and the controller's
   input handling joined by queues, the driver delaying each command by 0-3 periods
   (steady), or by k to k+1 periods at random (varying: an unsynchronised controller
   manager; ``--spread`` S: k to k+S), over several seeds;
2. over DDS (``--dds``): the simulator node in lockstep with ``command_latency_periods`` and
   the controller node, ``latency_periods`` -1 (measured) or 0, on a free local domain.

Controllers: no prediction, prediction over the measured latency with the explicit law
(``implicit_periods`` 0), the implicit law while the latency varies switching to the up half
on the sampled impact (``anticipate_impacts`` false), and the default (the implicit law and
the impact anticipated when the prediction meets it).
For each: impacts, second strikes (an impact within 50 ms of the previous one), the largest
penetration δm and the mean cycle period after the first five impacts; over seeds the
median, and the worst run in brackets.
"""

from __future__ import annotations

import argparse
import functools
import os
import random
import statistics
import subprocess
import sys
import time

from .common import table


# the controller's settings compared (name, latency_periods, implicit_periods,
# anticipate_impacts): no prediction; prediction over the measured latency with an explicit
# law; the law also evaluated implicitly while the measured latency varies, switching to the
# up half on the sampled impact; and the node's default, which also anticipates an impact
# the prediction meets
CONTROLLERS = (
    ('off', 0, 0, False),
    ('measured', -1, 0, False),
    ('measured + implicit, switch on the sample', -1, 1, False),
    ('measured + implicit + anticipation', -1, 1, True),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--scene', default='paper', help='scene file or installed name')
    parser.add_argument('--seconds', type=float, default=10.0, help='simulated s per run')
    parser.add_argument(
        '--latencies',
        type=int,
        nargs='*',
        default=[0, 1, 2, 3],
        help='steady command latencies to run, in control periods',
    )
    parser.add_argument(
        '--varying',
        type=int,
        nargs='*',
        default=[0, 1, 2],
        help='k of the latencies that vary between k and k+1 periods',
    )
    parser.add_argument(
        '--jitter',
        type=float,
        default=0.5,
        help='varying latency: the chance that a command takes the extra period',
    )
    parser.add_argument(
        '--spread',
        type=int,
        default=1,
        help='varying latency: k to k+SPREAD periods (SPREAD chances of an extra period each)',
    )
    parser.add_argument(
        '--bursts',
        nargs=3,
        metavar=('PROBABILITY', 'TOP', 'DECAY'),
        help='varying latency in bursts instead (tools/latency_study.LatencyBursts): each '
        'period a burst starts with PROBABILITY, adding 1..TOP periods, falling back one '
        'every DECAY periods (e.g. 0.05 2 1)',
    )
    parser.add_argument(
        '--controller',
        action='append',
        choices=[c[0] for c in CONTROLLERS],
        help='only this controller (repeatable; default: all four)',
    )
    parser.add_argument('--seeds', type=int, default=5, help='varying latency: runs (seeds)')
    parser.add_argument('--dds', action='store_true', help='also over DDS (nodes)')
    parser.add_argument(
        '--dds-seconds', type=float, default=4.0, help='simulated s per run over DDS'
    )


def _metrics(contacts, delta_m):
    """(impacts, second strikes, largest δm [mm], mean cycle [s] after the 5th impact)."""
    gaps = [b - a for a, b in zip(contacts, contacts[1:])]
    cycles = [g for g in gaps[4:] if g >= 0.05]
    return (
        len(contacts),
        sum(g < 0.05 for g in gaps),
        max(delta_m) * 1e3 if delta_m else None,
        sum(cycles) / len(cycles) if cycles else None,
    )


def _spread(values, fmt, worst=max):
    """'median (worst)' over runs; '-' where a run had none (no cycle completed)."""
    have = [v for v in values if v is not None]
    if not have:
        return '-'
    median = statistics.median(have)
    text = format(median, fmt)
    if len(values) > 1:
        bad = worst(have) if len(have) == len(values) else None
        text += f' ({format(bad, fmt) if bad is not None else "-"})'
    return text


def _row(kind, latency, controller, runs):
    """One table row over ``runs`` [(contacts, delta_m, failed)]: median and, for several
    runs, the worst run beside it (most impacts and second strikes, largest δm, the cycle
    farthest from the median)."""
    metrics = [_metrics(c, d) for c, d, _ in runs]
    cycles = [m[3] for m in metrics]
    mid = statistics.median([c for c in cycles if c is not None] or [0.0])
    failed = sorted({f[:40] for _, _, f in runs if f})
    return [
        kind,
        latency,
        controller,
        str(len(runs)),
        _spread([m[0] for m in metrics], 'g'),
        _spread([m[1] for m in metrics], 'g'),
        _spread([m[2] for m in metrics], '.3f'),
        _spread(cycles, '.4f', worst=lambda v: max(v, key=lambda c: abs(c - mid))),
        '; '.join(failed) or 'ok',
    ]


def _offline(scene, args):
    from impact_arm.tools.latency_study import LatencyBursts, closed_loop

    controllers = [c for c in CONTROLLERS if not args.controller or c[0] in args.controller]
    bursts = None
    if args.bursts:
        probability, top, decay = float(args.bursts[0]), int(args.bursts[1]), int(args.bursts[2])
        bursts = functools.partial(LatencyBursts, probability=probability, top=top, decay=decay)

    def run(
        latency: int,
        predicted: int,
        implicit: int,
        anticipate: bool,
        jitter: float = 0.0,
        seed: int = 0,
    ) -> tuple[tuple[float, ...], tuple[float, ...], str]:
        r = closed_loop(
            scene,
            latency,
            predicted,
            args.seconds,
            jitter=jitter,
            seed=seed,
            implicit_periods=implicit,
            spread=args.spread,
            anticipate_impacts=anticipate,
            # (the steady rows pass no jitter: no bursts there either)
            bursts=bursts(latency) if bursts and jitter else None,
        )
        return r.t_contact, r.delta_m, r.failed

    rows = []
    for latency in args.latencies:
        for name, *settings in controllers:
            runs = [run(latency, *settings)]  # deterministic: one run
            rows.append(_row('offline, steady', str(latency), name, runs))
            print('  ' + ' | '.join(rows[-1]), flush=True)
    kind = 'offline, bursts' if bursts else 'offline, varying'
    widest = int(args.bursts[1]) if bursts else args.spread
    for k in args.varying:
        for name, *settings in controllers:
            runs = [
                run(k, *settings, jitter=args.jitter, seed=seed)
                for seed in range(1, args.seeds + 1)
            ]
            rows.append(_row(kind, f'{k}..{k + widest}', name, runs))
            print('  ' + ' | '.join(rows[-1]), flush=True)
    return rows


def _dds_run(scene_name, latency, predicted, seconds):
    """Simulator (lockstep, command_latency_periods) and controller nodes; impacts by
    simulated time ``seconds``."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String

    from impact_arm.physics.impact import impact_from_json

    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = str(random.randint(101, 200))
    python = sys.executable
    sim = [
        python,
        '-m',
        'impact_arm.nodes.simulator',
        '--ros-args',
        '-p',
        f'scene:={scene_name}',
        '-p',
        'mode:=lockstep',
        '-p',
        'rate_factor:=0.0',
        '-p',
        f'command_latency_periods:={latency}',
    ]
    ctrl = [
        python,
        '-m',
        'impact_arm.nodes.controller',
        '--ros-args',
        '-p',
        f'scene:={scene_name}',
        '-p',
        'startup_hold:=0.5',
        '-p',
        f'latency_periods:={predicted}',
    ]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(env['ROS_DOMAIN_ID']))
    node = rclpy.create_node('bench_latency', context=context)
    reports = []
    node.create_subscription(
        String,
        '/impact_report',
        lambda m: reports.append(impact_from_json(m.data)),
        QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL),
    )
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    procs = [
        subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for cmd in (sim, ctrl)
    ]
    end = time.monotonic() + 30 * seconds + 60
    try:
        while time.monotonic() < end and all(p.poll() is None for p in procs):
            executor.spin_once(timeout_sec=0.1)
            if reports and reports[-1].t_contact > seconds:
                break
    finally:
        for p in procs:  # ended by PID
            if p.poll() is None:
                p.send_signal(2)
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    done = [r for r in reports if r.t_contact <= seconds]
    failed = '' if procs[0].returncode in (0, -2, None) else f'simulator exit {procs[0].returncode}'
    return done, failed


def _dds(args):
    rows = []
    for latency in args.latencies:
        for predicted, name in ((0, 'off'), (-1, 'measured + implicit')):
            done, failed = _dds_run(args.scene, latency, predicted, args.dds_seconds)
            runs = [([r.t_contact for r in done], [r.delta_m for r in done], failed)]
            rows.append(_row('DDS lockstep, steady', str(latency), name, runs))
            print('  ' + ' | '.join(rows[-1]), flush=True)
    return rows


def run(args: argparse.Namespace) -> int:
    from impact_arm.physics.scene import load_scene, resolve_scene_path

    scene = load_scene(resolve_scene_path(args.scene))
    rows = _offline(scene, args)
    if args.dds:
        rows += _dds(args)
    header = [
        'loop',
        'latency [periods]',
        'controller',
        'runs',
        'impacts',
        'second strikes',
        'δm max [mm]',
        'cycle [s]',
        'run',
    ]
    print(table(header, rows))
    return 0
