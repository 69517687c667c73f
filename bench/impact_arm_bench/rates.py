"""``impact-arm bench rates``: the nodes as a user runs them, measured.

1. realtime at 1 kHz, the article's 15 cycles with the controller in its own process:
   overruns, whole-run period jitter p50/p99/max, worst compute time of one period (with the
   simulated time it happened at: an impact period), simulator CPU and memory;
2. realtime at 5 kHz for a few seconds: achieved publish rate (simulator's count and a
   subscriber's count);
3. lockstep at 1 kHz, simulator and controller over DDS: real-time factor of the 15 cycles;
4. start-up: process start to the first /joint_states message; resident memory of each node;
5. the transport floor: the same lockstep exchange with no physics and no control law in it
   (``transport_floor``), i.e. the best real-time factor rclpy and DDS allow on this machine.

Processes run on a free local DDS domain (localhost discovery) and are ended by PID.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

from impact_arm.contract import DIAGNOSTICS, JOINT_STATES
from .common import cpu_seconds


GENTLE_GAINS = ('p:=[60.0,30.0]', 'd:=[10.0,10.0]')


def add_arguments(parser):
    parser.add_argument('--json', metavar='FILE', help='write the measured rows as JSON')
    parser.add_argument('--scene', default='paper', help='scene file or name (default paper)')
    parser.add_argument(
        '--fast-seconds',
        type=float,
        default=5.0,
        metavar='S',
        help='duration of the 5 kHz run (default 5)',
    )
    parser.add_argument(
        '--skip',
        nargs='*',
        default=[],
        choices=('realtime', 'fast', 'lockstep', 'floor'),
        help='measurements to leave out',
    )


def _memory_mb(pid, key='VmHWM'):
    with open(f'/proc/{pid}/status') as f:
        for line in f:
            if line.startswith(key + ':'):
                return int(line.split()[1]) / 1024
    return float('nan')


def _session(scene_path, mode, rate, rate_factor=None):
    from impact_arm.tools.runner import Run

    args = argparse.Namespace(mode=mode, rate=rate, law=None, out=os.path.join('runs', 'bench'))
    return Run(_scene(scene_path), scene_path, args, None, os.environ.copy())


def _scene(path):
    from impact_arm.physics.scene import load_scene

    return load_scene(path)


def _run_cycles(scene_path, mode, rate, timeout=300):
    """Simulator + controller until the scene's cycles are done; returns measurements."""
    import rclpy
    from sensor_msgs.msg import JointState

    run = _session(scene_path, mode, rate)
    started = time.monotonic()
    first_state = []
    run.start()
    probe = run.node.create_subscription(
        JointState, JOINT_STATES, lambda m: first_state or first_state.append(time.monotonic()), 10
    )
    try:
        sim = run.procs['simulator']
        while not (run.simulator and run.simulator.status.commands):
            rclpy.spin_once(run.node, timeout_sec=0.05)
            if time.monotonic() - started > 60 or sim.poll() is not None:
                raise RuntimeError(f'simulator did not start; see {run.logs["simulator"]}')
        if first_state:
            # a 1 kHz reader in this process would load the machine and the simulator
            # beyond what a user's run (controller, recorder) does
            run.node.destroy_subscription(probe)
        # CPU of each node over the run (user + system, all its threads)
        cpu0 = {name: cpu_seconds(f'/proc/{p.pid}/stat') for name, p in run.procs.items()}
        wall0 = time.monotonic()
        outcome = run.watch(timeout)
        cpu1 = {name: cpu_seconds(f'/proc/{p.pid}/stat') for name, p in run.procs.items()}
        wall1 = time.monotonic()
        load = os.getloadavg()[0]
        final = run.simulator
        deadline = time.monotonic() + 2.5  # one more report, covering the last impact
        while run.simulator is final and time.monotonic() < deadline:
            rclpy.spin_once(run.node, timeout_sec=0.05)
        memory = {name: _memory_mb(p.pid) for name, p in run.procs.items()}
        d = run.simulator.status  # (set: the loop above waited for a command in it)
    finally:
        run.stop()
    return {
        'mode': mode,
        'rate_hz': rate,
        'outcome': outcome,
        'impacts': len(run.impacts),
        'sim_time_s': d.sim_time,
        'real_time_factor': d.real_time_factor or 0.0,
        'overruns': d.overruns,
        'publish_failures': d.publish_failures,
        'jitter_p50_us': d.jitter_run_p50_us,
        'jitter_p99_us': d.jitter_run_p99_us,
        'jitter_max_us': d.jitter_run_max_us,
        'jitter_max_at_s': d.jitter_run_max_at_s,
        'scheduling': d.scheduling,
        'worst_compute_us': d.compute_worst_us,
        'compute_mean_us': {
            'commands': d.compute_commands_mean_us,
            'physics': d.compute_physics_mean_us,
            'publish': d.compute_publish_mean_us,
        },
        'worst_compute_parts_us': {
            'commands': d.compute_worst_commands_us,
            'physics': d.compute_worst_physics_us,
            'publish': d.compute_worst_publish_us,
        },
        'lockstep_wait_mean_us': (
            d.lockstep_wait_mean_us if d.lockstep_wait_mean_us is not None else math.nan
        ),
        'worst_compute_at_s': d.compute_worst_at_s,
        'period_us': 1e6 / rate,
        'simulator_cpu_percent': 100 * (cpu1['simulator'] - cpu0['simulator']) / (wall1 - wall0),
        'cpu_percent': {name: 100 * (cpu1[name] - cpu0[name]) / (wall1 - wall0) for name in cpu0},
        'load_average': load,
        'rss_peak_mb': memory,
        'first_joint_state_after_s': (first_state[0] - started) if first_state else None,
    }


def _run_fast(scene_path, rate, seconds):
    """Realtime at ``rate`` Hz (controller at 1 kHz) for ``seconds``: achieved rate, as the
    simulator counts it and as a separate listener (events executor) receives it."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from sensor_msgs.msg import JointState

    from impact_arm.tools.runner import simulator_report

    run = _session(scene_path, 'realtime', rate)
    run.args.control_rate = 1000.0  # the controller keeps its 1 kHz
    # This measures the simulator's clock, not the control loop: a Python controller taking
    # 10 000 messages/s next to a simulator using a whole core falls behind on two cores, and
    # the article's stiff gains (kd = 100) then go unstable on stale states. Gentle gains keep
    # the arm striking the surface whatever the controller's latency.
    run.args.controller_params = GENTLE_GAINS
    received, diagnostics = [], []
    run.start()
    context = Context()
    rclpy.init(context=context, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    node = rclpy.create_node('bench_rates_listener', context=context)
    node.create_subscription(
        JointState, JOINT_STATES, lambda m: received.append(time.monotonic()), 1000
    )

    def on_diagnostics(msg):
        report = simulator_report(msg)
        if report is not None:
            diagnostics.append(report.status)

    node.create_subscription(DiagnosticArray, DIAGNOSTICS, on_diagnostics, 10)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 60
        while not (diagnostics and diagnostics[-1].commands) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if not (diagnostics and diagnostics[-1].commands):
            raise RuntimeError(
                f'realtime {rate:g} Hz: no command reached the simulator within '
                f'60 s (logs in {run.logdir})'
            )
        begin, first = len(received), diagnostics[-1]
        end = time.monotonic() + seconds
        while time.monotonic() < end or diagnostics[-1] is first:
            executor.spin_once(timeout_sec=0.05)
        window, last = received[begin:], diagnostics[-1]
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        run.stop()
    periods = last.periods_published - first.periods_published
    wall = last.wall_time - first.wall_time
    sub_rate = (len(window) - 1) / (window[-1] - window[0]) if len(window) > 1 else 0.0
    return {
        'mode': 'realtime',
        'rate_hz': rate,
        'achieved_hz_simulator': periods / wall if wall > 0 else 0.0,
        'achieved_hz_subscriber': sub_rate,
        'overruns': last.overruns,
        'jitter_p99_us': last.jitter_run_p99_us,
        'publish_failures': last.publish_failures,
        'outcome': 'completed' if periods else 'failed: no period published',
    }


def run(args) -> int:
    from impact_arm.tools.runner import dds_environment
    from impact_arm.physics.scene import resolve_scene_path

    scene_path = resolve_scene_path(args.scene)
    env = dds_environment()
    from impact_arm.physics.scene import load_scene
    from impact_arm.tools.runner import precompile

    precompile(load_scene(scene_path), 1000.0)  # a cold cache compiles here, announced
    print(
        f'bench rates: scene {args.scene}, ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]} '
        f'(localhost); machine: {os.cpu_count()} cores',
        file=sys.stderr,
    )
    rows = []
    if 'realtime' not in args.skip:
        print('  realtime 1 kHz, 15 cycles ...', file=sys.stderr, flush=True)
        rows.append(_run_cycles(scene_path, 'realtime', 1000.0))
        r = rows[-1]
        print(
            f'realtime 1 kHz: {r["impacts"]} impacts, {r["overruns"]} overruns; period '
            f'jitter p50 {r["jitter_p50_us"]:.0f} us, p99 {r["jitter_p99_us"]:.0f} us, max '
            f'{r["jitter_max_us"]:.0f} us (at t = {r["jitter_max_at_s"]:.3f} s); worst compute '
            f'{r["worst_compute_us"]:.0f} us of a {r["period_us"]:.0f} us period '
            f'(at t = {r["worst_compute_at_s"]:.3f} s); '
            'CPU of one core: '
            + ', '.join(f'{k} {v:.1f} %' for k, v in r['cpu_percent'].items())
            + f' ({r["scheduling"]}; load average {r["load_average"]:.1f}); peak RSS '
            + ', '.join(f'{k} {v:.0f} MB' for k, v in r['rss_peak_mb'].items())
            + f'; first /joint_states {r["first_joint_state_after_s"]:.2f} s after start'
        )
        print(
            "  a period's compute, mean: "
            + ', '.join(f'{part} {us:.0f} us' for part, us in r['compute_mean_us'].items())
            + '; the worst period: '
            + ', '.join(f'{part} {us:.0f} us' for part, us in r['worst_compute_parts_us'].items())
        )
    if 'fast' not in args.skip:
        print('  realtime 5 kHz ...', file=sys.stderr, flush=True)
        try:
            rows.append(_run_fast(scene_path, 5000.0, args.fast_seconds))
        except RuntimeError as exc:
            rows.append({'mode': 'realtime', 'rate_hz': 5000.0, 'outcome': f'failed: {exc}'})
            print(f'realtime 5 kHz: FAILED: {exc}')
        else:
            r = rows[-1]
            print(
                f'realtime 5 kHz: simulator published {r["achieved_hz_simulator"]:.1f} Hz '
                f'({100 * r["achieved_hz_simulator"] / 5000:.2f} %), a subscriber received '
                f'{r["achieved_hz_subscriber"]:.1f} Hz; {r["overruns"]} overruns, jitter '
                f'p99 {r["jitter_p99_us"]:.0f} us; {r["publish_failures"]} samples the '
                f'middleware refused'
            )
    if 'lockstep' not in args.skip:
        print('  lockstep 1 kHz, 15 cycles ...', file=sys.stderr, flush=True)
        rows.append(_run_cycles(scene_path, 'lockstep', 1000.0))
        r = rows[-1]
        print(
            f'lockstep 1 kHz: {r["impacts"]} impacts, {r["sim_time_s"]:.3f} s simulated, '
            f'real-time factor {r["real_time_factor"]:.2f}'
        )
        print(
            '  a period, mean: '
            + ', '.join(f'{part} {us:.0f} us' for part, us in r['compute_mean_us'].items())
            + f', waiting for the command {r["lockstep_wait_mean_us"]:.0f} us'
        )
    if 'floor' not in args.skip:
        from .transport_floor import measure

        print(
            '  transport floor (lockstep exchange without physics or control) ...',
            file=sys.stderr,
            flush=True,
        )
        floor = measure(env=env)
        rows.append(
            {
                'mode': 'transport_floor',
                'period_s': floor,
                'real_time_factor_ceiling_1khz': 1e-3 / floor,
            }
        )
        print(
            f'transport floor: {floor * 1e6:.0f} us per lockstep period with no physics and '
            f'no control law (wrench + joint state + clock out, command back): real-time '
            f'factor at 1 kHz can never exceed {1e-3 / floor:.2f} here'
        )
        lockstep = next((r for r in rows if r['mode'] == 'lockstep'), None)
        if lockstep and lockstep['real_time_factor'] > 0:
            # target: a lockstep period within 1.25x the bare exchange of this run
            period = 1e-3 / lockstep['real_time_factor']
            print(
                f'lockstep period {period * 1e6:.0f} us = {period / floor:.2f}x the transport '
                f'floor measured in this run (target <= 1.25x)'
            )
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(rows, f, indent=1)
        print(f'rows written to {args.json}')
    return 0
