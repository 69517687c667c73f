"""Offline runs of a scene: the down/up striking cycle, sampled output, impact records.

Two ways to drive the arm, both on the same integrator:
* continuous control (``control_rate`` 0): the law is evaluated inside the right-hand side and
  its target switches at located events, as in the article;
* sampled control (``control_rate`` > 0 Hz): a ``CycleController`` sees the sampled joint
  state and contact force and its torques are held between samples, as the ROS loop does.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from .control import CycleController
from .driver import advance_period, feed_events
from .errors import SceneError, SimulationError
from .integrator import PhaseIntegrator, options_from_spec
from .metrics import ImpactBuilder, settle_index
from .model import ArmModel
from .scene import Scene


@dataclass
class Sample:
    t: float
    q: tuple
    qd: tuple
    tau: tuple
    wrench: tuple    # (F_tangential, F_normal) averaged over the period that ends at t
    mode: str


MAX_KEPT_SAMPLES = 2e7    # publish_rate * t_max of a run that keeps its samples in memory


class SampleRanges:
    """Running ranges of the samples for the run summary (joint angles, tip velocity), so a
    run that streams its samples to an observer holds none of them."""

    def __init__(self):
        self.q_min = self.q_max = self.v_min = self.v_max = None

    def add(self, q, tip_velocity):
        if self.q_min is None:
            self.q_min, self.q_max = list(q), list(q)
            self.v_min, self.v_max = list(tip_velocity), list(tip_velocity)
            return
        for lo, hi, values in ((self.q_min, self.q_max, q),
                               (self.v_min, self.v_max, tip_velocity)):
            for k, x in enumerate(values):
                if x < lo[k]:
                    lo[k] = x
                if x > hi[k]:
                    hi[k] = x

    def q_range_deg(self, k):
        if self.q_min is None or k >= len(self.q_min):
            return []
        return [math.degrees(self.q_min[k]), math.degrees(self.q_max[k])]

    def v_range(self, k):
        return [] if self.v_min is None else [self.v_min[k], self.v_max[k]]


@dataclass
class RunResult:
    scene: Scene
    impacts: list
    samples: list = field(default_factory=list)    # empty when run(keep_samples=False)
    ranges: SampleRanges = field(default_factory=SampleRanges)
    traces: list = field(default_factory=list)     # one list of trace rows per impact
    t_end: float = 0.0
    rhs_evaluations: int = 0
    wall_time: float = 0.0                         # the integration (and its bookkeeping)
    load_time: float = 0.0                         # loading the compiled kernel, first run
    stopped: str = ''                              # why the run ended
    error: str = ''

    def summary(self) -> dict:
        """The "run" object of the JSON output (SI units, angles in degrees)."""
        imp = self.impacts
        contact_times = [i['t_contact'] for i in imp]
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
        }

    def to_json(self) -> dict:
        return {'impacts': self.impacts, 'run': self.summary()}

    @property
    def settled_after(self):
        return settle_index(self.impacts)


def run(scene: Scene, *, control_rate: float | None = None, preset: str | None = None,
        rtol=None, atol=None, publish_rate: float | None = None, trace=False,
        observer=None, progress=None, t_max: float | None = None,
        keep_samples=True) -> RunResult:
    """Simulate ``scene`` for its number of cycles (or until ``t_max``).

    ``observer`` may have ``on_sample(sample)``, ``on_impact(record, trace_rows)``; ``progress``
    is called as progress(cycle, cycles, impacts, t). The samples go to the observer as they
    are produced (at most ``integrator.OUTPUT_CAPACITY`` at once); ``keep_samples`` also keeps
    them all in ``result.samples``, refused beyond ``MAX_KEPT_SAMPLES`` (publish_rate * t_max).
    With ``keep_samples=False`` memory stays bounded whatever the sample count."""
    control_rate = scene.controller.rate if control_rate is None else control_rate
    publish_rate = publish_rate or scene.publish_rate
    t_max = scene.t_max if t_max is None else t_max
    if keep_samples and publish_rate * t_max > MAX_KEPT_SAMPLES:
        raise SceneError(
            f'publish_rate = {publish_rate:g} is out of range with t_max = {t_max:g} s for a '
            f'run that keeps its samples in memory: {publish_rate * t_max:.3g} samples; '
            f'publish_rate * t_max must be <= {MAX_KEPT_SAMPLES:g} (impact-arm simulate '
            f'streams them: no limit there)')
    model = ArmModel(scene)
    spec = scene.integrator
    integ = PhaseIntegrator(
        model, control='held' if control_rate else 'continuous', trace=True,
        **options_from_spec(spec, preset, rtol, atol))
    st = integ.state
    n = model.n
    ctrl = None
    if control_rate:
        ctrl = CycleController.for_scene(model, scene.controller)
    builder = ImpactBuilder(model)
    result = RunResult(scene=scene, impacts=builder.impacts)
    cycles_done = 0
    impulse = [0.0, 0.0]
    last_publish = 0.0
    wall0 = time.perf_counter()

    # the clock of the loop: publish samples and control ticks, merged
    k_pub, k_ctl = 0, 0
    dt_pub = 1.0 / publish_rate
    dt_ctl = 1.0 / control_rate if control_rate else math.inf

    def apply_control(t):
        q, qd = st.y[:n].tolist(), st.y[n:2 * n].tolist()
        fn = impulse_since_ctl[1] / dt_ctl if dt_ctl < math.inf else None
        mode_before = ctrl.mode
        tau = ctrl.update(t, q, qd, normal_force=fn)
        st.held_torque = tuple(tau)
        integ.reset_derivative()
        return mode_before, ctrl.mode

    def count_switch(event):
        nonlocal cycles_done
        cycles_done += event.kind == 'switch'

    def report(impacts):
        """Impact records and their trace rows to the result, observers and progress."""
        for record, rows in impacts:
            if trace:
                result.traces.append(rows)
            if observer is not None and hasattr(observer, 'on_impact'):
                observer.on_impact(record, rows)
            if progress:
                progress(cycles_done, scene.cycles, len(builder.impacts), st.t)

    def feed(events):
        """Cycles, impact records, observers and progress for the located events."""
        report(feed_events(integ, builder, events, count_switch))

    def publish(sample, tip_velocity):
        if keep_samples:
            result.samples.append(sample)
        result.ranges.add(sample.q, tip_velocity)
        if observer is not None and hasattr(observer, 'on_sample'):
            observer.on_sample(sample)

    if not ctrl:
        # continuous control: nothing happens on the sample grid, so the integrator's own
        # steps run on and the samples come from each step's continuous extension
        try:
            _run_sampled(scene, integ, dt_pub, t_max, feed, publish, result,
                         lambda: cycles_done)
        except SimulationError as exc:
            result.error = str(exc)
            result.stopped = 'error'
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
                result.stopped = f't_max = {t_max:g} s reached'
                break
            if t_next > st.t:
                impacts, j = advance_period(integ, builder, t_next, count_switch)
                impulse[0] += j[0]
                impulse[1] += j[1]
                impulse_since_ctl[0] += j[0]
                impulse_since_ctl[1] += j[1]
                report(impacts)
            if ctrl and t_ctl <= t_next:
                before, after = apply_control(t_ctl)
                impulse_since_ctl = [0.0, 0.0]
                if before == 'up' and after == 'down':
                    cycles_done += 1
                k_ctl += 1
            if t_pub <= t_next:
                q, qd = st.y[:n].tolist(), st.y[n:2 * n].tolist()
                period = t_pub - last_publish
                wrench = (impulse[0] / period, impulse[1] / period) if period > 0 else \
                    integ.contact_force_now()
                impulse = [0.0, 0.0]
                last_publish = t_pub
                tau = integ.torque()
                tau_now = tuple(tau) if tau is not None else tuple([0.0] * n)
                publish(Sample(t_pub, tuple(q), tuple(qd), tau_now, wrench,
                               ctrl.mode if ctrl else st.mode), model.tip(q, qd)[2:])
                k_pub += 1
            if scene.cycles and cycles_done >= scene.cycles:
                result.stopped = f'{scene.cycles} cycles completed'
                break
    except SimulationError as exc:  # keep what was simulated; the caller reports the error
        result.error = str(exc)
        result.stopped = 'error'
    return _finish(result, integ, wall0)


def _finish(result, integ, wall0):
    result.t_end = integ.state.t
    result.rhs_evaluations = integ.stats.rhs_evaluations
    result.wall_time = time.perf_counter() - wall0
    result.load_time = integ.load_time
    result.integrator = integ
    return result


def _run_sampled(scene, integ, dt, t_max, feed, publish, result, cycles_done):
    """``run`` with continuous control: samples every ``dt`` from the integrator's output
    rows (``PhaseIntegrator.start_output``), handed on as each kernel call ends (at most
    ``OUTPUT_CAPACITY`` rows held), events fed as they are located."""
    model, st = integ.model, integ.state
    n, eq = model.n, model.eq
    mode = st.mode           # samples carry the cycle half at the advance's start
    last_t = 0.0

    def publish_rows(rows):
        nonlocal last_t
        for row in rows.tolist():
            q, qd = tuple(row[eq.R_Y:eq.R_Y + n]), tuple(row[eq.R_Y + n:eq.R_Y + 2 * n])
            tau = tuple(row[eq.R_TAU:eq.R_TAU + n]) if row[eq.R_ACT] else (0.0,) * n
            wrench = (row[eq.R_JT] / dt, row[eq.R_JN] / dt)
            publish(Sample(row[eq.R_T], q, qd, tau, wrench, mode),
                    tuple(row[eq.R_VTIP:eq.R_VTIP + 2]))
            last_t = row[eq.R_T]

    # the sample at t = 0, before anything moves (no period yet: the force acting now)
    q, qd = st.y[:n].tolist(), st.y[n:2 * n].tolist()
    tau = integ.torque()
    publish(Sample(0.0, tuple(q), tuple(qd), tau if tau is not None else (0.0,) * n,
                   integ.contact_force_now(), st.mode), model.tip(q, qd)[2:])
    integ.take_impulse()
    last_index = math.floor(t_max / dt * (1 + 1e-12))
    t_final = last_index * dt
    integ.start_output(dt, 1, sink=publish_rows)
    while st.t < t_final:
        mode = st.mode
        # stop where the cycle half changes: the samples after it carry the new mode
        events = integ.advance(t_final, stop_at_event=('contact', 'switch'))
        feed(events)
        if scene.cycles and cycles_done() >= scene.cycles:
            # as on the sampled clock: the run ends with the first sample from then on
            if last_t < st.t:
                next_sample = min(t_final, math.ceil(st.t / dt - 1e-9) * dt)
                mode = st.mode
                feed(integ.advance(next_sample))
            result.stopped = f'{scene.cycles} cycles completed'
            return
    result.stopped = f't_max = {t_max:g} s reached'


def format_table(result: RunResult) -> str:
    """The impact table people read in a terminal."""
    lines = [f"{'#':>3} {'t [s]':>9} {'q1,q2 [deg]':>15} {'dur [us]':>9} {'dm [um]':>8} "
             f"{'dr [um]':>8} {'Fmax [kN]':>9} {'vx,vy before':>14} {'vx,vy after':>14} "
             f"{'e':>6} {'T before->after [J]':>19} {'e_energy':>17}"]
    for i in result.impacts:
        lines.append(
            f"{i['index']:>3} {i['t_contact']:>9.5f} "
            f"{i['q_contact_deg'][0]:>7.2f},{i['q_contact_deg'][1]:>7.2f} "
            f"{i['duration'] * 1e6:>9.2f} {i['delta_m'] * 1e6:>8.2f} {i['delta_r'] * 1e6:>8.2f} "
            f"{i['F_max'] / 1e3:>9.3f} "
            f"{i['v_before'][0]:>6.3f},{i['v_before'][1]:>7.3f} "
            f"{i['v_after'][0]:>6.3f},{i['v_after'][1]:>7.3f} {i['cor_kinematic']:>6.3f} "
            f"{i['T_before'][-1]:>8.3f} -> {i['T_after'][-1]:>7.3f} "
            f"{', '.join(f'{e:.3f}' for e in i['cor_energetic']):>17}")
    s = result.summary()
    lines.append('')
    lines.append(f"{s['impacts']} impacts in {s['t_end']:.4f} s simulated "
                 f"({result.stopped}); {s['rhs_evaluations']} right-hand-side evaluations, "
                 f"{s['wall_time']:.4f} s wall integrating"
                 + (f" (+{result.load_time:.3f} s loading the compiled kernel, once per "
                    f"process)" if result.load_time else ''))
    if s['period_last'] is not None:
        settled = result.settled_after
        lines.append(f"last period {s['period_last']:.5f} s; limit cycle "
                     + (f"reached after {settled} impacts" if settled else 'not reached'))
    if result.error:
        lines.append(f'STOPPED: {result.error}')
    return '\n'.join(lines)


@dataclass
class EventRun:
    """A run on the event-only path: impact records, no samples."""
    impacts: list
    t_end: float
    integrator: PhaseIntegrator
    wall_time: float
    exception: SimulationError | None = None    # what ended the run early; impacts before kept

    @property
    def error(self) -> str:
        return str(self.exception) if self.exception else ''


def run_impacts(scene: Scene, *, preset=None, rtol=None, atol=None, max_step=None,
                method=None, contact_rtol=None) -> EventRun:
    """The scene's cycles with continuous control and no sampled output: the integrator runs
    from event to event. A simulation error ends the run and is returned with the impacts
    completed before it (studies record it as a row, never as the end of the study)."""
    model = ArmModel(scene)
    spec = scene.integrator
    options = options_from_spec(spec, preset, rtol, atol, contact_rtol)
    if max_step is not None:
        options['max_step'] = max_step
    options['method'] = method or options['method']
    integ = PhaseIntegrator(model, **options)
    builder = ImpactBuilder(model)
    cycles = 0
    failure = None
    wall0 = time.perf_counter()
    try:
        while integ.state.t < scene.t_max and (not scene.cycles or cycles < scene.cycles):
            # a cycle ends at a switch: the kernel crosses the impact's phases by itself
            for event in integ.advance(scene.t_max, stop_at_event=('switch',)):
                cycles += event.kind == 'switch'
                builder.feed(event)
    except SimulationError as exc:
        failure = exc
    return EventRun(builder.impacts, integ.state.t, integ, time.perf_counter() - wall0, failure)


def run_without_samples(scene: Scene, *, preset=None) -> RunResult:
    """``run`` on the event-only path (continuous control): impacts and the run's totals, no
    samples, no traces; what ``simulate --no-samples`` prints."""
    events = run_impacts(scene, preset=preset)
    cycles_done = scene.cycles and events.t_end < scene.t_max and not events.error
    result = RunResult(
        scene=scene, impacts=events.impacts, t_end=events.t_end,
        rhs_evaluations=events.integrator.stats.rhs_evaluations, wall_time=events.wall_time,
        stopped='error' if events.error else f'{scene.cycles} cycles completed' if cycles_done
        else f't_max = {scene.t_max:g} s reached', error=events.error,
        load_time=events.integrator.load_time)
    result.integrator = events.integrator
    return result


def run_events(scene: Scene, **options):
    """``run_impacts`` for benchmarks and tests: a simulation error is raised. Returns
    (impacts, t_end, integrator, wall)."""
    result = run_impacts(scene, **options)
    if result.exception:
        raise result.exception
    return result.impacts, result.t_end, result.integrator, result.wall_time
