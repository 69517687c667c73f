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

import numpy as np

PERIOD_PARTS = ('commands', 'physics', 'publish')   # where a period's compute goes


class PeriodStats:
    """Timing of the published periods, kept by the stepping thread, read by diagnostics."""

    def __init__(self, nominal=None):
        self.lock = threading.Lock()
        self.intervals = []        # wall time between consecutive publications [s]
        self.computes = []         # wall time to step and publish one period [s]
        self.published = 0
        self.overruns = 0
        self.worst_compute = 0.0
        self.worst_compute_t = 0.0
        self.worst_parts = (0.0, 0.0, 0.0)   # the worst period's commands, physics, publish
        self.last_publish = None
        self.t_published = 0.0     # simulated time of the last period counted in ``published``
        self.nominal = nominal     # the wall period the jitter is measured against [s]
        # whole-run jitter |interval - period| as a 1 us histogram (0 ... 20 ms), plus the max
        self.histogram = np.zeros(20001, dtype=np.int64)
        self.jitter_max = 0.0
        self.jitter_max_t = 0.0
        # whole-run sums of a period's parts: commands, physics, publication and (lockstep)
        # the wait from one publication to the next command [s]
        self.part_sums = [0.0, 0.0, 0.0, 0.0]
        self.part_count = 0

    def part_means(self):
        with self.lock:
            return [s / self.part_count if self.part_count else 0.0 for s in self.part_sums]

    def add(self, published_at, compute, t_sim, overrun, parts=None):
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

    def run_percentiles(self, *qs):
        """Whole-run jitter percentiles [s] from the histogram."""
        with self.lock:
            total = int(self.histogram.sum())
            if not total:
                return [0.0 for _ in qs]
            cumulative = np.cumsum(self.histogram)
            return [float(np.searchsorted(cumulative, q / 100 * total)) * 1e-6 for q in qs]

    def take(self):
        with self.lock:
            intervals, computes = self.intervals, self.computes
            self.intervals, self.computes = [], []
            return intervals, computes


class Watchdog:
    """Zero-order hold of the newest command, zero torque once it is older than ``timeout``.

    ``state``: waiting (no command yet: brakes on) | ok | timeout."""

    def __init__(self, timeout):
        self.timeout = timeout
        self.state = 'waiting'
        self.pending = None        # (torques, arrival time) of the newest valid command
        self.applied = None        # the pending command the arm holds
        self.last_command = None   # arrival time of the newest valid command

    def command(self, torques, now):
        self.pending = (torques, now)
        self.last_command = now

    def hold(self, arm, now):
        """Make ``arm`` hold the newest command, or zero torque when it is too old. Returns
        'timeout' or 'resumed' when the state changes that way (for the log), else None."""
        pending = self.pending
        if pending is None:
            self.state = 'waiting'
            arm.release()
            return None
        if now - pending[1] > self.timeout:
            changed = self.state != 'timeout'
            self.state = 'timeout'
            arm.release()
            self.applied = None
            return 'timeout' if changed else None
        resumed = self.state == 'timeout'
        self.state = 'ok'
        if pending is not self.applied:    # a held command is not applied again each period
            arm.apply_checked(pending[0])  # checked on arrival
            self.applied = pending
        return 'resumed' if resumed else None

    def reapply(self):
        """Apply the held command again at the next period (a new effort limit)."""
        self.applied = None

    def status(self, now):
        """The state as of ``now``: a loop that has not run since the timeout elapsed will
        zero the torque on its next period."""
        if self.state == 'ok' and self.last_command is not None and \
                now - self.last_command > self.timeout:
            self.state = 'timeout'
        return self.state


class DriverLoop:
    """Runs the arm's periods. ``take_commands(now)`` delivers the commands queued since the
    last period (through ``command``); ``publish(tick)`` sends a period's sensor messages;
    ``log(level, text)`` reports watchdog changes. ``clock`` and ``sleep`` are the wall clock
    (``time.monotonic``, ``time.sleep``; fakes in tests)."""

    def __init__(self, arm, *, wall_period, command_timeout, take_commands=None,
                 publish=None, log=None, clock=time.monotonic, sleep=time.sleep):
        self.arm = arm
        self.wall_period = wall_period          # realtime: wall seconds per period
        self.watchdog = Watchdog(command_timeout)
        self.stats = PeriodStats(wall_period)
        self.take_commands = take_commands or (lambda now: None)
        self.publish = publish or (lambda tick: None)
        self.log = log or (lambda level, text: None)
        self.clock, self.sleep = clock, sleep
        self.start_wall = None                  # wall time of the first period
        self.first_command_wall = None          # simulated time starts here
        self.commands = 0
        self._k = 0                             # realtime periods since start_wall

    def command(self, torques, now):
        """A valid command (already checked by ``arm.check_command``) arrived at ``now``."""
        if self.commands == 0:
            self.first_command_wall = now
        self.commands += 1
        self.watchdog.command(torques, now)

    def _hold(self, now):
        change = self.watchdog.hold(self.arm, now)
        if change == 'timeout':
            self.log('warning', f'no command for {self.watchdog.timeout:g} s: torques zeroed')
        elif change == 'resumed':
            self.log('info', 'commands resumed')

    # ---------------------------------------------------------------------------- realtime
    def realtime_period(self):
        """Wait for the next period's deadline, take its commands, step and publish it.
        Returns the period's tick (its impact reports still to be sent), or None while the
        brakes are on (before the first command). SimulationError propagates."""
        if self.start_wall is None:
            self.start_wall = self.clock()
        period = self.wall_period
        deadline = self.start_wall + (self._k + 1) * period
        now = self.clock()
        if deadline > now:
            self.sleep(deadline - now)
        woke = self.clock()
        self._k += 1
        self.take_commands(woke)
        if self.watchdog.pending is None and self.arm.periods == 0:
            # brakes on until the first command: the arm holds its initial state and
            # simulated time starts at 0 with the first command, as offline. (Timing
            # statistics start with the motion: start-up hiccups are not the loop's.)
            self.publish(self.arm.sample())
            self.stats.published += 1
            return None
        self._hold(woke)
        stepping = self.clock()
        tick = self.arm.step()
        stepped = self.clock()
        self.publish(tick)
        done = self.clock()
        # late if this period's publication happened after the next one was due
        self.stats.add(done, done - woke, self.arm.t, done > deadline + period,
                       (stepping - woke, stepped - stepping, done - stepped))
        return tick

    # ---------------------------------------------------------------------------- lockstep
    def lockstep_period(self, arrived, rate_factor):
        """The period a command that arrived at ``arrived`` starts (lockstep); paced so that
        simulated time never runs ahead of ``rate_factor`` x wall time (0: unpaced)."""
        self.watchdog.hold(self.arm, arrived)
        woke = self.clock()
        if self.start_wall is None:
            self.start_wall = woke
        taken = woke - arrived
        if rate_factor > 0:
            due = self.start_wall + (self.arm.periods + 1) / (self.arm.rate * rate_factor)
            if due > woke:
                self.sleep(due - woke)
                woke = self.clock()
        tick = self.arm.step()
        stepped = self.clock()
        self.publish(tick)
        done = self.clock()
        # the wait is what the controller and the transport take (the exchange's round trip)
        last = self.stats.last_publish
        self.stats.add(done, done - woke, self.arm.t, False,
                       (taken, stepped - woke, done - stepped,
                        arrived - last if last is not None else 0.0))
        return tick
