"""The controller's input handling, free of ROS: which samples it trusts and when it ticks.

Its inputs come from any peer on the graph, so each is checked before it can move the arm: a
state out of range, a stamp that goes backwards or jumps far ahead (unless the next sample
confirms it: then the cycle re-arms there, as after a reset) and a torque that would not be
finite are each dropped and counted (``dropped``). The contact wrench is latched until the
next tick (the largest normal force counts), and with trigger ``joint_states`` a state waits
for the wrench of its own instant, so the decision never depends on arrival order.

The controller node parses the messages and hands the fields here; ``send`` gets each
command (in the order of the command array). Tests drive it with a fake clock.
"""

from __future__ import annotations

import math
import time
from collections import Counter, deque
from typing import Callable, Sequence

from ..contract import ControlTrigger, CycleMode, JointCoordinates, StartAfter
from ..physics.kinds import TextEnum
from ..physics.control import CycleController
from ..physics.prediction import StatePredictor

STAMP_EPS = 1e-9  # stamps are integer nanoseconds: ticks compare to 1 ns
# A state beyond these is not an arm's: a broken or hostile peer. Angles may wind a few turns;
# 1e4 rad/s is the scene's own bound on initial rates.
MAX_ANGLE = 1e3  # rad
MAX_RATE = 1e4  # rad/s
MAX_FORCE = 1e12  # N, a contact wrench beyond any scene's
# samples come at >= 1 Hz (a scene's slowest publish_rate): a longer gap forward than the
# stream was silent for, or any step back, is a reset or a bad stamp, and the cycle re-arms at
# the new time
MAX_STAMP_GAP = 1.0  # s
# A state whose stamp is within this fraction of a control period (or of the state stream's
# own spacing, when finer) before the next tick still ticks: a driver stamping with its own
# wall clock (ros2_control's joint_state_broadcaster) jitters around the simulated grid
TICK_TOLERANCE = 0.4
# a sample equal to the previous one within this many periods is the driver's repetition
REPEAT_WINDOW = 1.5
# the most commands in flight a measurement counts (8 ms at 1 kHz)
MAX_MEASURED_LATENCY = 8
# commands kept to predict and to match the efforts a driver reports against
SENT_HISTORY = 32
# the latency varies when, among the measurements of this long a time (at the control rate),
# two values or more were each measured at least LATENCY_RECURS times (a pipeline filling at
# start-up measures each shorter latency once)
LATENCY_WINDOW_S = 1.0
LATENCY_RECURS = 3
# the controller node's implicit_window [s]: the rebound, where the implicit law matters
DEFAULT_IMPLICIT_WINDOW = 0.05
# The first this long of the rebound, where its rates make the law's torques largest: a
# command there may act for as long as the recurring latencies' spread plus one period (sent
# at the shortest latency, overtaken by one at the longest), and the implicit law looks that
# far ahead; afterwards half the spread suffices (docs/benchmarks.md)
REBOUND_HOLD_S = 0.005
DROPPED = (
    'malformed_joint_states',
    'malformed_wrenches',
    'out_of_range_states',
    'out_of_range_wrenches',
    'missing_wrenches',
    'stamp_jumps',
    'unsafe_torques',
    'unsafe_predictions',
)


def follows(before: float, t: float, silent: float = 0.0) -> bool:
    """Whether a stamp t continues a stream whose previous sample had stamp ``before`` and
    which was silent for ``silent`` seconds (by the receiver's clock) before t came: a driver
    paused by its machine for longer than MAX_STAMP_GAP resumes with a stamp that far ahead,
    and that is time that passed, not a bad stamp."""
    return before - STAMP_EPS <= t <= before + MAX_STAMP_GAP + max(silent, 0.0)


class Answer(TextEnum):
    """How the driver showed that it applies the controller's commands: a reported effort
    equal to a command sent, or a state other than the one the first command was computed
    on (the arm moved)."""

    EFFORT = 'effort'
    MOTION = 'motion'


class ControlInputs:
    """Samples in, commands out. ``ready()`` says whether the first command may go (its
    readers are matched); ``wrench_publishers()`` whether anyone publishes wrenches;
    ``log(text)`` gets the (throttled by the caller) warnings."""

    def __init__(
        self,
        ctrl: CycleController,
        joint_names: Sequence[str],
        order: Sequence[int],
        rate: float,
        trigger: ControlTrigger | str,
        send: Callable[[list[float]], None],
        log: Callable[[str], object] = lambda text: None,
        ready: Callable[[], bool] = lambda: True,
        wrench_publishers: Callable[[], bool] = lambda: True,
        startup_hold: float = 0.0,
        start_after: StartAfter | str = StartAfter.JOINT_STATE,
        clock: Callable[[], float] = time.monotonic,
        latency_periods: int = 0,
        wrench_tolerance: float = math.inf,
        implicit_periods: int = 0,
        implicit_window: float = math.inf,
        anticipate_impacts: bool = True,
        coordinates: JointCoordinates | None = None,
        effort_limits: Sequence[float] = (),
    ):
        self.ctrl = ctrl
        # the wire's joint coordinates (the robot's zero and sign) against the law's
        self.coordinates = coordinates or JointCoordinates.identity(len(joint_names))
        # the robot's effort limits (inf: none): a command never asks for more, as a
        # ros2_control stack with joint limits never sends more
        self.effort_limits = list(effort_limits) or [math.inf] * len(joint_names)
        self.clip = any(math.isfinite(limit) for limit in self.effort_limits)
        self.joint_names = list(joint_names)
        # where our joints are in the latest joint state's names
        self._names: list[str] | None = None
        self._index: list[int] = []
        self.order = list(order)
        self.period = 1.0 / rate
        self.trigger = ControlTrigger(trigger)
        self.send, self.log, self.ready = send, log, ready
        self.wrench_publishers = wrench_publishers
        self.clock = clock
        self.created = clock()
        # the first command waits ``startup_hold`` after the first joint state or wrench
        # (``start_after``): discovery settles around the driver's publisher, whenever the
        # driver starts
        self.startup_hold = startup_hold
        self.start_after = StartAfter(start_after)
        self.hold_until = math.inf
        # The loop is closed once the driver answers the first command (``Answer``). Until
        # then each tick sends the first command again and the law does not run: a driver
        # stack publishes its initial values before its hardware's first state (a
        # broadcaster over TopicBasedSystem, the simulator not started yet): a law run on
        # them would integrate, predict over its commands in flight and switch on a state
        # that is not the arm's, and meet the arm with what it computed meanwhile.
        self.answered_by: Answer | None = None
        self.first_efforts: list[float] | None = None  # as sent, in joint_names order
        self.first_state: tuple[list[float], list[float]] | None = None  # as received
        self.unanswered = 0  # ticks that sent the first command again
        # when the first command went, by this clock, after the inputs were created
        self.first_command_after: float | None = None
        self.next_tick = 0.0
        self.latest: tuple[float, list[float], list[float]] | None = None  # absolute angles
        self.latest_arrival = -math.inf  # when it came, by ``clock``
        self.latest_joint: tuple[list[float], list[float]] = ([], [])  # as received
        # a joint state waiting for its wrench
        self.waiting: tuple[float, list[float], list[float]] | None = None
        self.wrench_stamp = -math.inf
        self.normal_force: float | None = None  # the largest since the last tick
        self.wrench_flowing = True  # wait for each state's wrench (see joint_state)
        self.started = False
        self.dropped = dict.fromkeys(DROPPED, 0)
        self.jump_from: float | None = None  # stamp of a sample that jumped, until confirmed
        # a state is waited for its wrench only when the newest wrench is at most this far
        # behind it on the same clock: a wrench on another clock (or far late) is latched
        # and used at the next tick, never a reason to hold or drop states
        self.wrench_tolerance = wrench_tolerance
        # the driver's repetitions of a sample (a broadcaster republishing the state each
        # update): not new periods
        self.repeated = 0
        # repetitions that ticked (``_tick_on_repetition``), and the stamp of the real state
        # the latest one predicted from
        self.repetition_ticks = 0
        self.repetition_ticked = -math.inf
        self.sample_gap = math.inf  # stamp spacing of the newest two distinct samples
        # prediction over the commands in flight: ``latency_periods`` >= 0 fixed, -1 measured
        # from the efforts the driver reports (``measured_latency``)
        if latency_periods < -1:
            raise ValueError(f'latency_periods = {latency_periods}: must be >= -1')
        self.latency_periods = latency_periods
        self.measured_latency = 0
        self.latency_max = 0  # the largest measured
        self.latency_seen: Counter[int] = Counter()  # every measurement of the run, by value
        self.sent: deque[list[float]] = deque(maxlen=SENT_HISTORY)  # joint order, newest last
        self.predictor = StatePredictor(ctrl.model, self.period) if latency_periods else None
        # the latencies measured over the last LATENCY_WINDOW_S: when they differ, each
        # command may act a period early or late and be held one period or two, and the law
        # is evaluated on the state its own command leads to after ``implicit_periods``
        # periods (StatePredictor.implicit_command); steady, the law stays the article's
        if implicit_periods < 0:
            raise ValueError(f'implicit_periods = {implicit_periods}: must be >= 0')
        self.implicit_periods = implicit_periods
        # ... only this long after the cycle switched to its up half (an impact): a command
        # held longer than planned turns the rebound back into the surface, where in the
        # swing it costs only a slower cycle (the implicit law's own cost: ~1 %, offline)
        if not implicit_window >= 0:
            raise ValueError(f'implicit_window = {implicit_window} s: must be >= 0')
        self.implicit_window = implicit_window
        self._up_since: float | None = None  # sample time of the latest switch to the up half
        self._up_switch = -1  # the controller's switch count that time
        # an impact between the sample and the state a command meets: the command is the up
        # half's, on the state with the tip stopped (CycleController.anticipate_impact)
        self.anticipate_impacts = anticipate_impacts
        self.recent_latency: deque[int] = deque(maxlen=max(1, round(rate * LATENCY_WINDOW_S)))
        self.latency_counts: Counter[int] = Counter()  # of recent_latency's values
        self.implicit_commands = 0  # commands computed so

    def warm_up(self, q: Sequence[float], qd: Sequence[float]) -> None:
        """Run the prediction and the implicit law once on (``q``, ``qd``), changing no
        state: their first call loads compiled code (milliseconds, far more on a busy
        machine), which must not fall on the first ticks after the brakes release."""
        if self.predictor is None:
            return
        q, qd = [float(v) for v in q], [float(v) for v in qd]
        tau = self.ctrl.torque(q, qd)
        self.predictor.ahead(q, qd, [tau])
        self.predictor.implicit_command(
            lambda q_at, qd_at: self.ctrl.torque(q_at, qd_at),
            q,
            qd,
            tau,
            q_law=self.ctrl.q_law_terms(),
        )

    def drop(self, counter: str, why: str) -> None:
        self.dropped[counter] += 1
        self.log(f'{why} ({counter}: {self.dropped[counter]})')

    # --------------------------------------------------------------------------- inputs
    def wrench(self, sec: int, nanosec: int, force: Sequence[float]) -> bool:
        """A contact wrench sample; True when it completed a waiting state (which ticked)."""
        if not all(abs(f) <= MAX_FORCE for f in force):  # also false for NaN
            self.drop(
                'out_of_range_wrenches',
                f'contact wrench dropped: force {list(force)} N '
                f'not finite or beyond {MAX_FORCE:g} N',
            )
            return False
        self.wrench_stamp = sec + nanosec * 1e-9
        if math.isinf(self.hold_until) and self.start_after is StartAfter.WRENCH:
            self.hold_until = self.clock() + self.startup_hold
        # latched until the next tick: an impact is seen even when the wrench sample of its
        # period comes late or after a newer one (the largest force counts)
        self.normal_force = (
            force[1] if self.normal_force is None else max(self.normal_force, force[1])
        )
        self.wrench_flowing = True
        if self.waiting is not None and self.wrench_stamp >= self.waiting[0] - STAMP_EPS:
            state, self.waiting = self.waiting, None
            self._tick(*state)
            return True
        return False

    def joint_state(
        self,
        sec: int,
        nanosec: int,
        names: Sequence[str],
        position: Sequence[float],
        velocity: Sequence[float],
        effort: Sequence[float] = (),
    ) -> None:
        t = sec + nanosec * 1e-9
        try:
            if names == self._names:  # a driver names its joints alike in every message
                index = self._index
            else:
                index = [names.index(j) for j in self.joint_names]
                self._names, self._index = list(names), index
            pos = [position[k] for k in index]
            vel = [velocity[k] for k in index]
        except (ValueError, IndexError):
            self.log(f'joint state without {self.joint_names} positions and velocities: ignored')
            return
        same = pos == self.latest_joint[0] and vel == self.latest_joint[1]
        if (
            same
            and self.started  # (before, the held state's repetitions let the first tick retry)
            and self.waiting is None
            and self.latest is not None
            and t < self.latest[0] + REPEAT_WINDOW * self._spacing()
        ):
            # the same sample again under a newer stamp (a broadcaster republishing each
            # update) or the same stamp (a lockstep driver's repetition): no new period. A
            # state still waiting for its wrench is answered by the repetition (below); an
            # arm that really stands still ticks again once the window has passed.
            self.repeated += 1
            self._tick_on_repetition(t)
            return
        if not (all(abs(v) <= MAX_ANGLE for v in pos) and all(abs(v) <= MAX_RATE for v in vel)):
            # also false for NaN
            self.drop(
                'out_of_range_states',
                f'joint state dropped: positions {pos} / '
                f'velocities {vel} not finite or beyond {MAX_ANGLE:g} rad, '
                f'{MAX_RATE:g} rad/s',
            )
            return
        if self.latest is not None and not follows(
            self.latest[0], t, self.clock() - self.latest_arrival
        ):
            # a reset, or one bad stamp: a second sample that follows the new one confirms a
            # reset; until then the sample is dropped (one stamp of 2^31 s must not silence
            # the controller, nor stamps alternating between two clocks make it tick on each)
            confirmed = self.jump_from is not None and follows(self.jump_from, t)
            self.jump_from = None if confirmed else t
            if not confirmed:
                self.drop(
                    'stamp_jumps',
                    f'joint state stamp went from {self.latest[0]:.9f} '
                    f'to {t:.9f} s: dropped unless the next one follows it',
                )
                return
            self.log(f'joint state stamps restarted at {t:.9f} s: cycle re-armed')
            self.next_tick = t
            self.waiting = None
            if self.wrench_stamp > t + STAMP_EPS:  # of the old time line (the new one's
                self.wrench_stamp = -math.inf  # wrench may be here already)
                self.normal_force = None
            # time went back (a simulator ~/reset, a replay restarted): the cycle starts
            # again from its down half
            self.ctrl.rearm(restart=t < self.latest[0])
        self.jump_from = None
        if self.latest is not None and t > self.latest[0] and not same:
            self.sample_gap = t - self.latest[0]
        self.latest = (t, self.coordinates.absolute(pos), self.coordinates.absolute_rates(vel))
        self.latest_arrival = self.clock()
        if math.isinf(self.hold_until) and self.start_after is StartAfter.JOINT_STATE:
            self.hold_until = self.latest_arrival + self.startup_hold
        if self.first_efforts is not None and self.answered_by is None:
            self._check_answer(pos, vel, effort, index)
        self.latest_joint = (pos, vel)
        if effort and self.latency_periods == -1:
            self._measure_latency(effort, index)
        if self.trigger is not ControlTrigger.JOINT_STATES or not self._reaches_next_tick(t):
            return
        # the wrench of the same instant is published just before the joint state: wait for
        # it when someone publishes wrenches. A wrench publisher that sends no valid wrench
        # (broken, a relay losing samples, hostile) must not hold the arm at its last torque:
        # a state still waiting when the next one (or its repetition) arrives is dropped and
        # the newer one ticks without its wrench; states then stop waiting until a wrench
        # arrives again (the loop keeps its rate).
        if self.waiting is not None:  # (a lockstep driver repeats the same state)
            self.drop(
                'missing_wrenches',
                f'no contact wrench for the state at '
                f'{self.waiting[0]:.6f} s: ticking on the next state without it, '
                f'without waiting until a wrench arrives',
            )
            self.wrench_flowing = False
        elif (
            self.wrench_flowing
            and t - self.wrench_tolerance <= self.wrench_stamp < t - STAMP_EPS
            and self.wrench_publishers()
        ):
            self.waiting = self.latest
            return
        self.waiting = None
        self._tick(*self.latest)

    def _tick_on_repetition(self, t: float) -> None:
        """A repetition stamped at the next tick: the driver's update found no new state (it
        came late, or the simulator left one out) and its command slot is open now. Skipping
        it would hold the previous command a period longer, which the prediction does not
        model; instead the command is computed on the latest real state predicted over one
        more command in flight (the one sent on that state), so one command still goes per
        update. Only with a prediction, once the loop is closed, and once per real state: a
        second repetition is past the repeat window and ticks as a sample."""
        if (
            self.predictor is None
            or self.answered_by is None
            or self.trigger is not ControlTrigger.JOINT_STATES
            or self.latest is None
            or self.repetition_ticked == self.latest[0]
            or not self._reaches_next_tick(t)
        ):
            return
        self.repetition_ticked = self.latest[0]
        self.repetition_ticks += 1
        self._tick(*self.latest, extra=1)

    def _check_answer(
        self, pos: list[float], vel: list[float], effort: Sequence[float], index: list[int]
    ) -> None:
        try:
            acting = [float(effort[k]) for k in index] if effort else None
        except IndexError:
            acting = None
        if acting == self.first_efforts:
            self.answered_by = Answer.EFFORT
        elif (pos, vel) != self.first_state:
            self.answered_by = Answer.MOTION
        else:
            return
        if self.unanswered:
            # the law starts now, from the driver's answer: not from the first command's
            # time (a PID would integrate the wait), nor with its tip velocity
            self.ctrl.rearm()
            self.log(
                f'the driver answered the first command ({self.answered_by.value}) after '
                f'{self.unanswered} ticks that sent it again: the law runs'
            )

    def _reaches_next_tick(self, t: float) -> bool:
        """Whether a sample stamped ``t`` is due to tick: at the next tick, or within
        TICK_TOLERANCE of the period (or of the stream's own spacing, when finer) before it."""
        tolerance = TICK_TOLERANCE * min(self.period, self.sample_gap)
        return t >= self.next_tick - tolerance - STAMP_EPS

    def _spacing(self) -> float:
        """The stamp spacing of the driver's new samples: a control period, or the stream's
        own when coarser (a simulator slower than real time behind a wall-clock broadcaster)."""
        return self.period if math.isinf(self.sample_gap) else max(self.period, self.sample_gap)

    def timer(self) -> None:
        """Trigger timer: tick on the latest state."""
        if self.latest is not None:
            self._tick(*self.latest)

    # --------------------------------------------------------------------------- output
    def _tick(self, t: float, q: list[float], qd: list[float], extra: int = 0) -> None:
        """A command from the state (``q``, ``qd``) sampled at ``t``; ``extra`` periods
        have passed since without a new state (``_tick_on_repetition``): the prediction
        covers that many more of the commands sent."""
        if not self.started:
            # the driver repeats its held state, which brings us back here
            now = self.clock()
            if now < self.hold_until or not self.ready():
                return
            self.started = True
            self.first_command_after = now - self.created
        self.next_tick = (math.floor(t / self.period + 1e-6) + 1 + extra) * self.period
        if self.first_efforts is not None and self.answered_by is None:
            self.unanswered += 1
            # in the history as the law's own would be (the same command on the same held
            # state): the latency measured later matches efforts against it, and a lone
            # first command there would be an unambiguous match a run that never waited
            # does not have
            self.sent.append(self.sent[-1])
            self.send([self.first_efforts[j] for j in self.order])
            return
        ahead = self.in_flight(extra)
        sensed = None
        if ahead and self.predictor is not None:
            # act on the state this command will meet: the driver applies it only after
            # the commands still on their way
            q_ahead, qd_ahead = self.predictor.ahead(q, qd, ahead)
            if all(abs(v) <= MAX_ANGLE for v in q_ahead) and all(
                abs(v) <= MAX_RATE for v in qd_ahead
            ):  # (also false for NaN)
                sensed, (q, qd) = (q, qd), (q_ahead, qd_ahead)
                t += len(ahead) * self.period
                if self.anticipate_impacts:
                    # the command may act earlier than predicted by the latencies' spread:
                    # the impact must lie that far before the predicted state, a period at
                    # least (a wider lead, offline, gave up what anticipation restores)
                    lead = max(1, self.latency_spread()) * self.period
                    q, qd = self.ctrl.anticipate_impact(q, qd, sensed, self.normal_force, lead=lead)
            else:  # the model's free motion left any arm's range: act on the sample itself
                self.drop(
                    'unsafe_predictions',
                    f'state predicted {len(ahead)} periods ahead of {t:.6f} s out of '
                    f'range: acting on the sampled state',
                )
        tau = self.ctrl.update(t, q, qd, normal_force=self.normal_force, sensed=sensed)
        self.normal_force = None  # the latch covers one tick
        self._note_up_switch(t)
        if (
            self.implicit_periods
            and self.predictor is not None
            and self.latency_varies()
            and self._after_impact(t)
        ):
            tau = self.predictor.implicit_command(
                lambda q_at, qd_at: self.ctrl.torque(q_at, qd_at),
                q,
                qd,
                tau,
                self.implicit_ahead(t),
                self.ctrl.q_law_terms(),
            )
            self.implicit_commands += 1
        if not all(math.isfinite(v) for v in tau):
            self.drop(
                'unsafe_torques',
                f'torques {tau} from the state at {t:.6f} s are not '
                f'finite: not sent, cycle re-armed',
            )
            self.ctrl.rearm()
            return
        self.sent.append(tau)
        tau = self.coordinates.efforts(tau)
        if self.clip:
            tau = [min(max(v, -limit), limit) for v, limit in zip(tau, self.effort_limits)]
        if self.first_efforts is None:
            self.first_efforts = [float(v) for v in tau]
            self.first_state = self.latest_joint
        self.send([tau[j] for j in self.order])

    def _note_up_switch(self, t: float) -> None:
        """Remember when (``t``) the cycle last switched to its up half: each tick, so that
        the window counts from the switch even when the latency begins to vary later."""
        ctrl = self.ctrl
        if ctrl.mode is CycleMode.UP and ctrl.switches != self._up_switch:
            self._up_switch, self._up_since = ctrl.switches, t

    def _after_impact(self, t: float) -> bool:
        """Whether the sample at ``t`` lies within ``implicit_window`` of the cycle's latest
        switch to its up half (always with an infinite window)."""
        if math.isinf(self.implicit_window):
            return True
        if self.ctrl.mode is not CycleMode.UP or self._up_since is None:
            return False
        return t - self._up_since < self.implicit_window

    # ------------------------------------------------------------------------- latency
    def in_flight(self, extra: int = 0) -> list[list[float]]:
        """The newest sent commands the latest state does not show yet, oldest first: the
        latency's, and ``extra`` more when that state is ``extra`` periods old (the commands
        sent on it and since)."""
        k = self.measured_latency if self.latency_periods == -1 else self.latency_periods
        k = min(k + extra, len(self.sent))
        return list(self.sent)[len(self.sent) - k :] if k else []

    def latency_spread(self) -> int:
        """The largest minus the smallest of the latencies that recur among those measured
        over the last LATENCY_WINDOW_S (0: steady, or a single value recurs)."""
        recurring = [k for k, n in self.latency_counts.items() if n >= LATENCY_RECURS]
        return max(recurring) - min(recurring) if len(recurring) >= 2 else 0

    def latency_varies(self) -> bool:
        """Whether two latencies or more recur among those measured over the last
        LATENCY_WINDOW_S."""
        return self.latency_spread() > 0

    def implicit_ahead(self, t: float = -math.inf) -> int:
        """Periods the implicit law looks ahead for the command acting at ``t``:
        ``implicit_periods``, and at least the longest a command may then act while the
        recurring latencies vary: their spread plus one period in the rebound's first
        REBOUND_HOLD_S (a command held one period longer than the look-ahead there reverses
        the rebound's rates into the surface), half the spread (rounded up) after it, where
        a look-ahead that long would only slow the cycle (offline, latency 1..4 and 1..5:
        one period ahead struck twice, two did not; docs/benchmarks.md)."""
        spread = self.latency_spread()
        if spread and self._up_since is not None and t - self._up_since < REBOUND_HOLD_S:
            return max(self.implicit_periods, spread + 1)
        return max(self.implicit_periods, -(-spread // 2))

    def _measure_latency(self, effort: Sequence[float], index: list[int]) -> None:
        """The driver reports the torques acting now: the commands sent after the one it
        reports are in flight. Only an unambiguous match counts (a command equal to its
        successor, as in a hold, could be either)."""
        try:
            acting = [float(effort[k]) for k in index]
        except IndexError:
            return
        sent = self.sent
        # a match further back is no latency but a driver holding an old command (its
        # brake, a stall): not counted
        for back in range(len(sent) - 1, max(len(sent) - 2 - MAX_MEASURED_LATENCY, -1), -1):
            if sent[back] == acting:
                if back + 1 < len(sent) and sent[back + 1] == acting:
                    return
                if back > 0 and sent[back - 1] == acting:
                    return
                self.measured_latency = len(sent) - 1 - back
                self.latency_max = max(self.latency_max, self.measured_latency)
                if len(self.recent_latency) == self.recent_latency.maxlen:
                    self.latency_counts[self.recent_latency[0]] -= 1
                self.recent_latency.append(self.measured_latency)
                self.latency_counts[self.measured_latency] += 1
                self.latency_seen[self.measured_latency] += 1
                return
