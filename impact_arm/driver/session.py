"""A simulation session, free of ROS: the simulator node's behaviour behind one interface.

Two kinds, one surface: commands in (``offer``), periods out (the ``publish`` and ``report``
callables of ``Outputs``), ``pause``, ``step``, ``reset``, ``set_e_stop`` and a typed
``SessionStatus`` snapshot the node only serialises to /diagnostics.

``RealtimeSession``: a loop thread paces the periods by the wall clock (``run``) and takes
each period's queued commands itself. ``LockstepSession``: each valid command advances one
period, now or, with a ``recorder_window``, once the recorder has written far enough
(``recorder_progress``); ``tick`` (every 0.1 s) repeats a period nobody answered.

Both run on any clock: tests drive them with a fake one (test_session.py).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Callable, Iterable

import numpy as np

from ..contract import SimulatorMode, SimulatorStatus
from ..physics import jit
from ..physics.kinds import TextEnum
from .arm import CommandError, SimulatedArm, Tick
from ..physics.errors import SimulationError
from .realtime import DEFAULT_WATCHDOG_POLICY, DriverLoop, WatchdogPolicy, WatchdogState

LOCKSTEP_REPEAT_S = 1.0  # lockstep: publish a period again when unanswered this long
# lockstep release_after: before the release, a braked period of its own when no command came
# for this long
LOCKSTEP_BRAKED_S = 0.1


class Level(IntEnum):
    """Severity of a status, as diagnostic_msgs/DiagnosticStatus numbers it."""

    OK = 0
    WARN = 1
    ERROR = 2


class Release(TextEnum):
    """Which command releases the brakes and starts simulated time (at start-up and after a
    reset). first_command: any valid one. nonzero_command: one with a non-zero torque; all-zero
    commands before it are counted and ignored, as a drive ignores a disabled controller's.
    nonzero_joint_command: so for JointState commands (topic hardware such as ros2_control's
    TopicBasedSystem writes zeros from its activation on, long before a controller runs), the
    first one for command arrays (the project's controller sends the model's holding torque
    first)."""

    FIRST_COMMAND = 'first_command'
    NONZERO_COMMAND = 'nonzero_command'
    NONZERO_JOINT_COMMAND = 'nonzero_joint_command'

    def needs_torque(self, joint_command: bool) -> bool:
        """Whether an all-zero command of this kind leaves the brakes on."""
        return self is Release.NONZERO_COMMAND or (
            self is Release.NONZERO_JOINT_COMMAND and joint_command
        )


@dataclass(frozen=True)
class JointCommand:
    """A command read from the topic hardware's JointState topic: ``offer`` takes it like any
    ``read`` callable; its kind matters to the ``Release`` rule."""

    read: Callable[[], list[float]]

    def __call__(self) -> list[float]:
        return self.read()


@dataclass(frozen=True)
class SessionStatus:
    """One snapshot of a session for /diagnostics: severity, a one-line message and the
    values (``diagnostics.values()`` is what goes on the wire)."""

    level: Level
    message: str
    diagnostics: SimulatorStatus


@dataclass
class Outputs:
    """Where a session's results go: ``publish(tick)`` a period's sensor messages,
    ``report(tick)`` its impact reports (after the sensor messages), ``log(level, text)``
    (levels info, warning, waiting: a repeated warning, error); ``failures()`` counts the
    samples the transport refused, ``left_out()`` the periods whose state a driver stack's
    topic was not sent (``joint_states_gap``)."""

    publish: Callable[[Tick], None] = lambda tick: None
    report: Callable[[Tick], None] = lambda tick: None
    log: Callable[[str, str], None] = lambda level, text: None
    failures: Callable[[], int] = lambda: 0
    left_out: Callable[[], int] = lambda: 0


class Session:
    """What both kinds share: commands, control, failure and status."""

    mode = SimulatorMode.REALTIME

    def __init__(
        self,
        arm: SimulatedArm,
        *,
        publish_rate: float,
        rate_factor: float,
        command_timeout: float,
        command_order: list[int],
        outputs: Outputs | None = None,
        policy: WatchdogPolicy = DEFAULT_WATCHDOG_POLICY,
        take_command: Callable[[], Any] | None = None,
        max_takes: int = 100,
        release: Release = Release.FIRST_COMMAND,
        command_latency: int = 0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ):
        self.arm = arm
        self.release = Release(release)
        self.zero_before_release = 0  # all-zero commands that left the brakes on
        self.braked_periods = 0  # lockstep release_after: periods run braked before the release
        self.out = outputs or Outputs()
        self.publish_rate, self.rate_factor = publish_rate, rate_factor
        self.command_order = command_order
        self.clock, self.sleep = clock, sleep
        self.loop = DriverLoop(
            arm,
            wall_period=1.0 / (publish_rate * (rate_factor or 1.0)),
            command_timeout=command_timeout,
            take_command=take_command,
            accept=self.offer,
            publish=self.out.publish,
            log=self.out.log,
            clock=clock,
            sleep=sleep,
            max_takes=max_takes,
            policy=policy,
            latency=command_latency,
        )
        self.rejected = self.clipped = 0
        self.failed = ''  # why the simulation stopped ('' while it runs)
        self.scheduling = 'normal'  # set by whoever runs the periods
        self._last_reject_log = -math.inf
        self._diag_window_start = clock()
        self._diag_published = 0
        self.last_tick: tuple[Tick, float] | None = None  # (tick, when published)

    def publish_initial(self) -> None:
        """The state at t = 0, before anything moves."""
        initial = self.arm.sample()
        self.out.publish(initial)
        self.last_tick = (initial, self.clock())

    # ---------------------------------------------------------------------- commands in
    def ordered(self, values: Iterable[float]) -> list[float]:
        """A command array (in the order ``command_order`` names) as joint torques."""
        values = self.arm.check_command(values)
        torques = [0.0] * self.arm.n
        for k, joint in enumerate(self.command_order):
            torques[joint] = values[k]
        return torques

    def released(self) -> bool:
        """Whether a command has released the brakes (since the start or the last reset)."""
        return self.loop.watchdog.pending is not None or self.arm.periods > self.braked_periods

    def offer(self, read: Callable[[], list[float]], now: float | None = None) -> bool:
        """One command: ``read()`` gives its joint torques, or raises CommandError or
        ValueError when it is malformed. True when taken (applied, or an all-zero command
        the ``release`` rule ignores before the brakes are released), False when refused
        (counted, logged at most once a second)."""
        try:
            torques = read()
        except (CommandError, ValueError) as exc:
            return self._reject(exc, now)
        if not self.released() and self._keeps_brakes(torques, isinstance(read, JointCommand), now):
            return True
        now = self.clock() if now is None else now
        self.clipped += self.arm.clips(torques)
        self.loop.command(torques, now)
        self._commanded(now)
        return True

    def _keeps_brakes(self, torques: list[float], joint_command: bool, now: float | None) -> bool:
        """Before the release: whether this valid command leaves the brakes on (an all-zero
        one the ``release`` rule ignores), counted and logged."""
        if any(torques) or not self.release.needs_torque(joint_command):
            return False
        if not self.zero_before_release:
            self.out.log(
                'info',
                'zero command: brakes stay on until a command with a torque '
                f'(release_on {self.release})',
            )
        self.zero_before_release += 1
        return True

    def _reject(self, exc: Exception, now: float | None) -> bool:
        # formatted only when logged: a flood of garbage must cost as little as possible
        self.rejected += 1
        now = self.clock() if now is None else now
        if now - self._last_reject_log >= 1.0:
            self._last_reject_log = now
            self.out.log('warning', f'command rejected: {exc} ({self.rejected} so far)')
        return False

    def _commanded(self, now):
        """After a valid command (lockstep: run its period)."""

    # -------------------------------------------------------------------------- control
    def set_max_effort(self, limit: float) -> None:
        self.arm.max_effort = limit
        self.loop.watchdog.reapply()  # re-clip the held command with the new limit

    def set_command_timeout(self, timeout: float) -> None:
        self.loop.watchdog.timeout = timeout

    def set_e_stop(self, on: bool) -> bool:
        """Latch or clear the e-stop; True when that changed it."""
        changed = on != self.loop.e_stop
        self.loop.e_stop = on
        return changed

    def pause(self, paused: bool) -> str:
        self.loop.set_paused(paused)
        return 'paused' if self.loop.paused else 'running'

    def step(self, periods: int) -> tuple[bool, str]:
        if not self.loop.paused:
            return False, 'not paused: ~/pause true first'
        self.loop.request_steps(periods)
        if not self.released():  # a step answered with no motion must say why
            return True, (
                f'{periods} period(s) requested; the arm stays braked, time stopped, until a '
                'command releases the brakes (none since the start or the last reset)'
            )
        return True, f'{periods} period(s) requested'

    def run_steps(self, periods: int) -> tuple[bool, str]:
        """``step``; lockstep runs each period on its command."""
        return self.step(periods)

    def reset(self) -> tuple[bool, str]:
        if self.failed:
            return False, f'stopped: {self.failed}'
        done = self._reset()
        return done, (
            'reset to the initial state at t = 0; brakes on until the next command'
            if done
            else 'the loop did not answer within 1 s'
        )

    def _reset(self) -> bool:
        raise NotImplementedError

    def stepping(self, period: Callable[[], Tick | None]) -> Tick | None:
        """Run ``period``; None when the simulation had to stop (``failed``)."""
        try:
            return period()
        except SimulationError as exc:
            state = exc.state.tolist() if exc.state is not None else '?'
            self.fail(f'{exc} [state {state}, held torque {self.arm.command}]')
            return None

    def fail(self, why: str) -> None:
        self.failed = why
        self.out.log('error', f'simulation stopped: {why}')

    # ---------------------------------------------------------------------------- status
    def _message(self, watchdog: WatchdogState) -> tuple[Level, str]:
        if self.failed:
            return Level.ERROR, f'stopped: {self.failed}'
        if self.loop.e_stop:
            return Level.ERROR, 'e-stop: zero torque until /e_stop false'
        if watchdog is WatchdogState.TIMEOUT:
            action = (
                'brakes on'
                if self.loop.watchdog.policy is WatchdogPolicy.BRAKE
                else 'torques zeroed'
            )
            return Level.WARN, (
                f'no command for more than {self.loop.watchdog.timeout:g} s: '
                f'{action}' + (' (lockstep paused)' if self.mode is SimulatorMode.LOCKSTEP else '')
            )
        if watchdog is WatchdogState.WAITING:
            return Level.WARN, 'waiting for the first command (zero torque)'
        if not jit.AVAILABLE:
            return Level.WARN, f'interpreted kernel ({jit.UNAVAILABLE}): periods overrun; {jit.FIX}'
        return Level.OK, 'paused' if self.loop.paused else 'running'

    def take_status(self, now: float | None = None) -> SessionStatus:
        """The status as of ``now``; its jitter and achieved rate cover the time since the
        previous call (which this one ends)."""
        loop, stats, dog = self.loop, self.loop.stats, self.loop.watchdog
        # one snapshot: the wall time and the periods published and skipped up to it
        counts = loop.counts(now)
        now, published, t_published = counts.now, counts.published, counts.t_published
        watchdog = dog.status(now)
        intervals, computes = stats.take()
        window = now - self._diag_window_start
        self._diag_window_start = now
        if published < self._diag_published:  # a reset
            self._diag_published = 0
        achieved = (published - self._diag_published) / window if window > 0 else 0.0
        self._diag_published = published
        pace = self.rate_factor or 1.0
        nominal = 1.0 / self.publish_rate / pace
        jitter = np.abs(np.asarray(intervals) - nominal) if intervals else np.zeros(1)
        integ = self.arm.integrator.stats
        start, first_command = loop.start_wall, loop.first_command_wall
        run_p50, run_p99 = stats.run_percentiles(50, 99)
        part_means = stats.part_means()
        lockstep = self.mode is SimulatorMode.LOCKSTEP
        commands_mean, physics_mean, publish_mean, wait_mean = part_means
        worst_commands, worst_physics, worst_publish = stats.worst_parts
        status = SimulatorStatus(
            mode=self.mode,
            publish_rate_requested=self.publish_rate,
            publish_rate_achieved=achieved if lockstep else achieved * pace,
            jitter_p50_us=np.percentile(jitter, 50) * 1e6,
            jitter_p99_us=np.percentile(jitter, 99) * 1e6,
            jitter_max_us=jitter.max() * 1e6,
            jitter_run_p50_us=run_p50 * 1e6,
            jitter_run_p99_us=run_p99 * 1e6,
            jitter_run_max_us=stats.jitter_max * 1e6,
            jitter_run_max_at_s=stats.jitter_max_t,
            periods_published=published,
            periods_published_until_s=t_published,
            wall_time=now - start if start else 0.0,
            overruns=stats.overruns,
            periods_skipped=counts.skipped,
            periods_skipped_at_s=tuple(counts.skipped_at),
            commands_flooded=loop.flooded,
            commands_superseded=loop.superseded,
            watchdog_timeouts=dog.timeouts,
            longest_command_silence_s=dog.longest_silence,
            periods_without_new_command=loop.stale,
            paused=bool(loop.paused),
            e_stop=bool(loop.e_stop),
            kernel='compiled (numba)' if jit.AVAILABLE else f'interpreted ({jit.UNAVAILABLE})',
            compute_max_us=(max(computes) if computes else 0.0) * 1e6,
            compute_worst_us=stats.worst_compute * 1e6,
            compute_worst_at_s=stats.worst_compute_t,
            period_us=nominal * 1e6,
            compute_commands_mean_us=commands_mean * 1e6,
            compute_physics_mean_us=physics_mean * 1e6,
            compute_publish_mean_us=publish_mean * 1e6,
            lockstep_wait_mean_us=wait_mean * 1e6 if lockstep else None,
            compute_worst_commands_us=worst_commands * 1e6,
            compute_worst_physics_us=worst_physics * 1e6,
            compute_worst_publish_us=worst_publish * 1e6,
            watchdog=watchdog,
            watchdog_policy=dog.policy,
            brake_events=dog.brakes,
            brake_torque_limit_nm=self.arm.brake_torque,
            brake_torque_max_nm=dog.brake_peak,
            scheduling=self.scheduling,
            commands=loop.commands,
            commands_rejected=self.rejected,
            commands_clipped=self.clipped,
            limits='; '.join(e.text() for e in tuple(self.arm.limits.found)),
            zero_commands_before_release=self.zero_before_release,
            publish_failures=self.out.failures(),
            hardware_states_left_out=self.out.left_out(),
            sim_time=self.arm.t,
            real_time_factor=self.arm.t / (now - first_command)
            if first_command and now > first_command
            else None,
            impacts=loop.impacts,
            rhs_evaluations=integ.rhs_evaluations,
            steps=integ.steps,
            rejected_steps=integ.rejected,
            events=integ.events,
        )
        level, message = self._message(watchdog)
        return SessionStatus(level, message, self._with_extra_values(status))

    def _with_extra_values(self, status: SimulatorStatus) -> SimulatorStatus:
        """The status with the values only this kind of session has."""
        return status


class RealtimeSession(Session):
    """Periods paced by the wall clock; ``run`` is the loop thread's body."""

    mode = SimulatorMode.REALTIME

    def __init__(self, arm: SimulatedArm, **kwargs: Any) -> None:
        super().__init__(arm, **kwargs)
        if not self.rate_factor > 0:
            raise ValueError(f'rate_factor = {self.rate_factor}: realtime needs a pace > 0')

    def run(self, should_stop: Callable[[], bool]) -> None:
        """Run periods until ``should_stop()`` or a failure."""
        while not should_stop() and not self.failed:
            tick = self.stepping(self.loop.realtime_period)
            if tick is not None:
                self.out.report(tick)

    def _reset(self) -> bool:
        return self.loop.request_reset(1.0)  # done by the loop thread at its next period

    def run_steps(self, periods: int) -> tuple[bool, str]:
        """``step``, answered once the loop thread has run the periods (simulation_interfaces'
        StepSimulation returns when the step is done), or failed after twice their time."""
        target = self.arm.periods + periods
        ok, message = self.step(periods)
        if not ok:
            return ok, message
        period = 1.0 / (self.arm.rate * self.rate_factor)
        limit = 1.0 + 2.0 * periods * period
        end = self.clock() + limit
        while self.arm.periods < target and self.clock() < end and not self.failed:
            self.sleep(min(period, 0.01))
        if self.arm.periods < target:
            return False, (
                f'{target - self.arm.periods} of {periods} period(s) not run '
                f'within {limit:.3g} s (brakes stay on until the first command)'
            )
        return True, f'{periods} period(s) run, t = {self.arm.t:.6f} s'


class LockstepSession(Session):
    """One period per valid command. With ``recorder_window`` N > 0 a period starts only
    while simulated time is less than N periods ahead of the newest joint state the recorder
    says it has written (``recorder_progress``): a recorder frozen for seconds holds the run
    instead of losing what the writers' history could no longer resend. ``recorder_present``
    and ``controller_present`` tell whether those peers are still on the graph."""

    mode = SimulatorMode.LOCKSTEP

    def __init__(
        self,
        arm: SimulatedArm,
        *,
        recorder_window: int = 0,
        recorder_present: Callable[[], bool] = lambda: True,
        controller_present: Callable[[], bool] = lambda: True,
        release_after: float = 0.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(arm, **kwargs)
        if not release_after >= 0.0:  # (also false for NaN)
            raise ValueError(f'release_after = {release_after}: must be >= 0 s')
        self.release_after = release_after
        self._last_braked = -math.inf  # when the latest braked period ran (wall clock)
        self._braked_start: float | None = None  # when the first one ran
        self.loop.stats.nominal = None  # lockstep has no wall period to jitter around
        self.window_ns = round(recorder_window * 1e9 / self.publish_rate)
        self.recorder_window = recorder_window
        self.recorder_present, self.controller_present = recorder_present, controller_present
        self.recorded_until: int | None = None  # ns, from the recorder's progress
        self.deferred: float | None = None  # arrival of a command waiting for the recorder
        self.waits_for_recorder = 0  # periods that waited
        self.recorder_seen = False
        self.repeats = 0

    def _keeps_brakes(self, torques: list[float], joint_command: bool, now: float | None) -> bool:
        """``release_after`` > 0: every command before the release runs a braked period
        (simulated time advances, the arm stays where it is, the period's messages and /clock go
        out), so that a driver stack updating on /clock keeps writing; the brakes release at
        the first command the ``release`` rule takes once simulated time has reached
        ``release_after``. 0: time stays stopped until the release."""
        zero_held = super()._keeps_brakes(torques, joint_command, now)
        if not self.release_after:
            return zero_held
        if zero_held or self.arm.t < self.release_after - 0.5 / self.arm.rate:
            self._braked_period(self.clock() if now is None else now)
            return True
        return False

    def _braked_period(self, now: float) -> None:
        """One braked period, no sooner than in real time from the first (the controller has
        ``release_after`` wall seconds from the simulator's start to send its first command)."""
        if self.failed:
            return
        if self._braked_start is None:
            self._braked_start = now
        due = self._braked_start + self.braked_periods / self.arm.rate
        if due > now:
            self.sleep(due - now)
            now = self.clock()
        self.arm.hold_still()
        self.braked_periods += 1
        self._last_braked = now
        tick = self.arm.sample()
        self.out.publish(tick)
        self.last_tick = (tick, now)

    def _commanded(self, now):
        if self.failed:
            return
        if self.loop.paused and not self.loop.take_step():
            return  # held until resumed or stepped
        self._advance(now)

    def pause(self, paused: bool) -> str:
        was = self.loop.paused
        message = super().pause(paused)
        if was and not self.loop.paused and self.loop.watchdog.pending:
            self._advance(self.clock())  # the exchange waits for a period
        return message

    def step(self, periods: int) -> tuple[bool, str]:
        ok, message = super().step(periods)
        if ok and self.loop.watchdog.pending and self.loop.take_step():
            self._advance(self.clock())  # the exchange waits for a period
        return ok, message

    def _reset(self) -> bool:
        self.loop.request_reset(None)
        self.braked_periods = 0
        self._braked_start = None
        self.deferred = None
        self.recorded_until = None  # the recorder's next progress is after the reset
        self.out.publish(self.arm.sample())
        return True

    # ------------------------------------------------------------------- the recorder
    def behind_recorder(self) -> bool:
        if not self.window_ns:
            return False
        if self.recorder_seen and not self.recorder_present():
            return False  # the recorder left: the run goes on without it
        return (
            self.recorded_until is None
            or round(self.arm.t * 1e9) - self.recorded_until >= self.window_ns
        )

    def recorder_progress(self, written_ns: int) -> None:
        """The recorder has written the joint states up to stamp ``written_ns``."""
        self.recorder_seen = True
        self.recorded_until = written_ns
        if self.deferred is not None and not self.behind_recorder():
            arrived, self.deferred = self.deferred, None
            self._period(arrived)

    def _advance(self, arrived):
        """The period a command starts, now or once the recorder has caught up."""
        if self.behind_recorder():
            if self.deferred is None:
                self.waits_for_recorder += 1
            self.deferred = arrived
            return
        self._period(arrived)

    def _period(self, arrived):
        if self.failed:
            return
        tick = self.stepping(lambda: self.loop.lockstep_period(arrived, self.rate_factor))
        if tick is not None:
            self.last_tick = (tick, self.loop.stats.last_publish or self.clock())
            self.out.report(tick)

    # ------------------------------------------------------------------- every 0.1 s
    def tick(self, now: float | None = None) -> None:
        """Before the first command the initial state goes out again; later, a period
        unanswered for LOCKSTEP_REPEAT_S is published again with its own stamp: a sample
        lost on the way must not stall the run forever, and a controller answers each stamp
        once, so one that was merely slow ignores the repeat."""
        if self.failed:
            return
        if self.loop.commands == 0:
            now = self.clock() if now is None else now
            if (
                self.release_after
                and self.arm.t < self.release_after - 1.5 / self.arm.rate
                and now - self._last_braked >= LOCKSTEP_BRAKED_S
            ):
                # no command for a while (a stack on /clock that wrote before the simulator
                # was there waits for the clock): a braked period of its own wakes it
                self._braked_period(now)
                return
            self.out.publish(self.arm.sample())
            return
        if self.deferred is not None:
            if self.recorder_seen and not self.recorder_present():
                self.out.log('warning', 'the recorder left: the run goes on without it')
                arrived, self.deferred = self.deferred, None
                self._period(arrived)
            else:
                self.out.log(
                    'waiting',
                    f'waiting for the recorder: written up to t = '
                    f'{(self.recorded_until or 0) * 1e-9:.3f} s, simulated '
                    f'{self.arm.t:.3f} s (recorder_window {self.recorder_window})',
                )
            return
        if self.last_tick is None:  # (publish_initial not called yet)
            return
        now = self.clock() if now is None else now
        tick, published = self.last_tick
        last_command = self.loop.watchdog.last_command or published
        if (
            now - published > LOCKSTEP_REPEAT_S
            and now - last_command > LOCKSTEP_REPEAT_S
            and self.controller_present()
        ):  # not once the controller left
            self.repeats += 1
            self.out.log(
                'warning',
                f'no command for {now - published:.1f} s after the period '
                f'ending at t = {tick.t:.6f} s: published it again ({self.repeats} '
                f'so far)',
            )
            self.out.publish(tick)
            self.last_tick = (tick, now)

    def _with_extra_values(self, status: SimulatorStatus) -> SimulatorStatus:
        return dataclasses.replace(
            status,
            lockstep_repeats=self.repeats,
            periods_waiting_for_recorder=self.waits_for_recorder,
            braked_periods=self.braked_periods,
        )
