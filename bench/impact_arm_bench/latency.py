"""``impact-arm bench latency``: the article's limit cycle against the command latency a driver
stack adds, with and without the controller's prediction (its ``latency_periods``).

1. offline (tools/latency_study.py): the simulator's lockstep session and the controller's
   input handling joined by queues, the driver delaying each command by 0-3 periods, fixed or
   with a jitter of one period (an unsynchronised controller manager);
2. over DDS (``--dds``): the simulator node in lockstep with ``command_latency_periods`` and
   the controller node, ``latency_periods`` -1 (measured) or 0, on a free local domain.

For each: impacts, second strikes (an impact within 50 ms of the previous one), the largest
penetration δm and the mean cycle period after the first five impacts.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time

from .common import table


def add_arguments(parser):
    parser.add_argument('--scene', default='paper')
    parser.add_argument('--seconds', type=float, default=10.0, help='simulated s per run')
    parser.add_argument('--latencies', type=int, nargs='*', default=[0, 1, 2, 3])
    parser.add_argument('--jitter', type=float, default=0.3, help='offline jitter runs')
    parser.add_argument('--dds', action='store_true', help='also over DDS (nodes)')
    parser.add_argument('--dds-seconds', type=float, default=4.0)


def _row(kind, latency, prediction, impacts, contacts, delta_m, failed=''):
    gaps = [b - a for a, b in zip(contacts, contacts[1:])]
    second = sum(g < 0.05 for g in gaps)
    cycles = [g for g in gaps[4:] if g >= 0.05]
    return [
        kind,
        str(latency),
        prediction,
        str(impacts),
        str(second),
        f'{max(delta_m) * 1e3:.3f}' if delta_m else '-',
        f'{sum(cycles) / len(cycles):.4f}' if cycles else '-',
        failed[:40] or 'ok',
    ]


def _offline(scene, args):
    from impact_arm.tools.latency_study import closed_loop

    rows = []
    for jitter in (0.0, args.jitter):
        for latency in args.latencies:
            for predicted, name in ((0, 'off'), (-1, 'measured')):
                if jitter and not latency:
                    continue
                r = closed_loop(scene, latency, predicted, args.seconds, jitter=jitter, seed=1)
                kind = f'offline, jitter {jitter:g}' if jitter else 'offline'
                rows.append(_row(kind, latency, name, r.impacts, r.t_contact, r.delta_m, r.failed))
                print('  ' + ' | '.join(rows[-1]), flush=True)
    return rows


def _dds_run(scene_name, latency, predicted, seconds):
    """Simulator (lockstep, command_latency_periods) and controller nodes; impacts by
    simulated time ``seconds``."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from std_msgs.msg import String

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
        lambda m: reports.append(json.loads(m.data)),
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
            if reports and reports[-1]['t_contact'] > seconds:
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
    done = [r for r in reports if r['t_contact'] <= seconds]
    failed = '' if procs[0].returncode in (0, -2, None) else f'simulator exit {procs[0].returncode}'
    return done, failed


def _dds(args):
    rows = []
    for latency in args.latencies:
        for predicted, name in ((0, 'off'), (-1, 'measured')):
            done, failed = _dds_run(args.scene, latency, predicted, args.dds_seconds)
            rows.append(
                _row(
                    'DDS lockstep',
                    latency,
                    name,
                    len(done),
                    [r['t_contact'] for r in done],
                    [r['delta_m'] for r in done],
                    failed,
                )
            )
            print('  ' + ' | '.join(rows[-1]), flush=True)
    return rows


def run(args):
    from impact_arm.physics.scene import load_scene, resolve_scene_path

    scene = load_scene(resolve_scene_path(args.scene))
    rows = _offline(scene, args)
    if args.dds:
        rows += _dds(args)
    header = [
        'loop',
        'latency [periods]',
        'prediction',
        'impacts',
        'second strikes',
        'δm max [mm]',
        'cycle [s]',
        'run',
    ]
    print(table(header, rows))
    return 0
