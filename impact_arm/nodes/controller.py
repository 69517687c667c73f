"""controller: the down/up striking cycle as an effort controller (design.md §3-4).

It knows the arm only as a real model-based controller would (kinematics and gravity terms
from the scene) and talks only through topics: /joint_states and, if anyone publishes it,
/contact_wrench in; /effort_controller/commands out, [τ_joint1, τ_joint2] in the order of
``joints`` — what ros2_control's forward_command_controller named ``effort_controller`` takes.

trigger joint_states (default): one command per joint state whose stamp reaches the next tick
of ``rate`` (sensor-synchronous, deterministic on simulated time); trigger timer: a timer at
``rate`` on the node's clock uses the latest joint state. On shutdown it sends a zero command.

Its inputs come from any peer on the graph, so each is checked before it can move the arm: a
malformed payload, a state out of range, a stamp that goes backwards or jumps far ahead (unless
the next sample confirms it: then the cycle re-arms there, as after a reset), and a torque
that would not be finite are each dropped, counted, logged throttled and reported on
/diagnostics (~1 Hz).
"""
from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from .. import contract
from ..contract import (ANTIWINDUP_STRATEGIES, COMMANDS, CONTACT_WRENCH, DIAGNOSTICS,
                        FEEDBACK_LAWS, JOINT_STATES, PID_SPACES, joint_names, to_absolute,
                        to_joint_space)
from ..core.control import CycleController, PidIntegrator
from ..core.model import ArmModel
from ..core.scene import load_scene, resolve_scene_path
from ..io.wire import (MalformedMessage, PatchedMessage, joint_state_fields,
                       wrench_stamped_fields)
from ._runner import realtime_priority, run
from .params import NODE_OPTIONS, Param, ParameterError, declare, refuse_unknown, validator

STAMP_EPS = 1e-9                 # stamps are integer nanoseconds: ticks compare to 1 ns
# A state beyond these is not an arm's: a broken or hostile peer. Angles may wind a few turns;
# 1e4 rad/s is the scene's own bound on initial rates.
MAX_ANGLE = 1e3                  # rad
MAX_RATE = 1e4                   # rad/s
MAX_FORCE = 1e12                 # N, a contact wrench beyond any scene's
# samples come at >= 1 Hz (a scene's slowest publish_rate): a longer gap forward, or any step
# back, is a reset or a bad stamp, and the cycle re-arms at the new time
MAX_STAMP_GAP = 1.0              # s
DROPPED = ('malformed_joint_states', 'malformed_wrenches', 'out_of_range_states',
           'out_of_range_wrenches', 'missing_wrenches', 'stamp_jumps', 'unsafe_torques')


def _follows(before, t):
    """Whether a stamp t continues a stream whose previous sample had stamp ``before``."""
    return before - STAMP_EPS <= t <= before + MAX_STAMP_GAP


def parameter_table(scene):
    """The controller's parameters; defaults come from the scene's controller section."""
    c, n = scene.controller, scene.n_links
    surfaces = [s.height for s in scene.surfaces]
    return (
        Param('scene', '', 'scene YAML file or installed scene name (empty: paper): the model '
              'the controller knows (kinematics, gravity) and its default gains', 'str',
              read_only=True),
        Param('law', c.law if c.law in FEEDBACK_LAWS else 'q',
              'q (article eq. 9: PD on link angles + gravity compensation), pid or pd', 'str',
              choices=FEEDBACK_LAWS),
        Param('rate', 1000.0, 'command rate [Hz]', low=0.1, high=100000.0, read_only=True),
        Param('trigger', 'joint_states', 'joint_states: compute on each joint state reaching '
              'the next tick; timer: compute at rate on the node clock', 'str',
              choices=('joint_states', 'timer'), read_only=True),
        Param('p', list(c.kp), 'proportional gains per joint [N m/rad]', 'floats', low=0.0,
              size=n),
        Param('i', list(c.ki), 'integral gains per joint [N m/(rad s)] (law pid)', 'floats',
              low=0.0, size=n),
        Param('d', list(c.kd), 'derivative gains per joint [N m s/rad]', 'floats', low=0.0,
              size=n),
        Param('i_clamp_max', math.inf, 'upper clamp of the integral term [N m] (legacy)',
              high=math.inf),
        Param('i_clamp_min', -math.inf, 'lower clamp of the integral term [N m] (legacy)',
              low=-math.inf),
        Param('u_clamp_max', math.inf, 'upper limit of each joint\'s PID output [N m]',
              high=math.inf),
        Param('u_clamp_min', -math.inf, 'lower limit of each joint\'s PID output [N m]',
              low=-math.inf),
        Param('antiwindup_strategy', 'none', 'integral anti-windup: none, legacy (i_clamp on '
              'the integral term), conditional_integration (integral frozen while the output '
              'is at a u_clamp limit)', 'str',
              choices=ANTIWINDUP_STRATEGIES),
        Param('space', c.space, 'angles the PID acts on: absolute link angles or relative '
              'joint angles', 'str', choices=PID_SPACES),
        Param('down_target', to_joint_space(c.down_target), 'joint positions aimed at on the '
              'way down [rad]', 'floats', low=-4 * math.pi, high=4 * math.pi, size=n),
        Param('up_target', to_joint_space(c.up_target), 'joint positions aimed at on the way '
              'up [rad]', 'floats', low=-4 * math.pi, high=4 * math.pi, size=n),
        Param('switch_height', c.switch_height, 'tip height that ends the up phase [m]',
              low=-1e3, high=1e3),
        Param('surface_height', min(surfaces) if surfaces else -1e3,
              'height of the struck surface, for velocity-reversal detection [m]',
              low=-1e3, high=1e3),
        Param('force_threshold', 1.0, 'contact normal force that means impact [N]', low=0.0),
        Param('reversal_band', 0.01, 'tip velocity reversal within this height above the '
              'surface means impact [m]', low=0.0, high=10.0),
        Param('joints', joint_names(n), 'joint order of the command '
              'array', 'strs', size=n, read_only=True),
        Param('command_readers', 1, 'readers of the command topic (the driver, a recorder) '
              'matched before the first command; the arm is held until then, so nothing of the '
              'run goes unrecorded', 'int', low=1, high=100, read_only=True),
        Param('startup_hold', contract.STARTUP_HOLD, 'seconds after start before the first '
              'command: the arm is held while DDS discovery settles, because Fast DDS can '
              'stop a process\'s reception for 0.33 s when it discovers a participant late '
              '(docs/nodes.md); impact-arm run and the launch file set 0 in lockstep',
              low=0.0, high=60.0, read_only=True),
        Param('command_history', contract.qos(COMMANDS).depth, 'commands the writer keeps to '
              'resend to a reader that fell behind (a recorder); impact-arm run sets '
              f'{contract.WRITER_REPAIR_DEPTH} in lockstep. Realtime keeps the default: a '
              'deep history makes a publish stall ~1 us per sample when acknowledgements '
              'arrive', 'int', low=1, high=100000, read_only=True),
        Param('thread_priority', 49, 'SCHED_FIFO priority of the control thread and of the '
              'middleware threads that deliver its samples (0: normal scheduling; falls back '
              'when the system refuses); one below the simulator loop\'s default, as a '
              'controller manager sits below its hardware driver', 'int', low=0, high=99,
              read_only=True),
    )


class Controller(Node):
    executor_kind = 'events'   # see _runner.make_executor

    def __init__(self):
        super().__init__('controller', **NODE_OPTIONS)
        # the scene (given at start-up, hence already declared) sets the table's defaults
        name = self.get_parameter('scene').value if self.has_parameter('scene') else ''
        scene = load_scene(resolve_scene_path(str(name) or 'paper'))
        self.table = parameter_table(scene)
        p = self.p = declare(self, self.table)
        self.n = scene.n_links
        self.model = ArmModel(scene)
        self.joint_names = joint_names(self.n)
        if sorted(p['joints']) != self.joint_names:
            raise ParameterError(f'parameter joints = {p["joints"]}: must name each of '
                                 f'{self.joint_names} once')
        self.order = [self.joint_names.index(j) for j in p['joints']]
        refuse_unknown(self, self.table)
        self.ctrl = CycleController(self.model, p['law'], p['p'], p['d'], p['i'],
                                    to_absolute(p['down_target']), to_absolute(p['up_target']),
                                    p['switch_height'], p['surface_height'], space=p['space'],
                                    force_threshold=p['force_threshold'],
                                    reversal_band=p['reversal_band'],
                                    integrator=self._integrator(p))
        self._warm_up(scene)
        self.add_on_set_parameters_callback(validator(self.table, self._set_parameters))
        self.period = 1.0 / p['rate']
        self.next_tick = 0.0
        self.latest = None                 # (t, q, qd) in absolute angles
        self.waiting = None                # a joint state waiting for its wrench
        self.wrench_stamp = -math.inf
        self.normal_force = None           # the largest normal force since the last tick
        self.wrench_flowing = True         # wait for each state's wrench (see _on_joint_state)
        self.sent = 0
        self.started = False
        self.hold_until = time.monotonic() + p['startup_hold']
        if p['startup_hold'] > 0:
            self.get_logger().info(f'first command held {p["startup_hold"]:g} s after start '
                                   f'while DDS discovery settles (startup_hold)')
        self.dropped = dict.fromkeys(DROPPED, 0)
        self.jump_from = None              # stamp of a sample that jumped, until confirmed
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS,
                                              contract.qos(DIAGNOSTICS).to_rclpy())
        self.create_timer(1.0, self._publish_diagnostics)
        self.pub = self.create_publisher(Float64MultiArray, COMMANDS, contract.qos(
            COMMANDS).to_rclpy(p['command_history']))
        # keep only the newest sample: a controller that fell behind acts on the present
        latest_only = contract.qos(JOINT_STATES).to_rclpy()
        latest_only.depth = 1
        # raw: the callbacks read the few fields they need from the bytes, which costs a
        # fraction of rclpy's conversion to message objects (twice per period)
        self.sub_wrench = self.create_subscription(WrenchStamped, CONTACT_WRENCH,
                                                   self._on_wrench, latest_only, raw=True)
        self.sub_state = self.create_subscription(JointState, JOINT_STATES,
                                                  self._on_joint_state, latest_only, raw=True)
        if p['trigger'] == 'timer':
            self.create_timer(self.period, self._on_timer)
        self.wire_command = PatchedMessage(Float64MultiArray(data=[0.0] * self.n), ('data',),
                                           stamp=None)
        # like a controller manager's update loop: the thread that runs the callbacks
        self.scheduling = realtime_priority(p['thread_priority'])
        self.middleware_priority = p['thread_priority']    # for the runner (_runner.run)
        self.get_logger().info(f'law {p["law"]} at {p["rate"]:g} Hz ({p["trigger"]}), '
                               f'scene {scene.name!r}, scheduling {self.scheduling}')

    done = False

    def _warm_up(self, scene):
        """Load the compiled laws and kinematics now: their first call reads numba's cache
        (~0.5 s), which must not happen on the first tick, with the arm already moving."""
        c, law = self.ctrl, self.ctrl.law
        for c.law in ('q', 'pid'):
            c.torque(scene.q0, scene.qd0)
        c.law = law
        self.model.tip(scene.q0, scene.qd0)

    @staticmethod
    def _integrator(p):
        return PidIntegrator(len(p['p']), p['i_clamp_max'], p['i_clamp_min'],
                             p['antiwindup_strategy'], p['u_clamp_max'], p['u_clamp_min'])

    def _set_parameters(self, values):
        p = dict(self.p, **values)
        for name in ('i_clamp', 'u_clamp'):
            if p[f'{name}_min'] > p[f'{name}_max']:
                raise ParameterError(f'{name}_min = {p[f"{name}_min"]:g} > {name}_max = '
                                     f'{p[f"{name}_max"]:g}')
        c = self.ctrl
        settings = ('antiwindup_strategy', 'i_clamp_max', 'i_clamp_min', 'u_clamp_max',
                    'u_clamp_min')
        if p['law'] != c.law or any(p[k] != self.p[k] for k in settings):
            c.integral = self._integrator(p)   # a new law or clamp starts a fresh integral
        c.law, c.space = p['law'], p['space']
        c.kp, c.ki, c.kd = list(p['p']), list(p['i']), list(p['d'])
        c.targets = {'down': to_absolute(p['down_target']), 'up': to_absolute(p['up_target'])}
        c.switch_height, c.surface_height = p['switch_height'], p['surface_height']
        c.force_threshold, c.reversal_band = p['force_threshold'], p['reversal_band']
        self.p = p
        self.get_logger().info(f'parameters changed: {", ".join(sorted(values))}')

    # ------------------------------------------------------------------------- inputs
    def _drop(self, counter, why):
        self.dropped[counter] += 1
        self.get_logger().warning(f'{why} ({counter}: {self.dropped[counter]})',
                                  throttle_duration_sec=2.0)

    def _on_wrench(self, raw):
        try:
            sec, nanosec, force = wrench_stamped_fields(raw)
        except MalformedMessage as exc:
            self._drop('malformed_wrenches', f'contact wrench dropped: {exc}')
            return
        if not all(abs(f) <= MAX_FORCE for f in force):     # also false for NaN
            self._drop('out_of_range_wrenches', f'contact wrench dropped: force {force} N not '
                       f'finite or beyond {MAX_FORCE:g} N')
            return
        self.wrench_stamp = sec + nanosec * 1e-9
        # latched until the next tick: an impact is seen even when the wrench sample of its
        # period comes late or after a newer one (the largest force counts)
        self.normal_force = force[1] if self.normal_force is None else \
            max(self.normal_force, force[1])
        self.wrench_flowing = True
        if self.waiting is not None and self.wrench_stamp >= self.waiting[0] - STAMP_EPS:
            state, self.waiting = self.waiting, None
            self._tick(*state)
            return
        # the driver publishes the joint state of the same instant right after the wrench:
        # when it is already here, take it now rather than after another executor wake-up
        handle = self.sub_state.handle
        with handle:
            taken = handle.take_message(JointState, True)
        if taken is not None:
            self._on_joint_state(taken[0])

    def _on_joint_state(self, raw):
        try:
            sec, nanosec, names, position, velocity = joint_state_fields(raw)
        except MalformedMessage as exc:
            self._drop('malformed_joint_states', f'joint state dropped: {exc}')
            return
        t = sec + nanosec * 1e-9
        try:
            index = [names.index(j) for j in self.joint_names]
            pos = [position[k] for k in index]
            vel = [velocity[k] for k in index]
        except (ValueError, IndexError):
            self.get_logger().warning(f'joint state without {self.joint_names} positions and '
                                      f'velocities: ignored', throttle_duration_sec=2.0)
            return
        if not (all(abs(v) <= MAX_ANGLE for v in pos) and all(abs(v) <= MAX_RATE for v in vel)):
            # also false for NaN
            self._drop('out_of_range_states', f'joint state dropped: positions {pos} / '
                       f'velocities {vel} not finite or beyond {MAX_ANGLE:g} rad, '
                       f'{MAX_RATE:g} rad/s')
            return
        if self.latest is not None and not _follows(self.latest[0], t):
            # a reset, or one bad stamp: a second sample that follows the new one confirms a
            # reset; until then the sample is dropped (one stamp of 2^31 s must not silence
            # the controller, nor stamps alternating between two clocks make it tick on each)
            confirmed = self.jump_from is not None and _follows(self.jump_from, t)
            self.jump_from = None if confirmed else t
            if not confirmed:
                self._drop('stamp_jumps', f'joint state stamp went from {self.latest[0]:.9f} '
                           f'to {t:.9f} s: dropped unless the next one follows it')
                return
            self.get_logger().warning(f'joint state stamps restarted at {t:.9f} s: cycle '
                                      f're-armed', throttle_duration_sec=2.0)
            self.next_tick = t
            self.waiting = None
            if self.wrench_stamp > t + STAMP_EPS:   # of the old time line (the new one's
                self.wrench_stamp = -math.inf         # wrench may be here already)
                self.normal_force = None
            # time went back (a simulator ~/reset, a replay restarted): the cycle starts
            # again from its down half
            self.ctrl.rearm(restart=t < self.latest[0])
        self.jump_from = None
        self.latest = (t, to_absolute(pos), to_absolute(vel))
        if self.p['trigger'] != 'joint_states' or t < self.next_tick - STAMP_EPS:
            return
        # the wrench of the same instant is published just before the joint state: wait for
        # it when someone publishes wrenches, so the decision never depends on arrival order.
        # A wrench publisher that sends no valid wrench (broken, a relay losing samples,
        # hostile) must not hold the arm at its last torque: a state still waiting when the
        # next one (or its repetition) arrives is dropped and the newer one ticks without its
        # wrench; states then stop waiting until a wrench arrives again (the loop keeps its
        # rate).
        if self.waiting is not None:       # (a lockstep driver repeats the same state)
            self._drop('missing_wrenches', f'no contact wrench for the state at '
                       f'{self.waiting[0]:.6f} s: ticking on the next state without it, '
                       f'without waiting until a wrench arrives')
            self.wrench_flowing = False
        elif self.wrench_flowing and self.wrench_stamp < t - STAMP_EPS and \
                self.sub_wrench.get_publisher_count() > 0:
            self.waiting = self.latest
            return
        self.waiting = None
        self._tick(*self.latest)

    def _on_timer(self):
        if self.latest is not None:
            self._tick(*self.latest)

    # ------------------------------------------------------------------------ output
    def _tick(self, t, q, qd):
        if not self.started:
            if time.monotonic() < self.hold_until:
                return         # the driver repeats its held state, which brings us back here
            # The arm is held until our first command, so send it only once the readers we
            # were told of (command_readers) and every one the graph already knows of are
            # matched: our own view of the graph may not show a recorder yet. The driver
            # repeats its held state, which brings us back here.
            if self.pub.get_subscription_count() < max(self.p['command_readers'],
                                                       self.count_subscribers(COMMANDS)):
                return
            self.started = True
        self.next_tick = (math.floor(t / self.period + 1e-6) + 1) * self.period
        tau = self.ctrl.update(t, q, qd, normal_force=self.normal_force)
        self.normal_force = None           # the latch covers one tick
        if not all(math.isfinite(v) for v in tau):
            self._drop('unsafe_torques', f'torques {tau} from the state at {t:.6f} s are not '
                       f'finite: not sent, cycle re-armed')
            self.ctrl.rearm()
            return
        self._send([tau[j] for j in self.order])

    def _send(self, values):
        self.pub.publish(self.wire_command.fill([float(v) for v in values]))
        self.sent += 1

    def finish(self, executor) -> int:
        """Like a deactivated controller: leave the actuators with zero torque."""
        from rclpy.duration import Duration
        try:
            self._send([0.0] * self.n)
            self.pub.wait_for_all_acked(Duration(seconds=0.5))
        except Exception:  # noqa: BLE001 - best effort once the middleware is shutting down
            self.get_logger().warning('could not send the zero command on exit')
        dropped = ', '.join(f'{k} {v}' for k, v in self.dropped.items() if v)
        self.get_logger().info(f'{self.sent} commands sent; zero command on exit'
                               + (f'; dropped: {dropped}' if dropped else ''))
        return 0

    def _publish_diagnostics(self):
        dropped = sum(self.dropped.values())
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if dropped else DiagnosticStatus.OK,
            name=contract.CONTROLLER_STATUS, hardware_id='impact_arm_controller',
            message=f'{dropped} inputs dropped' if dropped else 'running',
            values=[KeyValue(key='commands_sent', value=str(self.sent)),
                    *(KeyValue(key=k, value=str(v)) for k, v in self.dropped.items())])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)


def main(args=None):
    raise SystemExit(run(Controller, args))


if __name__ == '__main__':
    main()
