"""``impact-arm run``: simulator, controller and recorder as separate processes over DDS.

The embedded default behind ``make run``: the same nodes a ROS 2 user starts with
``ros2 launch impact_arm arm.launch.py``, without needing ros2cli or launch. DDS stays on this
machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and on a domain nobody else uses, unless
the user chose otherwise. Every child is ended by its PID on success, failure or Ctrl-C, and
dies with this process even if it is killed (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import FrameType
from typing import TYPE_CHECKING, Any

from .. import contract
from ..contract import (
    COMMANDS,
    CONTACT_FORCE_PEAK,
    CONTACT_WRENCH,
    DIAGNOSTICS,
    FEEDBACK_LAWS,
    IMPACT_REPORT,
    JOINT_STATES,
    SIMULATOR_MODES,
    SURFACE_MOUNTS,
    SimulatorMode,
    SimulatorStatus,
    WatchdogPolicy,
    WatchdogState,
)
from ..driver.session import Level
from ..physics.errors import ImpactArmError
from ..physics.impact import Impact, impact_from_json
from .progress import Progress

if TYPE_CHECKING:
    from rclpy.node import Node

    from ..physics.scene import Scene

NODES = ('recorder', 'simulator', 'controller')  # start order (the arm moves with the
# first command, so the controller comes last, once the recorder listens)
STOP_ORDER = ('controller', 'simulator', 'recorder')  # zero command first, recorder last
# what the recorder must have matched before the first command (the commands themselves: the
# controller waits for its two readers)
SIMULATOR_TOPICS = (JOINT_STATES, CONTACT_WRENCH, CONTACT_FORCE_PEAK, IMPACT_REPORT, DIAGNOSTICS)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--scene', default='paper', help='scene file or installed scene name')
    parser.add_argument(
        '--mode',
        choices=SIMULATOR_MODES,
        default=SimulatorMode.LOCKSTEP.value,
        help='lockstep (default): one period per controller command, '
        'deterministic, as fast as the loop allows; realtime: paced by '
        "the wall clock like hardware (the article's stiff gains need a "
        'machine that keeps every 1 ms deadline)',
    )
    parser.add_argument(
        '--rate',
        type=float,
        default=1000.0,
        metavar='HZ',
        help='publish and control rate (default 1000)',
    )
    parser.add_argument(
        '--law', choices=FEEDBACK_LAWS, default=None, help="control law (default: the scene's)"
    )
    parser.add_argument(
        '--name', default=None, help='recording name: runs/NAME.mcap (default: scene and time)'
    )
    parser.add_argument('--out', default='runs', help='directory of the recording')
    parser.add_argument('--no-record', action='store_true', help='do not start the recorder')
    parser.add_argument(
        '--timeout',
        type=float,
        default=None,
        metavar='S',
        help="give up after S wall seconds (default: 3 x the scene's t_max)",
    )


def cli(args: argparse.Namespace) -> int:
    from ..physics.scene import load_scene, resolve_scene_path
    from ..physics.simulate import RunResult, StopReason, format_table

    lockstep = SimulatorMode(args.mode) is SimulatorMode.LOCKSTEP
    if not 1.0 <= args.rate <= 100000.0:
        raise ImpactArmError(f'--rate {args.rate:g}: allowed 1 ... 100000 Hz')
    scene_path = resolve_scene_path(args.scene)
    scene = load_scene(scene_path)
    # the controller node samples at the run's rate, not the scene's: refused (or warned)
    # here, before any node starts, as simulate --control-rate does
    from ..physics.stability import check_stability

    rate = getattr(args, 'control_rate', None) or args.rate
    if rate != scene.controller.rate or args.law:
        check_stability(scene, rate, args.law, rate_source="--rate, the controller node's")
    name = args.name or f'{scene.name}-{time.strftime("%Y%m%d-%H%M%S")}'
    output = os.path.join(args.out, name + '.mcap') if not args.no_record else None
    if output:
        os.makedirs(args.out, exist_ok=True)
    env = dds_environment()
    precompile(scene, args.rate)

    run = Run(scene, scene_path, args, output, env)

    def interrupt(signum: int, frame: FrameType | None) -> None:
        # raised here, KeyboardInterrupt can land inside an rclpy call, whose pybind11 layer
        # turns it into a RuntimeError traceback: flag it, the run's loops stop between calls
        run.interrupted.set()

    # Ctrl-C and SIGTERM stop the run the same orderly way (even if SIGINT was ignored, as
    # for a background job of a non-interactive shell)
    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    try:
        run.start()
        outcome = run.watch(args.timeout or 3 * scene.t_max + 30)
    except KeyboardInterrupt:
        outcome = 'interrupted'
    finally:
        run.line.end()
        codes = run.stop()
    status = run.simulator.status if run.simulator else None
    result = RunResult(
        scene=scene,
        impacts=run.impacts,
        t_end=run.sim_time,
        rhs_evaluations=run.rhs_evaluations,
        wall_time=integrating_wall(status, run.wall),
        stop_reason=StopReason.CYCLES_COMPLETED
        if outcome == 'completed'
        else StopReason.INTERRUPTED
        if outcome == 'interrupted'
        else StopReason.FAILED,
        stop_detail=outcome,
    )
    print(format_table(result))
    if run.chatter:
        print(f'CHATTER: {run.chatter}: the law is unstable at its rate')
    simulator = status
    if simulator and simulator.limits:
        print(f'LIMIT: {simulator.limits}')
    if run.simulator and run.simulator.watchdog_line():
        print(run.simulator.watchdog_line())
    if lockstep and run.wall > 0:
        print(
            f'lockstep: {run.sim_time:.3f} s simulated in {run.wall:.3f} s wall (from the '
            f"first command to the last impact; the nodes' start-up not included), "
            f'real-time factor {run.sim_time / run.wall:.2f}'
        )
    elif run.simulator:
        print(f'realtime: {run.simulator.summary()}')
    failed = {n: c for n, c in codes.items() if c not in (0, None)}
    # a run a node failed in is no complete run, whatever the file holds
    why_failed = '; '.join(
        ([] if outcome in ('completed', 'interrupted') else [outcome])
        + [f'{node} exited with status {code}' for node, code in failed.items()]
    )
    incomplete = False
    if output and os.path.exists(output):
        from ..io.recording_check import check_recording

        # until the simulator's last period: a recorder that stopped receiving (frozen, then
        # starved) lost the tail without a sequence gap, and the run's own end can be earlier
        # than the pause that ended it
        until = max(run.sim_time, run.published_until)
        check = check_recording(output, args.rate, simulator_topics(scene), until=until)
        print(f'wrote {output}: {check.summary(lockstep, failed=why_failed)}')
        from ..io.viewer_layout import write_layout_beside

        # made for this arm and the topics the file holds (every joint, the plates); a file
        # the recorder left unreadable has no layout, and the check above says why
        try:
            print(f'viewer layout: {write_layout_beside(output, scene)}')
        except Exception as exc:  # noqa: BLE001 - any reader failure: no layout, the run stands
            print(f'no viewer layout: {exc}')
        # lockstep waits for the recorder: a gap there is a defect, not load
        incomplete = lockstep and not check.complete and outcome == 'completed'
    elif output:
        print(f'no recording: {output} was not written')
    if outcome == 'interrupted':
        print('interrupted: nodes stopped, recording closed', file=sys.stderr)
        return 130
    if why_failed:
        print(f'the run failed: {why_failed}', file=sys.stderr)
        for node in failed:
            print(f'{node} log: {run.logs[node]}', file=sys.stderr)
        return 1
    if incomplete:
        print('the lockstep recording is incomplete', file=sys.stderr)
        return 1
    return 0


def precompile(scene: Scene, rate: float) -> None:
    """Compile, or load from the cache, what the simulator and controller nodes run, here
    where the CLI announces it: otherwise each node compiles in its own process on the first
    run of a scene shape, 20-45 s of silence before the arm moves."""
    from ..physics.control import CycleController
    from ..driver.arm import SimulatedArm

    arm = SimulatedArm(scene, rate, trace=False)
    arm.warm_up()
    ctrl = CycleController.for_scene(arm.model, scene.controller)
    for ctrl.law in ('q', 'pid'):
        ctrl.torque(scene.q0, scene.qd0)
    arm.model.tip(scene.q0, scene.qd0)


def dds_environment() -> dict[str, str]:
    """The children's environment: localhost discovery, and a domain nobody is using, unless
    the user set them."""
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['PYTHONUNBUFFERED'] = '1'
    if 'ROS_DOMAIN_ID' not in env:
        env['ROS_DOMAIN_ID'] = str(free_domain(env))
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    return env


def free_domain(env: dict[str, str], tries: int = 5, listen: float = 0.3) -> int:
    """A ROS_DOMAIN_ID in 1..101 on which no participant answers within ``listen`` s."""
    import rclpy
    from rclpy.context import Context

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = env['ROS_AUTOMATIC_DISCOVERY_RANGE']
    candidates = random.sample(range(1, 102), tries)
    for domain in candidates:
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            node = rclpy.create_node('impact_arm_domain_probe', context=context)
            time.sleep(listen)
            others = [n for n in node.get_node_names() if n != 'impact_arm_domain_probe']
            node.destroy_node()
        finally:
            rclpy.shutdown(context=context)
        if not others:
            return domain
    return candidates[-1]


def _die_with_parent():
    """In the child: get SIGTERM when the runner dies, however it dies."""
    try:
        import ctypes

        ctypes.CDLL('libc.so.6', use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass
    os.setpgrp()  # Ctrl-C reaches the runner only; it stops the nodes in order


def status_values(msg: Any, name: str) -> dict[str, str] | None:
    """The key-values of the status ``name`` (contract.SIMULATOR_STATUS,
    contract.CONTROLLER_STATUS) in ``msg`` (a DiagnosticArray), or None: both nodes publish
    their own status on /diagnostics."""
    for status in msg.status:
        if status.name == name:
            return {kv.key: kv.value for kv in status.values}
    return None


@dataclass(frozen=True)
class SimulatorReport:
    """One status of the simulator on /diagnostics: its severity (an error: the simulation
    stopped), its one-line message and its values."""

    level: Level
    message: str
    status: SimulatorStatus

    @property
    def stopped(self) -> bool:
        return self.level is Level.ERROR

    def watchdog_line(self) -> str:
        """Why the arm was braked or let go while the run went on ('' : it never was): a
        stall in command reception longer than ``command_timeout`` must not pass unsaid."""
        s = self.status
        if not s.watchdog_timeouts:
            return ''
        if s.watchdog_policy is WatchdogPolicy.BRAKE:
            action = (
                f'the brakes held the joints ({s.brake_events} times, at most '
                f'{s.brake_torque_max_nm:.3f} of {s.brake_torque_limit_nm:g} N m)'
            )
        else:
            action = 'zero torque (the arm fell)'
        return (
            f'WATCHDOG: {s.watchdog_timeouts} command timeout(s), the longest silence '
            f'{s.longest_command_silence_s * 1e3:.1f} ms (parameter command_timeout): {action}'
        )

    def summary(self) -> str:
        """The realtime line of ``impact-arm run``'s summary."""
        s = self.status
        return (
            f'{s.overruns} overruns; worst period compute '
            f'{s.compute_worst_us:.1f} us of {s.period_us:.1f} us'
        )


def simulator_report(msg: Any) -> SimulatorReport | None:
    """The simulator's status in ``msg`` (a DiagnosticArray), parsed; None when ``msg``
    holds only other nodes' statuses."""
    for status in msg.status:
        if status.name == contract.SIMULATOR_STATUS:
            level = status.level
            return SimulatorReport(
                Level(level[0] if isinstance(level, (bytes, bytearray)) else int(level)),
                status.message,
                SimulatorStatus.parse({kv.key: kv.value for kv in status.values}),
            )
    return None


RECORDER_READER = '_recorder_reader'  # the recorder's reader node (nodes/_runner.reader_node)


def integrating_wall(status: SimulatorStatus | None, run_wall: float) -> float:
    """The wall time the simulator spent in its physics [s] (its mean per stepped period
    times the periods stepped), what "s wall integrating" means offline; ``run_wall`` (the
    run's wall time) when the simulator never reported it. In a realtime run the run's
    wall time is about its simulated time, and it counted the start-up wait too."""
    if status is None or status.compute_physics_mean_us <= 0:
        return run_wall
    stepped = round(status.periods_published_until_s * status.publish_rate_requested)
    return status.compute_physics_mean_us * 1e-6 * stepped


class RecorderProgress:
    """What the recorder says it has written: on /recorder/progress, the stamp up to which
    it has written every per-period topic (ns; None until it says anything). A progress
    message proves the recorder is writing each of the simulator's streams, not merely
    subscribed to them."""

    def __init__(self, node: Node) -> None:
        from builtin_interfaces.msg import Time

        self.written_until: int | None = None
        self.subscription = node.create_subscription(
            Time, contract.RECORDER_PROGRESS, self._on_progress, contract.PROGRESS_QOS.to_rclpy()
        )

    def _on_progress(self, msg):
        self.written_until = msg.sec * 1_000_000_000 + msg.nanosec


def simulator_topics(scene: Scene) -> tuple[str, ...]:
    """What the recorder must have matched for ``scene``: ``SIMULATOR_TOPICS``, and the
    plates of its mounted surfaces if it has any."""
    mounted = any(s.mount is not None and s.law != 'none' for s in scene.surfaces)
    return SIMULATOR_TOPICS + ((SURFACE_MOUNTS,) if mounted else ())


def recorder_subscribed(node: Node, topics: Sequence[str] = SIMULATOR_TOPICS) -> set[str]:
    """The simulator ``topics`` the recorder's reader subscribes to, as ``node`` sees the
    graph."""
    return {
        topic
        for topic in topics
        if any(
            info.node_name == RECORDER_READER
            for info in node.get_subscriptions_info_by_topic(topic)
        )
    }


def ready_for_commands(
    node: Node, recorder: RecorderProgress | None = None, topics: Sequence[str] = SIMULATOR_TOPICS
) -> bool:
    """Whether the controller may start, as ``node`` sees the graph: the simulator publishes,
    its command reader (and the recorder's) are known and, with a recorder (``recorder``: a
    RecorderProgress), the recorder's reader subscribes to every simulator topic (``topics``)
    and the recorder has said it wrote every per-period topic (the simulator publishes its
    held initial state on each until the first command). The arm starts moving with the
    first command and nothing must go unrecorded: a subscription in the graph is not a
    matched reader (it may match seconds later); a written sample is proof."""
    listeners = 1 if recorder is not None else 0
    if not (
        node.count_publishers(JOINT_STATES) >= 1
        and node.count_subscribers(COMMANDS) >= 1 + listeners
    ):
        return False
    if recorder is None:
        return True
    return recorder.written_until is not None and recorder_subscribed(node, topics) == set(topics)


class Run:
    def __init__(self, scene, scene_path, args, output, env):
        self.scene, self.scene_path, self.args, self.output, self.env = (
            scene,
            scene_path,
            args,
            output,
            env,
        )
        self.procs, self.logs = {}, {}
        self.impacts: list[Impact] = []  # the /impact_report records, read as they come
        self.mode = SimulatorMode(args.mode)
        self.simulator: SimulatorReport | None = None  # its latest /diagnostics
        self.sim_time = 0.0
        # the simulator's own last reported time, its final report on exit included: the
        # periods it published, whether or not the run counts them
        self.published_until = 0.0
        self.rhs_evaluations = 0
        self.chatter = ''  # the controller's /diagnostics 'chatter'
        # the controller's cycle counts (its CycleCount, physics/cycle_count.py) as its
        # /diagnostics report them: not counted here from the cycle's halves, which the run
        # never sees, but kept from messages that come at 1 Hz and at each strike: the
        # largest count seen, and each strike count's down half start
        self.strikes = 0  # cycles whose down half an impact ended (the controller's count)
        self.down_half_start = {}  # strike count -> stamp at which that cycle's down half began
        self.cycles_completed = 0  # the controller's count of cycles whose up half ended
        self.wall = 0.0
        self.node = None
        self.interrupted = threading.Event()  # set by the CLI's SIGINT/SIGTERM handler
        self._reported = 0
        self.stopping = False
        self.line = Progress(total=scene.cycles or 1, prefix='  ', keep=True)
        self.logdir = os.path.join(args.out, 'logs')

    def command(self, node: str) -> list[str]:
        a = self.args
        params = {
            'simulator': [
                f'scene:={self.scene_path}',
                f'publish_rate:={a.rate}',
                f'mode:={self.mode}',
                f'rate_factor:={0.0 if self.mode is SimulatorMode.LOCKSTEP else 1.0}',
            ]
            # lockstep: the simulator waits for the recorder, so nothing is lost
            + (
                [f'recorder_window:={contract.RECORDER_WINDOW}']
                if self.output and self.mode is SimulatorMode.LOCKSTEP
                else []
            ),
            'controller': [
                f'scene:={self.scene_path}',
                f'rate:={getattr(a, "control_rate", None) or a.rate}',
            ]
            + ([f'law:={a.law}'] if a.law else [])
            + (['command_readers:=2'] if self.output else [])  # simulator + recorder
            + (
                [f'command_history:={contract.WRITER_REPAIR_DEPTH}']
                if self.output and self.mode is SimulatorMode.LOCKSTEP
                else []
            )
            + (['startup_hold:=0.0'] if self.mode is SimulatorMode.LOCKSTEP else [])
            # lockstep: the controller stops at the count itself, so time stops there
            # however late this process sees it (a loaded machine)
            + ([f'cycles:={self.scene.cycles}'] if self.mode is SimulatorMode.LOCKSTEP else [])
            + list(getattr(a, 'controller_params', None) or []),
            'recorder': [f'output:={self.output}', f'scene:={self.scene_path}'],
        }[node]
        cmd = [sys.executable, '-m', f'impact_arm.nodes.{node}', '--ros-args']
        for p in params:
            cmd += ['-p', p]
        return cmd

    def start(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from std_msgs.msg import String

        os.makedirs(self.logdir, exist_ok=True)
        from rclpy.signals import SignalHandlerOptions

        # Ctrl-C must reach us as KeyboardInterrupt (rclpy's handler would shut the context
        # down under our feet): the nodes are then stopped in order and the table printed
        rclpy.init(
            domain_id=int(self.env['ROS_DOMAIN_ID']), signal_handler_options=SignalHandlerOptions.NO
        )
        self.node = rclpy.create_node('impact_arm_run')
        self.node.create_subscription(
            String, IMPACT_REPORT, self._on_impact, contract.qos(IMPACT_REPORT).to_rclpy()
        )
        self.node.create_subscription(
            DiagnosticArray, DIAGNOSTICS, self._on_diagnostics, contract.qos(DIAGNOSTICS).to_rclpy()
        )
        for node in NODES:
            if node == 'recorder' and not self.output:
                continue
            if node == 'controller':
                self._await_graph()
            if any(proc.poll() is not None for proc in self.procs.values()):
                break  # a node already failed: watch() reports it, start nothing more
            self.logs[node] = os.path.join(self.logdir, f'{node}.log')
            with open(self.logs[node], 'wb') as log:
                self.procs[node] = subprocess.Popen(
                    self.command(node),
                    env=self.env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    preexec_fn=_die_with_parent,
                )
        print(
            f'impact-arm run: scene {self.scene.name!r}, {self.mode} at '
            f'{self.args.rate:g} Hz, ROS_DOMAIN_ID={self.env["ROS_DOMAIN_ID"]}, '
            f'logs in {self.logdir}',
            file=sys.stderr,
        )

    def _await_graph(self, timeout=60.0):
        """Until the controller may start (``ready_for_commands``)."""
        assert self.node is not None, 'start() makes the node before it waits for the graph'
        recorder = RecorderProgress(self.node) if 'recorder' in self.procs else None
        self.recorder_progress = recorder
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self._spin_once(0.05)
            if ready_for_commands(self.node, recorder, simulator_topics(self.scene)):
                return
            for name, proc in self.procs.items():
                if proc.poll() is not None:
                    return  # watch() reports it
        raise ImpactArmError(
            f'the simulator did not appear or the recorder did not match its '
            f'publishers within {timeout:g} s;'
            f' see {self.logdir}'
        )

    def _spin_once(self, timeout):
        """One spin of the run's node; KeyboardInterrupt once the CLI was interrupted."""
        import rclpy

        assert self.node is not None, 'start() makes the node before any wait'
        rclpy.spin_once(self.node, timeout_sec=timeout)
        if self.interrupted.is_set():
            raise KeyboardInterrupt

    def _on_impact(self, msg):
        if not self.stopping:  # the arm released by the stopped controller falls: not the run
            self.impacts.append(impact_from_json(msg.data))

    def _on_diagnostics(self, msg):
        values = status_values(msg, contract.CONTROLLER_STATUS)
        if values is not None and not self.stopping:
            controller = contract.ControllerStatus.parse(values)
            # the controller's own commands alternating in sign and growing ('' : none)
            self.chatter = controller.chatter or self.chatter
            self.strikes = max(self.strikes, controller.strikes)
            self.cycles_completed = max(self.cycles_completed, controller.cycles_completed)
            # the first message of a strike count comes at the strike, while its cycle's
            # down half is still the latest
            self.down_half_start.setdefault(controller.strikes, controller.down_half_start)
        report = simulator_report(msg)
        if report is not None:
            self.simulator = report
            self.published_until = max(self.published_until, report.status.sim_time)
            if not self.stopping:  # the run's time ends with it; the counters with the node
                self.sim_time = report.status.sim_time
            self.rhs_evaluations = report.status.rhs_evaluations

    def watch(self, timeout: float) -> str:
        """Spin until the scene's cycles are done; returns why the run ended."""
        cycles = self.scene.cycles or 1
        start = time.monotonic()
        first = None
        while True:
            self._spin_once(0.1)
            now = time.monotonic()
            simulator = self.simulator.status if self.simulator else None
            if first is None and simulator and simulator.commands:
                # diagnostics come once a second: seeing the first command in them can be a
                # second late (which made the printed real-time factor up to ~30 % high), so
                # count from the moment the simulator itself reports
                first = now - simulator.wall_time
            if self.impacts:
                self.sim_time = max(
                    self.sim_time, self.impacts[-1].t_contact + self.impacts[-1].duration
                )
            self.wall = now - (first or start)
            self._progress(cycles)
            # a cycle counts once the controller saw its impact: an arm that bounces reports
            # several impacts per cycle (the article's reports one)
            if self._struck(cycles):
                if self.mode is SimulatorMode.REALTIME:
                    self._pause_simulator()
                return 'completed'
            for name, proc in self.procs.items():
                if proc.poll() is not None:
                    return f'{name} exited with status {proc.returncode}'
            if self.simulator and self.simulator.stopped:
                return f'simulator stopped: {self.simulator.message}'
            if now - start > timeout:
                return f'timeout after {timeout:g} s'

    def _struck(self, cycles) -> bool:
        """Whether the controller has struck in each of ``cycles`` cycles and the report of
        the last strike's impact is here (the first contact after that cycle's down half
        began; the report and the controller's count travel on different topics). In
        lockstep also whether the controller has stopped at the scene's count (its
        ``cycles``): the recording ends there."""
        if self.strikes < cycles or len(self.impacts) < cycles:
            return False
        if self.mode is SimulatorMode.LOCKSTEP and self.scene.cycles:
            if self.cycles_completed < self.scene.cycles:
                return False
        began = self.down_half_start.get(cycles, -math.inf)
        return any(record.t_contact >= began for record in self.impacts)

    def _pause_simulator(self, timeout=2.0):
        """Realtime: freeze the arm where the run completed. Stopping the controller first
        let the arm fall and chatter on the surface until the simulator stopped too (41 extra
        impacts in one recording); paused, the simulator holds the state."""
        from std_srvs.srv import SetBool

        node = self.node
        assert node is not None, 'start() makes the node before the run can complete'
        client = node.create_client(SetBool, '/simulator/pause')
        try:
            if not client.wait_for_service(timeout_sec=timeout):
                return
            future = client.call_async(SetBool.Request(data=True))
            end = time.monotonic() + timeout
            while not future.done() and time.monotonic() < end:
                self._spin_once(0.05)
        finally:
            node.destroy_client(client)

    def _progress(self, cycles):
        """One refreshed line on a terminal; otherwise a line per impact (logs stay short)."""
        count = len(self.impacts)
        line = (
            f'cycle {min(self.strikes + 1, cycles)}/{cycles}  impacts {count}  '
            f't = {self.sim_time:7.3f} s'
        )
        # /diagnostics come at 1 Hz: 'waiting' seen before the first command is stale once
        # impacts arrive, so only a state worth acting on is shown
        watchdog = self.simulator.status.watchdog if self.simulator else None
        if watchdog is WatchdogState.TIMEOUT or (watchdog is WatchdogState.WAITING and not count):
            line += f'  watchdog {watchdog}'
        self.line.show(line, done=min(self.strikes, cycles), log=count != self._reported)
        self._reported = count

    def _wait(self, proc, timeout):
        """``proc.wait`` that keeps spinning the run's node: the simulator publishes a last
        /diagnostics as it stops, and the summary is made from those final counts (overruns,
        right-hand-side evaluations, simulated time), not from the last 1 Hz one."""
        if self.node is None:
            return proc.wait(timeout=timeout)
        import rclpy

        end = time.monotonic() + timeout
        while proc.poll() is None:
            if time.monotonic() > end:
                raise subprocess.TimeoutExpired(proc.args, timeout)
            rclpy.spin_once(self.node, timeout_sec=0.05)
        for _ in range(4):  # what arrived just before the exit
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return proc.returncode

    def _await_recorder(self, settle=0.3, timeout=10.0):
        """Before the recorder is ended: until what it has written reaches the run's last
        simulated time and stays there for ``settle`` s (the last messages on their way), at
        most ``timeout`` s. A recorder that lagged (descheduled, frozen) is still taking what
        the transport buffered for it; ended then, it lost the tail without a gap to count."""
        progress = getattr(self, 'recorder_progress', None)
        if progress is None or self.node is None or self.interrupted.is_set():
            time.sleep(settle)  # interrupted: the user wants it to end now
            return
        import rclpy

        last = max(self.sim_time, self.published_until)
        target = int(last * 1e9) - 1_000_000  # one period of slack: stamps round
        end = time.monotonic() + timeout
        seen, since = progress.written_until, time.monotonic()
        # rclpy.spin_once, not _spin_once: that raises once interrupted, and stop() must go on
        while time.monotonic() < end and not self.interrupted.is_set():
            rclpy.spin_once(self.node, timeout_sec=0.05)
            if progress.written_until != seen:
                seen, since = progress.written_until, time.monotonic()
            elif seen is not None and seen >= target and time.monotonic() - since >= settle:
                return

    def stop(self) -> dict[str, int | None]:
        """SIGINT each node in order (controller first: it sends a zero command), SIGKILL any
        that does not exit; returns exit codes by node."""
        self.stopping = True
        codes = {}
        for name in STOP_ORDER:
            proc = self.procs.get(name)
            if proc is None:
                continue
            if name == 'recorder':
                self._await_recorder()
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            try:
                codes[name] = self._wait(proc, timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                codes[name] = proc.wait()
        if self.node is not None:
            import rclpy

            self.node.destroy_node()
            rclpy.try_shutdown()
        return codes
