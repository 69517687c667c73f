"""``impact-arm bench stress --flood RATE``: the realtime loop under a garbage flood on its
command topic (target: simulator >= 99 % of 1 kHz with <= 0.5 % overruns under 40 k msg/s).

The simulator (realtime, 1 kHz, defaults) and the controller start as a user starts them
(``bench starts``); once the controller's commands flow, ``--flood-processes`` flooder
processes publish garbage on the command topic for ``--flood-seconds``: raw malformed
payloads (random bytes, truncated messages, absurd lengths, an unknown encapsulation) and
well-typed garbage (wrong lengths, NaN, infinity), at RATE messages/s in all, in bursts every
5 ms. One Python process reaches a few thousand messages/s; what was reached is measured
(messages each flooder published, over its own time) and printed. Zero-length payloads are
left out: with rmw_fastrtps one blocks its own writer's later samples (docs/hostile_input.md),
which would silence the flood rather than test the simulator.

From the simulator's /diagnostics at the start and the end of the flood: periods published
per wall second of the simulator's own clock, overruns and skipped periods, commands taken
and refused, and the impacts (the controller still cycling).
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import tempfile
import time

from .common import worker_environment
from .generators import malformed_commands

BURST_PERIOD = 0.005  # s between two bursts of a flooder
PAYLOADS = 4000  # distinct garbage payloads a flooder cycles through
RATE_TARGET = 0.99  # share of the nominal rate targeted under a flood
OVERRUN_TARGET = 0.5  # % of periods


def add_arguments(parser):
    parser.add_argument(
        '--flood',
        type=float,
        metavar='RATE',
        default=0.0,
        help="instead of the matrix: flood the realtime simulator's command "
        'topic with RATE garbage messages/s (all flooders together) '
        'while the controller runs (bench/impact_arm_bench/flood.py)',
    )
    parser.add_argument(
        '--flood-seconds',
        type=float,
        default=15.0,
        metavar='S',
        help='length of the flood (default 15)',
    )
    parser.add_argument(
        '--flood-processes',
        type=int,
        default=4,
        metavar='N',
        help='flooder processes sharing RATE (default 4)',
    )
    parser.add_argument(
        '--flooders-idle',
        action='store_true',
        help='run the flooders under SCHED_IDLE: they get only the CPU nobody '
        'else wants, which separates "the flooders take the cores" from '
        '"the simulator\'s own work under a flood"',
    )


def flooder():
    """A flooder process: argv rate, seconds, seed, go file. Once matched, creates GO.SEED
    and waits for GO (every flooder started, the statistics taken); publishes until the time
    is up, then
    prints {"sent": N, "seconds": S} (S from its first to its last burst)."""
    import rclpy
    from std_msgs.msg import Float64MultiArray
    from impact_arm import contract

    rate, seconds, seed, go = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    rclpy.init()
    node = rclpy.create_node(f'bench_flooder_{seed}')
    pub = node.create_publisher(
        Float64MultiArray, contract.COMMANDS, contract.qos(contract.COMMANDS).to_rclpy()
    )
    payloads = malformed_commands(random.Random(seed), PAYLOADS)
    end = time.monotonic() + 30.0
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    ready = go + f'.{seed}'
    open(ready, 'w').close()
    while not os.path.exists(go) and time.monotonic() < end:  # all flooders start together
        time.sleep(0.01)
    per_burst = max(1, round(rate * BURST_PERIOD))
    sent, k = 0, 0
    start = time.monotonic()
    end = start + seconds
    while time.monotonic() < end:
        for _ in range(per_burst):
            pub.publish(payloads[sent % PAYLOADS])
            sent += 1
        k += 1
        delay = start + k * BURST_PERIOD - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    print(json.dumps({'sent': sent, 'seconds': time.monotonic() - start}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def _idle():
    """In a flooder child: SCHED_IDLE."""
    os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))


def thread_cpu(pid) -> dict:
    """CPU seconds so far of a process's threads, by role: the realtime loop ('sim-loop'),
    the middleware's threads ('dds.*') and the rest (the executor), each with its scheduling
    (``SCHED_FIFO 50``) as a second key."""
    from .common import cpu_seconds

    roles = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as f:
                comm = f.read().strip()
            seconds = cpu_seconds(f'/proc/{pid}/task/{tid}/stat')
            policy = os.sched_getscheduler(int(tid))
            priority = os.sched_getparam(int(tid)).sched_priority
        except OSError:
            continue  # the thread ended meanwhile
        role = (
            'loop' if comm == 'sim-loop' else 'middleware' if comm.startswith('dds.') else 'other'
        )
        cpu, schedules = roles.get(role, (0.0, set()))
        roles[role] = (
            cpu + seconds,
            schedules | {f'SCHED_FIFO {priority}' if policy == os.SCHED_FIFO else 'normal'},
        )
    return roles


def _values_now(seen):
    """The simulator's latest report (a runner.SimulatorReport), None before its first."""
    return seen['diagnostics'][-1] if seen['diagnostics'] else None


def _wait_diagnostics(executor, seen, since, timeout):
    """The first report that arrives after ``since`` (a previous report, or None)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
        if seen['diagnostics'] and seen['diagnostics'][-1] is not since:
            return seen['diagnostics'][-1]
    return None


def measure(args, env, logdir) -> dict:
    from .starts import START_TIMEOUT, _listener, start_nodes, stop_all

    domain = int(env['ROS_DOMAIN_ID'])
    rclpy, context, node, executor, seen = _listener(domain)
    procs, flooders = {}, []
    try:
        start_nodes(procs, env, logdir)
        end = time.monotonic() + START_TIMEOUT
        while not (seen['diagnostics'] and seen['diagnostics'][-1].status.commands):
            executor.spin_once(timeout_sec=0.05)
            if time.monotonic() > end or procs['simulator'].poll() is not None:
                return {
                    'error': "the controller's commands did not reach the simulator; "
                    f'logs in {logdir}'
                }
        count = max(1, args.flood_processes)
        go = os.path.join(logdir, 'flood-go')
        for k in range(count):
            flooders.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        '-c',
                        'from impact_arm_bench.flood import flooder; flooder()',
                        repr(args.flood / count),
                        repr(args.flood_seconds),
                        str(k),
                        go,
                    ],
                    env=worker_environment(env),
                    stdout=subprocess.PIPE,
                    stderr=subprocess.DEVNULL,
                    text=True,
                    preexec_fn=_idle if args.flooders_idle else None,
                )
            )
        # the window starts when every flooder is ready (their start-up is not the flood)
        end = time.monotonic() + START_TIMEOUT
        while not all(os.path.exists(f'{go}.{k}') for k in range(count)) and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        before = _wait_diagnostics(executor, seen, _values_now(seen), 5.0) or _values_now(seen)
        cpu_before, wall_before = thread_cpu(procs['simulator'].pid), time.monotonic()
        open(go, 'w').close()
        end = time.monotonic() + args.flood_seconds + 30.0
        while any(f.poll() is None for f in flooders) and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        cpu_after, wall = thread_cpu(procs['simulator'].pid), time.monotonic() - wall_before
        after = _wait_diagnostics(executor, seen, _values_now(seen), 5.0) or _values_now(seen)
        sent = [json.loads(f.communicate(timeout=10)[0] or '{}') for f in flooders]
        alive = {name: p.poll() is None for name, p in procs.items()}
    finally:
        for p in flooders:
            if p.poll() is None:
                p.kill()
                p.wait()
        stop_all(procs, rclpy, context, node, executor)
    figures = _figures(before, after, sent, alive)
    figures['simulator_cpu'] = {
        role: (100.0 * (cpu - cpu_before.get(role, (0.0,))[0]) / wall, sorted(schedules))
        for role, (cpu, schedules) in cpu_after.items()
    }
    return figures


def _figures(before, after, sent, alive) -> dict:
    """The flood window's figures from the simulator's reports ``before`` and ``after`` it."""
    b, a = before.status, after.status
    wall = a.wall_time - b.wall_time
    periods = a.periods_published - b.periods_published
    nominal = a.publish_rate_requested
    reached = [s['sent'] / s['seconds'] for s in sent if s.get('seconds')]
    return {
        'flood_rate_reached': sum(reached),
        'flooders': len(sent),
        'flood_sent': sum(s.get('sent', 0) for s in sent),
        'window_s': wall,
        'periods': periods,
        'rate_achieved': periods / wall if wall > 0 else float('nan'),
        'rate_nominal': nominal,
        'overruns': a.overruns - b.overruns,
        'periods_skipped': a.periods_skipped - b.periods_skipped,
        'overrun_percent': 100.0 * (a.overruns - b.overruns) / periods if periods else float('nan'),
        'commands': a.commands - b.commands,
        'commands_rejected': a.commands_rejected - b.commands_rejected,
        'commands_superseded': a.commands_superseded - b.commands_superseded,
        'periods_flooded': a.commands_flooded - b.commands_flooded,
        'periods_without_new_command': a.periods_without_new_command
        - b.periods_without_new_command,
        'impacts': a.impacts - b.impacts,
        'sim_time_s': a.sim_time - b.sim_time,
        'watchdog': a.watchdog.value,
        'level': int(after.level),
        'message': after.message,
        'alive': alive,
        # the flood window's mean period parts [us], from the whole-run means before and after
        'period_parts_us': {
            'commands': _window_mean(b, a, lambda s: s.compute_commands_mean_us),
            'physics': _window_mean(b, a, lambda s: s.compute_physics_mean_us),
            'publish': _window_mean(b, a, lambda s: s.compute_publish_mean_us),
        },
    }


def _window_mean(before, after, mean):
    """The mean over the periods between two simulator statuses of a whole-run mean
    (``mean(status)``)."""
    n0, n1 = before.periods_published, after.periods_published
    m0, m1 = mean(before), mean(after)
    return (m1 * n1 - m0 * n0) / (n1 - n0) if n1 > n0 else float('nan')


def report(args) -> int:
    from impact_arm.tools.runner import dds_environment
    from .starts import wakeup_floor

    if not args.flood > 0 or args.flood_seconds <= 0:
        print('--flood and --flood-seconds must be > 0', file=sys.stderr)
        return 2
    env = dds_environment()
    logdir = tempfile.mkdtemp(prefix='impact_arm_bench_flood_')
    print(
        f'bench stress --flood {args.flood:g}: simulator (realtime 1 kHz) + controller, '
        f'{args.flood_processes} flooders for {args.flood_seconds:g} s, '
        f'ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]} (localhost); {os.cpu_count()} cores; logs in '
        f'{logdir}',
        file=sys.stderr,
        flush=True,
    )
    floor = wakeup_floor()
    f = measure(args, env, logdir)
    if 'error' in f:
        print(f'bench stress --flood: {f["error"]}', file=sys.stderr)
        return 1
    share = f['rate_achieved'] / f['rate_nominal']
    print(
        f'flood: {f["flood_sent"]} garbage messages from {f["flooders"]} processes, '
        f'{f["flood_rate_reached"]:.0f} msg/s reached (asked {args.flood:g}); the simulator '
        f'refused {f["commands_rejected"]}, left {f["commands_superseded"]} unchecked behind '
        f'a newer valid one and applied {f["commands"]} valid commands'
    )
    print(
        f'simulator: {f["periods"]} periods in {f["window_s"]:.2f} s = '
        f'{f["rate_achieved"]:.1f} Hz ({100 * share:.2f} % of {f["rate_nominal"]:g}, target '
        f'>= {100 * RATE_TARGET:g} %); {f["overruns"]} overruns = '
        f'{f["overrun_percent"]:.3f} % (target <= {OVERRUN_TARGET:g} %), '
        f'{f["periods_skipped"]} periods skipped, {f["periods_flooded"]} periods left '
        f'commands queued, {f["periods_without_new_command"]} without a new command'
    )
    parts = f['period_parts_us']
    print(
        f'period parts during the flood (means): commands {parts["commands"]:.1f} us, '
        f'physics {parts["physics"]:.1f} us, publish {parts["publish"]:.1f} us; simulator '
        f'CPU '
        + ', '.join(
            f'{role} {cpu:.0f} % ({"/".join(sched)})'
            for role, (cpu, sched) in sorted(f['simulator_cpu'].items())
        )
        + ('; flooders at SCHED_IDLE' if args.flooders_idle else '')
    )
    print(
        f'controller: {f["impacts"]} impacts in {f["sim_time_s"]:.2f} s simulated during the '
        f'flood; watchdog {f["watchdog"]}; still running: '
        + ', '.join(f'{k} {"yes" if v else "NO"}' for k, v in f['alive'].items())
    )
    if f['level'] == 2:
        print(
            f'the simulator stopped during the flood: {f["message"]} (the window above ends there)'
        )
    print(
        f'machine just before: {floor["late"]} of {floor["periods"]} bare 1 ms sleeps woke '
        f'> 1 ms late ({100 * floor["late"] / floor["periods"]:.2f} %)'
    )
    if args.json:
        from . import common

        common.write_json(
            args.json,
            {
                'benchmark': 'stress --flood',
                'machine': common.machine(),
                'flood': f,
                'machine_floor': floor,
            },
        )
    return 0 if all(f['alive'].values()) else 1
