"""How the recorded efforts acted between samples: the readings of a driver's reported
efforts, and the choice among them by how well each predicts the free flight."""

from __future__ import annotations

from collections.abc import Sequence

import itertools
import math

import numpy as np

from ...physics.errors import SimulationError
from ...physics.integrator import PhaseIntegrator
from ...physics.kinds import ImpactSide, TextEnum
from ...physics.model import ArmModel
from ..identify import ImpactWindow, joint_to_absolute_matrix


class EffortTiming(TextEnum):
    """How the torque acted between the samples of the recorded efforts (``TorqueSchedule``
    reads them; ``effort_timing`` chooses one; ``effort_timing`` in fit.json names it)."""

    LINEAR = 'linear'  # the effort at a stamp is the torque at that instant
    PREVIOUS = 'previous'  # the command held over the period that ends at the stamp
    NEXT = 'next'  # the command held from the stamp to the next one
    # no recorded effort read: the scene's own continuous controller recomputes the torque
    CONTROLLER = 'controller'

    @property
    def held(self) -> bool:
        """Whether the torque is held over each period (a sampled controller's commands):
        it jumps from period to period."""
        return self in (EffortTiming.PREVIOUS, EffortTiming.NEXT)

    @property
    def reads_efforts(self) -> bool:
        """Whether the torque is the recorded efforts, held piecewise between their renewals,
        rather than the scene's controller integrated continuously."""
        return self is not EffortTiming.CONTROLLER


# the readings of the recorded efforts, in the order the first of equal errors is chosen
EFFORT_TIMINGS = (EffortTiming.LINEAR, EffortTiming.PREVIOUS, EffortTiming.NEXT)
SUBSTEPS = 8  # torque pieces per sample period (linear timing)


def effort_shift(model: ArmModel) -> float:
    """How much later than the joint states the scene's sensors report the efforts [s]: the
    effort latency less the states' own (only the difference shows in a recording)."""
    sensors = model.scene.sensors
    return float(sensors.effort_latency - sensors.state_latency)


def wrench_shift(model: ArmModel) -> float:
    """How much later than the joint states the scene's sensors publish the wrench [s]."""
    sensors = model.scene.sensors
    return float(sensors.wrench_latency - sensors.state_latency)


def _sampled_controller(model: ArmModel):  # -> CycleController | None
    """The scene's controller when it is a memoryless sampled law (``q``, ``pd`` at a
    rate), approaching the surface; None otherwise."""
    ctrl = model.scene.controller
    if ctrl.rate <= 0 or ctrl.law not in ('q', 'pd'):
        return None
    from ...physics.control import CycleController

    return CycleController.for_scene(model, ctrl)


def _law_command(ctrl, model: ArmModel, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The sampled law's command at absolute angles and rates, clipped at each joint's
    effort limit as the driver clips it (a symmetric limit: the joint's sign changes
    nothing)."""
    limits = np.asarray(model.scene.effort_limits, float)
    return np.clip(np.array(ctrl.torque(q, qd)), -limits, limits)


def controller_reproduces(model: ArmModel, win: ImpactWindow) -> bool:
    """Whether the scene's sampled controller, from each recorded sample before the impact
    (positions and rates as recorded), gives the effort recorded at the next sample one
    period later (the command held over that period: the reading 'previous'), within six
    standard deviations of the efforts' noise, at three such pairs or more: then it is the
    recording's controller, and may stand in for a command the recording does not hold."""
    ctrl = _sampled_controller(model)
    inputs = getattr(win, 'controller_inputs', None)
    if ctrl is None or inputs is None:
        return False
    t, q, qd = inputs
    period = 1.0 / model.scene.controller.rate
    pairs = [k for k in range(len(t) - 1) if abs(t[k + 1] - t[k] - period) < 0.1 * period]
    if len(pairs) < 3:
        return False
    T = joint_to_absolute_matrix(model.n)
    t_all, effort_all, floor = win.effort_source
    shift = effort_shift(model)
    for k in pairs:
        command = _law_command(ctrl, model, T @ q[k], T @ qd[k])
        recorded = [np.interp(t[k + 1] + shift, t_all, effort_all[:, j]) for j in range(model.n)]
        if np.any(np.abs(command - recorded) > floor):
            return False
    return True


def contact_period_command(model: ArmModel, win: ImpactWindow) -> np.ndarray | None:
    """The command held over the period in which the contact begins, when the recording
    cannot hold it (the sample ending that period is taken in the contact with the actuators
    off, so it shows no torque): the scene's own sampled controller at the last sample
    before the impact, from that sample as recorded (the positions and rates the driver's
    controller saw, difference rates included), approaching the surface. Only when that
    controller reproduces the recorded commands before the impact (``controller_reproduces``,
    checked once per window: ``own_command``); else None, and the command of the period
    before stands in. A controller acting on noisy rates makes each command differ from the
    one before by its gain times that noise; standing in, the previous command moves the
    replayed impact by as much, in step with the rate noise of the sample the replay starts
    from, which biased the fitted law (docs/fit.md, step 4)."""
    ctrl = _sampled_controller(model)
    if ctrl is None or not getattr(win, 'own_command', False):
        return None
    T = joint_to_absolute_matrix(model.n)
    _, q, qd = win.controller_inputs
    return _law_command(ctrl, model, T @ q[-1], T @ qd[-1])


class TorqueSchedule:
    """The joint torque between samples from the recorded efforts, by how a driver reports
    them: 'linear' (the effort at a stamp is the torque at that instant; continuous between),
    'previous' (it is the command held over the period that ends at the stamp, as our
    simulator reports it), 'next' (held from the stamp to the next one). Before the contact
    only efforts recorded before it are used, after it only those after it (a controller that
    reacts to the impact changes its torque there).

    ``latency`` [s]: the efforts are reported that much later than the joint states (the
    scene's ``sensors.effort_latency`` less ``state_latency``): the effort at each stamp is
    read ``latency`` later in the recording, linear between its samples (a continuous delay;
    a driver that delays by whole periods is the case of a whole number of periods)."""

    def __init__(
        self,
        win: ImpactWindow,
        timing: EffortTiming,
        latency: float = 0.0,
        contact_command: np.ndarray | None = None,
    ):
        self.t, self.tau, self.timing = win.effort_t, win.effort.copy(), timing
        self.ib = ib = getattr(win, 'effort_ib', 2)
        off = getattr(win, 'effort_off', [])
        source = getattr(win, 'effort_source', None)
        if latency and source is not None:
            t_all, effort_all, floor = source
            self.tau = np.stack(
                [
                    np.interp(self.t + latency, t_all, effort_all[:, j])
                    for j in range(self.tau.shape[1])
                ],
                axis=1,
            )
            off = [bool(np.all(np.abs(row) < floor)) for row in self.tau]
        # A sample taken during the contact with the actuators off shows no torque, not the
        # command: read as 'previous', that command acted before the contact began (the one
        # after it is reported at b), so the command of the last free sample stands in.
        # ``contact_command`` (``contact_period_command``): the command of the period in
        # which the contact begins, recomputed, in place of the one before it.
        for k in range(2, ib):
            if off[k]:
                if timing is not EffortTiming.PREVIOUS:
                    self.tau[k] = self.tau[ib]
                elif k == 2 and contact_command is not None:
                    self.tau[k] = contact_command
                else:
                    self.tau[k] = self.tau[1]

    def __call__(self, t0: float, t1: float, side: ImpactSide) -> np.ndarray:
        t, tau, mid, last = self.t, self.tau, 0.5 * (t0 + t1), len(self.t) - 1
        if self.timing is EffortTiming.PREVIOUS:
            return tau[min(max(int(np.searchsorted(t, mid, side='left')), 2), last)]
        if self.timing is EffortTiming.NEXT:
            return tau[min(max(int(np.searchsorted(t, mid, side='right')) - 1, 1), last)]
        if side is ImpactSide.BEFORE:
            i, j = 0, 1
        elif mid < t[self.ib]:
            i, j = self.ib, self.ib + 1
        else:
            i = min(max(int(np.searchsorted(t, mid, side='right')) - 1, self.ib), last - 1)
            j = i + 1
        if t[j] == t[i]:
            return tau[j]
        return tau[i] + (tau[j] - tau[i]) * (mid - t[i]) / (t[j] - t[i])

    def boundaries(self, t_from: float, t_to: float) -> list[float]:
        """Times where the held torque is renewed: every sample, and SUBSTEPS per period for
        'linear'."""
        grid: list | np.ndarray = [x for x in self.t if t_from < x < t_to]
        if self.timing is EffortTiming.LINEAR:
            edges = np.concatenate([[t_from], grid, [t_to]])
            grid = np.concatenate(
                [np.linspace(lo, hi, SUBSTEPS + 1)[1:-1] for lo, hi in itertools.pairwise(edges)]
                + [grid]
            )
        return sorted({float(x) for x in grid} | {float(t_to)})


def free_flight_error(
    model: ArmModel, win: ImpactWindow, timing: EffortTiming, shift: float | None = None
) -> float:
    """Squared error of one-period predictions between the compared post-impact samples,
    from the recorded state, under ``timing``: how well that reading of the efforts explains
    the free motion where the torque changes fastest. ``shift``: the efforts' delay behind
    the joint states (default: the scene's sensors')."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    torque = TorqueSchedule(win, timing, effort_shift(model) if shift is None else shift)
    period = win.rate_period
    if period is not None:
        return _mean_rate_change_error(model, win, torque, timing, period)
    q_post = [win.post.state(t)[0] for t in win.post_t]
    err = 0.0
    for k in range(len(win.post_t) - 1):
        state = model.initial_state()
        state.t = win.post_t[k]
        state.y[:n], state.y[n : 2 * n] = T @ q_post[k], T @ win.post_qd[k]
        held = timing.reads_efforts
        state.mode = 'up'  # after an impact the scene's controller lifts the arm
        integ = PhaseIntegrator(
            model, state, control='held' if held else 'continuous', preset='balanced'
        )
        try:
            for edge in torque.boundaries(win.post_t[k], win.post_t[k + 1]):
                if held:
                    integ.set_held_torque(torque(integ.state.t, edge, ImpactSide.AFTER))
                integ.advance(edge)
        except SimulationError:
            return math.inf
        if integ.state.phase != 0:
            return math.inf
        err += float(
            np.sum((np.linalg.solve(T, integ.state.y[n : 2 * n]) - win.post_qd[k + 1]) ** 2)
        )
    return err


def _mean_rate_change_error(
    model: ArmModel, win: ImpactWindow, torque: TorqueSchedule, timing: EffortTiming, period: float
) -> float:
    """``free_flight_error`` for rates that are period means: from the first compared sample
    after the impact, with the rate there that reproduces the recorded mean over the first
    period (the rate at a sample is not recorded; two Newton steps), the mean rate over the
    next period against the recorded one. 0 when fewer than three samples a period apart."""
    t = win.post_t
    if len(t) < 3 or np.any(np.abs(np.diff(t[:3]) - period) > 0.25 * period):
        return 0.0
    n = model.n
    T = joint_to_absolute_matrix(n)
    q0, qd0, _ = win.post.state(t[0])
    held = timing.reads_efforts

    def flight(qd: np.ndarray, until: int) -> list[np.ndarray] | None:
        state = model.initial_state()
        state.t = t[0]
        state.y[:n], state.y[n : 2 * n] = T @ q0, T @ qd
        state.mode = 'up'  # after an impact the scene's controller lifts the arm
        integ = PhaseIntegrator(
            model, state, control='held' if held else 'continuous', preset='balanced'
        )
        q = []
        try:
            for k in range(1, until + 1):
                for edge in torque.boundaries(t[k - 1], t[k]):
                    if held:
                        integ.set_held_torque(torque(integ.state.t, edge, ImpactSide.AFTER))
                    integ.advance(edge)
                q.append(np.linalg.solve(T, integ.state.y[:n]))
        except SimulationError:
            return None
        return q if integ.state.phase == 0 else None

    qd = qd0.copy()
    for _ in range(2):  # the mean over the first period is ~ the start's rate: J ~ identity
        first = flight(qd, 1)
        if first is None:
            return math.inf
        qd = qd + (win.post_qd[1] - (first[0] - q0) / (t[1] - t[0]))
    both = flight(qd, 2)
    if both is None:
        return math.inf
    predicted = (both[1] - both[0]) / (t[2] - t[1])
    return float(np.sum((predicted - win.post_qd[2]) ** 2))


def effort_timing(
    model: ArmModel,
    windows: Sequence[ImpactWindow],
    shift: float | None = None,
    readings: Sequence[EffortTiming] | None = None,
) -> tuple[EffortTiming, dict[EffortTiming, float]]:
    """The reading of the efforts that best predicts the free motion after the impacts, and
    the error of each: the three readings of the recorded efforts, and the scene's own
    controller when it is a continuous state feedback (a stiff controller changes its torque
    within a sample period faster than any interpolation of the samples follows)."""
    timings = list(readings or EFFORT_TIMINGS)
    ctrl = model.scene.controller
    if readings is None and ctrl.rate == 0 and ctrl.law in ('q', 'pd') and model.n_integral == 0:
        timings.append(EffortTiming.CONTROLLER)
    each = {t: [free_flight_error(model, w, t, shift) for w in windows] for t in timings}
    # an impact after which one reading's flight meets the surface again (inf) says nothing
    # of the readings: compared over the impacts every reading flies through (all of them
    # when there is none such)
    common = [k for k in range(len(windows)) if all(math.isfinite(each[t][k]) for t in timings)]
    errors = {t: sum(each[t][k] for k in (common or range(len(windows)))) for t in timings}
    return min(errors, key=errors.get), errors  # type: ignore[arg-type]  # every key is present


# readings in the order a tie is resolved: 'previous' at a latency is 'next' one period
# later, and 'previous' is the convention of the simulated driver (and of many real ones)
TIE_ORDER = (EffortTiming.PREVIOUS, EffortTiming.NEXT, EffortTiming.LINEAR)


def effort_timing_and_latency(
    model: ArmModel,
    windows: Sequence[ImpactWindow],
    state_latency: float,
    bounds: tuple[float, float],
    period: float,
) -> tuple[EffortTiming, float, dict[EffortTiming, float]]:
    """For a fitted effort latency: the reading of the recorded efforts and the latency within
    ``bounds`` [s] that together best predict the free motion after the impacts (a grid of
    half periods; the scene's own controller is no candidate, it reads no effort). A reading
    and a latency are one timing of the torque: 'previous' at L is 'next' at L + one period,
    so exact ties go to the earlier reading of ``TIE_ORDER``. Returns (reading, latency,
    the error of each reading at its best latency)."""
    lo, hi = bounds
    grid = np.unique(np.concatenate([np.arange(lo, hi + 1e-12, 0.5 * period), [lo, hi]]))
    best: dict[EffortTiming, tuple[float, float]] = {}
    for latency in grid:
        _, errors = effort_timing(model, windows, float(latency) - state_latency, EFFORT_TIMINGS)
        for reading, err in errors.items():
            if reading not in best or err < best[reading][0] * (1 - 1e-9):
                best[reading] = (err, float(latency))
    least = min(err for err, _ in best.values())
    reading = next(r for r in TIE_ORDER if best[r][0] <= least * (1 + 1e-3) + 1e-300)
    return reading, best[reading][1], {r: e for r, (e, _) in best.items()}
