"""controller: the down/up striking cycle as an effort controller (docs/nodes.md), a thin ROS
shell over the ROS-free cycle (physics/control.py) and input handling (driver/control_inputs.py);
parameters in controller_params.py.

It knows the arm only as a real model-based controller would (kinematics and gravity terms
from the scene) and talks only through topics: /joint_states and, if anyone publishes it,
/contact_wrench in; /effort_controller/commands out, [τ_joint1, …, τ_jointN] (the scene's
joints) in the order of ``joints``: what ros2_control's forward_command_controller named
``effort_controller`` takes.

trigger joint_states (default): one command per joint state whose stamp reaches the next tick
of ``rate`` (sensor-synchronous, deterministic on simulated time); trigger timer: a timer at
``rate`` on the node's clock uses the latest joint state. Each input is checked before it can
move the arm (ControlInputs); what is dropped is counted on /diagnostics (~1 Hz). On shutdown
it sends a zero command.

The samples are taken by a control thread of the node's own, like the simulator's loop: it
waits on the two subscriptions (of a reader node no executor spins), reads the few fields it
needs from the raw bytes and publishes the command from pre-serialized bytes. The executor
keeps the rest (parameters, diagnostics, the timer trigger); one lock keeps them from acting
on the inputs while a sample is handled.
"""

from __future__ import annotations

import sys
import threading
import traceback
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NoReturn

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from .. import contract
from ..contract import (
    COMMANDS,
    CONTACT_WRENCH,
    DIAGNOSTICS,
    JOINT_STATES,
    ControlTrigger,
    CycleMode,
)
from ..physics.control import CycleController, PidIntegrator
from ..physics.cycle_count import CycleCount
from ..driver.control_inputs import ControlInputs
from ..physics.model import ArmModel
from ..physics.stability import ChatterWatch, analyse
from ..io.wire import (
    MalformedMessage,
    PatchedMessage,
    joint_state_effort,
    joint_state_fields,
    wrench_stamped_fields,
)
from ._runner import SampleWait, name_thread, reader_node, realtime_priority, run, take_raw
from .controller_params import check, parameter_table
from .param_types import ControllerParameters
from .params import (
    NODE_OPTIONS,
    declare,
    refuse_unknown,
    scene_joint_names,
    startup_scene,
    validator,
)

if TYPE_CHECKING:
    from rclpy.executors import Executor

    from ..physics.scene import Scene

# s: the control thread's longest wait for a sample before it looks at its stop flag again
WAIT_TIMEOUT = 0.1
# s: how long ``finish`` waits for the control thread to end before sending the zero command
JOIN_TIMEOUT = 2.0
# wrenches queued between two states: more than a state's worth at any driver rate the
# controller runs with, so none is lost to the latch while the thread sleeps until a state
WRENCH_QUEUE = 16

# the settings whose change starts a fresh integral
INTEGRAL_SETTINGS = (
    'law',
    'antiwindup_strategy',
    'i_clamp_max',
    'i_clamp_min',
    'u_clamp_max',
    'u_clamp_min',
)


class Controller(Node):
    executor_kind = 'events'  # see _runner.make_executor

    def __init__(self) -> None:
        super().__init__('controller', **NODE_OPTIONS)
        self._declare()
        self._configure()
        self._activate()

    # ------------------------------------------------------------------------ start-up
    def _declare(self) -> None:
        """The parameters of the start-up scene's table as ``self.p``; ParameterError for a
        bad value, an unknown name or a joint order that is not the scene's."""
        # the scene (given at start-up, hence already declared) sets the table's defaults
        _, self.scene = startup_scene(self)
        self.table = parameter_table(self.scene)
        self.p: ControllerParameters = declare(self, self.table, ControllerParameters)
        self.joint_names = scene_joint_names(self.scene)
        self.command_order = check(self.p, self.joint_names)
        refuse_unknown(self, self.table)

    def _configure(self) -> None:
        """The arm model, the cycle's control law and the input handling (ROS-free), warmed
        up; the counts /diagnostics reports and what the control thread shares."""
        scene = self.scene
        self.n = scene.n_links
        self.model = ArmModel(scene)
        # targets and joint states in the robot's joint coordinates; the law in the model's
        self.coordinates = scene.joint_coordinates
        self._check_stability(scene)
        self.ctrl = self._cycle_controller()
        self._warm_up(scene)
        self._init_counts()
        # the inputs and the control law are shared by the control thread and the executor
        # (parameters, diagnostics, the timer trigger): one at a time. Reentrant: a strike's
        # command publishes the diagnostics at once, from inside the control thread's turn.
        self.lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.failure: str | None = None
        self.inputs = self._control_inputs()
        self.inputs.warm_up(scene.q0, scene.qd0)
        # its own commands, in the order sent: chatter is reported on /diagnostics
        self.chatter = ChatterWatch([self.joint_names[j] for j in self.inputs.order])
        self.wire_command = PatchedMessage(
            Float64MultiArray(data=[0.0] * self.n), ('data',), stamp=None
        )
        self.middleware_priority = self.p.thread_priority  # for the runner (_runner.run)

    def _cycle_controller(self) -> CycleController:
        p = self.p
        return CycleController(
            self.model,
            p.law,
            p.p,
            p.d,
            p.i,
            self.coordinates.absolute(p.down_target),
            self.coordinates.absolute(p.up_target),
            p.switch_height,
            p.surface_height,
            space=p.space,
            force_threshold=p.force_threshold,
            reversal_band=p.reversal_band,
            integrator=self._integrator(p),
        )

    def _init_counts(self) -> None:
        """The counts /diagnostics reports, all zero, and the half the cycle begins in."""
        self.sent = 0
        # the cycles struck (down halves ended by a detected impact), the stamp at which the
        # latest down half began and the cycles completed (up halves ended: the arm back
        # through switch_height, the offline run's count), told the cycle's half at each
        # command: `impact-arm run` ends a run on them (an arm that bounces reports several
        # impacts per cycle; its strike is the first contact after the down half began); at
        # ``cycles`` completed no further command is sent
        self.cycle_count = CycleCount(self.p.cycles)
        self._mode = self.ctrl.mode
        self._switches = self.ctrl.switches  # a re-arm sets the down half without a switch

    def _control_inputs(self) -> ControlInputs:
        p = self.p
        return ControlInputs(
            self.ctrl,
            self.joint_names,
            self.command_order,
            p.rate,
            p.trigger,
            self._send,
            log=lambda text: self.get_logger().warning(text, throttle_duration_sec=2.0),
            ready=self._readers_matched,
            startup_hold=p.startup_hold,
            start_after=p.start_after,
            wrench_publishers=self._wrench_published,
            latency_periods=p.latency_periods,
            wrench_tolerance=p.wrench_tolerance,
            implicit_periods=p.implicit_periods,
            implicit_window=p.implicit_window,
            anticipate_impacts=p.anticipate_impacts,
            coordinates=self.coordinates,
            effort_limits=self.scene.effort_limits,
        )

    def _activate(self) -> None:
        """Parameter changes, the command publisher, the sample readers, the timers and
        /diagnostics (the control thread begins in ``start``)."""
        p = self.p
        self.add_on_set_parameters_callback(validator(self.table, self._set_parameters))
        self.pub = self.create_publisher(
            Float64MultiArray, COMMANDS, contract.qos(COMMANDS).to_rclpy(p.command_history)
        )
        self._create_readers()
        if p.startup_hold > 0:
            self.get_logger().info(
                f'first command held {p.startup_hold:g} s after the first '
                f'{p.start_after.replace("_", " ")} '
                f'while DDS discovery settles (startup_hold)'
            )
        if p.trigger is ControlTrigger.TIMER:
            self._create_tick_timer()
        self.pub_diag = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS, contract.qos(DIAGNOSTICS).to_rclpy()
        )
        self.create_timer(1.0, self._publish_diagnostics)
        self.get_logger().info(
            f'law {p.law} at {p.rate:g} Hz ({p.trigger}), scene {self.scene.name!r}'
        )

    def _create_readers(self) -> None:
        """The subscriptions to the wrenches and the joint states, taken by the control
        thread (_control_loop) from a helper node no executor spins: handled in the
        executor's callbacks, a period's two samples cost the callback thread ~10x the
        control law itself. Raw: the few fields needed are read from the bytes, a fraction
        of rclpy's conversion to message objects."""
        # keep only the newest sample: a controller that fell behind acts on the present
        latest_only = contract.qos(JOINT_STATES).to_rclpy()
        latest_only.depth = 1
        self.reader_node = reader = reader_node(self, 'state_reader')
        # the wrenches since the last state, all of them (the largest force is latched): the
        # thread wakes on states only, unless a state waits for its wrench (_control_loop)
        wrenches = contract.qos(CONTACT_WRENCH).to_rclpy()
        wrenches.depth = WRENCH_QUEUE
        self.sub_wrench = reader.create_subscription(
            WrenchStamped, CONTACT_WRENCH, _unused, wrenches, raw=True
        )
        self.sub_state = reader.create_subscription(
            JointState, JOINT_STATES, _unused, latest_only, raw=True
        )
        self.samples = SampleWait(reader, (self.sub_wrench, self.sub_state))

    def _create_tick_timer(self) -> None:
        """trigger timer: the ticks at ``rate`` on the node's clock."""
        self.create_timer(1.0 / self.p.rate, self._on_timer)
        # the ticks come from the executor thread (this one): at the control thread's
        # priority, as all of the controller's work was before it had a thread of its own
        realtime_priority(self.p.thread_priority)

    def _warm_up(self, scene: Scene) -> None:
        """Load the compiled laws and kinematics now: their first call reads numba's cache
        (~0.5 s), which must not happen on the first tick, with the arm already moving."""
        c, law = self.ctrl, self.ctrl.law
        for c.law in ('q', 'pid'):
            c.torque(scene.q0, scene.qd0)
        c.law = law
        self.model.tip(scene.q0, scene.qd0)

    @staticmethod
    def _integrator(p: ControllerParameters) -> PidIntegrator:
        return PidIntegrator(
            len(p.p),
            p.i_clamp_max,
            p.i_clamp_min,
            p.antiwindup_strategy,
            p.u_clamp_max,
            p.u_clamp_min,
        )

    def _set_parameters(self, values: dict[str, Any]) -> None:
        with self.lock:  # never half-applied to a tick
            self._apply_parameters(values)

    def _apply_parameters(self, values: dict[str, Any]) -> None:
        p = self.p.replace(**values)
        check(p, self.joint_names)
        c = self.ctrl
        if any(getattr(p, k) != getattr(self.p, k) for k in INTEGRAL_SETTINGS):
            c.integral = self._integrator(p)
        c.law, c.space = p.law, p.space
        c.kp, c.ki, c.kd = list(p.p), list(p.i), list(p.d)
        c.targets = {
            CycleMode.DOWN: self.coordinates.absolute(p.down_target),
            CycleMode.UP: self.coordinates.absolute(p.up_target),
        }
        c.switch_height, c.surface_height = p.switch_height, p.surface_height
        c.force_threshold, c.reversal_band = p.force_threshold, p.reversal_band
        self.p = p
        self.get_logger().info(f'parameters changed: {", ".join(sorted(values))}')

    # ------------------------------------------------------------------------- inputs
    @property
    def done(self) -> bool:
        return self.failure is not None

    def start(self) -> None:
        """Start the control thread once the process has settled (_runner.run)."""
        self._thread = threading.Thread(target=self._control_loop, name='control', daemon=True)
        self._thread.start()

    def _control_loop(self) -> None:
        try:
            # the executor thread (parameters, diagnostics) shares the GIL with this one; a
            # thread woken by a sample would otherwise wait up to the 5 ms switch interval
            sys.setswitchinterval(5e-5)
            name_thread('control')
            # like a controller manager's update loop
            scheduling = realtime_priority(self.p.thread_priority)
            self.get_logger().info(f'control thread: scheduling {scheduling}')
            wait, take, stop = self.samples.wait, self._take_samples, self._stop.is_set
            inputs, states_only = self.inputs, (self.sub_state,)
            while not stop():
                # a wrench alone does nothing until the next state: waking for it too would
                # double the thread's wake-ups (the costliest part of its period)
                wait(WAIT_TIMEOUT, None if inputs.waiting is not None else states_only)
                take()
        except Exception as exc:  # noqa: BLE001 - reported, and the node stops with an error
            self.get_logger().error(traceback.format_exc())
            self.failure = f'the control thread failed: {type(exc).__name__}: {exc}'

    def _take_samples(self) -> None:
        """The queued samples: the wrenches, oldest first, then the state (its reader keeps
        only the newest), as the driver publishes a period's wrench before its joint state
        (ControlInputs takes either order). One that arrives meanwhile ends the next wait at
        once."""
        with self.lock:
            for _ in range(WRENCH_QUEUE):  # bounded: a flood cannot hold the thread here
                taken = take_raw(self.sub_wrench)
                if taken is None:
                    break
                self._on_wrench(taken[0])
            taken = take_raw(self.sub_state)
            if taken is not None:
                self._on_joint_state(taken[0])

    def _on_timer(self) -> None:
        with self.lock:
            self.inputs.timer()

    def _on_wrench(self, raw: bytes) -> None:
        try:
            fields = wrench_stamped_fields(raw)
        except MalformedMessage as exc:
            self.inputs.drop('malformed_wrenches', f'contact wrench dropped: {exc}')
            return
        self.inputs.wrench(*fields)

    def _on_joint_state(self, raw: bytes) -> None:
        try:
            fields = joint_state_fields(raw)
            # the acting torques, only to measure the latency from them
            effort = joint_state_effort(raw) if self.p.latency_periods == -1 else ()
        except MalformedMessage as exc:
            self.inputs.drop('malformed_joint_states', f'joint state dropped: {exc}')
            return
        self.inputs.joint_state(*fields, effort)

    # ------------------------------------------------------------------------ output
    def _check_stability(self, scene: Scene) -> None:
        """Warn at start when the law, at this node's rate with its gains, is unstable on the
        scene's arm: its commands would chatter. A warning, not a refusal: the node may drive
        an arm that is not the scene's (a stand-in, hardware); ``impact-arm run`` and
        ``simulate --control-rate`` refuse it for the simulated arm."""
        import dataclasses

        p = self.p
        spec = dataclasses.replace(
            scene.controller,
            law=contract.ControlLaw(p.law),
            space=contract.PidSpace(p.space),
            kp=tuple(p.p),
            kd=tuple(p.d),
            ki=tuple(p.i),
            rate=p.rate,
        )
        report = analyse(
            dataclasses.replace(scene, controller=spec), margins=False, model=self.model
        )
        if report is not None and not report.stable:
            self.get_logger().warning(
                f"on the scene's arm {report.key().replace('controller.kd', 'd')} "
                f'{report.refusal("the rate parameter")}'
            )

    def _wrench_published(self) -> bool:
        """Whether anyone publishes the contact wrench."""
        return self.sub_wrench.get_publisher_count() > 0

    def _readers_matched(self) -> bool:
        """The arm is held until our first command: send it only once the readers we were
        told of (command_readers) and every one the graph already knows of are matched (our
        own view of the graph may not show a recorder yet)."""
        return self.pub.get_subscription_count() >= max(
            self.p.command_readers, self.count_subscribers(COMMANDS)
        )

    def _send(self, values: Sequence[float]) -> None:
        count = self.cycle_count
        if count.done:
            return  # the cycles are done: the driver holds the last command
        # the half since the previous command: a change with no switch is a re-arm's
        mode, self._mode = self._mode, self.ctrl.mode
        switched, self._switches = self.ctrl.switches != self._switches, self.ctrl.switches
        latest = self.inputs.latest
        strikes = count.strikes
        count.turn(
            mode, self._mode, latest[0] if latest is not None else None, rearmed=not switched
        )
        if count.done:
            # before the next down half's first command: not one period of it is run
            self.get_logger().info(
                f'{count.completed} cycles completed: no further commands (cycles)'
            )
            self._publish_diagnostics()  # now: a run ends on it
            return
        self.chatter.add(latest[0] if latest is not None else 0.0, values)
        self._publish(values)
        if count.strikes != strikes:
            self._publish_diagnostics()  # now: a run ends on its count

    def _publish(self, values: Sequence[float]) -> None:
        self.pub.publish(self.wire_command.fill([float(v) for v in values]))
        self.sent += 1
        if self.sent == 1 and self.inputs.first_command_after is not None:
            self.get_logger().info(
                f'first command sent {self.inputs.first_command_after:.3f} s after start '
                f'(startup_hold {self.p.startup_hold:g} s after the first '
                f'{self.p.start_after.replace("_", " ")})'
            )

    def _stop_thread(self) -> None:
        self._stop.set()
        self.samples.wake()
        if self._thread is not None:
            self._thread.join(timeout=JOIN_TIMEOUT)
            if self._thread.is_alive():
                self.get_logger().warning(
                    f'control thread still running {JOIN_TIMEOUT:g} s after the stop'
                )

    def destroy_node(self) -> None:
        self.reader_node.destroy_node()
        super().destroy_node()

    def finish(self, executor: Executor | None) -> int:
        """Like a deactivated controller: leave the actuators with zero torque (after the
        control thread's last command)."""
        from rclpy.duration import Duration

        self._stop_thread()
        if self.failure is not None:
            self.get_logger().error(self.failure)
        try:
            self._publish([0.0] * self.n)  # also after the cycles: the actuators let go
            self.pub.wait_for_all_acked(Duration(seconds=0.5))
        except Exception:  # noqa: BLE001 - best effort once the middleware is shutting down
            self.get_logger().warning('could not send the zero command on exit')
        dropped = ', '.join(f'{k} {v}' for k, v in self.inputs.dropped.items() if v)
        self.get_logger().info(
            f'{self.sent} commands sent; zero command on exit'
            + (f'; dropped: {dropped}' if dropped else '')
        )
        return 1 if self.failure is not None else 0

    def _publish_diagnostics(self) -> None:
        with self.lock:  # one instant's counts
            msg = self._diagnostics()
        self.pub_diag.publish(msg)

    def status(self) -> contract.ControllerStatus:
        """What /diagnostics reports of the controller now (under ``lock``)."""
        inputs = self.inputs
        return contract.ControllerStatus(
            chatter=self.chatter.summary(),
            commands_sent=self.sent,
            strikes=self.cycle_count.strikes,
            cycles_completed=self.cycle_count.completed,
            down_half_start=self.cycle_count.down_half_start,
            repeated_states=inputs.repeated,
            repetition_ticks=inputs.repetition_ticks,
            latency_periods=len(inputs.in_flight()),
            latency_periods_max=inputs.latency_max,
            latency_histogram=tuple(sorted(inputs.latency_seen.items())),
            implicit_commands=inputs.implicit_commands,
            driver_answered=inputs.answered_by.value if inputs.answered_by else '',
            unanswered_ticks=inputs.unanswered,
            dropped=tuple(inputs.dropped.items()),
        )

    def _diagnostics(self) -> DiagnosticArray:
        dropped = sum(self.inputs.dropped.values())
        message = 'cycles completed' if self.cycle_count.done else 'running'
        chatter = self.chatter.summary()
        if dropped:
            message = f'{dropped} inputs dropped'
        if chatter:
            message = f'chatter: {chatter}'
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if dropped or chatter else DiagnosticStatus.OK,
            name=contract.CONTROLLER_STATUS,
            hardware_id='impact_arm_controller',
            message=message,
            values=[KeyValue(key=k, value=v) for k, v in self.status().values()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        return msg


def _unused(raw: bytes) -> None:
    """The callback of a subscription only taken from (``take_raw``): never called."""


def main(args: list[str] | None = None) -> NoReturn:
    raise SystemExit(run(Controller, args))


if __name__ == '__main__':
    main()
