"""simulator: the arm as a hardware driver presents it (docs/nodes.md): a thin ROS shell
over a ROS-free session (driver/session.py), parameters in simulator_params.py.

Publishes /joint_states, /contact_wrench (averaged over each period), /impact_report (JSON per
impact), /diagnostics, /clock on simulated time and the 3D view (_period_io.py, _visuals.py);
holds the latest /effort_controller/commands (or JointState commands on
``joint_commands_topic``) under an effort limit and a watchdog (``watchdog_policy``).
Services ~/reset, ~/pause, ~/step (and simulation_interfaces' where installed); /e_stop.

mode realtime: a thread paces the periods by the wall clock and takes each period's commands
from readers no executor spins; until the first command the arm is held at its initial state
(stamp 0). mode lockstep: each command advances one period, in its callback (deterministic).
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NoReturn

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from .. import contract
from ..contract import COMMANDS, DIAGNOSTICS, SimulatorMode
from ..physics import jit
from ..driver.arm import SimulatedArm
from ..driver.session import JointCommand, LockstepSession, Outputs, RealtimeSession
from ..io.wire import float64_array_data, joint_state_command
from . import sim_services
from ._period_io import PeriodPublishers
from ._runner import (
    await_acknowledgements,
    name_thread,
    reader_node,
    realtime_priority,
    run,
    take_raw,
)
from .params import (
    NODE_OPTIONS,
    declare,
    refuse_unknown,
    scene_joint_names,
    startup_scene,
    validator,
)
from .param_types import SimulatorParameters
from .simulator_params import check, parameter_table

if TYPE_CHECKING:
    from rclpy.executors import Executor
    from rclpy.qos import QoSProfile

    from ..driver.arm import Tick

# s at most, at exit, for the readers to acknowledge the last samples: 2 s (under Fast DDS's
# 3 s heartbeat) lost reports of a lagging recorder in one run of three under load
ACK_WAIT = 4.0


class Simulator(Node):
    executor_kind = 'events'  # see _runner.make_executor

    def __init__(self) -> None:
        super().__init__('simulator', **NODE_OPTIONS)
        self._declare()
        self._configure()
        self._activate()

    # ------------------------------------------------------------------ start-up
    def _declare(self) -> None:
        """The parameters of the start-up scene's table as ``self.p``; ParameterError for a
        bad value, an unknown name or a joint order that is not the scene's."""
        # the scene (given at start-up, hence already declared) sets the joints' defaults
        self.scene_path, self.scene = startup_scene(self)
        self.table = parameter_table(self.scene)
        self.p: SimulatorParameters = declare(self, self.table, SimulatorParameters)
        self.joint_names = scene_joint_names(self.scene)
        self.command_order = check(self.p, self.joint_names)
        refuse_unknown(self, self.table)

    def _configure(self) -> None:
        """The simulated arm and the session that runs its periods (ROS-free; its outputs go
        to the publishers ``_activate`` creates)."""
        p = self.p
        # no contact trace: impact reports are built from the located events
        self.arm = SimulatedArm(
            self.scene,
            p.publish_rate,
            preset=p.preset or None,
            max_effort=p.max_effort,
            trace=False,
            brake_torque=p.brake_torque,
        )
        self.lockstep = p.mode is SimulatorMode.LOCKSTEP
        # lockstep runs in the executor thread, unprioritized (read by _runner.run)
        self.middleware_priority = 0 if self.lockstep else p.thread_priority
        self.reader_node: Node | None = None
        self.session: LockstepSession | RealtimeSession = (
            self._lockstep_session()
            if self.lockstep
            else RealtimeSession(self.arm, take_command=self._take_command, **self._settings())
        )
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _settings(self) -> dict[str, Any]:
        """The session settings both modes share."""
        p = self.p
        outputs = Outputs(
            self._publish_period,
            self._report_period,
            self._log,
            self._publish_failures,
            self._hardware_states_left_out,
        )
        return dict(
            publish_rate=p.publish_rate,
            rate_factor=p.rate_factor,
            command_timeout=p.command_timeout,
            outputs=outputs,
            command_order=self.command_order,
            policy=p.watchdog_policy,
            max_takes=contract.qos(COMMANDS).depth,
            release=p.release_on,
            command_latency=p.command_latency_periods,
        )

    def _lockstep_session(self) -> LockstepSession:
        p = self.p
        return LockstepSession(
            self.arm,
            recorder_window=p.recorder_window,
            release_after=p.release_after,
            **self._settings(),
            recorder_present=self._recorder_present,
            controller_present=self._controller_present,
        )

    def _activate(self) -> None:
        """Parameter changes, the publishers, the command inputs, the services and the
        diagnostics timer; then the kernel is warmed up and the state at t = 0 published
        (the periods begin in ``start``)."""
        self.add_on_set_parameters_callback(validator(self.table, self._set_parameters))
        self.out = PeriodPublishers(self, self.scene, self.joint_names, self.p, self.lockstep)
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS, _qos(DIAGNOSTICS))
        if isinstance(self.session, LockstepSession):
            self._subscribe_commands(self.session)
        else:
            self._create_command_readers()
        self._serve_controls()
        self.create_timer(self.p.diagnostics_period, self._publish_diagnostics)
        self._warm_up()  # before the clock starts: no cache loads later
        self.session.publish_initial()  # the state at t = 0, before anything moves
        self.get_logger().info(
            f'scene {self.scene.name!r} ({self.scene_path}), {self.p.mode} at '
            f'{self.p.publish_rate:g} Hz, preset {self.arm.integrator.rtol:g} rtol, '
            f'watchdog {self.p.watchdog_policy}'
        )

    def _subscribe_commands(self, session: LockstepSession) -> None:
        """Lockstep: the commands (and the recorder's progress) through the executor, each
        command running its period in its callback."""
        p = self.p

        def on_progress(msg: Time) -> None:
            session.recorder_progress(msg.sec * 1_000_000_000 + msg.nanosec)

        self.progress_sub = (
            self.create_subscription(
                Time, contract.RECORDER_PROGRESS, on_progress, contract.PROGRESS_QOS.to_rclpy()
            )
            if p.recorder_window
            else None
        )
        offer = session.offer

        # callbacks return nothing: offer's answer (taken or refused) the session counts
        def on_array_command(raw: bytes) -> None:
            offer(self._array_command(raw))

        def on_named_command(raw: bytes) -> None:
            offer(self._named_command(raw))

        self.command_sub = self.create_subscription(
            Float64MultiArray, COMMANDS, on_array_command, _qos(COMMANDS), raw=True
        )
        self.create_subscription(
            JointState, p.joint_commands_topic, on_named_command, _qos(COMMANDS), raw=True
        )

    def _create_command_readers(self) -> None:
        """Realtime: the commands are read by the loop thread itself at the start of each
        period, from a reader node no executor spins: with the executor delivering commands,
        two Python threads contended for the GIL each period."""
        self.reader_node = reader = reader_node(self, 'command_reader')
        self.readers = (
            (
                reader.create_subscription(
                    Float64MultiArray, COMMANDS, _unused, _qos(COMMANDS), raw=True
                ),
                self._array_command,
            ),
            (
                reader.create_subscription(
                    JointState, self.p.joint_commands_topic, _unused, _qos(COMMANDS), raw=True
                ),
                self._named_command,
            ),
        )

    def _serve_controls(self) -> None:
        """~/reset, ~/pause, ~/step, /e_stop and simulation_interfaces' services."""
        self.create_service(Trigger, '~/reset', self._on_reset)
        self.create_service(SetBool, '~/pause', self._on_pause)
        self.create_service(Trigger, '~/step', self._on_step)
        self.create_subscription(Bool, contract.E_STOP, self._on_e_stop, 10)
        sim_services.attach(
            self,
            sim_services.SimulationControls(
                self.session.reset,
                lambda paused: (True, self.session.pause(paused)),
                self.session.run_steps,
                lambda: self.session.loop.paused,
                lambda: self.session.failed,
            ),
        )

    def _warm_up(self) -> None:
        """Load the compiled kernel now, saying so when it runs interpreted."""
        if not jit.AVAILABLE:
            self.get_logger().warning(
                f'running the INTERPRETED kernel: {jit.UNAVAILABLE}; '
                f'realtime periods will overrun. Fix: {jit.FIX}'
            )
        self.arm.warm_up()

    def start(self) -> None:
        """Start the periods once the process has settled (_runner.run: its last full
        garbage collection held the GIL for 120-170 ms and stalled a loop started earlier)."""
        session = self.session
        if isinstance(session, LockstepSession):
            self.create_timer(0.1, lambda: session.tick())  # (no TimerInfo)
        else:
            self._thread = threading.Thread(
                target=self._realtime_loop, args=(session,), name='sim-loop', daemon=True
            )
            self._thread.start()

    @property
    def done(self) -> bool:
        return bool(self.session.failed)

    # ------------------------------------------------------------------ commands in
    def _array_command(self, raw: bytes) -> Callable[[], list[float]]:
        return lambda: self.session.ordered(float64_array_data(raw))

    def _named_command(self, raw: bytes) -> JointCommand:
        return JointCommand(
            lambda: self.arm.check_command(joint_state_command(raw, self.joint_names))
        )

    def _take_command(self) -> Callable[[], list[float]] | None:
        """The oldest queued command, arrays first (one controller uses one topic; in a
        period where both sent, a valid JointState command wins); None when none is queued."""
        for reader, read in self.readers:
            taken = take_raw(reader)
            if taken is not None:
                return read(taken[0])
        return None

    def _recorder_present(self) -> bool:
        """Lockstep: whether a recorder publishes its progress to us."""
        return self.progress_sub is not None and self.progress_sub.get_publisher_count() > 0

    def _controller_present(self) -> bool:
        """Lockstep: whether a controller publishes array commands to us."""
        return self.command_sub.get_publisher_count() > 0

    # ------------------------------------------------------------------- control
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.session.reset()
        self.get_logger().info(f'reset: {response.message}')
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        response.success, response.message = True, self.session.pause(bool(request.data))
        self.get_logger().info(f'simulation {response.message} at t = {self.arm.t:.6f} s')
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.session.step(self.p.step_periods)
        return response

    def _on_e_stop(self, msg: Bool) -> None:
        if self.session.set_e_stop(bool(msg.data)):
            if msg.data:
                self.get_logger().error('e-stop: zero torque until /e_stop false')
            else:
                self.get_logger().warning('e-stop released: commands apply again')

    def _set_parameters(self, values: dict[str, Any]) -> None:
        self.p = self.p.replace(**values)
        if 'max_effort' in values:
            self.session.set_max_effort(values['max_effort'])
        if 'command_timeout' in values:
            self.session.set_command_timeout(values['command_timeout'])
        if 'brake_torque' in values:
            self.arm.brake_torque = values['brake_torque']

    # --------------------------------------------------------------------- out
    def _realtime_loop(self, session: RealtimeSession) -> None:
        try:
            # the executor thread (diagnostics) and this one share the GIL; a thread waking
            # from its sleep would otherwise wait up to the 5 ms default switch interval
            sys.setswitchinterval(5e-5)
            name_thread('sim-loop')
            session.scheduling = realtime_priority(self.p.thread_priority)
            session.run(self._stop.is_set)
        except Exception as exc:  # noqa: BLE001 - reported, and the node stops with an error
            self.get_logger().error(traceback.format_exc())
            session.fail(f'the stepping thread failed: {type(exc).__name__}: {exc}')

    def _publish_period(self, tick: Tick) -> None:
        self.out.publish(tick)

    def _report_period(self, tick: Tick) -> None:
        self.out.report(tick)

    def _publish_failures(self) -> int:
        return self.out.failures

    def _hardware_states_left_out(self) -> int:
        return self.out.hw_gaps.left_out

    def _log(self, level: str, text: str) -> None:
        # rclpy fixes each call site's severity at its first call: one site per level
        if level == 'error':
            self.get_logger().error(text)
            self._publish_diagnostics()  # a failure: say it now
        elif level == 'warning':
            self.get_logger().warning(text)
        elif level == 'waiting':
            self.get_logger().warning(text, throttle_duration_sec=2.0)
        else:
            self.get_logger().info(text)

    def _publish_diagnostics(self) -> None:
        status = self.session.take_status(time.monotonic())
        msg = DiagnosticArray(
            status=[
                DiagnosticStatus(
                    level=bytes([status.level]),
                    name=contract.SIMULATOR_STATUS,
                    message=status.message,
                    hardware_id='impact_arm_simulated_arm',
                    values=[KeyValue(key=k, value=v) for k, v in status.diagnostics.values()],
                )
            ]
        )
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    # ------------------------------------------------------------------- exit
    def destroy_node(self) -> None:
        if self.reader_node is not None:
            self.reader_node.destroy_node()
        super().destroy_node()

    def finish(self, executor: Executor | None) -> int:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if executor is not None:
            self._publish_diagnostics()
            per_period = (self.out.joints, self.out.wrench, self.out.peak, self.out.mounts)
            await_acknowledgements(
                self,
                (self.out.impact, *(p for p in per_period if p is not None), self.pub_diag),
                ACK_WAIT,
            )
        loop = self.session.loop
        self.get_logger().info(
            f'{self.arm.periods} periods, {loop.impacts} impacts, '
            f'{loop.stats.overruns} overruns, t = {self.arm.t:.3f} s; '
            f'{self.out.sent_text()}'
        )
        return 1 if self.session.failed else 0


def _qos(topic: str) -> QoSProfile:
    return contract.qos(topic).to_rclpy()


def _unused(msg: bytes) -> None:
    """The callback of a reader only polled (``take_raw``): never called."""


def main(args: list[str] | None = None) -> NoReturn:
    raise SystemExit(run(Simulator, args))


if __name__ == '__main__':
    main()
