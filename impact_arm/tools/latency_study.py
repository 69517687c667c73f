"""The controller and the simulated driver in one process, joined by queues instead of DDS:
the lockstep loop of the two nodes (the same ``LockstepSession`` and ``ControlInputs`` they
run), with a command latency in the driver, to show what a driver stack's latency does to the
article's limit cycle and what the controller's prediction (``latency_periods``) restores.

Deterministic: no wall clock, no middleware. ``bench/latency.py`` prints the table of
docs/benchmarks.md from it.
"""

from __future__ import annotations

import functools
import math
import random
from collections import deque
from dataclasses import dataclass
from typing import Callable

from ..contract import ControlTrigger, joint_names, to_absolute, to_joint_space
from ..driver.arm import SimulatedArm, Tick
from ..driver.control_inputs import DEFAULT_IMPLICIT_WINDOW, ControlInputs
from ..driver.session import LockstepSession, Outputs
from ..driver.state_gaps import REBOUND_QUIET_S, StateGaps
from ..physics.control import CycleController
from ..physics.model import ArmModel
from ..physics.scene import Scene

# an impact this soon after the previous one is a second strike of the same down-swing (the
# article's cycle strikes every ~0.4 s; a second strike follows within a few ms). Told apart
# by the contact times alone, not by the cycle's halves (physics/cycle_count.py): the study
# counts impacts, a strike each, as the arm makes them
SECOND_STRIKE_S = 0.05


@dataclass(frozen=True)
class LoopResult:
    """What one closed-loop run did: its impacts' contact times [s], largest penetrations
    [m] and normal tip speeds before contact [m/s]; ``failed`` says why it stopped early."""

    latency: int
    predicted: int
    t_max: float
    t_contact: tuple[float, ...]
    delta_m: tuple[float, ...]
    v_before: tuple[float, ...]
    failed: str = ''

    @property
    def impacts(self) -> int:
        return len(self.t_contact)

    @property
    def second_strikes(self) -> int:
        gaps = [b - a for a, b in zip(self.t_contact, self.t_contact[1:])]
        return sum(g < SECOND_STRIKE_S for g in gaps)

    def cycle_periods(self, skip: int = 5) -> list[float]:
        """Times between strikes of successive cycles, after the first ``skip`` impacts."""
        t = [x for i, x in enumerate(self.t_contact) if i >= skip]
        return [b - a for a, b in zip(t, t[1:]) if b - a >= SECOND_STRIKE_S]

    def mean_cycle(self, skip: int = 5) -> float:
        """The mean of ``cycle_periods(skip)`` [s] (nan without a whole cycle)."""
        periods = self.cycle_periods(skip)
        return sum(periods) / len(periods) if periods else math.nan


class LatencyBursts:
    """Command delays that come in bursts, as a loaded machine delays a driver stack's
    threads: each period, with probability ``probability``, the delay jumps to
    ``latency`` + 1..``top`` periods (evenly), then falls back a period every ``decay``
    periods; between bursts it is ``latency``. Consecutive commands see nearly the same
    delay, so a burst that starts at an impact holds its first command several periods
    where independent draws (``closed_loop``'s ``jitter``) rarely do. Call it with the
    period a command is sent in and the run's random generator."""

    def __init__(self, latency: int, probability: float, top: int, decay: int = 1):
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f'probability = {probability}: must be within [0, 1]')
        if top < 1 or decay < 1:
            raise ValueError(f'top = {top}, decay = {decay}: each must be >= 1')
        self.latency, self.probability, self.top, self.decay = latency, probability, top, decay
        self.extra = 0
        self.period = -1  # the latest period drawn

    def __call__(self, period: int, rng: random.Random) -> int:
        while self.period < period:
            self.period += 1
            if self.extra and self.period % self.decay == 0:
                self.extra -= 1
            if rng.random() < self.probability:
                self.extra = max(self.extra, rng.randint(1, self.top))
        return self.latency + self.extra


def closed_loop(
    scene: Scene,
    latency: int,
    predicted: int,
    t_max: float = 10.0,
    rate: float = 1000.0,
    jitter: float = 0.0,
    seed: int = 0,
    implicit_periods: int = 1,
    spread: int = 1,
    force_sensor: bool = True,
    release_after: float = 0.0,
    tap: Callable[[int, int, Tick], None] | None = None,
    anticipate_impacts: bool = True,
    implicit_window: float = DEFAULT_IMPLICIT_WINDOW,
    repeat_every: int = 0,
    repeat_quiet: float = REBOUND_QUIET_S,
    bursts: LatencyBursts | None = None,
) -> LoopResult:
    """Run the scene's controller (the node's defaults) on the simulated arm for ``t_max``
    simulated seconds, the driver delaying each command by ``latency`` periods and the
    controller predicting ``predicted`` periods ahead (0: no prediction; -1: measured).

    ``jitter`` > 0: each command takes one period more with this probability (an
    unsynchronised controller manager), so that some periods hold the previous command and
    some commands are superseded before they act (the driver applies a period's newest);
    ``spread`` such chances per command: it takes ``latency`` to ``latency + spread`` periods.
    ``bursts``: the delays come from it instead (its own ``latency``; ``jitter`` unused).
    ``implicit_periods``: the controller's parameter of that name (0: off).
    ``force_sensor`` False: no contact wrench reaches the controller (an arm without a force
    sensor): it tells an impact from the tip's reversal alone.
    ``release_after`` > 0: the simulator's parameter of that name (the arm braked, time
    running, until then); meanwhile the driver writes its newest command each period, as a
    ros2_control stack does. ``anticipate_impacts``, ``implicit_window``: the controller's
    parameters of those names.
    ``repeat_every`` > 0: in one period of that many the controller gets the previous
    period's state again under this period's stamp (a driver stack's update that found no
    new state: ``joint_states_gap``), never in contact nor ``repeat_quiet`` seconds after;
    the driver then holds its newest command while no new one comes.
    ``tap(sec, nanosec, tick)``: each sample as the controller gets it
    (a recording to replay, bench controller_tick)."""
    arm = SimulatedArm(scene, rate, trace=False)
    model = ArmModel(scene)
    ctrl = CycleController.for_scene(model, scene.controller)
    # the node's targets pass through joint space (parameters), as here
    ctrl.targets = {k: to_absolute(to_joint_space(v)) for k, v in ctrl.targets.items()}
    ticks: deque = deque()
    commands: deque = deque()
    contacts: list[tuple[float, float, float]] = []

    def report(tick: Tick) -> None:
        for record, _ in tick.impacts:
            contacts.append((record.t_contact, record.delta_m, record.v_before[1]))

    # jitter or repeated states: the commands go through the delay line below (a period's
    # newest acts, held while none comes) instead of the session's fixed latency
    delay_line = bool(jitter or repeat_every or bursts)
    session = LockstepSession(
        arm,
        publish_rate=rate,
        rate_factor=0.0,
        command_timeout=math.inf,
        command_order=list(range(arm.n)),
        outputs=Outputs(publish=ticks.append, report=report),
        command_latency=0 if delay_line else latency,
        clock=lambda: 0.0,
        sleep=lambda s: None,
        release_after=release_after,
    )
    names = joint_names(arm.n)
    inputs = ControlInputs(
        ctrl,
        names,
        list(range(arm.n)),
        rate,
        ControlTrigger.JOINT_STATES,
        commands.append,
        latency_periods=predicted,
        clock=lambda: 0.0,
        implicit_periods=implicit_periods,
        anticipate_impacts=anticipate_impacts,
        implicit_window=implicit_window,
        wrench_publishers=lambda: force_sensor,
    )
    gaps = StateGaps(repeat_every, round(repeat_quiet * rate))
    previous: Tick | None = None
    rng = random.Random(seed)
    line: list[tuple[int, int, list[float]]] = []  # (period it acts from, order, torques)
    sent = 0
    acting: list[float] = []
    session.publish_initial()
    while not session.failed and arm.t < t_max - 0.5 / rate:
        while ticks:
            tick = ticks.popleft()
            sec, nsec = divmod(round(tick.t * 1e9), 1_000_000_000)
            if tap is not None:
                tap(sec, nsec, tick)
            if force_sensor:
                inputs.wrench(sec, nsec, (tick.wrench[0], tick.wrench[1], 0.0))
            state = tick
            if gaps.leave_out(tick.force_peak > 0.0) and previous is not None:
                state = previous
            previous = state
            inputs.joint_state(sec, nsec, names, state.position, state.velocity, state.effort)
        if not commands and release_after and not session.released() and acting:
            session.offer(functools.partial(list, acting))  # the driver writes it again
            continue
        if not commands and not repeat_every:
            return _result(latency, predicted, t_max, contacts, 'the controller sent nothing')
        if not delay_line:
            while commands:
                acting = commands.popleft()
                session.offer(functools.partial(list, acting))
            continue
        # the delay line: each command acts from the period it arrives in, the newest wins
        while commands:
            sent += 1
            if sent == 1:
                delay = 0  # the release: at once
            elif bursts is not None:
                delay = bursts(arm.periods, rng)
            else:
                delay = latency + sum(rng.random() < jitter for _ in range(spread))
            line.append((arm.periods + delay, sent, commands.popleft()))
        arrived = [c for c in line if c[0] <= arm.periods]
        if arrived:
            newest = max(arrived, key=lambda c: c[1])
            line[:] = [c for c in line if c[1] > newest[1]]
            acting = newest[2]
        session.offer(functools.partial(list, acting))
    return _result(latency, predicted, t_max, contacts, session.failed)


def _result(latency, predicted, t_max, contacts, failed):
    return LoopResult(
        latency,
        predicted,
        t_max,
        tuple(c[0] for c in contacts),
        tuple(c[1] for c in contacts),
        tuple(c[2] for c in contacts),
        failed,
    )
