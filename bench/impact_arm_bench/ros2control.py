"""``impact-arm bench ros2control``: the ros2_control set-up of docs/ros2_control.md in real
time at 1 kHz, with the stand-in stack (test/ros2control_standin.py) in place of
controller_manager + TopicBasedSystem + joint_state_broadcaster + JointGroupEffortController.

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

import contextlib
import json
import os
import sys
import tempfile
import time

from .common import cpu_seconds

ROLES = ('standin', 'simulator', 'controller')
CYCLES = 15


def add_arguments(parser):
    parser.add_argument('--runs', type=int, default=1, help='runs (default 1)')
    parser.add_argument(
        '--order',
        default='standin,simulator,controller',
        help='start order, comma-separated permutation of ' + ','.join(ROLES),
    )
    parser.add_argument('--timeout', type=float, default=40.0, help='s of wall time per run')
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
        '--standin',
        metavar='FILE',
        help="another stand-in program with the same options (default: the tests' one)",
    )
    parser.add_argument(
        '--logs', metavar='DIR', help="keep each run's process output in DIR/run_N (default: none)"
    )
    parser.add_argument('--json', metavar='FILE', help='write the runs as JSON')


def _commands(args):
    from ros_helpers import controller, simulator

    tests = os.path.dirname(os.path.abspath(sys.modules[controller.__module__].__file__))
    standin = args.standin or os.path.join(tests, 'ros2control_standin.py')
    remaps = (
        '-r',
        '/joint_states:=/joint_state_broadcaster/joint_states',
        '-r',
        '/effort_controller/commands:=/arm_effort_controller/commands',
    )
    return {
        'standin': [
            sys.executable,
            standin,
            '--rate',
            '1000',
            '--late',
            '1',
            '--duration',
            str(args.timeout + 30),
            '--priority',
            str(args.standin_priority),
        ],
        'simulator': simulator('mode:=realtime'),
        'controller': controller(*args.controller_params, ros_args=remaps),
    }


def _one_run(args, order, workdir):
    from diagnostic_msgs.msg import DiagnosticArray
    from ros_helpers import Probe, diagnostics_values, from_simulator, make_env, start_process
    from std_msgs.msg import String

    from impact_arm.tools.latency_study import SECOND_STRIKE_S

    env = make_env()
    probe = Probe(int(env['ROS_DOMAIN_ID']))
    reports = probe.listen(String, '/impact_report', transient=True)
    sim_diags = probe.listen(DiagnosticArray, '/diagnostics', keep=from_simulator)
    ctrl_diags = probe.listen(
        DiagnosticArray,
        '/diagnostics',
        keep=lambda m: bool(m.status) and 'controller' in m.status[0].name,
    )
    commands = _commands(args)
    procs = {}
    try:
        with contextlib.ExitStack() as stack:
            for role in order:
                procs[role] = stack.enter_context(start_process(commands[role], env, workdir, role))
                time.sleep(1.0)

            def sim_values():
                return diagnostics_values(sim_diags[-1][1]) if sim_diags else {}

            # the driven part: from the simulator's first command on
            deadline = time.monotonic() + 60
            while int(sim_values().get('commands', '0') or 0) == 0:
                if time.monotonic() > deadline or not procs['simulator'].alive():
                    break
                time.sleep(0.02)
            cpu0 = {r: cpu_seconds(f'/proc/{p.pid}/stat') for r, p in procs.items()}
            wall0 = time.monotonic()
            end = wall0 + args.timeout
            while (
                len(reports) < CYCLES + 1
                and time.monotonic() < end
                and all(p.alive() for p in procs.values())
            ):
                time.sleep(0.05)
            alive = {r: p.alive() for r, p in procs.items()}
            cpu1 = {
                r: cpu_seconds(f'/proc/{p.pid}/stat') if alive[r] else cpu0[r]
                for r, p in procs.items()
            }
            wall = time.monotonic() - wall0
            driven = [json.loads(m.data) for _, m in list(reports)]
            time.sleep(1.2)  # one more report of each
            sim = sim_values()
            ctrl = diagnostics_values(ctrl_diags[-1][1]) if ctrl_diags else {}
            updates = [e for e in procs['standin'].lines() if e.get('event') == 'update']
            load = os.getloadavg()[0]
    finally:
        probe.close()
    contacts = [r['t_contact'] for r in driven]
    gaps = [b - a for a, b in zip(contacts, contacts[1:])]
    return {
        'order': list(order),
        'impacts': len(driven),
        'second_strikes': sum(g < SECOND_STRIKE_S for g in gaps),
        'first_strike_s': contacts[0] if contacts else None,
        'delta_m_max_mm': 1e3 * max((r['delta_m'] for r in driven), default=float('nan')),
        'sim_time_s': float(sim.get('sim_time', 'nan')),
        'wall_s': wall,
        'alive': alive,
        'latency_histogram': ctrl.get('latency_histogram', ''),
        'implicit_commands': int(ctrl.get('implicit_commands', -1)),
        'repeated_states': int(ctrl.get('repeated_states', -1)),
        'overruns': int(sim.get('overruns', -1)),
        'periods_skipped': int(sim.get('periods_skipped', -1)),
        'periods_without_new_command': int(sim.get('periods_without_new_command', -1)),
        'watchdog_timeouts': int(sim.get('watchdog_timeouts', -1)),
        'zero_commands_before_release': int(sim.get('zero_commands_before_release', -1)),
        'standin_updates': updates[-1] if updates else {},
        'cpu_percent': {r: 100 * (cpu1[r] - cpu0[r]) / max(wall, 1e-9) for r in cpu0},
        'load_average': load,
    }


def run(args) -> int:
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
