"""``impact-arm bench ros2control``: the ros2_control set-up of docs/ros2_control.md in real
time at 1 kHz, with the stand-in stack (test/ros2control_standin.py) in place of
controller_manager + TopicBasedSystem + joint_state_broadcaster + JointGroupEffortController.
One run is test/standin_stack.py's, which the realtime test of test/test_topic_hardware.py
runs too.

Per run the three processes start in the chosen order (``--order``, a second apart): the
stand-in at 1 000 updates per wall second on its sleep-until schedule (no waiting for peers),
the simulator ``mode:=realtime`` at 1 kHz, the project's controller remapped to the
broadcaster's states and the effort controller's commands. Until the article's 15 cycles (16
impacts) or ``--timeout``: impacts, second strikes (two within 50 ms), the first strike's
simulated time, the largest penetration δm, the controller's measured latency histogram and
implicit commands, the simulator's overruns and skipped periods, the stand-in's stale updates,
and CPU per process (user + system over the driven part of the run). Processes run on a free
local DDS domain (localhost discovery) and are ended by PID.
"""

from __future__ import annotations

import json
import os
import tempfile

from .common import cpu_seconds


def add_arguments(parser):
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
        '--standin-fifo-threads',
        choices=('all', 'update'),
        default='all',
        help="the stand-in's threads under SCHED_FIFO: all (default) or update (the "
        "controller_manager's own choice: its update thread only, the middleware at normal "
        'priority)',
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
        standin_args=('--fifo-threads', args.standin_fifo_threads),
        controller_params=args.controller_params,
        cpu_seconds=lambda pid: cpu_seconds(f'/proc/{pid}/stat'),
        scene=args.scene,
    ).as_dict()


def run(args) -> int:
    from standin_stack import CYCLES, ROLES

    order = [r.strip() for r in args.order.split(',')]
    if sorted(order) != sorted(ROLES):
        raise SystemExit(f'--order = {args.order}: must be a permutation of {",".join(ROLES)}')
    results = []
    for i in range(args.runs):
        if args.logs:
            workdir = os.path.join(args.logs, f'run_{i + 1}')
            os.makedirs(workdir, exist_ok=True)
            result = _one_run(args, order, workdir)
        else:
            with tempfile.TemporaryDirectory(prefix='bench_ros2control_') as workdir:
                result = _one_run(args, order, workdir)
        results.append(result)
        cpu = ' '.join(f'{r} {v:.0f}%' for r, v in result['cpu_percent'].items())
        print(
            f'run {i + 1}: {result["impacts"]} impacts, {result["second_strikes"]} second '
            f'strikes, first strike {result["first_strike_s"]} s, δm '
            f'{result["delta_m_max_mm"]:.3f} mm, t_sim {result["sim_time_s"]:.2f} s in '
            f'{result["wall_s"]:.1f} s wall; latency [{result["latency_histogram"]}], '
            f'implicit {result["implicit_commands"]}, repeated {result["repeated_states"]}; '
            f'overruns {result["overruns"]}, skipped {result["periods_skipped"]}, '
            f'no new command {result["periods_without_new_command"]}, watchdog '
            f'{result["watchdog_timeouts"]}; stand-in '
            f'{result["standin_updates"]}; CPU {cpu}; load {result["load_average"]:.1f}; '
            f'ended: {[r for r, up in result["alive"].items() if not up]}',
            flush=True,
        )
    held = sum(r['impacts'] >= CYCLES + 1 and r['second_strikes'] == 0 for r in results)
    print(f'{held} of {len(results)} runs: {CYCLES} cycles, no second strike')
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(results, f, indent=1)
    return 0
