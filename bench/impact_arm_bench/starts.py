"""``impact-arm bench starts [--runs N]``: does the realtime mode survive being started the
way a user starts it?

Each run starts the simulator (realtime, 1 kHz, defaults) and the controller as two separate
processes at the same moment, as from two shells (``python -m impact_arm.nodes.simulator``
is what ``ros2 run impact_arm simulator`` runs), with no warm-up and no waiting between them,
and lets them run for the article's 15 cycles (15 impacts, or 7 simulated seconds when
impacts go missing). A listener in this process takes only /impact_report and /diagnostics.
The controller's start-up hold (``startup_hold``, 4 s before its first command) is the node's
own default, so it counts here exactly as it does for a user.
Per start it prints: stopped or not, the cycle period against the article's 0.397 s, impacts
per simulated second, overruns and skipped periods, the worst period and its split; then the
summary the targets are stated in.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from typing import Any

ARTICLE_PERIOD = 0.397  # s, the article's limit cycle
CYCLES = 15
PERIOD_TOLERANCE = 0.05  # a cycle period further off than this means a missed impact
SIM_TIME_LIMIT = 7.0  # s simulated: the 15th impact is due at ~5.8 s
START_TIMEOUT = 120.0  # wall s for the first command (a cold numba cache compiles)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--runs',
        type=int,
        default=5,
        metavar='N',
        help='number of starts (default 5; docs/benchmarks.md uses 30)',
    )
    parser.add_argument('--json', metavar='FILE', help='write the per-start rows as JSON')
    parser.add_argument(
        '--keep-logs',
        action='store_true',
        help="keep the nodes' logs (else removed unless a start failed)",
    )


def _listener(domain):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String
    from impact_arm import contract
    from impact_arm.physics.impact import impact_from_json
    from impact_arm.tools.runner import simulator_report

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('bench_starts_listener', context=context)
    seen = {'impacts': [], 'diagnostics': []}
    node.create_subscription(
        String,
        contract.IMPACT_REPORT,
        lambda m: seen['impacts'].append(impact_from_json(m.data)),
        contract.qos(contract.IMPACT_REPORT).to_rclpy(),
    )

    def on_diagnostics(msg: Any) -> None:
        report = simulator_report(msg)
        if report is not None:
            seen['diagnostics'].append(report)

    node.create_subscription(DiagnosticArray, contract.DIAGNOSTICS, on_diagnostics, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return rclpy, context, node, executor, seen


def start_nodes(
    procs: dict[str, subprocess.Popen], env: dict[str, str], logdir: str, prefix: str = ''
) -> None:
    """Start simulator and controller into ``procs`` as a user does (``python -m`` is what
    ``ros2 run`` runs), each logging to LOGDIR/PREFIX<node>.log; filled one by one, so
    ``stop_all`` ends whatever started even if the second start fails."""
    for name in ('simulator', 'controller'):
        with open(os.path.join(logdir, f'{prefix}{name}.log'), 'wb') as log:
            procs[name] = subprocess.Popen(
                [sys.executable, '-m', f'impact_arm.nodes.{name}'],
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
            )


def stop_all(
    procs: dict[str, subprocess.Popen], rclpy: Any, context: Any, node: Any, executor: Any
) -> None:
    """SIGINT every node still running (by PID; SIGKILL after 10 s), then the listener."""
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs.values():
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def one_start(index: int, env: dict[str, str], logdir: str) -> dict[str, Any]:
    """One user-like start; returns its row."""
    domain = int(env['ROS_DOMAIN_ID'])
    rclpy, context, node, executor, seen = _listener(domain)
    procs = {}
    try:
        start_nodes(procs, env, logdir, f'{index:02d}_')
        started = time.monotonic()
        sim = procs['simulator']
        outcome = ''
        while not outcome:
            executor.spin_once(timeout_sec=0.05)
            report = seen['diagnostics'][-1] if seen['diagnostics'] else None
            status = report.status if report else None
            if sim.poll() is not None:
                outcome = f'simulator exited ({sim.returncode})'
            elif report and report.stopped:
                outcome = 'stopped: ' + report.message
            elif len(cycles_of(sorted(i.t_contact for i in seen['impacts']))) >= CYCLES:
                outcome = 'completed'
            elif status and status.sim_time > SIM_TIME_LIMIT:
                outcome = f'{SIM_TIME_LIMIT:g} s simulated'
            elif not (status and status.commands) and time.monotonic() - started > START_TIMEOUT:
                outcome = f'no command within {START_TIMEOUT:g} s'
        # one more report, covering the last impact
        last = seen['diagnostics'][-1] if seen['diagnostics'] else None
        deadline = time.monotonic() + 2.5
        while (
            sim.poll() is None
            and time.monotonic() < deadline
            and (not seen['diagnostics'] or seen['diagnostics'][-1] is last)
        ):
            executor.spin_once(timeout_sec=0.05)
    finally:
        stop_all(procs, rclpy, context, node, executor)
    return _row(index, outcome, seen)


def wakeup_floor(
    seconds: float = 2.0, period: float = 1e-3, priority: int = 50
) -> dict[str, float]:
    """The machine's own share of late periods: a bare loop that only sleeps to a 1 ms
    schedule, at the simulator loop's default priority (SCHED_FIFO 50 where allowed), counts
    wake-ups later than one period after their deadline — what an overrun is to the
    simulator. Measured next to every start, so a VM that stalls on its own is told apart
    from our code."""
    policy = os.sched_getscheduler(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError):
        pass  # no realtime priority here: the nodes fall back likewise
    late, worst, k = 0, 0.0, 0
    start = time.monotonic()
    try:
        while k * period < seconds:
            k += 1
            deadline = start + k * period
            now = time.monotonic()
            if deadline > now:
                time.sleep(deadline - now)
            lateness = time.monotonic() - deadline
            late += lateness > period
            worst = max(worst, lateness)
    finally:
        try:
            os.sched_setscheduler(0, policy, os.sched_param(0))
        except (AttributeError, OSError):
            pass
    return {'periods': k, 'late': late, 'worst_us': worst * 1e6}


def cycles_of(times: Iterable[float]) -> list[list[float]]:
    """Impact times grouped into cycles: an impact within half a period of the previous one
    is a re-strike of the same cycle (the arm bounced before it rose), not a new cycle."""
    cycles = []
    for t in times:
        if cycles and t - cycles[-1][-1] < 0.5 * ARTICLE_PERIOD:
            cycles[-1].append(t)
        else:
            cycles.append([t])
    return cycles


def _simulator_counts(status):
    """The row's values from the simulator's latest status (None: it never reported one:
    -1, NaN or '?')."""
    if status is None:
        nan = float('nan')
        return {
            'overruns': -1,
            'periods_skipped': 0,
            'periods_without_new_command': 0,
            'watchdog_timeouts': 0,
            'longest_command_silence_s': nan,
            'worst_period_us': nan,
            'worst_period_at_s': nan,
            'worst_split_us': {'commands': nan, 'physics': nan, 'publish': nan},
            'jitter_max_us': nan,
            'kernel': '?',
        }
    return {
        'overruns': status.overruns,
        'periods_skipped': status.periods_skipped,
        'periods_without_new_command': status.periods_without_new_command,
        # a silence of the controller longer than the watchdog zeroes the torque and the arm
        # falls: a cycle lost that way is the transport's, not a missed down-up switch
        'watchdog_timeouts': status.watchdog_timeouts,
        # ~0.333 s here is Fast DDS's shared-memory health check (docs/benchmarks.md)
        'longest_command_silence_s': status.longest_command_silence_s,
        'worst_period_us': status.compute_worst_us,
        'worst_period_at_s': status.compute_worst_at_s,
        'worst_split_us': {
            'commands': status.compute_worst_commands_us,
            'physics': status.compute_worst_physics_us,
            'publish': status.compute_worst_publish_us,
        },
        'jitter_max_us': status.jitter_run_max_us,
        'kernel': status.kernel,
    }


def _row(index, outcome, seen):
    status = seen['diagnostics'][-1].status if seen['diagnostics'] else None
    times = sorted(i.t_contact for i in seen['impacts'])
    starts = [c[0] for c in cycles_of(times)]
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    period = (starts[-1] - starts[0]) / (len(starts) - 1) if len(starts) > 1 else float('nan')
    worst_gap = max((abs(g / ARTICLE_PERIOD - 1) for g in gaps), default=float('inf'))
    sim_time = status.sim_time if status else 0.0
    periods = status.periods_published if status else 0
    # a missed down-up switch leaves the arm on the surface: a cycle too long or too short
    missed = (
        len(starts) < min(CYCLES, sim_time / ARTICLE_PERIOD - 1) or worst_gap > PERIOD_TOLERANCE
    )
    return {
        'start': index,
        'outcome': outcome,
        'stopped': not outcome.startswith(('completed', f'{SIM_TIME_LIMIT:g}')),
        'impacts': len(times),
        'cycles': len(starts),
        're_strikes': len(times) - len(starts),
        'sim_time_s': sim_time,
        'impacts_per_sim_s': len(times) / sim_time if sim_time else 0.0,
        'cycle_period_s': period,
        'worst_cycle_deviation': worst_gap,
        'missed_impact': missed,
        'periods': periods,
        **_simulator_counts(status),
        'impact_times_s': times,
    }


def _missed_label(r):
    if not r['missed_impact']:
        return ''
    return ' MISSED IMPACT' + (
        ' (after a watchdog timeout: the commands stopped and the arm fell)'
        if r['watchdog_timeouts']
        else ''
    )


def _print_row(r):
    split = ', '.join(f'{k} {v:.0f}' for k, v in r['worst_split_us'].items())
    print(
        f'start {r["start"]:2d}: {"STOPPED" if r["stopped"] else "ran"} ({r["outcome"]}); '
        f'{r["impacts"]} impacts in {r["sim_time_s"]:.2f} s simulated = '
        f'{r["impacts_per_sim_s"]:.3f}/s (article {1 / ARTICLE_PERIOD:.3f}/s), '
        f'{r["cycles"]} cycles, {r["re_strikes"]} re-strikes, cycle '
        f'{r["cycle_period_s"]:.4f} s{_missed_label(r)}; '
        f'{r["overruns"]} overruns, {r["periods_skipped"]} skipped of {r["periods"]} periods, '
        f'{r["periods_without_new_command"]} without a new command, '
        f'{r["watchdog_timeouts"]} watchdog timeouts (longest silence '
        f'{r["longest_command_silence_s"] * 1e3:.0f} ms); '
        f'worst period {r["worst_period_us"]:.0f} us at t = {r["worst_period_at_s"]:.3f} s '
        f'({split} us)',
        flush=True,
    )
    floor = r.get('machine_floor')
    if floor:
        print(
            f'          machine just before: {floor["late"]} of {floor["periods"]} bare 1 ms '
            f'sleeps woke > 1 ms late ({100 * floor["late"] / floor["periods"]:.2f} %), worst '
            f'{floor["worst_us"]:.0f} us',
            flush=True,
        )
    if (r['missed_impact'] or r['re_strikes']) and r['impact_times_s']:
        gaps = [b - a for a, b in zip(r['impact_times_s'], r['impact_times_s'][1:])]
        print(
            '          impacts at '
            + ', '.join(f'{t:.3f}' for t in r['impact_times_s'])
            + ' s; gaps '
            + ', '.join(f'{g:.3f}' for g in gaps),
            flush=True,
        )


def summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The target figures over all starts."""
    periods = sum(max(r['periods'], 0) for r in rows)
    overruns = sum(max(r['overruns'], 0) for r in rows)
    worst = [r['worst_period_us'] for r in rows]
    return {
        'starts': len(rows),
        'stopped': sum(r['stopped'] for r in rows),
        'missed_impact': sum(r['missed_impact'] for r in rows),
        'missed_after_watchdog_timeout': sum(
            r['missed_impact'] and r['watchdog_timeouts'] > 0 for r in rows
        ),
        'watchdog_timeouts': sum(r['watchdog_timeouts'] for r in rows),
        're_strikes': sum(r['re_strikes'] for r in rows),
        'overruns': overruns,
        'periods': periods,
        'periods_without_new_command': sum(r['periods_without_new_command'] for r in rows),
        'overrun_percent': 100.0 * overruns / periods if periods else float('nan'),
        'worst_period_us_median': statistics.median(worst) if worst else float('nan'),
        'worst_period_us_max': max(worst) if worst else float('nan'),
        'runs_worst_period_within_1ms_percent': 100.0 * sum(w <= 1000.0 for w in worst) / len(worst)
        if worst
        else float('nan'),
        'cycle_period_s_median': statistics.median(r['cycle_period_s'] for r in rows),
        'machine_late_percent': 100.0
        * sum(r['machine_floor']['late'] for r in rows)
        / sum(r['machine_floor']['periods'] for r in rows)
        if all('machine_floor' in r for r in rows)
        else float('nan'),
    }


def run(args: argparse.Namespace) -> int:
    from impact_arm.tools.runner import dds_environment

    if args.runs < 1:
        print(f'--runs = {args.runs}: must be >= 1', file=sys.stderr)
        return 2
    env = dds_environment()
    from impact_arm.physics.scene import load_scene
    from impact_arm.tools.runner import precompile

    precompile(load_scene('paper'), 1000.0)  # a cold cache compiles here, announced
    logdir = tempfile.mkdtemp(prefix='impact_arm_bench_starts_')
    print(
        f'bench starts: {args.runs} starts of simulator (realtime 1 kHz) + controller, '
        f'ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]} (localhost); {os.cpu_count()} cores; '
        f'logs in {logdir}',
        file=sys.stderr,
        flush=True,
    )
    rows = []
    for index in range(1, args.runs + 1):
        floor = wakeup_floor()
        rows.append(one_start(index, env, logdir))
        rows[-1]['machine_floor'] = floor
        _print_row(rows[-1])
    s = summary(rows)
    print(
        f'summary: {s["stopped"]} of {s["starts"]} starts stopped (target 0), '
        f'{s["missed_impact"]} with a missed impact (target 0; '
        f'{s["missed_after_watchdog_timeout"]} of them after a watchdog timeout), '
        f'{s["re_strikes"]} re-strikes, {s["watchdog_timeouts"]} watchdog timeouts; '
        f'overruns {s["overruns"]} of '
        f'{s["periods"]} periods = {s["overrun_percent"]:.3f} % (target <= 0.1 %); periods without a '
        f'new command (controller late) {s["periods_without_new_command"]}; worst '
        f'period median {s["worst_period_us_median"]:.0f} us, worst '
        f'{s["worst_period_us_max"]:.0f} us; runs with worst period <= 1 ms: '
        f'{s["runs_worst_period_within_1ms_percent"]:.0f} % (target >= 95 %); cycle period '
        f'median {s["cycle_period_s_median"]:.4f} s (article {ARTICLE_PERIOD} s); the machine '
        f'alone: {s["machine_late_percent"]:.3f} % of bare 1 ms sleeps woke > 1 ms late'
    )
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'starts': rows, 'summary': s}, f, indent=1)
    failed = s['stopped'] or s['missed_impact']
    if not (failed or args.keep_logs):
        import shutil

        shutil.rmtree(logdir, ignore_errors=True)
    return 1 if failed else 0
