"""``impact-arm bench ros2control``: the ros2_control set-up of docs/ros2_control.md in real
time at 1 kHz, with the stand-in stack (test/support/ros2control_standin.py) in place of
controller_manager + TopicBasedSystem + joint_state_broadcaster + JointGroupEffortController.
One run is test/support/standin_stack.py's, which the realtime test of test/nodes/test_topic_hardware.py
runs too.

Per run the three processes start in the chosen order (``--order``, a second apart): the
stand-in at 1 000 updates per wall second on its sleep-until schedule (no waiting for peers),
the simulator ``mode:=realtime`` at 1 kHz, the project's controller remapped to the
broadcaster's states and the effort controller's commands. Until the article's 15 cycles (16
impacts) or ``--timeout``: impacts, second strikes (two within 50 ms), the first strike's
simulated time, the largest penetration δm, the controller's measured latency histogram and
implicit commands, the simulator's overruns and skipped periods, the stand-in's stale updates,
and CPU per process (user + system over the driven part of the run). Processes run on a free
local DDS domain (localhost discovery) and are ended by PID. ``--threads``: CPU per thread
too (user + system from /proc/PID/task/*/stat, by thread name). ``--standin-threads-model
stack``: the stand-in with the real stack's threads (an executor thread for the commands, the
update thread on its schedule reading one state per update as TopicBasedSystem does, the
broadcaster's publishing thread; test/support/ros2control_standin.py) instead of its one loop.

``--sim-time X``: docs/ros2_control.md's reproducible set-up on simulated time instead (the
stand-in updating on /clock, the simulator in lockstep braked until X s, the controller with
use_sim_time), and the offline closed loop (impact_arm.tools.latency_study.closed_loop) at the
latency it fixes, one period, with the same release: per run whether the impacts equal the
offline loop's to the bit (t_contact, δm), and whether all runs are identical (t_contact, δm,
F_max and the controller's latency histogram). ``--busy N`` runs N busy loops beside the
even-numbered runs (run 2, 4, ...): the same run at another load.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
from typing import Any

from .common import BENCH_FOLDER, cpu_seconds


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--runs', type=int, default=1, help='runs (default 1)')
    parser.add_argument(
        '--order',
        default='standin,simulator,controller',
        help='start order, comma-separated permutation of standin,simulator,controller',
    )
    parser.add_argument('--timeout', type=float, default=40.0, help='s of wall time per run')
    parser.add_argument(
        '--scene', help="scene file for the simulator and the controller (default: the article's)"
    )
    parser.add_argument(
        '--standin-priority',
        type=int,
        default=50,
        help="the stand-in's SCHED_FIFO priority (0: normal scheduling; default 50)",
    )
    parser.add_argument(
        '--controller-params',
        nargs='*',
        default=[],
        metavar='K:=V',
        help='extra controller parameters (e.g. implicit_periods:=0)',
    )
    parser.add_argument(
        '--simulator-params',
        nargs='*',
        default=[],
        metavar='K:=V',
        help='extra simulator parameters (e.g. thread_priority:=0)',
    )
    parser.add_argument(
        '--standin-fifo-threads',
        choices=('all', 'update'),
        default='all',
        help="the stand-in's threads under SCHED_FIFO: all (default) or update (the "
        "controller_manager's own choice: its update thread only, the middleware at normal "
        'priority)',
    )
    parser.add_argument(
        '--standin-threads-model',
        choices=('loop', 'stack'),
        default='loop',
        help="the stand-in's threads: loop (default: one loop takes its samples and "
        "publishes, commands written one update late) or stack (the real stack's: an "
        'executor thread for the commands, the update thread on its schedule, the '
        "broadcaster's publishing thread; commands written in the update)",
    )
    parser.add_argument(
        '--standin-state-reader',
        choices=('spin-some', 'executor'),
        default='spin-some',
        help='with --standin-threads-model stack: the states taken one per read in the '
        "update (TopicBasedSystem's spin_some, default) or by the executor, newest wins",
    )
    parser.add_argument(
        '--standin-reception-stall',
        type=float,
        default=0.0,
        metavar='S',
        help='with --standin-threads-model stack: S s of reads that take nothing from the '
        "simulator's first state on (a discovery stall of the stack's reception; default 0)",
    )
    parser.add_argument(
        '--standin',
        metavar='FILE',
        help="another stand-in program with the same options (default: the tests' one)",
    )
    parser.add_argument(
        '--logs', metavar='DIR', help="keep each run's process output in DIR/run_N (default: none)"
    )
    parser.add_argument('--json', metavar='FILE', help='write the runs as JSON')
    parser.add_argument(
        '--sim-time',
        type=float,
        metavar='X',
        help='the reproducible set-up on simulated time, the arm released at X s (e.g. 3)',
    )
    parser.add_argument(
        '--busy',
        type=int,
        default=0,
        metavar='N',
        help='busy loops beside every second run (default 0)',
    )
    parser.add_argument('--threads', action='store_true', help='CPU per thread too')


def _one_run(args, order, workdir):
    from ros_helpers import make_env
    from standin_stack import run_stack

    return run_stack(
        order,
        make_env(),
        workdir,
        timeout=args.timeout,
        standin=args.standin,
        standin_priority=args.standin_priority,
        standin_args=(
            '--fifo-threads',
            args.standin_fifo_threads,
            *(
                (
                    '--state-reader',
                    args.standin_state_reader,
                    '--reception-stall',
                    repr(args.standin_reception_stall),
                )
                if args.standin_threads_model == 'stack'
                else ()
            ),
        ),
        standin_threads_model=args.standin_threads_model,
        controller_params=args.controller_params,
        simulator_params=args.simulator_params,
        cpu_seconds=lambda pid: cpu_seconds(f'/proc/{pid}/stat'),
        thread_cpu=thread_cpu_seconds if args.threads else None,
        scene=args.scene,
        sim_time=args.sim_time,
    )


def thread_cpu_seconds(pid: int) -> dict[str, float]:
    """User + system CPU seconds of each of a process's threads, by ``name/tid`` (a thread
    that ended meanwhile is left out)."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm') as f:
                name = f.read().strip()
            out[f'{name}/{tid}'] = cpu_seconds(f'/proc/{pid}/task/{tid}/stat')
        except OSError:
            continue
    return out


def _offline(args):
    """The offline closed loop the sim-time set-up is compared with: one period of latency,
    the latency measured from the efforts, the same release."""
    from standin_stack import CYCLES

    from impact_arm.physics.scene import load_scene, resolve_scene_path
    from impact_arm.tools.latency_study import closed_loop

    scene = load_scene(args.scene or resolve_scene_path('paper'))
    return closed_loop(
        scene, 1, -1, t_max=args.sim_time + 0.4 * (CYCLES + 2), release_after=args.sim_time
    )


def _direct_cycle(args) -> float:
    """The mean cycle of the scene's offline closed loop without latency (the direct run the
    realtime criteria compare with), after the fifth impact."""
    from standin_stack import CYCLES

    from impact_arm.physics.scene import load_scene, resolve_scene_path
    from impact_arm.tools.latency_study import closed_loop

    scene = load_scene(args.scene or resolve_scene_path('paper'))
    return closed_loop(scene, 0, 0, t_max=0.45 * (CYCLES + 2)).mean_cycle(skip=5)


def _latency_shares(histogram: str) -> tuple[int | None, float]:
    """(the most frequent latency, the share of commands at 4 periods or fewer) of a
    controller's ``latency_histogram`` text ('periods:count ...')."""
    counts = {int(k): int(v) for k, v in (pair.split(':') for pair in histogram.split())}
    total = sum(counts.values())
    if not total:
        return None, 0.0
    mode = max(counts, key=lambda k: counts[k])
    return mode, sum(v for k, v in counts.items() if k <= 4) / total


def _criteria(results: list[dict], direct: float) -> None:
    """The realtime criteria of docs/ros2_control.md beside the strikes: the mean cycle
    within 1 % of the direct run's, the command latency's mode at most 2 periods and at
    most 4 in 99 % of the commands, and the median CPU of the simulator and the
    controller under a third of a core."""
    n = len(results)
    within = sum(
        r['cycle_departure'] is not None and abs(r['cycle_departure']) <= 0.01 for r in results
    )
    modes = sum(r['latency_mode'] is not None and r['latency_mode'] <= 2 for r in results)
    tails = sum(r['latency_within_4'] >= 0.99 for r in results)
    print(
        f'direct run (offline, no latency): mean cycle {direct:.4f} s; cycle within 1 %: '
        f'{within} of {n}; latency mode <= 2: {modes} of {n}; <= 4 in 99 % of commands: '
        f'{tails} of {n}'
    )
    for role in ('simulator', 'controller'):
        cpu = [r['cpu_percent'][role] for r in results if role in r['cpu_percent']]
        if cpu:
            print(
                f'{role} CPU: median {statistics.median(cpu):.1f} %, worst {max(cpu):.1f} % '
                f'of a core (criterion: under 33.3 % in the median)'
            )


def _busy(n):
    return [
        subprocess.Popen([sys.executable, '-c', 'while True: pass'], stdin=subprocess.DEVNULL)
        for _ in range(n)
    ]


def _identical(runs) -> bool:
    """The first CYCLES + 1 impacts to the bit, and the latencies the controller measured
    (its histogram's counts run on until its latest diagnostics, at a wall-clock moment)."""
    from standin_stack import CYCLES

    def key(run: Any) -> tuple[list[tuple[float, float, float]], list[str]]:
        impacts = [(r.t_contact, r.delta_m, r.F_max) for r in run.impacts[: CYCLES + 1]]
        latencies = sorted(p.split(':')[0] for p in run.ctrl.get('latency_histogram', '').split())
        return impacts, latencies

    return len({repr(key(r)) for r in runs}) == 1


def _reach_the_stand_in_stack() -> None:
    """Put test/support on the path: the stand-in stack this benchmark drives is the tests'
    (standin_stack, ros_helpers), one run shared with test/nodes/test_topic_hardware.py, and no
    other benchmark needs that folder."""
    support = os.path.join(os.path.dirname(BENCH_FOLDER), 'test', 'support')
    if support not in sys.path:
        sys.path.insert(0, support)


def run(args: argparse.Namespace) -> int:
    _reach_the_stand_in_stack()
    from standin_stack import CYCLES, ROLES

    order = [r.strip() for r in args.order.split(',')]
    if sorted(order) != sorted(ROLES):
        raise SystemExit(f'--order = {args.order}: must be a permutation of {",".join(ROLES)}')
    results, runs = [], []
    offline = _offline(args) if args.sim_time else None
    direct = _direct_cycle(args)
    for i in range(args.runs):
        busy = _busy(args.busy) if i % 2 else []
        try:
            if args.logs:
                workdir = os.path.join(args.logs, f'run_{i + 1}')
                os.makedirs(workdir, exist_ok=True)
                run_i = _one_run(args, order, workdir)
            else:
                with tempfile.TemporaryDirectory(prefix='bench_ros2control_') as workdir:
                    run_i = _one_run(args, order, workdir)
        finally:
            for p in busy:
                p.kill()
                p.wait()
        runs.append(run_i)
        result = run_i.as_dict()
        result['busy_loops'] = len(busy)
        if offline is not None:
            n = min(len(run_i.impacts), CYCLES + 1)
            result['equals_offline'] = (
                n > 0
                and [r.t_contact for r in run_i.impacts] == list(offline.t_contact[:n])
                and [r.delta_m for r in run_i.impacts] == list(offline.delta_m[:n])
            )
        mode, within_4 = _latency_shares(result['latency_histogram'])
        result['latency_mode'], result['latency_within_4'] = mode, within_4
        cycle = result['mean_cycle_s']
        result['cycle_departure'] = cycle / direct - 1.0 if cycle else None
        results.append(result)
        cpu = ' '.join(f'{r} {v:.0f}%' for r, v in result['cpu_percent'].items())
        print(
            f'run {i + 1}: {result["impacts"]} impacts, {result["second_strikes"]} second '
            f'strikes, first strike {result["first_strike_s"]} s, last cycle '
            f'{result["last_cycle_s"] or float("nan"):.4f} s, mean cycle '
            f'{cycle or float("nan"):.4f} s ({100 * (result["cycle_departure"] or math.nan):+.2f} '
            f'% of the direct run), δm '
            f'{result["delta_m_max_mm"]:.3f} mm, t_sim {result["sim_time_s"]:.2f} s in '
            f'{result["wall_s"]:.1f} s wall; latency [{result["latency_histogram"]}], '
            f'implicit {result["implicit_commands"]}, repeated {result["repeated_states"]} '
            f'(ticked {result["repetition_ticks"]}); '
            f'overruns {result["overruns"]}, skipped {result["periods_skipped"]}, '
            f'no new command {result["periods_without_new_command"]}, watchdog '
            f'{result["watchdog_timeouts"]}; stand-in '
            f'{result["standin_updates"]}; CPU {cpu}; load {result["load_average"]:.1f}; '
            f'ended: {[r for r, up in result["alive"].items() if not up]}'
            + (f'; busy loops {len(busy)}' if busy else '')
            + (f'; equals offline: {result["equals_offline"]}' if offline is not None else ''),
            flush=True,
        )
        for role, threads in result['thread_cpu_percent'].items():
            top = sorted(threads.items(), key=lambda kv: -kv[1])
            print(f'  {role} threads: ' + ', '.join(f'{k} {v:.1f}%' for k, v in top if v >= 0.1))
    held = sum(r['impacts'] >= CYCLES + 1 and r['second_strikes'] == 0 for r in results)
    print(f'{held} of {len(results)} runs: {CYCLES} cycles, no second strike')
    _criteria(results, direct)
    if offline is not None:
        print(
            f'offline closed loop, 1 period of latency, released at {args.sim_time:g} s: first '
            f'strike {offline.t_contact[0]!r} s, δm {offline.delta_m[0]!r} m; runs identical '
            f'(t_contact, δm, F_max, latency histogram): {_identical(runs)}'
        )
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=1)
    return 0
