"""The simulated arm's driver loop, free of ROS: when a period runs, which command it holds,
and how long each period took.

``DriverLoop`` paces ``SimulatedArm`` periods by a clock (realtime) or one per command
(lockstep), holds the newest command through a ``Watchdog`` and keeps ``PeriodStats``. The
simulator node hands it three callables (take the queued commands, publish a period's sensor
messages, log) and adapts the rest to topics; tests drive it with a fake clock.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from ..contract import WatchdogPolicy, WatchdogState

if TYPE_CHECKING:
    from .arm import SimulatedArm, Tick

PERIOD_PARTS = ('commands', 'physics', 'publish')  # where a period's compute goes
SKIPS_KEPT = 8  # the latest stalls whose simulated times the diagnostics give

# How long the driver holds the last command before it zeroes the torques [s]: 20 periods at
# 1 kHz. Holding longer is what crashes a stiff loop. The middleware sometimes delivers
# nothing for ~0.33 s (docs/benchmarks.md); the article's controller has just switched to a
# large "up" torque right after an impact, and held 0.1 s that torque swings the arm over
# and through the floor. A fake-clock test (test_driver.py) replays that silence after an
# impact: 0.1 s crashes the arm, 0.02 s does not. A slower controller needs a longer
# timeout: a few of its periods.
DEFAULT_COMMAND_TIMEOUT = 0.02


# what the watchdog does unless told otherwise, in the driver and the simulator node alike: a
# real drive's safe stop holds the joints (zero torque lets the arm fall onto the part, where
# it chatters)
DEFAULT_WATCHDOG_POLICY = WatchdogPolicy.BRAKE


class PeriodStats:
    """Timing of the published periods, kept by the stepping thread, read by diagnostics."""

    def __init__(self, nominal: float | None = None):
        self.lock = threading.Lock()
        self.intervals: list[float] = []  # wall time between consecutive publications [s]
        self.computes: list[float] = []  # wall time to step and publish one period [s]
        self.published = 0
        self.overruns = 0
        self.worst_compute = 0.0
        self.worst_compute_t = 0.0
        # the worst period's commands, physics, publish
        self.worst_parts: tuple[float, ...] = (0.0, 0.0, 0.0)
        self.last_publish: float | None = None
        self.t_published = 0.0  # simulated time of the last period counted in ``published``
        self.nominal = nominal  # the wall period the jitter is measured against [s]
        # whole-run jitter |interval - period| as a 1 us histogram (0 ... 20 ms), plus the max
        self.histogram = np.zeros(20001, dtype=np.int64)
        self.jitter_max = 0.0
        self.jitter_max_t = 0.0
        # whole-run sums of a period's parts: commands, physics, publication and (lockstep)
        # the wait from one publication to the next command [s]
        self.part_sums = [0.0, 0.0, 0.0, 0.0]
        self.part_count = 0

    def part_means(self) -> list[float]:
        with self.lock:
            return [s / self.part_count if self.part_count else 0.0 for s in self.part_sums]

    def add(
        self,
        published_at: float,
        compute: float,
        t_sim: float,
        overrun: bool,
        parts: Sequence[float] | None = None,
    ) -> None:
        with self.lock:
            if parts is not None:
                for i, part in enumerate(parts):
                    self.part_sums[i] += part
                self.part_count += 1
            if self.last_publish is not None:
                interval = published_at - self.last_publish
                self.intervals.append(interval)
                if self.nominal is not None:
                    jitter = abs(interval - self.nominal)
                    self.histogram[min(int(jitter * 1e6), 20000)] += 1
                    if jitter > self.jitter_max:
                        self.jitter_max, self.jitter_max_t = jitter, t_sim
            self.last_publish = published_at
            self.computes.append(compute)
            self.published += 1
            self.t_published = t_sim
            self.overruns += overrun
            if compute > self.worst_compute:
                self.worst_compute, self.worst_compute_t = compute, t_sim
                if parts is not None:
                    self.worst_parts = tuple(parts[:3])

    def run_percentiles(self, *qs: float) -> list[float]:
        """Whole-run jitter percentiles [s] from the histogram."""
        with self.lock:
            total = int(self.histogram.sum())
            if not total:
                return [0.0 for _ in qs]
            cumulative = np.cumsum(self.histogram)
            return [float(np.searchsorted(cumulative, q / 100 * total)) * 1e-6 for q in qs]

    def take(self) -> tuple[list[float], list[float]]:
        with self.lock:
            intervals, computes = self.intervals, self.computes
            self.intervals, self.computes = [], []
            return intervals, computes


class Watchdog:
    """Zero-order hold of the newest command; once it is older than ``timeout``, zero torque
    (``policy`` zero) or the brake (brake) until the next valid command.

    ``state``: a WatchdogState; ``timeouts`` counts the changes to timeout (each one a
    silence of the controller longer than ``timeout``), ``brakes`` those the brake answered
    and ``brake_peak`` is the largest brake torque applied [N m]; ``silence`` is the wait
    before the newest command and ``longest_silence`` the longest one of the run (s): a
    middleware stall shows there with its length."""

    def __init__(self, timeout: float, policy: WatchdogPolicy | str = DEFAULT_WATCHDOG_POLICY):
        self.timeout = timeout
        self.policy = WatchdogPolicy(policy)
        self.state = WatchdogState.WAITING
        self.timeouts = 0
        self.brakes = 0
        self.brake_peak = 0.0
        # (torques, arrival time) of the newest valid command
        self.pending: tuple[list[float], float] | None = None
        self.applied: tuple[list[float], float] | None = None  # the pending command the arm holds
        self.last_command: float | None = None  # arrival time of the newest valid command
        self.silence = self.longest_silence = 0.0

    def command(self, torques: list[float], now: float) -> None:
        if self.last_command is not None:
            self.silence = now - self.last_command
            self.longest_silence = max(self.longest_silence, self.silence)
        self.pending = (torques, now)
        self.last_command = now

    def hold(self, arm: SimulatedArm, now: float) -> WatchdogState | None:
        """Make ``arm`` hold the newest command, or act on the policy when it is too old.
        Returns the new state when it changes to TIMEOUT or back to OK (for the log), else
        None."""
        pending = self.pending
        if pending is None:
            self.state = WatchdogState.WAITING
            arm.release()
            return None
        if now - pending[1] > self.timeout:
            changed = self.state is not WatchdogState.TIMEOUT
            self.state = WatchdogState.TIMEOUT
            self.timeouts += changed
            if self.policy is WatchdogPolicy.BRAKE:
                if changed:
                    self.brakes += 1
                    arm.engage_brake()
                self.brake_peak = max(self.brake_peak, *(abs(v) for v in arm.brake()))
            else:
                arm.release()
            self.applied = None
            return WatchdogState.TIMEOUT if changed else None
        resumed = self.state is WatchdogState.TIMEOUT
        self.state = WatchdogState.OK
        if pending is not self.applied:  # a held command is not applied again each period
            arm.apply_checked(pending[0])  # checked on arrival
            self.applied = pending
        return WatchdogState.OK if resumed else None

    def reapply(self) -> None:
        """Apply the held command again at the next period (a new effort limit)."""
        self.applied = None

    def status(self, now: float) -> WatchdogState:
        """The state as of ``now``: a loop that has not run since the timeout elapsed will
        zero the torque on its next period. Only reads: the change itself (its log line and
        count) is the loop's, in ``hold``."""
        if (
            self.state is WatchdogState.OK
            and self.last_command is not None
            and now - self.last_command > self.timeout
        ):
            return WatchdogState.TIMEOUT
        return self.state


@dataclass(frozen=True)
class LoopCounts:
    """The loop's schedule counters at one instant ``now`` (wall time): periods published,
    the simulated time of the last of them, periods skipped after stalls and the simulated
    times of the latest stalls."""

    now: float
    published: int
    t_published: float
    skipped: int
    skipped_at: tuple[float, ...]


class DriverLoop:
    """Runs the arm's periods. ``take_command()`` returns the next queued serialized command
    (oldest first) or None; ``accept(raw, now)`` checks one and, when valid, hands it to
    ``command`` and returns True (False when refused); ``publish(tick)`` sends a period's
    sensor messages; ``log(level, text)`` reports state changes. ``clock`` and ``sleep`` are
    the wall clock (``time.monotonic``, ``time.sleep``; fakes in tests).

    After a stall (a period published after the next one was due) the missed periods are
    skipped, as ros2_control's controller manager does: the loop resumes at the next deadline
    of its unchanged schedule, and simulated time advances one period per period run, so it
    falls behind the wall clock by the skipped periods (``skipped``; the real-time factor
    dips) instead of bursting through them back to back with a stale command.

    Simulation control, set from any thread and applied at the next period: ``paused``
    (physics and the watchdog's clock frozen, the held state published each period),
    ``request_steps(n)`` (while paused: n periods, one per wall period), ``request_reset()``
    (initial state at t = 0, brakes on until the next command, statistics and counts reset),
    ``e_stop`` (zero torque whatever the commands, until cleared)."""

    def __init__(
        self,
        arm: SimulatedArm,
        *,
        wall_period: float,
        command_timeout: float,
        take_command: Callable[[], Any] | None = None,
        accept: Callable[[Any, float], bool] | None = None,
        publish: Callable[[Tick], None] | None = None,
        log: Callable[[str, str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        max_takes: int = 100,
        take_budget: float = 0.5,
        policy: WatchdogPolicy | str = DEFAULT_WATCHDOG_POLICY,
        latency: int = 0,
    ):
        self.arm = arm
        # periods a command spends on its way to the actuators (a driver stack's latency,
        # simulated): each period's newest command reaches the watchdog ``latency`` periods
        # after the period that took it. The first command (the release) acts at once.
        if latency < 0:
            raise ValueError(f'command latency = {latency} periods: must be >= 0')
        self.latency = latency
        self._in_flight: deque[list[float] | None] = deque()
        self._newest: list[float] | None = None  # the newest command of this period
        self.wall_period = wall_period  # realtime: wall seconds per period
        self.watchdog = Watchdog(command_timeout, policy)
        self.stats = PeriodStats(wall_period)
        self.take_command = take_command or (lambda: None)
        self.accept = accept or (lambda raw, now: False)
        # the most commands taken in one period: a keep-last queue never holds more, so a
        # flood cannot make one period drain forever (what arrives meanwhile waits)
        self.max_takes = max_takes
        # and the most wall time spent taking them, as a fraction of the period: the
        # middleware's take alone costs ~6 us a message on the project's VM, so a full queue
        # would overrun a 1 ms period by itself. The check (~4 us) comes after, only for the
        # messages from the newest back to the first valid one. What is left stays
        # queued (a keep-last queue drops its oldest). Not less than half: a drain slower than
        # the flood delays every valid command by the queue's length, and a quarter (25
        # messages a period against 40 arriving) delayed the article's stiff controller
        # enough to drive the arm through the floor
        self.take_budget = take_budget
        self.publish = publish or (lambda tick: None)
        self.log = log or (lambda level, text: None)
        self.clock, self.sleep = clock, sleep
        self.start_wall: float | None = None  # wall time the schedule is counted from
        self.first_command_wall: float | None = None  # simulated time starts here
        self.commands = 0
        self.impacts = 0
        self.skipped = 0  # periods skipped after stalls
        # the simulated times at which the latest stalls skipped periods: what a stall did to
        # the loop around it (an impact's rebound) can be told from the run's own record
        # (a tuple replaced, never changed in place: other threads read it while the loop
        # thread records a stall)
        self.skipped_at: tuple[float, ...] = ()
        self.flooded = 0  # periods that left commands queued
        # commands taken but never checked: an accepted newer one of the same period
        # replaced them in the zero-order hold
        self.superseded = 0
        # periods run without a command newer than the previous period's: the controller did
        # not answer within the period (the zero-order hold then holds an older command)
        self.stale = 0
        self._last_pending: tuple[list[float], float] | None = None
        self.paused = False
        self.e_stop = False
        self._steps = 0
        self._reset = threading.Event()
        self._reset_done = threading.Event()
        self._frozen = 0.0  # wall time spent paused [s]
        self._paused_at: float | None = None
        self._k = 0  # index of the next period's deadline

    def counts(self, now: float | None = None) -> LoopCounts:
        """The schedule's counters as one snapshot, with the wall time they hold at: taken
        under the lock the loop thread updates them with, so that periods published plus
        skipped never run ahead of the wall time read beside them."""
        stats = self.stats
        with stats.lock:
            return LoopCounts(
                now=self.clock() if now is None else now,
                published=stats.published,
                t_published=stats.t_published,
                skipped=self.skipped,
                skipped_at=self.skipped_at,
            )

    # -------------------------------------------------------------------- commands in
    def command(self, torques: list[float], now: float) -> None:
        """A valid command (already checked by ``arm.check_command``) arrived at ``now``
        (wall time)."""
        if self.first_command_wall is None:
            self.first_command_wall = now
        self.commands += 1
        if self.latency and self.watchdog.pending is not None:
            self._newest = torques  # on its way: ``_deliver`` hands it on
            return
        self.watchdog.command(torques, self._run_time(now))
        self._in_flight = deque([None] * self.latency)

    def _deliver(self, now):
        """At a period's start: the command taken ``latency`` periods ago reaches the
        watchdog (which holds the one before it meanwhile)."""
        if not self.latency or self.watchdog.pending is None:
            return
        self._in_flight.append(self._newest)
        self._newest = None
        arriving = self._in_flight.popleft()
        if arriving is not None:
            self.watchdog.command(arriving, self._run_time(now))

    def _take_commands(self, now):
        """Take the queued commands, then check them newest first until one is valid: a
        zero-order hold applies only a period's newest valid command, so the older ones
        are not parsed at all (``superseded``; under a flood that is most of a period's
        messages). Refused ones checked on the way are counted by ``accept``."""
        taken, left_queued = self._take_queued(now)
        self.flooded += left_queued
        for newest in range(len(taken) - 1, -1, -1):
            if self.accept(taken[newest], now):
                self.superseded += newest
                return

    def _take_queued(self, now):
        """The queued commands, oldest first, at most ``max_takes`` and until
        ``take_budget`` of the period has gone; and whether some may be left queued."""
        end = now + self.take_budget * self.wall_period
        taken: list[Any] = []
        while len(taken) < self.max_takes:
            raw = self.take_command()
            if raw is None:
                return taken, False
            taken.append(raw)
            if self.clock() >= end:
                break
        return taken, True

    def _run_time(self, now):
        """Wall time with the paused intervals taken out: the watchdog's clock."""
        return (self._paused_at if self._paused_at is not None else now) - self._frozen

    def _hold(self, now):
        if self.e_stop:
            self.arm.release()
            self.watchdog.reapply()
            return
        change = self.watchdog.hold(self.arm, self._run_time(now))
        if change is WatchdogState.TIMEOUT:
            action = (
                'brakes on' if self.watchdog.policy is WatchdogPolicy.BRAKE else 'torques zeroed'
            )
            self.log('warning', f'no command for {self.watchdog.timeout:g} s: {action}')
        elif change is WatchdogState.OK:
            self.log('info', f'commands resumed after {self.watchdog.silence:.3f} s without one')

    # -------------------------------------------------------------------- control
    def set_paused(self, paused: bool) -> None:
        """Freeze (True) or resume the physics; the watchdog's and lockstep's clocks leave
        the paused time out, so nothing times out or catches up on resume."""
        now = self.clock()
        if paused and self._paused_at is None:
            self._paused_at = now
        elif not paused and self._paused_at is not None:
            self._frozen += now - self._paused_at
            self._paused_at = None
            self._steps = 0
        self.paused = paused

    def request_steps(self, n: int) -> None:
        self._steps += n

    def take_step(self) -> bool:
        """Lockstep while paused: True (and one step fewer to go) when a period may run."""
        if self._steps > 0:
            self._steps -= 1
            return True
        return False

    def request_reset(self, timeout: float | None = None) -> bool:
        """Ask the loop for a reset; True once it is done (realtime: at the next period;
        ``timeout`` None means the caller runs the periods itself, e.g. lockstep)."""
        self._reset_done.clear()
        self._reset.set()
        if timeout is None:
            self._apply_controls(self.clock())
            return True
        return self._reset_done.wait(timeout)

    def _apply_controls(self, now):
        if self._reset.is_set():
            self._reset.clear()
            self.arm.reset()
            self.watchdog = Watchdog(self.watchdog.timeout, self.watchdog.policy)
            self.stats = PeriodStats(self.stats.nominal)
            with self.stats.lock:
                self.skipped, self.skipped_at = 0, ()
            self.commands = self.impacts = self.flooded = self.stale = self.superseded = 0
            self.first_command_wall = None
            self._steps = 0
            self._in_flight, self._newest = deque(), None
            # a new schedule from now on: the next period is due one period later
            self.start_wall, self._k, self._frozen = now, -1, 0.0
            self._paused_at = now if self.paused else None
            self._reset_done.set()

    def _count(self, tick):
        self.impacts += len(tick.impacts)
        return tick

    # -------------------------------------------------------------------- realtime
    def realtime_period(self) -> Tick | None:
        """Wait for the next period's deadline, take its commands, step and publish it.
        Returns the period's tick (its impact reports still to be sent), or None when no
        physics ran (brakes on before the first command, paused). SimulationError
        propagates."""
        if self.start_wall is None:
            self.start_wall = self.clock()
        period = self.wall_period
        deadline = self.start_wall + (self._k + 1) * period
        now = self.clock()
        if deadline > now:
            self.sleep(deadline - now)
        woke = self.clock()
        self._take_commands(woke)
        self._deliver(woke)
        self._apply_controls(woke)
        held = self.watchdog.pending is None and self.arm.periods == 0
        if held or (self.paused and not self._steps):
            # brakes on until the first command: the arm holds its initial state and
            # simulated time starts at 0 with the first command, as offline (timing
            # statistics start with the motion); paused: the held state, its time frozen
            self._hold(woke)
            self.publish(self.arm.sample())
            with self.stats.lock:
                self.stats.published += 1
            self._next_deadline(self.clock(), deadline, count=False)
            return None
        if self.paused:
            self._steps -= 1
        pending = self.watchdog.pending
        self.stale += pending is self._last_pending
        self._last_pending = pending
        self._hold(woke)
        stepping = self.clock()
        tick = self.arm.step()
        stepped = self.clock()
        self.publish(tick)
        done = self.clock()
        # late if this period's publication happened after the next one was due
        late = done > deadline + period
        self.stats.add(
            done,
            done - woke,
            self.arm.t,
            late,
            (stepping - woke, stepped - stepping, done - stepped),
        )
        self._next_deadline(done, deadline, count=True)
        return self._count(tick)

    def _next_deadline(self, done, deadline, count):
        """The next period is due at the first deadline of the schedule after ``done``."""
        self._k += 1
        if done > deadline + self.wall_period:
            missed = int((done - self.start_wall) / self.wall_period) - self._k
            self._k += missed
            if count:
                with self.stats.lock:  # read with ``published`` as one snapshot
                    self.skipped += missed
                    self.skipped_at = (*self.skipped_at[-(SKIPS_KEPT - 1) :], self.arm.t)

    # ---------------------------------------------------------------------------- lockstep
    def lockstep_period(self, arrived: float, rate_factor: float) -> Tick:
        """The period a command that arrived at ``arrived`` starts (lockstep); paced so that
        simulated time never runs ahead of ``rate_factor`` x wall time (0: unpaced)."""
        self._deliver(arrived)
        if self.e_stop:
            self.arm.release()
            self.watchdog.reapply()
        else:
            self.watchdog.hold(self.arm, arrived)
        woke = self.clock()
        if self.start_wall is None:
            self.start_wall = woke
        taken = woke - arrived
        if rate_factor > 0:
            due = (
                self.start_wall
                + self._frozen
                + (self.arm.periods + 1) / (self.arm.rate * rate_factor)
            )
            if due > woke:
                self.sleep(due - woke)
                woke = self.clock()
        tick = self.arm.step()
        stepped = self.clock()
        self.publish(tick)
        done = self.clock()
        # the wait is what the controller and the transport take (the exchange's round trip)
        last = self.stats.last_publish
        self.stats.add(
            done,
            done - woke,
            self.arm.t,
            False,
            (taken, stepped - woke, done - stepped, arrived - last if last is not None else 0.0),
        )
        return self._count(tick)
