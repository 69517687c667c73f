"""Offline runs of a scene: the down/up striking cycle, sampled output, impact records.

Two ways to drive the arm, both on the same integrator:
* continuous control (``control_rate`` 0): the law is evaluated inside the right-hand side and
  its target switches at located events, as in the article;
* sampled control (``control_rate`` > 0 Hz): a ``CycleController`` sees the sampled joint
  state and contact force and its torques are held between samples, as the ROS loop does.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Any

import dataclasses
import math
import time
from dataclasses import dataclass, field

from .limits import LimitWatch
from .control import CycleController
from .cycle_count import CycleCount
from .periods import advance_period, feed_events
from .errors import SceneError, SimulationError
from .impact import Impact
from .integrator import Event, IntegratorOptions, PhaseIntegrator
from .kinds import TextEnum
from .metrics import ImpactBuilder, LimitCycle, limit_cycle
from .model import ArmModel
from .scene import Scene
from .stability import ChatterWatch, check_stability

if TYPE_CHECKING:
    import numpy as np


@dataclass
class Sample:
    t: float
    q: tuple
    qd: tuple
    tau: tuple
    wrench: tuple  # (F_tangential, F_normal) averaged over the period that ends at t
    mode: str
    force_peak: float = 0.0  # the largest normal contact force in that period [N]
    plates: tuple = ()  # (z, ż) of each mounted surface's plate, in surface order [m, m/s]


MAX_KEPT_SAMPLES = 2e7  # publish_rate * t_max of a run that keeps its samples in memory


class SampleRanges:
    """Running ranges of the samples for the run summary (joint angles, tip velocity), so a
    run that streams its samples to an observer holds none of them."""

    # lists of floats once a sample came (None before): Any, as mypy cannot follow that
    q_min: Any
    q_max: Any
    v_min: Any
    v_max: Any

    def __init__(self) -> None:
        self.q_min = self.q_max = self.v_min = self.v_max = None

    def add(self, q: Sequence[float], tip_velocity: Sequence[float] | np.ndarray) -> None:
        if self.q_min is None:
            self.q_min, self.q_max = list(q), list(q)
            self.v_min, self.v_max = list(tip_velocity), list(tip_velocity)
            return
        for lo, hi, values in ((self.q_min, self.q_max, q), (self.v_min, self.v_max, tip_velocity)):
            for k, x in enumerate(values):
                if x < lo[k]:
                    lo[k] = x
                if x > hi[k]:
                    hi[k] = x

    def q_range_deg(self, k: int) -> list[float]:
        if self.q_min is None or k >= len(self.q_min):
            return []
        return [math.degrees(self.q_min[k]), math.degrees(self.q_max[k])]

    def v_range(self, k: int) -> list[float]:
        return [] if self.v_min is None else [self.v_min[k], self.v_max[k]]


class StopReason(TextEnum):
    """Why a run ended (a str: it compares equal to its value)."""

    CYCLES_COMPLETED = 'cycles completed'
    T_MAX_REACHED = 't_max reached'
    ERROR = 'error'  # a SimulationError ended it: ``RunResult.error`` says what
    INTERRUPTED = 'interrupted'
    FAILED = 'failed'  # outside the physics (a node exited, a time-out, ...)


@dataclass
class RunResult:
    """What every run returns: the impact records, the samples if kept, the totals and why
    it stopped (``stop_reason``; ``stopped`` is the same in words, with its numbers)."""

    scene: Scene
    impacts: list[Impact]
    samples: list = field(default_factory=list)  # empty when run(keep_samples=False)
    ranges: SampleRanges = field(default_factory=SampleRanges)
    traces: list = field(default_factory=list)  # one list of trace rows per impact
    t_end: float = 0.0
    rhs_evaluations: int = 0
    wall_time: float = 0.0  # the integration (and its bookkeeping)
    load_time: float = 0.0  # loading the compiled kernel, first run
    stop_reason: StopReason | None = None
    stop_detail: str = ''  # e.g. '15 cycles completed'
    error: str = ''
    exception: SimulationError | None = None  # what ended the run early, if anything
    integrator: PhaseIntegrator | None = None
    chatter: list = field(default_factory=list)  # stability.Chatter of each joint that chattered
    limits: list = field(default_factory=list)  # limits.LimitExcursion: periods beyond a limit

    @property
    def stopped(self) -> str:
        """Why the run ended, in words ('15 cycles completed', 't_max = 6 s reached')."""
        return self.stop_detail or (self.stop_reason.value if self.stop_reason else '')

    def stop(self, reason: StopReason, detail: str = '') -> None:
        self.stop_reason, self.stop_detail = reason, detail

    def fail(self, exc: SimulationError) -> None:
        """A simulation error ended the run; what was simulated before it is kept."""
        self.exception, self.error = exc, str(exc)
        self.stop(StopReason.ERROR)

    def summary(self) -> dict:
        """The "run" object of the JSON output (SI units, angles in degrees)."""
        imp = self.impacts
        contact_times = [i.t_contact for i in imp]
        ranges = self.ranges
        return {
            'impacts': len(imp),
            't_end': self.t_end,
            'period_last': contact_times[-1] - contact_times[-2] if len(imp) > 1 else None,
            'q1_range_deg': ranges.q_range_deg(0),
            'q2_range_deg': ranges.q_range_deg(1),
            'vx_range': ranges.v_range(0),
            'vy_range': ranges.v_range(1),
            'rhs_evaluations': self.rhs_evaluations,
            'wall_time': self.wall_time,
            'chatter': [c.to_json() for c in self.chatter],
            'limits': [e.to_json() for e in self.limits],
        }

    def to_json(self) -> dict:
        """The JSON output: {'impacts': [record dicts], 'run': the summary}."""
        return {'impacts': [i.to_dict() for i in self.impacts], 'run': self.summary()}

    @property
    def limit_cycle(self) -> LimitCycle | None:
        """Where the impacts start repeating (one or a few per cycle), or None."""
        return limit_cycle(self.impacts)

    @property
    def settled_after(self) -> int | None:
        cycle = self.limit_cycle
        return cycle.settled_after if cycle else None


def run(
    scene: Scene,
    *,
    samples: bool = True,
    control_rate: float | None = None,
    preset: str | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    contact_rtol: float | None = None,
    method: str | None = None,
    max_step: float | None = None,
    publish_rate: float | None = None,
    trace: bool = False,
    observer: Any = None,
    progress: Callable[[int, int, int, float], Any] | None = None,
    t_max: float | None = None,
    keep_samples: bool = True,
) -> RunResult:
    """Simulate ``scene`` for its number of cycles (or until ``t_max``): the one way to run.

    ``samples=False`` takes the event-only path (continuous control, no sampled output: the
    integrator runs from event to event; what studies, fits and ``simulate --no-samples``
    use). A simulation error never raises: it ends the run with ``stop_reason`` ERROR and
    the impacts completed before it (``result.exception`` to re-raise).

    ``observer`` may have ``on_sample(sample)``, ``on_impact(record, trace_rows)``; ``progress``
    is called as progress(cycle, cycles, impacts, t). The samples go to the observer as they
    are produced (at most ``integrator.OUTPUT_CAPACITY`` at once); ``keep_samples`` also keeps
    them all in ``result.samples``, refused beyond ``MAX_KEPT_SAMPLES`` (publish_rate * t_max).
    With ``keep_samples=False`` memory stays bounded whatever the sample count."""
    control_rate = scene.controller.rate if control_rate is None else control_rate
    options = IntegratorOptions.of_scene(scene.integrator, preset, rtol, atol, contact_rtol)
    options = dataclasses.replace(
        options,
        max_step=max_step if max_step is not None else options.max_step,
        method=method or options.method,
    )
    t_max = scene.t_max if t_max is None else t_max
    if not samples:
        if control_rate or observer is not None or trace:
            raise ValueError(
                'run(samples=False) runs from event to event with continuous '
                'control: no control_rate, observer or trace'
            )
        return _run_events(scene, t_max, options, progress)
    publish_rate = publish_rate or scene.publish_rate
    if keep_samples and publish_rate * t_max > MAX_KEPT_SAMPLES:
        raise SceneError(
            f'publish_rate = {publish_rate:g} is out of range with t_max = {t_max:g} s for a '
            f'run that keeps its samples in memory: {publish_rate * t_max:.3g} samples; '
            f'publish_rate * t_max must be <= {MAX_KEPT_SAMPLES:g} (impact-arm simulate '
            f'streams them: no limit there)'
        )
    model = ArmModel(scene)
    if control_rate and control_rate != scene.controller.rate:
        # the scene's own rate was checked on load; refused (or warned) before running
        check_stability(scene, control_rate, rate_source="the run's control rate", model=model)
    integ = PhaseIntegrator(
        model, control='held' if control_rate else 'continuous', trace=True, options=options
    )
    st = integ.state
    n = model.n
    ctrl: Any = None  # a CycleController when the control is sampled
    chatter = ChatterWatch(scene.joint_names)
    limits_watch = LimitWatch(scene)
    coordinates = scene.joint_coordinates
    if control_rate:
        ctrl = CycleController.for_scene(model, scene.controller)
    builder = ImpactBuilder(model)
    result = RunResult(scene=scene, impacts=builder.impacts)
    # the cycles completed: the kernel's switches (continuous control), the sampled
    # controller's up-to-down changes (sampled control), as the controller node counts them
    count = CycleCount(scene.cycles)
    impulse = [0.0, 0.0]
    last_publish = 0.0
    wall0 = time.perf_counter()

    # the clock of the loop: publish samples and control ticks, merged
    k_pub, k_ctl = 0, 0
    dt_pub = 1.0 / publish_rate
    dt_ctl = 1.0 / control_rate if control_rate else math.inf
    limits = scene.effort_limits  # (a sign never changes a symmetric limit)
    clip = any(math.isfinite(limit) for limit in limits)

    def apply_control(t: float) -> tuple[str, str]:
        q, qd = st.y[:n].tolist(), st.y[n : 2 * n].tolist()
        fn = impulse_since_ctl[1] / dt_ctl if dt_ctl < math.inf else None
        mode_before = ctrl.mode
        tau = ctrl.update(t, q, qd, normal_force=fn)
        chatter.add(t, tau)  # what the law commands, before the drive clips it
        if clip:  # each joint's drive clips at its limit, as the driver does
            tau = [min(max(v, -limit), limit) for v, limit in zip(tau, limits)]
        integ.set_held_torque(tau)
        return mode_before, ctrl.mode

    def report(impacts: Iterable[tuple[Impact, list]]) -> None:
        """Impact records and their trace rows to the result, observers and progress."""
        for record, rows in impacts:
            if trace:
                result.traces.append(rows)
            if observer is not None and hasattr(observer, 'on_impact'):
                observer.on_impact(record, rows)
            if progress:
                progress(count.completed, scene.cycles, len(builder.impacts), st.t)

    def feed(events: Iterable[Event]) -> None:
        """Cycles, impact records, observers and progress for the located events."""
        report(feed_events(integ, builder, events, count.on_event))

    def publish(sample: Sample, tip_velocity: Sequence[float] | np.ndarray) -> None:
        if keep_samples:
            result.samples.append(sample)
        if limits_watch.active:  # the robot's joint angles against its URDF's limits
            limits_watch.add(coordinates.positions(sample.q), coordinates.rates(sample.qd))
        result.ranges.add(sample.q, tip_velocity)
        if observer is not None and hasattr(observer, 'on_sample'):
            observer.on_sample(sample)

    if not ctrl:
        # continuous control: nothing happens on the sample grid, so the integrator's own
        # steps run on and the samples come from each step's continuous extension
        try:
            _run_sampled(scene, integ, dt_pub, t_max, feed, publish, result, count)
        except SimulationError as exc:
            result.fail(exc)
        return _finish(result, integ, wall0)

    impulse_since_ctl = [0.0, 0.0]
    tau_now = tuple([0.0] * n)
    if ctrl:
        apply_control(0.0)
    try:
        while True:
            t_pub = k_pub * dt_pub
            t_ctl = k_ctl * dt_ctl
            t_next = min(t_pub, t_ctl)
            if t_next > t_max:
                result.stop(StopReason.T_MAX_REACHED, f't_max = {t_max:g} s reached')
                break
            if t_next > st.t:
                impacts, j = advance_period(integ, builder, t_next, count.on_event)
                impulse[0] += j[0]
                impulse[1] += j[1]
                impulse_since_ctl[0] += j[0]
                impulse_since_ctl[1] += j[1]
                report(impacts)
            if ctrl and t_ctl <= t_next:
                before, after = apply_control(t_ctl)
                impulse_since_ctl = [0.0, 0.0]
                count.turn(before, after, t_ctl)
                k_ctl += 1
            if t_pub <= t_next:
                q, qd = st.y[:n].tolist(), st.y[n : 2 * n].tolist()
                period = t_pub - last_publish
                wrench = (
                    (impulse[0] / period, impulse[1] / period)
                    if period > 0
                    else integ.contact_force_now()
                )
                impulse = [0.0, 0.0]
                last_publish = t_pub
                tau = integ.torque()
                tau_now = tuple(tau) if tau is not None else tuple([0.0] * n)
                mode = ctrl.mode if ctrl else st.mode
                publish(
                    Sample(
                        t_pub,
                        tuple(q),
                        tuple(qd),
                        tau_now,
                        wrench,
                        mode,
                        integ.take_peak(),
                        model.plate_states(st.y),
                    ),
                    model.tip(q, qd)[2:],
                )
                k_pub += 1
            if count.done:
                result.stop(StopReason.CYCLES_COMPLETED, f'{scene.cycles} cycles completed')
                break
    except SimulationError as exc:  # keep what was simulated; the caller reports the error
        result.fail(exc)
    result.chatter = chatter.found
    result.limits = limits_watch.found
    return _finish(result, integ, wall0)


def _finish(result, integ, wall0):
    result.t_end = integ.state.t
    result.rhs_evaluations = integ.stats.rhs_evaluations
    result.wall_time = time.perf_counter() - wall0
    result.load_time = integ.load_time
    result.integrator = integ
    return result


def _run_sampled(scene, integ, dt, t_max, feed, publish, result, count):
    """``run`` with continuous control: samples every ``dt`` from the integrator's output
    rows (``PhaseIntegrator.start_output``), handed on as each kernel call ends (at most
    ``OUTPUT_CAPACITY`` rows held), events fed as they are located."""
    model, st = integ.model, integ.state
    n, eq = model.n, model.eq
    mode = st.mode  # samples carry the cycle half at the advance's start
    last_t = 0.0

    def publish_rows(rows: np.ndarray) -> None:
        nonlocal last_t
        for row in rows.tolist():
            q, qd = tuple(row[eq.R_Y : eq.R_Y + n]), tuple(row[eq.R_Y + n : eq.R_Y + 2 * n])
            tau = tuple(row[eq.R_TAU : eq.R_TAU + n]) if row[eq.R_ACT] else (0.0,) * n
            wrench = (row[eq.R_JT] / dt, row[eq.R_JN] / dt)
            plates = model.plate_states(row[eq.R_Y : eq.R_Y + model.size]) if model.n_mount else ()
            publish(
                Sample(row[eq.R_T], q, qd, tau, wrench, mode, row[eq.R_FPEAK], plates),
                tuple(row[eq.R_VTIP : eq.R_VTIP + 2]),
            )
            last_t = row[eq.R_T]

    # the sample at t = 0, before anything moves (no period yet: the force acting now)
    q, qd = st.y[:n].tolist(), st.y[n : 2 * n].tolist()
    tau = integ.torque()
    publish(
        Sample(
            0.0,
            tuple(q),
            tuple(qd),
            tau if tau is not None else (0.0,) * n,
            integ.contact_force_now(),
            st.mode,
            integ.contact_force_now()[1],
            model.plate_states(st.y),
        ),
        model.tip(q, qd)[2:],
    )
    integ.take_impulse()
    integ.take_peak()
    last_index = math.floor(t_max / dt * (1 + 1e-12))
    t_final = last_index * dt
    integ.start_output(dt, 1, sink=publish_rows)
    while st.t < t_final:
        mode = st.mode
        # stop where the cycle half changes: the samples after it carry the new mode
        events = integ.advance(t_final, stop_at_event=('contact', 'switch'))
        feed(events)
        if count.done:
            # as on the sampled clock: the run ends with the first sample from then on
            if last_t < st.t:
                next_sample = min(t_final, math.ceil(st.t / dt - 1e-9) * dt)
                mode = st.mode
                feed(integ.advance(next_sample))
            result.stop(StopReason.CYCLES_COMPLETED, f'{scene.cycles} cycles completed')
            return
    result.stop(StopReason.T_MAX_REACHED, f't_max = {t_max:g} s reached')


def impact_rows(impacts: Sequence[Impact], robot: bool = False) -> str:
    """The impact rows of ``format_table``: a header and a line per impact record. ``robot``:
    the contact angles as the robot's joint angles (a URDF arm's), else as the article's
    absolute link angles."""
    # every link's contact angle (the article's two in its columns)
    n = len(impacts[0].q_contact_deg) if impacts else 2
    angles = ','.join(f'{"θ" if robot else "q"}{k + 1}' for k in range(n)) + ' [deg]'
    lines = [
        f'{"#":>3} {"t [s]":>9} {angles:>{8 * n - 1}} {"dur [us]":>9} {"dm [um]":>8} '
        f'{"dr [um]":>8} {"Fmax [kN]":>9} {"vx,vy before":>14} {"vx,vy after":>14} '
        f'{"e":>6} {"T before->after [J]":>19} {"e_energy":>17}'
    ]
    for i in impacts:
        angles_deg = i.joints_contact_deg if robot else i.q_contact_deg
        lines.append(
            f'{i.index:>3} {i.t_contact:>9.5f} '
            f'{",".join(f"{a:>7.2f}" for a in angles_deg)} '
            f'{i.duration * 1e6:>9.2f} {i.delta_m * 1e6:>8.2f} {i.delta_r * 1e6:>8.2f} '
            f'{i.F_max / 1e3:>9.3f} '
            f'{i.v_before[0]:>6.3f},{i.v_before[1]:>7.3f} '
            f'{i.v_after[0]:>6.3f},{i.v_after[1]:>7.3f} {i.cor_kinematic:>6.3f} '
            f'{i.T_before[-1]:>8.3f} -> {i.T_after[-1]:>7.3f} '
            f'{", ".join(f"{e:.3f}" for e in i.cor_energetic):>17}'
        )
    return '\n'.join(lines)


def format_table(result: RunResult) -> str:
    """The impact table people read in a terminal."""
    # a URDF arm's own joint angles; the article's absolute link angles for the scene's rods
    robot = result.scene is not None and not result.scene.joint_coordinates.is_identity
    lines = [impact_rows(result.impacts, robot)]
    s = result.summary()
    lines.append('')
    lines.append(
        f'{s["impacts"]} impacts in {s["t_end"]:.4f} s simulated '
        f'({result.stopped}); {s["rhs_evaluations"]} right-hand-side evaluations, '
        f'{s["wall_time"]:.4f} s wall integrating'
        + (
            f' (+{result.load_time:.3f} s loading the compiled kernel, once per process)'
            if result.load_time
            else ''
        )
    )
    if s['period_last'] is not None:
        cycle = result.limit_cycle
        lines.append(
            f'last period {s["period_last"]:.5f} s; limit cycle '
            + (cycle.text() if cycle else 'not reached')
            + (
                f', period {cycle.period(result.impacts):.5f} s'
                if cycle and cycle.impacts_per_cycle > 1
                else ''
            )
        )
    for chatter in result.chatter:
        lines.append(f'CHATTER: {chatter.text()}: the law is unstable at its rate')
    for excursion in result.limits:
        lines.append(f'LIMIT: {excursion.text()}')
    if result.error:
        lines.append(f'STOPPED: {result.error}')
    return '\n'.join(lines)


def _run_events(scene: Scene, t_max: float, options: IntegratorOptions, progress=None) -> RunResult:
    """``run(samples=False)``: the scene's cycles on the event-only path. A cycle ends at a
    switch; the kernel crosses each impact's phases by itself."""
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, options=options)
    builder = ImpactBuilder(model)
    result = RunResult(scene=scene, impacts=builder.impacts)
    count = CycleCount(scene.cycles)
    wall0 = time.perf_counter()
    try:
        while integ.state.t < t_max and not count.done:
            for event in integ.advance(t_max, stop_at_event=('switch',)):
                count.on_event(event)
                builder.feed(event)
            if progress:
                progress(count.completed, scene.cycles, len(builder.impacts), integ.state.t)
        if count.done:
            result.stop(StopReason.CYCLES_COMPLETED, f'{scene.cycles} cycles completed')
        else:
            result.stop(StopReason.T_MAX_REACHED, f't_max = {t_max:g} s reached')
    except SimulationError as exc:
        result.fail(exc)
    return _finish(result, integ, wall0)
