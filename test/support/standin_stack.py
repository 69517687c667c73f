"""The ros2_control set-up of docs/ros2_control.md in real time at 1 kHz, with the stand-in stack
(ros2control_standin.py) in place of controller_manager + TopicBasedSystem +
joint_state_broadcaster + JointGroupEffortController: one run, shared by the realtime test
(test_topic_hardware.py) and ``impact-arm bench ros2control``.

The three processes start in the given order, a second apart: the stand-in at 1 000 updates
per wall second on its sleep-until schedule (no waiting for peers), the simulator
``mode:=realtime`` at 1 kHz, the project's controller remapped to the broadcaster's states and
the effort controller's commands, with its default start-up hold. The run lasts until the
article's 15 cycles (16 impacts), a process ends, or ``timeout`` wall seconds.

``sim_time`` = X s: docs/ros2_control.md's reproducible set-up instead: the stand-in on
simulated time (``--use-sim-time``, commands written one update late), the simulator
``mode:=lockstep`` as fast as the stack goes with ``release_after:=X`` (braked, time running,
until X), the controller with ``use_sim_time:=true`` and a start-up hold of 0.5 s (it must
send its first command before the simulator reaches X).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ros_helpers import (
    Probe,
    controller,
    diagnostics_values,
    from_simulator,
    simulator,
    simulator_status,
    start_process,
    wait_for,
)

from impact_arm.contract import SimulatorStatus
from impact_arm.driver.control_inputs import DROPPED
from impact_arm.physics.impact import Impact, impact_from_json
from impact_arm.tools.latency_study import SECOND_STRIKE_S

HERE = os.path.dirname(os.path.abspath(__file__))
ROLES = ('standin', 'simulator', 'controller')
CYCLES = 15  # the article's: 16 impacts
START_SPACING_S = 1.0
# the largest command latency (periods) the controller's law was shown to handle offline
# (each command taking 1 to 5 periods at random; docs/ros2_control.md)
HANDLED_LATENCY = 5
# a simulator stall (periods skipped after a late period) this long before an impact or
# during its rebound changes the periods the law's commands act in, as no latency it was
# shown to handle does
STALL_BEFORE_S = 0.02
REMAPS = (
    '-r',
    '/joint_states:=/joint_state_broadcaster/joint_states',
    '-r',
    '/effort_controller/commands:=/arm_effort_controller/commands',
)


@dataclass
class StackRun:
    """What one run showed: the simulator's impact reports while the controller drove the
    arm, the last diagnostics of the simulator and the controller, the stand-in's counts."""

    order: tuple[str, ...]
    impacts: list[Impact]
    sim: SimulatorStatus | None  # None: the simulator never reported
    ctrl: dict
    standin_updates: dict
    alive: dict
    cpu_percent: dict
    wall_s: float
    sim_time_s: float
    load_average: float
    thread_cpu_percent: dict = field(default_factory=dict)
    second_strike_s: float = SECOND_STRIKE_S
    contacts: list[float] = field(init=False)

    def __post_init__(self):
        self.contacts = [r.t_contact for r in self.impacts]

    @property
    def second_strike_pairs(self) -> list[tuple[float, float]]:
        """(previous contact, second contact) for each contact that began within
        ``second_strike_s`` of the previous one."""
        pairs = zip(self.contacts, self.contacts[1:])
        return [(a, b) for a, b in pairs if b - a < self.second_strike_s]

    def second_strike_details(self) -> list[list[dict]]:
        """For each second strike, what the simulator reported of the strike before it and
        of itself (tip velocities before and after, penetration, contact duration): whether
        the rebound was weak or the arm came back down fast says where to look."""
        keys = ('t_contact', 'v_before', 'v_after', 'cor_kinematic', 'delta_m', 'duration')
        by_contact = {r.t_contact: r for r in self.impacts}
        return [
            [{k: getattr(by_contact[t], k) for k in keys} for t in pair]
            for pair in self.second_strike_pairs
        ]

    @property
    def second_strikes(self) -> int:
        return len(self.second_strike_pairs)

    @property
    def last_cycle_s(self) -> float | None:
        """The last cycle's duration: between the last two impacts more than
        ``second_strike_s`` apart (None: fewer than two such impacts)."""
        strikes = [
            t
            for k, t in enumerate(self.contacts)
            if k == 0 or t - self.contacts[k - 1] >= self.second_strike_s
        ]
        return strikes[-1] - strikes[-2] if len(strikes) >= 2 else None

    @property
    def mean_cycle_s(self) -> float | None:
        """The mean time between strikes after the fifth impact, as the offline latency
        study measures a cycle (None: too few strikes)."""
        gaps = [b - a for a, b in zip(self.contacts, self.contacts[1:])][4:]
        cycles = [g for g in gaps if g >= self.second_strike_s]
        return sum(cycles) / len(cycles) if cycles else None

    @property
    def held(self) -> bool:
        return len(self.impacts) >= CYCLES + 1 and self.second_strikes == 0

    @property
    def stalls(self) -> list[float]:
        """The simulated times of the simulator's latest stalls (``periods_skipped_at_s``)."""
        return list(self.sim.periods_skipped_at_s) if self.sim else []

    def second_strikes_at_stalls(self) -> bool:
        """Whether there are second strikes and each followed a simulator stall, between
        ``STALL_BEFORE_S`` before its cycle's impact and the second contact."""
        pairs = self.second_strike_pairs
        return bool(pairs) and all(
            any(a - STALL_BEFORE_S <= t <= b for t in self.stalls) for a, b in pairs
        )

    def schedule_misses(self) -> list[str]:
        """Where the machine did not give the loop the schedule its law is made for, from the
        processes' own counters: a command silence the simulator's watchdog braked, or a
        command latency beyond those the implicit law was shown to handle."""
        misses = []
        if self.sim and self.sim.watchdog_timeouts > 0:
            misses.append(
                f'{self.sim.watchdog_timeouts} watchdog timeouts (longest command silence '
                f'{self.sim.longest_command_silence_s:.6f} s)'
            )
        latency_max = int(self.ctrl.get('latency_periods_max', 0))
        if latency_max > HANDLED_LATENCY:
            misses.append(
                f'command latency up to {latency_max} periods '
                f'(histogram {self.ctrl.get("latency_histogram")})'
            )
        return misses

    def as_dict(self) -> dict:
        sim, ctrl = self.sim, self.ctrl
        return {
            'order': list(self.order),
            'impacts': len(self.impacts),
            'second_strikes': self.second_strikes,
            # each second strike with the strike before it (what the simulator reported)
            'second_strike_details': self.second_strike_details(),
            'contacts': list(self.contacts),
            'first_strike_s': self.contacts[0] if self.contacts else None,
            'last_cycle_s': self.last_cycle_s,
            'mean_cycle_s': self.mean_cycle_s,
            'delta_m_max_mm': 1e3 * max((r.delta_m for r in self.impacts), default=float('nan')),
            'sim_time_s': self.sim_time_s,
            'wall_s': self.wall_s,
            'alive': self.alive,
            'latency_histogram': ctrl.get('latency_histogram', ''),
            'implicit_commands': int(ctrl.get('implicit_commands', -1)),
            # what the controller dropped or refused (its non-zero counters)
            'controller_dropped': {k: ctrl[k] for k in DROPPED if ctrl.get(k, '0') != '0'},
            'repeated_states': int(ctrl.get('repeated_states', -1)),
            'repetition_ticks': int(ctrl.get('repetition_ticks', -1)),
            # -1: the simulator never reported
            'overruns': sim.overruns if sim else -1,
            'periods_skipped': sim.periods_skipped if sim else -1,
            'periods_skipped_at_s': self.stalls,
            'periods_without_new_command': sim.periods_without_new_command if sim else -1,
            'watchdog_timeouts': sim.watchdog_timeouts if sim else -1,
            'zero_commands_before_release': sim.zero_commands_before_release if sim else -1,
            'standin_updates': self.standin_updates,
            'cpu_percent': self.cpu_percent,
            'thread_cpu_percent': self.thread_cpu_percent,
            'load_average': self.load_average,
        }


def commands(
    duration: float,
    standin: str | None = None,
    standin_priority: int = 50,
    controller_params=(),
    scene: str | None = None,
    standin_args=(),
    sim_time: float | None = None,
    simulator_params=(),
    standin_threads_model: str = 'loop',
) -> dict:
    """Each role's command line; ``scene``: a scene file for the simulator and the
    controller (default: the article's), whose joints the stand-in then drives;
    ``standin_threads_model``: the stand-in's ``--threads-model`` (loop: its one loop,
    commands written one update late; stack: the real stack's threads, written at once)."""
    from impact_arm.nodes.params import scene_joint_names
    from impact_arm.physics.scene import load_scene

    loaded = load_scene(scene or 'paper')
    joints = scene_joint_names(loaded) if scene else []
    # what the URDF's ros2_control block seeds the state interfaces with (impact-arm urdf):
    # the broadcaster publishes it until the simulator's first state
    initial = loaded.joint_coordinates.positions(loaded.q0)
    scene_param = [f'scene:={os.path.abspath(scene)}'] if scene else []
    if sim_time:
        sim = ['mode:=lockstep', 'rate_factor:=0.0', f'release_after:={sim_time!r}']
        standin_args = ('--use-sim-time', *standin_args)
        controller_params = ('use_sim_time:=true', 'startup_hold:=0.5', *controller_params)
    else:
        sim = ['mode:=realtime']
    return {
        'standin': [
            sys.executable,
            standin or os.path.join(HERE, 'ros2control_standin.py'),
            '--rate',
            '1000',
            # (the option only when not the default: another stand-in may not know it)
            *(
                ['--threads-model', standin_threads_model]
                if standin_threads_model != 'loop'
                else []
            ),
            '--late',
            '0' if standin_threads_model == 'stack' else '1',
            '--duration',
            str(duration),
            '--priority',
            str(standin_priority),
            *(['--joints', *joints] if joints else []),
            '--initial-positions',
            *(repr(float(v)) for v in initial),
            *standin_args,
        ],
        'simulator': simulator(*sim, *scene_param, *simulator_params),
        'controller': controller(
            'start_after:=wrench', *scene_param, *controller_params, ros_args=REMAPS
        ),
    }


def run_stack(
    order,
    env: dict,
    workdir: str,
    timeout: float = 40.0,
    standin: str | None = None,
    standin_priority: int = 50,
    controller_params=(),
    cpu_seconds: Callable[[int], float] | None = None,
    scene: str | None = None,
    standin_args=(),
    sim_time: float | None = None,
    cycles: int = CYCLES,
    thread_cpu: Callable[[int], dict[str, float]] | None = None,
    simulator_params=(),
    standin_threads_model: str = 'loop',
) -> StackRun:
    """One run in ``order`` (a permutation of ROLES) on ``env``'s DDS domain, of the
    article's arm or ``scene``'s; every process is ended by PID on the way out. With
    ``cpu_seconds`` (a process's CPU time by PID), the CPU each process used while the
    controller drove the arm, and with ``thread_cpu`` (a process's CPU time by thread name)
    each thread's. ``sim_time``: the reproducible set-up on simulated time (``commands``);
    ``cycles``: the run ends after cycles + 1 impacts; ``standin_threads_model``: as
    ``commands``'."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    if sorted(order) != sorted(ROLES):
        raise ValueError(f'order = {",".join(order)}: must be a permutation of {",".join(ROLES)}')
    probe = Probe(int(env['ROS_DOMAIN_ID']))
    reports = probe.listen(String, '/impact_report', transient=True)
    sim_diags = probe.listen(DiagnosticArray, '/diagnostics', keep=from_simulator)
    ctrl_diags = probe.listen(
        DiagnosticArray,
        '/diagnostics',
        keep=lambda m: bool(m.status) and 'controller' in m.status[0].name,
    )
    lines = commands(
        timeout + 30,
        standin,
        standin_priority,
        controller_params,
        scene,
        standin_args,
        sim_time,
        simulator_params,
        standin_threads_model,
    )
    procs = {}
    try:
        with contextlib.ExitStack() as stack:
            for role in order:
                procs[role] = stack.enter_context(start_process(lines[role], env, workdir, role))
                time.sleep(START_SPACING_S)

            def sim_status():
                return simulator_status(sim_diags[-1][1]) if sim_diags else None

            # the driven part: from the simulator's first command on
            deadline = time.monotonic() + 60
            while not (sim_diags and sim_status().commands):
                if time.monotonic() > deadline or not procs['simulator'].alive():
                    break
                time.sleep(0.02)
            cpu0 = {r: cpu_seconds(p.pid) for r, p in procs.items()} if cpu_seconds else {}
            threads0 = {r: thread_cpu(p.pid) for r, p in procs.items()} if thread_cpu else {}
            wall0 = time.monotonic()
            end = wall0 + timeout
            while (
                len(reports) < cycles + 1
                and time.monotonic() < end
                and all(p.alive() for p in procs.values())
            ):
                time.sleep(0.05)
            alive = {r: p.alive() for r, p in procs.items()}
            cpu1 = {r: cpu_seconds(procs[r].pid) if alive[r] else cpu0[r] for r in cpu0}
            threads1 = {r: thread_cpu(procs[r].pid) if alive[r] else {} for r in threads0}
            wall = time.monotonic() - wall0
            driven = [impact_from_json(m.data) for _, m in list(reports)]
            latest = sim_status()  # (its latest report)
            sim_time = latest.sim_time if latest else float('nan')
            # one more report of each (1 Hz), for the counters: a lagging probe may hold
            # stale ones after a fixed wait, and a run to skip would read as a failure
            seen = (len(sim_diags), len(ctrl_diags))
            wait_for(lambda: len(sim_diags) > seen[0] and len(ctrl_diags) > seen[1], 5)
            time.sleep(0.2)
            updates = [e for e in procs['standin'].lines() if e.get('event') == 'update']
            return StackRun(
                order=tuple(order),
                impacts=driven,
                sim=sim_status(),
                ctrl=diagnostics_values(ctrl_diags[-1][1]) if ctrl_diags else {},
                standin_updates=updates[-1] if updates else {},
                alive=alive,
                cpu_percent={r: 100 * (cpu1[r] - cpu0[r]) / max(wall, 1e-9) for r in cpu0},
                thread_cpu_percent={
                    r: {
                        name: 100 * (t - threads0[r].get(name, 0.0)) / max(wall, 1e-9)
                        for name, t in threads1[r].items()
                    }
                    for r in threads0
                },
                wall_s=wall,
                sim_time_s=sim_time,
                load_average=os.getloadavg()[0],
            )
    finally:
        probe.close()
