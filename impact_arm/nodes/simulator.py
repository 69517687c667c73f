"""simulator: the arm as a hardware driver presents it (design.md §3-4).

Publishes /joint_states, /contact_wrench (averaged over each period), /impact_report (one JSON
object per impact), /diagnostics (~1 Hz) and, on simulated time, /clock; applies the latest
/effort_controller/commands as a zero-order hold with an effort limit and a watchdog.

mode realtime: a dedicated thread paces the periods by the wall clock (a late period is an
overrun and the schedule is kept, never stretched) and takes each period's commands itself.
Until the first command arrives the arm is held at its initial state (brakes on) and the
initial state is published with stamp 0: simulated time starts with the first command.
mode lockstep: each command advances one period, inside the command callback (deterministic).

Topic hardware (design.md §8, as topic_based_ros2_control's TopicBasedSystem expects): commands
also arrive as sensor_msgs/JointState on ``joint_commands_topic`` (``effort`` matched by joint
name, other fields ignored; a command with an unknown joint, a joint left out or no effort per
name is rejected and counted like a bad array), and the joint states also go out on
``joint_states_topic`` (while someone listens there, as checked at ``tf_rate``; never
/joint_states, which a
JointStateBroadcaster publishes). 3D view: /robot_description (transient local) at start;
/tf_static and /tf at ``tf_rate`` where tf2_msgs is installed; /impact_markers at ``tf_rate``;
both also at each impact's first contact, maximum compression and separation (from the impact
report, io/scene_visuals.py). /tf and the markers come from a timer of the executor thread
that reads the latest published period, so they cost the realtime loop nothing but one
reference.
"""
from __future__ import annotations

import collections
import json
import math
import sys
import threading
import time
import traceback

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from .. import contract
from ..contract import (CLOCK, COMMANDS, CONTACT_WRENCH, DIAGNOSTICS, IMPACT_MARKERS,
                        IMPACT_REPORT, INTEGRATOR_PRESETS, JOINT_STATES, ROBOT_DESCRIPTION, TF,
                        TF_STATIC, VISUAL_TOPICS, joint_names, to_absolute)
from ..core import jit
from ..core.driver import CommandError, SimulatedArm
from ..core.errors import SimulationError
from ..core.realtime import DEFAULT_COMMAND_TIMEOUT, PERIOD_PARTS, DriverLoop
from ..core.scene import load_scene, resolve_scene_path
from ..io.msgdefs import has_type_support
from ..io.scene_visuals import DEFAULT_TF_RATE, SceneVisuals
from ..io.urdf import JOINT_COMMANDS_TOPIC, JOINT_STATES_TOPIC
from ..io.wire import PatchedMessage, float64_array_data, joint_state_command
from . import sim_services
from ._runner import name_thread, realtime_priority, run
from .params import NODE_OPTIONS, Param, ParameterError, declare, refuse_unknown, validator

LOCKSTEP_REPEAT_S = 1.0   # lockstep: publish a period again when unanswered this long
# s at most, at exit, for the readers to acknowledge the last samples. A reader that missed
# samples (stalled, loaded) asks for them again only when the writer's periodic heartbeat
# reaches it, every 3 s with Fast DDS's defaults (no new data piggybacks one at exit): a wait
# shorter than that (2 s) let the test of a lagging recorder lose reports in about one run
# of three under load. It ends as soon as every reader has acknowledged, so an exit without
# lagging readers does not wait.
ACK_WAIT = 4.0
PARAMS = (
    Param('scene', '', 'scene YAML file or installed scene name (empty: paper, the article)',
          'str', read_only=True),
    Param('publish_rate', 1000.0, 'rate of /joint_states and /contact_wrench [Hz]',
          low=1.0, high=100000.0, read_only=True),
    Param('mode', 'realtime', 'realtime: paced by the wall clock; lockstep: one period per '
          'received command', 'str', choices=('realtime', 'lockstep'), read_only=True),
    Param('rate_factor', 1.0, 'simulated seconds per wall second (lockstep: 0 = as fast as '
          'commands arrive); /clock is published unless realtime at 1.0',
          low=0.0, high=1000.0, read_only=True),
    # lower bounds: a watchdog under 1 ms fires between 1 kHz commands and a torque limit
    # under 1 mN m clips every command to nothing; either would silently disable control
    Param('command_timeout', DEFAULT_COMMAND_TIMEOUT, 'seconds without a valid command '
          'before the torques are zeroed (watchdog; a few control periods)',
          low=1e-3, high=3600.0),
    Param('max_effort', 5000.0, 'commanded torques are clipped to +-max_effort [N m]',
          low=1e-3, high=1e9),
    Param('joints', joint_names(2), 'joint order of the command array', 'strs',
          read_only=True),
    Param('preset', '', "integrator preset (empty: the scene's)", 'str',
          choices=('',) + INTEGRATOR_PRESETS, read_only=True),
    Param('thread_priority', 50, 'SCHED_FIFO priority of the realtime loop thread and of the '
          'middleware threads that deliver its commands (0: normal scheduling; needs '
          'CAP_SYS_NICE or an rtprio limit, else it falls back with a note in /diagnostics)',
          'int', low=0, high=99, read_only=True),
    Param('diagnostics_period', 1.0, 'seconds between /diagnostics messages',
          low=0.05, high=60.0, read_only=True),
    Param('step_periods', 1, 'periods one ~/step call advances while paused', 'int', low=1,
          high=1000000),
    Param('frame_id', contract.WRENCH_FRAME, 'TF frame of /contact_wrench (x tangential, '
          'y normal)', 'str', read_only=True),
    Param('joint_commands_topic', JOINT_COMMANDS_TOPIC, 'sensor_msgs/JointState commands '
          '(effort by joint name), as topic_based_ros2_control sends them', 'str',
          read_only=True),
    Param('joint_states_topic', JOINT_STATES_TOPIC, 'joint states again, for '
          'topic_based_ros2_control (not /joint_states)', 'str', read_only=True),
    Param('tf_rate', DEFAULT_TF_RATE, 'rate of /tf and /impact_markers [Hz] (wall clock)',
          low=0.0, high=1000.0, open_low=True, read_only=True),
    Param('recorder_window', 0, 'lockstep: periods simulated time may run ahead of what the '
          f'recorder reports written on {contract.RECORDER_PROGRESS}, so a stalled recorder '
          'holds the run instead of losing samples (0: do not wait for a recorder)', 'int',
          low=0, high=contract.WRITER_REPAIR_DEPTH // 2, read_only=True),
    Param('rod_radius', 0.0, 'radius the rods are drawn with [m] (0: 1 % of the shortest '
          'link)', low=0.0, high=1e3, read_only=True),
    Param('publish_tf', True, 'publish /tf and /tf_static (false when robot_state_publisher '
          'does, launch tf:=rsp)', 'bool', read_only=True),
)


class Simulator(Node):
    executor_kind = 'events'   # see _runner.make_executor

    def __init__(self):
        super().__init__('simulator', **NODE_OPTIONS)
        p = self.p = declare(self, PARAMS)
        scene_path = resolve_scene_path(p['scene'] or 'paper')
        self.scene = load_scene(scene_path)
        # no contact trace: impact reports are built from the located events, and the
        # node publishes no trace rows (converting them cost ~0.1 ms in each impact period)
        self.arm = SimulatedArm(self.scene, p['publish_rate'], preset=p['preset'] or None,
                                max_effort=p['max_effort'], trace=False)
        names = joint_names(self.arm.n)
        if sorted(p['joints']) != sorted(names):
            raise ParameterError(f'parameter joints = {p["joints"]}: must name each of '
                                 f'{names} once (the order of the command array)')
        self.command_order = [names.index(j) for j in p['joints']]
        self.joint_names = names
        if p['joint_states_topic'] in (JOINT_STATES, JOINT_STATES.lstrip('/')) or \
                p['joint_commands_topic'] == COMMANDS:
            raise ParameterError(
                f'parameter joint_states_topic = {p["joint_states_topic"]!r}, '
                f'joint_commands_topic = {p["joint_commands_topic"]!r}: the topic hardware '
                f'needs its own topics (not /joint_states, not {COMMANDS})')
        refuse_unknown(self, PARAMS)
        self.add_on_set_parameters_callback(validator(PARAMS, self._set_parameters))
        self.lockstep = p['mode'] == 'lockstep'
        # for the runner (_runner.run): lockstep runs in the executor thread, unprioritized
        self.middleware_priority = 0 if self.lockstep else p['thread_priority']
        self.publish_clock = self.lockstep or p['rate_factor'] != 1.0
        if not self.lockstep and p['rate_factor'] == 0.0:
            raise ParameterError('parameter rate_factor = 0.0: realtime mode needs a pace '
                                 '> 0 (use mode lockstep to run as fast as possible)')

        def qos(topic, min_depth=1):
            return contract.qos(topic).to_rclpy(min_depth)
        # lockstep: enough history on the per-period streams to repair a starved recorder
        stream_depth = contract.WRITER_REPAIR_DEPTH if self.lockstep else 1
        self.pub_joints = self.create_publisher(JointState, JOINT_STATES,
                                                qos(JOINT_STATES, stream_depth))
        self.pub_wrench = self.create_publisher(WrenchStamped, CONTACT_WRENCH,
                                                qos(CONTACT_WRENCH, stream_depth))
        self.pub_impact = self.create_publisher(String, IMPACT_REPORT, qos(IMPACT_REPORT))
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                              qos(DIAGNOSTICS))
        self.pub_clock = (self.create_publisher(Clock, CLOCK, qos(CLOCK))
                          if self.publish_clock else None)
        self.pub_hw_states = self.create_publisher(JointState, p['joint_states_topic'],
                                                   qos(JOINT_STATES, stream_depth))
        self.hw_states_wanted = False   # someone listens there (updated at tf_rate)
        self.command_reader = self.reader_node = None
        if self.lockstep:
            self.command_sub = self.create_subscription(
                Float64MultiArray, COMMANDS, self._on_command, qos(COMMANDS), raw=True)
            self.joint_command_sub = self.create_subscription(
                JointState, p['joint_commands_topic'], self._on_joint_command,
                qos(COMMANDS), raw=True)
        else:
            self.command_reader, self.joint_command_reader = self._command_readers(
                qos(COMMANDS))
        self._follow_recorder(p['recorder_window'] if self.lockstep else 0)

        # pre-serialized messages: each period only writes its numbers into their bytes
        zeros = [0.0] * self.arm.n
        self.wire_joints = PatchedMessage(
            JointState(name=names, position=zeros, velocity=zeros, effort=zeros),
            ('position', 'velocity', 'effort'))
        wrench = WrenchStamped()
        wrench.header.frame_id = p['frame_id']
        self.wire_wrench = PatchedMessage(wrench, ('wrench.force.x', 'wrench.force.y'))
        self.wire_clock = PatchedMessage(Clock(), (), stamp='clock')

        rate = p['publish_rate'] * (p['rate_factor'] or 1.0)
        self.loop = DriverLoop(self.arm, wall_period=1.0 / rate,
                               command_timeout=p['command_timeout'],
                               take_command=self._take_command, accept=self._accept,
                               publish=self._publish, log=self._log,
                               max_takes=contract.qos(COMMANDS).depth)
        if self.lockstep:
            self.loop.stats.nominal = None   # lockstep has no wall period to jitter around
        self.rejected = self.clipped = 0
        self.publish_failures = 0
        self.sent = collections.Counter()  # topic -> samples published (for loss accounting)
        self.lockstep_repeats = 0
        self.failed = ''
        self.last_reject_log = -math.inf
        self.diag_window_start = time.monotonic()
        self.diag_published = 0
        self._stop = threading.Event()
        self._thread = None
        self.scheduling = 'normal'
        self.create_timer(p['diagnostics_period'], self._publish_diagnostics)
        self._start_visuals()

        self._control_interfaces()
        if not jit.AVAILABLE:
            self.get_logger().warning(f'running the INTERPRETED kernel: {jit.UNAVAILABLE}; '
                                      f'realtime periods will overrun. Fix: {jit.FIX}')
        self.arm.warm_up()                 # before the clock starts: no compile-cache loads later
        initial = self.arm.sample()
        self._publish(initial)             # the state at t = 0, before anything moves
        self.last_tick = (initial, time.monotonic())   # (tick, when published): lockstep
        self.get_logger().info(
            f'scene {self.scene.name!r} ({scene_path}), {p["mode"]} at '
            f'{p["publish_rate"]:g} Hz, preset {self.arm.integrator.rtol:g} rtol')

    def start(self):
        """Start the periods; the runner calls this once the process has settled (its last
        full garbage collection held the GIL for 120-170 ms and stalled a loop started in
        the constructor)."""
        if self.lockstep:
            # until the first command arrives, repeat the initial state so a controller that
            # starts later still gets one (it answers each stamp once); later, repeat a
            # period nobody answered (see _repeat_unanswered)
            self.create_timer(0.1, self._repeat_unanswered)
        else:
            self._thread = threading.Thread(target=self._realtime_loop, name='sim-loop',
                                            daemon=True)
            self._thread.start()

    # ------------------------------------------------------------ simulation control
    def _control_interfaces(self):
        """~/reset, ~/pause, ~/step and /e_stop (design.md section 8)."""
        from std_msgs.msg import Bool
        from std_srvs.srv import SetBool, Trigger
        self.create_service(Trigger, '~/reset', self._on_reset)
        self.create_service(SetBool, '~/pause', self._on_pause)
        self.create_service(Trigger, '~/step', self._on_step)
        self.create_subscription(Bool, contract.E_STOP, self._on_e_stop, 10)
        sim_services.attach(self, self._simulation_controls())   # where the package is

    def _simulation_controls(self):
        """The actions of ~/reset, ~/pause and ~/step for simulation_interfaces."""
        from std_srvs.srv import SetBool, Trigger

        def outcome(handler, request, response):
            response = handler(request, response)
            return response.success, response.message
        return sim_services.SimulationControls(
            reset=lambda: outcome(self._on_reset, None, Trigger.Response()),
            pause=lambda paused: outcome(self._on_pause, SetBool.Request(data=paused),
                                         SetBool.Response()),
            step=lambda n: self._run_steps(n, wait=True),
            is_paused=lambda: self.loop.paused, failure=lambda: self.failed)

    def _on_reset(self, request, response):
        if self.failed:
            response.success, response.message = False, f'stopped: {self.failed}'
            return response
        done = self.loop.request_reset(None if self.lockstep else 1.0)
        if done and self.lockstep:
            self.deferred = None
            self.recorded_until = None     # the recorder's next progress is after the reset
            self._publish(self.arm.sample())
        response.success = done
        response.message = 'reset to the initial state at t = 0; brakes on until the next ' \
            'command' if done else 'the loop did not answer within 1 s'
        self.get_logger().info(f'reset: {response.message}')
        return response

    def _on_pause(self, request, response):
        was = self.loop.paused
        self.loop.set_paused(bool(request.data))
        if self.lockstep and was and not self.loop.paused and self.loop.watchdog.pending:
            self._advance(time.monotonic())   # the exchange waits for a period
        response.success = True
        response.message = 'paused' if self.loop.paused else 'running'
        self.get_logger().info(f'simulation {response.message} at t = {self.arm.t:.6f} s')
        return response

    def _on_step(self, request, response):
        response.success, response.message = self._run_steps(self.p['step_periods'])
        return response

    def _run_steps(self, n, wait=False):
        """While paused, let ``n`` periods run; ``wait``: realtime answers once they ran."""
        if not self.loop.paused:
            return False, 'not paused: ~/pause true first'
        target = self.arm.periods + n
        self.loop.request_steps(n)
        if self.lockstep and self.loop.watchdog.pending and self.loop.take_step():
            self._advance(time.monotonic())   # the exchange waits for a period
        if not wait or self.lockstep:
            return True, f'{n} period(s) requested'
        limit = 1.0 + 2 * n * self.loop.wall_period
        end = time.monotonic() + limit
        while self.arm.periods < target and time.monotonic() < end and not self.failed:
            time.sleep(min(self.loop.wall_period, 0.01))
        if self.arm.periods < target:
            return False, (f'{target - self.arm.periods} of {n} period(s) not run within '
                           f'{limit:.3g} s (brakes stay on until the first command)')
        return True, f'{n} period(s) run, t = {self.arm.t:.6f} s'

    def _on_e_stop(self, msg):
        if bool(msg.data) != self.loop.e_stop:
            self.loop.e_stop = bool(msg.data)
            if self.loop.e_stop:
                self.get_logger().error('e-stop: zero torque until /e_stop false')
            else:
                self.get_logger().warning('e-stop released: commands apply again')

    # ---------------------------------------------------------------------- parameters
    def _set_parameters(self, values):
        if 'max_effort' in values:
            self.arm.max_effort = values['max_effort']
            self.loop.watchdog.reapply()   # re-clip the held command with the new limit
        if 'step_periods' in values:
            self.p['step_periods'] = values['step_periods']
        if 'command_timeout' in values:
            self.p['command_timeout'] = values['command_timeout']
            self.loop.watchdog.timeout = values['command_timeout']

    def _command_readers(self, qos):
        """The command subscriptions of the realtime mode (array, JointState), on a helper
        node no executor spins: the loop thread takes the newest commands itself at the start
        of each period. With the executor delivering commands, the process ran two Python
        threads per period that contended for the GIL, and the loop could wait for a
        lower-priority thread that held it."""
        import rclpy
        self.reader_node = rclpy.create_node(
            '_' + self.get_name() + '_command_reader', namespace=self.get_namespace(),
            context=self.context, start_parameter_services=False, enable_rosout=False)
        return (self.reader_node.create_subscription(Float64MultiArray, COMMANDS,
                                                     lambda msg: None, qos, raw=True),
                self.reader_node.create_subscription(JointState, self.p['joint_commands_topic'],
                                                     lambda msg: None, qos, raw=True))

    def _take_command(self):
        """The oldest queued command of the two command topics (arrays first, then JointState
        commands: one controller uses one of them), with what accepts it; None when both
        queues are empty (realtime mode). So across the topics "newest" is the last taken: in
        a period where both sent, a valid JointState command wins over the arrays, as it did
        when every command was applied in taking order."""
        for reader, msg_type, accept in ((self.command_reader, Float64MultiArray,
                                          self._on_command),
                                         (self.joint_command_reader, JointState,
                                          self._on_joint_command)):
            handle = reader.handle
            with handle:
                taken = handle.take_message(msg_type, True)
            if taken is not None:
                return taken[0], accept
        return None

    @staticmethod
    def _accept(taken, now):
        raw, accept = taken
        return accept(raw, now)

    @property
    def done(self):
        return bool(self.failed)

    # ------------------------------------------------------------------------ commands
    def _on_command(self, raw, now=None):
        """One serialized Float64MultiArray command (joint order: parameter ``joints``);
        True when applied, False when refused."""
        try:
            values = self.arm.check_command(float64_array_data(raw))
        except (CommandError, ValueError) as exc:
            return self._reject(exc, now)
        torques = [0.0] * self.arm.n
        for k, joint in enumerate(self.command_order):
            torques[joint] = values[k]
        self._apply(torques, now)
        return True

    def _on_joint_command(self, raw, now=None):
        """One serialized JointState command of the topic hardware (efforts by name); True
        when applied, False when refused."""
        try:
            torques = self.arm.check_command(joint_state_command(raw, self.joint_names))
        except (CommandError, ValueError) as exc:
            return self._reject(exc, now)
        self._apply(torques, now)
        return True

    def _reject(self, exc, now):
        """Counted; logged at most once a second, and only then formatted: a flood of garbage
        must cost the loop as little as possible per message."""
        self.rejected += 1
        now = time.monotonic() if now is None else now
        if now - self.last_reject_log >= 1.0:
            self.last_reject_log = now
            self.get_logger().warning(f'command rejected: {exc} ({self.rejected} so far)')
        return False

    def _apply(self, torques, now):
        now = time.monotonic() if now is None else now
        self.clipped += any(abs(v) > self.arm.max_effort for v in torques)
        self.loop.command(torques, now)
        if self.lockstep and not self.failed:
            if self.loop.paused:
                if not self.loop.take_step():
                    return                 # held until resumed or stepped
            self._advance(now)

    def _log(self, level, text):
        # rclpy fixes each call site's severity at its first call: one site per level
        if level == 'warning':
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)

    # -------------------------------------------------------------------------- stepping
    def _stepping(self, period):
        """Run ``period`` (a DriverLoop method); None when the simulation had to stop."""
        try:
            return period()
        except SimulationError as exc:
            self._fail(f'{exc} [state {exc.state.tolist() if exc.state is not None else "?"}, '
                       f'held torque {self.arm.command}]')
            return None

    def _realtime_loop(self):
        try:
            # The executor thread (diagnostics) and this one share the GIL; a thread waking
            # from its sleep would otherwise wait up to the 5 ms default switch interval.
            sys.setswitchinterval(5e-5)
            name_thread('sim-loop')
            self.scheduling = realtime_priority(self.p['thread_priority'])
            while not self._stop.is_set() and not self.failed:
                tick = self._stepping(self.loop.realtime_period)
                if tick is not None:
                    self._publish_impacts(tick)
        except Exception as exc:  # noqa: BLE001 - reported, and the node stops with an error
            self.get_logger().error(traceback.format_exc())
            self._fail(f'the stepping thread failed: {type(exc).__name__}: {exc}')

    # ------------------------------------------------------------- recording in lockstep
    def _follow_recorder(self, window):
        """With ``window`` > 0 (lockstep), a period starts only while simulated time is at
        most ``window`` periods ahead of the newest joint state the recorder has written: a
        recorder frozen for seconds holds the run instead of losing what the writers' history
        (WRITER_REPAIR_DEPTH > window) could no longer resend."""
        self.window_ns = round(window * 1e9 / self.p['publish_rate'])
        self.recorded_until = None         # ns, from /recorder/progress
        self.deferred = None               # arrival time of a command waiting for the recorder
        self.waits_for_recorder = 0        # periods that waited
        self.recorder_seen = False
        self.progress_sub = None
        if window:
            from builtin_interfaces.msg import Time
            self.progress_sub = self.create_subscription(
                Time, contract.RECORDER_PROGRESS, self._on_recorder_progress,
                contract.PROGRESS_QOS.to_rclpy())

    def _behind_recorder(self) -> bool:
        if not self.window_ns:
            return False
        if self.progress_sub.get_publisher_count() == 0 and self.recorder_seen:
            return False                   # the recorder left: the run goes on without it
        return self.recorded_until is None or \
            round(self.arm.t * 1e9) - self.recorded_until >= self.window_ns

    def _on_recorder_progress(self, msg):
        self.recorder_seen = True
        self.recorded_until = msg.sec * 1_000_000_000 + msg.nanosec
        if self.deferred is not None and not self._behind_recorder():
            arrived, self.deferred = self.deferred, None
            self._lockstep_period(arrived)

    def _on_recorder_progress_lost(self):
        self.get_logger().warning('the recorder left: the run goes on without it')
        arrived, self.deferred = self.deferred, None
        self._lockstep_period(arrived)

    def _advance(self, arrived):
        """The lockstep period a command starts, now or once the recorder has caught up."""
        if self._behind_recorder():
            if self.deferred is None:
                self.waits_for_recorder += 1
            self.deferred = arrived
            return
        self._lockstep_period(arrived)

    def _lockstep_period(self, arrived):
        if self.failed:
            return
        tick = self._stepping(lambda: self.loop.lockstep_period(arrived, self.p['rate_factor']))
        if tick is not None:
            self.last_tick = (tick, self.loop.stats.last_publish)
            self._publish_impacts(tick)

    def _repeat_unanswered(self):
        """Lockstep waits for a command after each period. Before the first one, the initial
        state goes out every 0.1 s; later, a period unanswered for LOCKSTEP_REPEAT_S is
        published again with its own stamp: a sample lost on the way (a write the middleware
        refused) must not stall the run forever, and a controller answers each stamp once,
        so one that was merely slow ignores the repeat."""
        if self.failed:
            return
        if self.loop.commands == 0:
            self._publish(self.arm.sample())
            return
        if self.deferred is not None:
            if self.recorder_seen and self.progress_sub.get_publisher_count() == 0:
                self._on_recorder_progress_lost()
            else:
                self.get_logger().warning(
                    f'waiting for the recorder: written up to t = '
                    f'{(self.recorded_until or 0) * 1e-9:.3f} s, simulated {self.arm.t:.3f} s '
                    f'(recorder_window {self.p["recorder_window"]})', throttle_duration_sec=2.0)
            return
        tick, published = self.last_tick
        now = time.monotonic()
        last_command = self.loop.watchdog.last_command
        if now - published > LOCKSTEP_REPEAT_S and now - last_command > LOCKSTEP_REPEAT_S \
                and self.command_sub.get_publisher_count() > 0:   # not once the controller left
            self.lockstep_repeats += 1
            self.get_logger().warning(
                f'no command for {now - published:.1f} s after the period ending at t = '
                f'{tick.t:.6f} s: published it again ({self.lockstep_repeats} so far)')
            self._publish(tick)
            self.last_tick = (tick, now)

    def _publish(self, tick):
        # the controller waits for this period's wrench and joint state: they go first,
        # /clock after them
        sec, nsec = divmod(round(tick.t * 1e9), 1_000_000_000)
        self._send(self.pub_wrench, self.wire_wrench.fill(tick.wrench, (sec, nsec)))
        states = self.wire_joints.fill(tick.position + tick.velocity + tick.effort, (sec, nsec))
        self._send(self.pub_joints, states)
        if self.hw_states_wanted:
            self._send(self.pub_hw_states, states)
        self.latest_tick = tick            # for /tf and the markers (executor thread)
        if self.pub_clock is not None:
            self._send(self.pub_clock, self.wire_clock.fill((), (sec, nsec)))

    def _send(self, publisher, data):
        """Publish one sample. A sample the middleware refuses is lost like a dropped packet:
        counted (/diagnostics ``publish_failures``), logged, and the periods go on. Fast DDS
        refuses a reliable write when its readers lag too far behind for too long (seen at
        5 kHz on two cores); before this, the refusal ended the stepping thread."""
        try:
            publisher.publish(data)
            self.sent[publisher.topic_name] += 1
        except RuntimeError as exc:        # rclpy's RCLError: the write failed
            self.publish_failures += 1
            self.get_logger().warning(
                f'{publisher.topic_name}: sample not published ({exc}); '
                f'{self.publish_failures} lost so far', throttle_duration_sec=1.0)

    def _publish_impacts(self, tick):
        """The period's impact reports, once its sensor messages are out: no control loop
        waits for them, and their JSON (~30 shortest-repr floats) takes 40-200 us, which in
        the impact's own period made it the slowest period of a run."""
        for record, _rows in tick.impacts:
            self._send(self.pub_impact, String(data=json.dumps(record)))
            with self.visual_lock:
                self.visuals.add_impact(record)

    # --------------------------------------------------------------------------- 3D view
    def _start_visuals(self):
        """/robot_description and /tf_static once (transient local), then a timer for /tf
        and /impact_markers. Without tf2_msgs rclpy has no type support for TFMessage, so no
        live TF: recordings still hold it (the recorder derives it from /joint_states)."""
        from visualization_msgs.msg import MarkerArray

        def qos(topic):
            return VISUAL_TOPICS[topic][1].to_rclpy()
        self.visuals = SceneVisuals(self.scene, self.p['tf_rate'], self.p['rod_radius'])
        self.visual_lock = threading.Lock()
        self.latest_tick = None
        self._visual_stamp = None
        description = self.create_publisher(String, ROBOT_DESCRIPTION,
                                            qos(ROBOT_DESCRIPTION))
        description.publish(self.visuals.description())
        self.pub_markers = self.create_publisher(MarkerArray, IMPACT_MARKERS,
                                                 qos(IMPACT_MARKERS))
        tf_class = type(self.visuals.tf_static())
        self.pub_tf = None
        if self.p['publish_tf'] and has_type_support(tf_class):
            self.create_publisher(tf_class, TF_STATIC, qos(TF_STATIC)).publish(
                self.visuals.tf_static())
            self.pub_tf = self.create_publisher(tf_class, TF, qos(TF))
        elif self.p['publish_tf']:   # (false: robot_state_publisher owns /tf, tf:=rsp)
            self.get_logger().info('tf2_msgs is not installed: no live /tf or /tf_static '
                                   '(recordings still hold them; launch with tf:=rsp on a '
                                   'ROS install)')
        self.create_timer(1.0 / self.p['tf_rate'], self._publish_visuals)

    def _publish_visuals(self):
        # asking DDS for the subscription count costs ~3 us: here at tf_rate, not each period
        self.hw_states_wanted = self.pub_hw_states.get_subscription_count() > 0
        with self.visual_lock:   # each impact's events first: their stamps are older
            events = [(self.visuals.tf(q, t_ns), self.visuals.markers(t_ns))
                      for t_ns, q in self.visuals.take_events()]
        for tf, markers in events:
            if self.pub_tf is not None:
                self.pub_tf.publish(tf)
            self.pub_markers.publish(markers)
        tick = self.latest_tick
        if tick is None or tick.t == self._visual_stamp:
            return                         # nothing new (paused lockstep, waiting)
        self._visual_stamp = tick.t
        t_ns = round(tick.t * 1e9)
        if self.pub_tf is not None:
            self.pub_tf.publish(self.visuals.tf(to_absolute(tick.position), t_ns))
        with self.visual_lock:
            markers = self.visuals.markers(t_ns)
        self.pub_markers.publish(markers)

    def _fail(self, why):
        self.failed = why
        self.get_logger().error(f'simulation stopped: {why}')
        self._publish_diagnostics()

    # ------------------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self):
        now = time.monotonic()
        watchdog = self.loop.watchdog.status(now)
        intervals, computes = self.loop.stats.take()
        window = now - self.diag_window_start
        self.diag_window_start = now
        with self.loop.stats.lock:   # a consistent pair: periods counted up to this simulated time
            published, t_published = self.loop.stats.published, self.loop.stats.t_published
        if published < self.diag_published:   # a reset
            self.diag_published = 0
        achieved = (published - self.diag_published) / window if window > 0 else 0.0
        self.diag_published = published
        nominal = 1.0 / self.p['publish_rate'] / (self.p['rate_factor'] or 1.0)
        jitter = np.abs(np.asarray(intervals) - nominal) if intervals else np.zeros(1)
        integ = self.arm.integrator.stats
        if self.failed:
            level, message = DiagnosticStatus.ERROR, f'stopped: {self.failed}'
        elif self.loop.e_stop:
            level, message = DiagnosticStatus.ERROR, 'e-stop: zero torque until /e_stop false'
        elif watchdog == 'timeout':
            level, message = DiagnosticStatus.WARN, (
                f'no command for more than {self.p["command_timeout"]:g} s: torques zeroed'
                + (' (lockstep paused)' if self.lockstep else ''))
        elif watchdog == 'waiting':
            level, message = DiagnosticStatus.WARN, 'waiting for the first command (zero torque)'
        elif not jit.AVAILABLE:
            level, message = DiagnosticStatus.WARN, (
                f'interpreted kernel ({jit.UNAVAILABLE}): periods overrun; {jit.FIX}')
        else:
            level, message = DiagnosticStatus.OK, 'paused' if self.loop.paused else 'running'
        start, first_command = self.loop.start_wall, self.loop.first_command_wall
        elapsed = now - start if start else 0.0
        run_p50, run_p99 = self.loop.stats.run_percentiles(50, 99)
        part_means = self.loop.stats.part_means()
        values = {
            'mode': self.p['mode'],
            'publish_rate_requested': f'{self.p["publish_rate"]:g}',
            'publish_rate_achieved': f'{achieved * (self.p["rate_factor"] or 1.0):.1f}'
            if not self.lockstep else f'{achieved:.1f}',
            'jitter_p50_us': f'{np.percentile(jitter, 50) * 1e6:.1f}',
            'jitter_p99_us': f'{np.percentile(jitter, 99) * 1e6:.1f}',
            'jitter_max_us': f'{jitter.max() * 1e6:.1f}',
            'jitter_run_p50_us': f'{run_p50 * 1e6:.0f}',
            'jitter_run_p99_us': f'{run_p99 * 1e6:.0f}',
            'jitter_run_max_us': f'{self.loop.stats.jitter_max * 1e6:.1f}',
            'jitter_run_max_at_s': f'{self.loop.stats.jitter_max_t:.6f}',
            'periods_published': str(published),
            'periods_published_until_s': f'{t_published:.6f}',
            'wall_time': f'{elapsed:.6f}',
            'overruns': str(self.loop.stats.overruns),
            # periods skipped after stalls (simulated time fell behind by as many periods)
            'periods_skipped': str(self.loop.skipped),
            # periods that left commands queued (a flood): the rest waited a period
            'commands_flooded': str(self.loop.flooded),
            # commands taken but not checked: a newer valid one of the same period held
            'commands_superseded': str(self.loop.superseded),
            'watchdog_timeouts': str(self.loop.watchdog.timeouts),
            # the longest wait between two commands taken (s): a stall of the transport
            'longest_command_silence_s': f'{self.loop.watchdog.longest_silence:.6f}',
            # realtime periods run with no command newer than the previous period's
            'periods_without_new_command': str(self.loop.stale),
            'paused': str(self.loop.paused).lower(),
            'e_stop': str(self.loop.e_stop).lower(),
            'kernel': 'compiled (numba)' if jit.AVAILABLE else f'interpreted ({jit.UNAVAILABLE})',
            'compute_max_us': f'{(max(computes) if computes else 0.0) * 1e6:.1f}',
            'compute_worst_us': f'{self.loop.stats.worst_compute * 1e6:.1f}',
            'compute_worst_at_s': f'{self.loop.stats.worst_compute_t:.6f}',
            'period_us': f'{nominal * 1e6:.1f}',
            # where a realtime period's time goes (whole-run means): taking commands,
            # the physics, publishing the period's messages
            **{f'compute_{part}_mean_us': f'{mean * 1e6:.1f}' for part, mean in
               zip(PERIOD_PARTS, part_means)},
            **({'lockstep_wait_mean_us': f'{part_means[3] * 1e6:.1f}'} if self.lockstep else {}),
            # and the worst period's (is it the physics of an impact, or a stall?)
            **{f'compute_worst_{part}_us': f'{t * 1e6:.1f}' for part, t in
               zip(PERIOD_PARTS, self.loop.stats.worst_parts)},
            'watchdog': watchdog,
            'scheduling': self.scheduling,
            'commands': str(self.loop.commands),
            'commands_rejected': str(self.rejected),
            'commands_clipped': str(self.clipped),
            'publish_failures': str(self.publish_failures),
            **({'lockstep_repeats': str(self.lockstep_repeats),
                'periods_waiting_for_recorder': str(self.waits_for_recorder)}
               if self.lockstep else {}),
            'sim_time': f'{self.arm.t:.6f}',
            'real_time_factor': f'{self.arm.t / (now - first_command):.3f}'
            if first_command and now > first_command else '0',
            'impacts': str(self.loop.impacts),
            'rhs_evaluations': str(integ.rhs_evaluations),
            'steps': str(integ.steps),
            'rejected_steps': str(integ.rejected),
            'events': str(integ.events),
        }
        status = DiagnosticStatus(level=level, name=contract.SIMULATOR_STATUS, message=message,
                                  hardware_id='impact_arm_simulated_arm',
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def destroy_node(self):
        if self.reader_node is not None:
            self.reader_node.destroy_node()
        super().destroy_node()

    def finish(self, executor) -> int:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if executor is not None:
            self._publish_diagnostics()
            self._await_acknowledgements()
        self.get_logger().info(
            f'{self.arm.periods} periods, {self.loop.impacts} impacts, {self.loop.stats.overruns} '
            f'overruns, t = {self.arm.t:.3f} s; samples sent: '
            + ', '.join(f'{t} {n}' for t, n in sorted(self.sent.items())))
        return 1 if self.failed else 0


    def _await_acknowledgements(self):
        """Samples a reader has not acknowledged yet die with this process: a recorder
        lagging on a loaded machine lost the last impact reports of a run (12 of 15). Give
        the readers up to ACK_WAIT to take them."""
        from rclpy.duration import Duration
        end = time.monotonic() + ACK_WAIT
        for pub in (self.pub_impact, self.pub_wrench, self.pub_joints, self.pub_diag):
            left = end - time.monotonic()
            if left <= 0 or not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                self.get_logger().warning(f'{pub.topic_name}: not every reader acknowledged '
                                          f'the last samples within {ACK_WAIT:g} s')
                return


def main(args=None):
    raise SystemExit(run(Simulator, args))


if __name__ == '__main__':
    main()
