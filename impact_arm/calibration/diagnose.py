"""What is wrong with a recording before it is fitted: the effects of real drivers that make a
fit of the impacts wrong without saying so, each detected, estimated and named with what to
do about it.

* ``DIFFERENCE_RATES``: the published rates are exact finite differences of the published
  positions (backward or central): the mean rate over a period, not the rate at the stamp,
  smeared across an impact;
* ``FILTERED_RATES``: the rates are those differences through a first-order low-pass;
* ``STAMP_JITTER``: the stamps scatter about a regular grid while the values follow the grid
  (stamps taken on arrival, not at sampling);
* ``EFFORT_DELAY``: the reported efforts are late (or early) against the joint states, from
  the power balance of the free flight (the change of the arm's energy between two samples is
  the work of the joint torques over the joint angles swept);
* ``POSITION_NOISE``: the positions scatter far more than the encoder's resolution (the
  smallest step of the positions);
* ``WRENCH_LAG``: the wrench rises later (or earlier) than the impacts the joint rates show.

``diagnose`` only reports; ``correct`` applies the corrections the user asks for (a known
effort or wrench latency, difference rates read as the mean rates of their periods, regular
stamps) to a copy of the recording. Nothing is changed unless asked.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from enum import Enum
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from .identify import (
    contact_test,
    IdentifyError,
    JointRecording,
    RateMeaning,
    estimate_noise,
    find_impacts,
    joint_to_absolute_matrix,
)

if TYPE_CHECKING:
    from ..physics.model import ArmModel
    from ..physics.scene import SensorSpec

# A delay or a lag is reported from this many sample periods on: within one period the fit's
# own reading of the efforts (the effort at the stamp, or held over the period before or
# after it) already absorbs it, and a period-averaged wrench may rise one period after the
# step of the rates when the contact begins late in a period.
DELAY_PERIODS = 1.5
# relative agreement of a rate with a finite difference that no measured rate reaches by
# chance (the difference and the rate at the stamp differ by ~ period x acceleration)
DIFFERENCE_TOLERANCE = 1e-9
DIFFERENCE_SHARE = 0.9  # of the moving samples
# stamp jitter reported above this share of the period (rms) and this absolute floor
JITTER_SHARE = 0.01
JITTER_FLOOR = 1e-6  # s
NOISE_PER_STEP = 3.0  # position noise (rms) beyond this many encoder steps is "far above"
FREE_MARGIN = 15  # samples either side of an impact left out of the free flight
SEARCH_PERIODS = 20  # effort delays searched within +- this many periods
# F statistic a delay must reach against none (1 parameter over thousands of intervals: the
# 0.1 % tail is F ~ 11; the intervals share their samples, so well beyond it)
DELAY_F_MIN = 100.0


class FindingKind(str, Enum):
    DIFFERENCE_RATES = 'difference_rates'
    FILTERED_RATES = 'filtered_rates'
    STAMP_JITTER = 'stamp_jitter'
    EFFORT_DELAY = 'effort_delay'
    POSITION_NOISE = 'position_noise'
    WRENCH_LAG = 'wrench_lag'


@dataclass(frozen=True)
class Finding:
    """One effect found: what was seen (with its estimate) and what to do."""

    kind: FindingKind
    estimate: float  # in ``unit``: the delay, the jitter rms, the noise, the share of rates
    unit: str
    seen: str  # one sentence with the numbers
    advice: str  # what to do about it
    corrected_by: str = ''  # the option that corrects it, when given

    def text(self) -> str:
        done = f' (corrected: {self.corrected_by})' if self.corrected_by else ''
        return f'{self.seen}{done}; {self.advice}'

    def to_json(self) -> dict:
        return {
            'kind': self.kind.value,
            'estimate': self.estimate,
            'unit': self.unit,
            'seen': self.seen,
            'advice': self.advice,
            'corrected_by': self.corrected_by,
        }


@dataclass
class Diagnosis:
    """The findings of every check that could run, and why the others could not."""

    findings: list[Finding] = field(default_factory=list)
    checked: list[FindingKind] = field(default_factory=list)
    skipped: dict[FindingKind, str] = field(default_factory=dict)
    estimates: dict[FindingKind, float] = field(default_factory=dict)  # also when quiet
    corrections: list[str] = field(default_factory=list)

    def kinds(self) -> set[FindingKind]:
        return {f.kind for f in self.findings}

    def lines(self) -> list[str]:
        """What the command line says: each finding, or that there is none, and the checks
        that could not run."""
        out = [f'recording diagnosis: {f.text()}' for f in self.findings] or [
            f'recording diagnosis: nothing found ({len(self.checked)} checks)'
        ]
        if self.skipped:
            out.append(
                'recording diagnosis: not checked: '
                + '; '.join(f'{k.value} ({why})' for k, why in self.skipped.items())
            )
        return out

    def markdown(self) -> list[str]:
        """The fit report's section on the recording itself."""
        lines = ['## The recording', '']
        if self.findings:
            lines += [f'- **{f.kind.value}**: {f.text()}.' for f in self.findings]
        else:
            lines.append(f'Nothing found by the {len(self.checked)} checks that could run.')
        lines += [f'- not checked, {k.value}: {why}' for k, why in self.skipped.items()]
        lines += [f'- corrected before the fit, {c}' for c in self.corrections]
        return lines + ['']

    def to_json(self) -> dict:
        return {
            'findings': [f.to_json() for f in self.findings],
            'checked': [k.value for k in self.checked],
            'skipped': {k.value: why for k, why in self.skipped.items()},
            'estimates': {k.value: v for k, v in self.estimates.items()},
            'corrections': list(self.corrections),
        }


@dataclass(frozen=True)
class Corrections:
    """What the user knows about the recording and wants corrected before the fit."""

    effort_latency: float = 0.0  # [s] efforts reported this late: read them this much earlier
    wrench_latency: float = 0.0  # [s] the wrench stamped this late
    difference_rates: bool = False  # the rates are backward differences: read as mean rates
    regular_stamps: bool = False  # stamps put back on the regular grid the values follow

    def __post_init__(self) -> None:
        for name in ('effort_latency', 'wrench_latency'):
            value = getattr(self, name)
            if not (math.isfinite(value) and abs(value) <= 1.0):
                option = '--' + name.replace('_', '-')
                raise ValueError(f'{option} = {value}: must be a finite delay within +-1 s')

    @property
    def requested(self) -> bool:
        return self != Corrections()

    def shift_conflict(self, sensors: SensorSpec, fitted: Iterable[str]) -> str | None:
        """Why these corrections cannot go with a scene that states or a fit that frees the
        same delay, in one line (None when they can): the fit replays the scene's sensor
        latencies (the efforts read ``effort_latency - state_latency`` later, the wrench
        ``wrench_latency - state_latency``), so an option on top would shift them twice."""
        fitted = set(fitted)
        for option, key, shift in (
            ('effort_latency', 'sensors.effort_latency', sensors.effort_latency),
            ('wrench_latency', 'sensors.wrench_latency', sensors.wrench_latency),
        ):
            value = getattr(self, option)
            if not value:
                continue
            flag = '--' + option.replace('_', '-')
            freed = sorted(fitted & {key, 'sensors.state_latency'})
            if freed:
                return (
                    f'{flag} {value:g} and the fitted {" and ".join(freed)} would both delay '
                    f'the same signal: drop {flag} (the fit finds the delay) or fix the key '
                    f'in the scene and drop its --param'
                )
            stated = shift - sensors.state_latency
            if stated:
                return (
                    f"{flag} {value:g} and the scene's {key} = {shift:g} (less "
                    f'sensors.state_latency = {sensors.state_latency:g}) would both delay the '
                    f"same signal, the fit replaying the scene's latencies too: drop {flag} "
                    f"(the scene's value is used) or set {key} to sensors.state_latency in the "
                    f'scene'
                )
        return None


# ------------------------------------------------------------------------------ checks
def _consecutive(rec: JointRecording) -> tuple[np.ndarray, float]:
    """Indices k of the samples that follow their predecessor by one period (no sample lost
    between), and the period."""
    dt = np.diff(rec.t)
    period = float(np.median(dt))
    return np.flatnonzero((dt > 0.5 * period) & (dt < 1.5 * period)) + 1, period


def check_difference_rates(rec: JointRecording) -> Finding | None:
    """Rates equal to (q[k] - q[k-1]) / period (or the stamps' difference), or to central
    differences, at nearly every sample where the arm moves."""
    k, period = _consecutive(rec)
    k = k[(k >= 1) & (k < len(rec.t) - 1)]
    q, v, t = rec.position, rec.velocity, rec.t
    moving = np.any(q[k] != q[k - 1], axis=1)
    k = k[moving]
    if len(k) < 20:
        return None
    scale = np.maximum(np.abs(v[k]), 1e-12)
    candidates = {
        'backward': ((q[k] - q[k - 1]) / period, (q[k] - q[k - 1]) / (t[k] - t[k - 1])[:, None]),
        'central': (
            (q[k + 1] - q[k - 1]) / (2 * period),
            (q[k + 1] - q[k - 1]) / (t[k + 1] - t[k - 1])[:, None],
        ),
    }
    for name, guesses in candidates.items():
        share = max(
            float(np.mean(np.all(np.abs(g - v[k]) <= DIFFERENCE_TOLERANCE * scale, axis=1)))
            for g in guesses
        )
        if share >= DIFFERENCE_SHARE:
            lag = ' half a period late and' if name == 'backward' else ''
            return Finding(
                FindingKind.DIFFERENCE_RATES,
                share,
                '-',
                f'the joint rates are exact {name} differences of the positions at '
                f'{share:.0%} of the moving samples: each is the mean rate over '
                f'{"the period before" if name == "backward" else "two periods around"} '
                f'its stamp,{lag} smeared across an impact, not a measured rate',
                "record the drive's own velocity if it has one"
                + (
                    ', or fit with --difference-rates (each rate read as the mean over its period)'
                    if name == 'backward'
                    else ''
                )
                + '; contact parameters fitted from these rates as measured ones are biased',
            )
    return None


def check_filtered_rates(rec: JointRecording) -> Finding | None:
    """Rates that are the backward differences d[k] = (q[k] - q[k-1]) / period through a
    discrete first-order low-pass, v[k] = v[k-1] + alpha (d[k] - v[k-1]), with one alpha
    (0 < alpha < 1) at nearly every sample where the arm moves."""
    k, period = _consecutive(rec)
    k = k[k >= 1]
    q, v = rec.position, rec.velocity
    x = (q[k] - q[k - 1]) / period - v[k - 1]
    y = v[k] - v[k - 1]
    moving = np.any(x != 0, axis=1)
    x, y = x[moving], y[moving]
    if len(x) < 20 or not np.any(x):
        return None
    alpha = float(np.sum(x * y) / np.sum(x * x))
    if not 0.0 < alpha < 1.0 - 1e-9:
        return None
    scale = np.abs(v[k][moving]) + np.abs(x) + 1e-12
    share = float(
        np.mean(np.all(np.abs(y - alpha * x) <= 1e3 * DIFFERENCE_TOLERANCE * scale, axis=1))
    )
    if share < DIFFERENCE_SHARE:
        return None
    cutoff = -math.log(1.0 - alpha) / (2.0 * math.pi * period)
    return Finding(
        FindingKind.FILTERED_RATES,
        cutoff,
        'Hz',
        f'the joint rates are backward differences of the positions through a first-order '
        f'low-pass (cut-off {cutoff:.4g} Hz, alpha {alpha:.4g}) at {share:.0%} of the moving '
        f'samples: late and smoothed across every impact, not a measured rate',
        "record the drive's own velocity if it has one, or fit with --difference-rates (the "
        'rates recomputed from the positions and read as mean rates over their periods); '
        'contact parameters fitted from these rates as measured ones are biased',
    )


class SampleTimes(str, Enum):
    """What the values of a recording follow in time."""

    GRID = 'grid'  # a regular grid: the stamps' scatter is the stamps' own error
    STAMPS = 'stamps'  # the stamps: irregular sampling, truly stamped
    EITHER = 'either'  # the data cannot tell (noise above what the jitter moves)


def stamp_jitter(rec: JointRecording) -> tuple[float, SampleTimes]:
    """(rms of the stamps about a regular grid [s], what the values follow). The values
    follow the grid when the positions advance by the rates times the period rather than
    times the stamps' difference."""
    k, period = _consecutive(rec)
    dev = np.diff(rec.t)[k - 1] - period
    # difference of two stamps' errors: sqrt(2) times one stamp's
    jitter = float(np.sqrt(np.mean(dev**2)) / math.sqrt(2)) if len(k) else 0.0
    dq = rec.position[k] - rec.position[k - 1]
    mean_rate = 0.5 * (rec.velocity[k] + rec.velocity[k - 1])
    dt = np.diff(rec.t)[k - 1][:, None]
    e_stamps = float(np.sum((dq - mean_rate * dt) ** 2))
    e_grid = float(np.sum((dq - mean_rate * period) ** 2))
    if e_grid < 0.5 * e_stamps:
        return jitter, SampleTimes.GRID
    return jitter, SampleTimes.STAMPS if e_stamps < 0.5 * e_grid else SampleTimes.EITHER


def check_stamp_jitter(rec: JointRecording) -> tuple[Finding | None, float]:
    jitter, follows = stamp_jitter(rec)
    period = rec.period
    if jitter <= max(JITTER_SHARE * period, JITTER_FLOOR) or follows is SampleTimes.STAMPS:
        # a regular clock, or irregular sampling stamped truly: nothing to correct
        return None, jitter
    values = (
        'the positions advance with the regular period, not with the stamps'
        if follows is SampleTimes.GRID
        else 'the data cannot tell whether the values follow the stamps or a regular grid'
    )
    return (
        Finding(
            FindingKind.STAMP_JITTER,
            jitter,
            's',
            f'the stamps scatter by {jitter * 1e6:.3g} us rms ({jitter / period:.1%} of the '
            f'{period * 1e3:.4g} ms period) about a regular grid, and {values}',
            "stamp the samples where they are taken (the driver's header stamp or its "
            'sample counter), or fit with --regular-stamps',
        ),
        jitter,
    )


def _impacts(rec: JointRecording, model: ArmModel | None) -> list[int]:
    """The impacts of the recording; with a model, only steps with the tip near a surface."""
    if model is None:
        return find_impacts(rec)
    # the fit's own test: near a surface, the tip moving down before the step and less so
    # after it (a torque step near the surface, a drive leaving its limit, is no contact)
    return find_impacts(rec, is_contact=contact_test(model))


def _free(rec: JointRecording, impacts: list[int]) -> np.ndarray:
    free = np.ones(len(rec.t), bool)
    for a in impacts:
        free[max(0, a - FREE_MARGIN) : a + FREE_MARGIN + 2] = False
    return free


def effort_delay(
    rec: JointRecording, model: ArmModel, impacts: list[int]
) -> tuple[float, float] | None:
    """(delay of the efforts behind the joint states [s], F statistic of the delay against
    the best reading within half a period of none), or None when the free flight holds too
    little work of the torques. Between two consecutive free samples the change of the arm's
    energy equals the joint torques' work, tau(t_mid + delay) . (q[k] - q[k-1]); the delay
    is the one that balances it best (least squares). F = (cost(none) - cost(delay)) /
    (cost(delay) / (intervals - 1)): how much more the delay explains than the noise does."""
    k, period = _consecutive(rec)
    free = _free(rec, impacts)
    k = k[free[k] & free[k - 1]]
    if len(k) < 50:
        return None
    T = joint_to_absolute_matrix(rec.n)
    qa, va = rec.position @ T.T, rec.velocity @ T.T
    energy = np.array(
        [
            float(np.sum(model.link_energies(qa[i], va[i]))) + model.potential_energy(qa[i])
            for i in range(len(rec.t))
        ]
    )
    d_energy = energy[k] - energy[k - 1]
    dq = rec.position[k] - rec.position[k - 1]
    mid = 0.5 * (rec.t[k] + rec.t[k - 1])
    if not np.any(rec.effort[k]) or not np.any(dq):
        return None
    shifts = np.arange(-SEARCH_PERIODS, SEARCH_PERIODS + 0.01, 0.25) * period

    def cost(shift: float) -> float:
        w = sum(np.interp(mid + shift, rec.t, rec.effort[:, j]) * dq[:, j] for j in range(rec.n))
        return float(np.sum((d_energy - w) ** 2))

    costs = np.array([cost(s) for s in shifts])
    # no delay: the best reading within half a period, as finely searched as the delay
    at_zero = min(cost(s) for s in np.linspace(-0.5, 0.5, 41) * period)
    # then finer around the best of the coarse grid
    coarse = float(shifts[int(np.argmin(costs))])
    fine = coarse + np.linspace(-0.25, 0.25, 26) * period
    fine_costs = np.array([cost(s) for s in fine])
    best = int(np.argmin(fine_costs))
    residual = max(float(fine_costs[best]), 1e-300) / (len(k) - 1)
    return float(fine[best]), (at_zero - float(fine_costs[best])) / residual


def check_effort_delay(
    rec: JointRecording, model: ArmModel, impacts: list[int]
) -> tuple[Finding | None, float | None]:
    found = effort_delay(rec, model, impacts)
    if found is None:
        return None, None
    delay, f_stat = found
    period = rec.period
    # a real delay explains the power balance far better than any reading within half a
    # period (the fit's readings of the efforts cover that much) and than noise could
    if abs(delay) < DELAY_PERIODS * period or f_stat < DELAY_F_MIN:
        return None, delay
    late = 'late' if delay > 0 else 'early'
    return (
        Finding(
            FindingKind.EFFORT_DELAY,
            delay,
            's',
            f'the efforts are {abs(delay) * 1e3:.3g} ms {late} against the joint states '
            f'({abs(delay) / period:.2g} periods; from the power balance of the free flight: '
            f'F = {f_stat:.3g} against no delay)',
            _latency_advice(
                model,
                'effort',
                delay,
                period,
                f'fit with --effort-latency {delay:.6g} (if the delay is known, give its value); '
                f'mid-contact samples would otherwise be read with the wrong torque',
            ),
        ),
        delay,
    )


def _latency_advice(
    model: ArmModel | None, signal: str, found: float, period: float, otherwise: str
) -> str:
    """The advice for a delay of the efforts or the wrench found in the recording: the
    option (``otherwise``), or, when the scene states a delay of that signal (which the fit
    replays, so the option would shift it twice), that the scene's is used, and whether it
    agrees with the one found."""
    if model is None:
        return otherwise
    sensors = model.scene.sensors
    stated = getattr(sensors, f'{signal}_latency') - sensors.state_latency
    if not stated:
        return otherwise
    key = f'sensors.{signal}_latency'
    said = (
        f'the scene states it ({key} less sensors.state_latency = {stated:.6g} s), which the '
        f'fit replays: give no --{signal}-latency'
    )
    if abs(found - stated) <= DELAY_PERIODS * period:
        return said
    return (
        f"{said}, but it differs from the delay found: correct the scene's {key}, or fit it "
        f'(--param {key}=LO:HI)'
    )


# the smallest step of a joint may be several counts: a joint that never turns slower than
# a few counts per period (a fine encoder on a fast arm) never shows a single count
MAX_COUNTS_IN_SMALLEST_STEP = 1000


def encoder_resolution(rec: JointRecording) -> np.ndarray | None:
    """Per joint, the largest step of which every step of the positions is a whole number
    (an encoder's count), looked for among whole fractions of the smallest step; None when
    the positions are not on such a grid."""
    steps = np.diff(rec.position, axis=0)
    out = []
    for j in range(rec.n):
        d = np.abs(steps[:, j])
        d = d[d > 0]
        if len(d) < 10 or float(np.min(d)) > 0.1:
            return None
        count = _grid_step(d)
        if count is None:
            return None
        out.append(count)
    return np.array(out)


def _grid_step(d: np.ndarray) -> float | None:
    smallest = float(np.min(d))
    for k in range(1, MAX_COUNTS_IN_SMALLEST_STEP + 1):
        counts = d * (k / smallest)
        if np.max(np.abs(counts - np.round(counts))) <= 1e-4:
            return smallest / k
    return None


def check_position_noise(
    rec: JointRecording, impacts: list[int]
) -> tuple[Finding | None, float | None, str]:
    """(finding, worst noise / step, why not checked)."""
    steps = encoder_resolution(rec)
    if steps is None:
        return None, None, 'the positions are not on an encoder grid: resolution unknown'
    try:
        noise = estimate_noise(rec, impacts).position
    except IdentifyError as exc:
        return None, None, str(exc)
    ratio = noise / steps
    j = int(np.argmax(ratio))
    if ratio[j] <= NOISE_PER_STEP:
        return None, float(ratio[j]), ''
    name = rec.joints[j] if j < len(rec.joints) else f'joint {j + 1}'
    return (
        Finding(
            FindingKind.POSITION_NOISE,
            float(noise[j]),
            'rad',
            f'{name}: the positions scatter by {noise[j]:.3g} rad rms, {ratio[j]:.3g} times '
            f'the encoder resolution of {steps[j]:.3g} rad (one count)',
            'look for electrical noise, a loose coupling or backlash, or a position that is '
            "an estimate rather than the encoder's count; the fit weights the samples by "
            'this noise, so its intervals widen',
        ),
        float(ratio[j]),
        '',
    )


def wrench_lag(rec: JointRecording, impacts: list[int]) -> float | None:
    """Median over the impacts of how late the wrench rises (its first sample above half its
    peak) after the first joint sample after the step of the rates [s]; negative: how early
    before one period after the last sample before the step."""
    if rec.wrench is None or rec.wrench_t is None or not impacts:
        return None
    period = rec.period
    lags = []
    normal = np.abs(rec.wrench[:, 1])
    for a in impacts:
        t_a, t_b = rec.t[a], rec.t[a + 1]
        sel = np.flatnonzero(
            (rec.wrench_t > t_b - SEARCH_PERIODS * period)
            & (rec.wrench_t < t_b + SEARCH_PERIODS * period)
        )
        if len(sel) < 3:
            continue
        peak = float(np.max(normal[sel]))
        if peak <= 0:
            continue
        rise = float(rec.wrench_t[sel[np.flatnonzero(normal[sel] >= 0.5 * peak)[0]]])
        # on time: stamped from one period after the last sample before the contact to the
        # first sample after it (later when samples around the contact are lost)
        lags.append(rise - t_b if rise > t_b else min(rise - (t_a + period), 0.0))
    return float(np.median(lags)) if lags else None


def check_wrench_lag(
    rec: JointRecording, impacts: list[int], model: ArmModel | None = None
) -> tuple[Finding | None, float | None]:
    lag = wrench_lag(rec, impacts)
    if lag is None:
        return None, None
    period = rec.period
    if abs(lag) < DELAY_PERIODS * period:
        return None, lag
    late = 'after' if lag > 0 else 'before'
    return (
        Finding(
            FindingKind.WRENCH_LAG,
            lag,
            's',
            f'the wrench rises {abs(lag) * 1e3:.3g} ms ({abs(lag) / period:.2g} periods) {late} '
            f'the impacts the joint rates show (median over {len(impacts)} impacts)',
            _latency_advice(
                model,
                'wrench',
                lag,
                period,
                f"fit with --wrench-latency {lag:.6g} (the force sensor's latency, if known), "
                f'or --no-wrench; the wrench impulse of each impact is otherwise summed over '
                f'the wrong periods',
            ),
        ),
        lag,
    )


def diagnose(rec: JointRecording, model: ArmModel | None = None) -> Diagnosis:
    """Every check that the recording (and the scene's ``model``, for the power balance and to
    tell contacts from other steps of the rates) allows."""
    out = Diagnosis()

    def ran(kind: FindingKind, found: Finding | None, estimate: float | None) -> None:
        out.checked.append(kind)
        if estimate is not None:
            out.estimates[kind] = estimate
        if found is not None:
            out.findings.append(found)

    found = check_difference_rates(rec)
    ran(FindingKind.DIFFERENCE_RATES, found, found.estimate if found else None)
    found = None if found else check_filtered_rates(rec)
    ran(FindingKind.FILTERED_RATES, found, found.estimate if found else None)
    ran(FindingKind.STAMP_JITTER, *check_stamp_jitter(rec))
    try:
        impacts = _impacts(rec, model)
    except IdentifyError as exc:
        impacts = []
        why = str(exc)
    else:
        why = 'no impact found in the joint rates'
    if model is None:
        out.skipped[FindingKind.EFFORT_DELAY] = 'needs the scene (the power balance)'
    else:
        finding, estimate = check_effort_delay(rec, model, impacts)
        if estimate is None:
            out.skipped[FindingKind.EFFORT_DELAY] = 'too little work of the torques in free flight'
        else:
            ran(FindingKind.EFFORT_DELAY, finding, estimate)
    finding, ratio, why_not = check_position_noise(rec, impacts)
    if why_not:
        out.skipped[FindingKind.POSITION_NOISE] = why_not
    else:
        ran(FindingKind.POSITION_NOISE, finding, ratio)
    if rec.wrench is None:
        out.skipped[FindingKind.WRENCH_LAG] = 'no wrench recorded'
    elif not impacts:
        out.skipped[FindingKind.WRENCH_LAG] = why
    else:
        ran(FindingKind.WRENCH_LAG, *check_wrench_lag(rec, impacts, model))
    return out


# ------------------------------------------------------------------------- corrections
def correct(
    rec: JointRecording, corrections: Corrections, diagnosis: Diagnosis | None = None
) -> JointRecording:
    """A copy of ``rec`` with the asked ``corrections`` applied, each named in its notes (and
    in ``diagnosis.corrections``, whose findings are marked corrected)."""
    if not corrections.requested:
        return rec
    out = dataclasses.replace(rec, notes=list(rec.notes))
    done: list[tuple[str, FindingKind, str]] = []
    if corrections.regular_stamps:
        out = _regular_stamps(out)
        done.append(
            ('--regular-stamps', FindingKind.STAMP_JITTER, 'stamps put on the regular grid')
        )
    if corrections.difference_rates:
        out = rates_as_period_means(out)
        done.append(
            (
                '--difference-rates',
                FindingKind.DIFFERENCE_RATES,
                'rates read as the mean rates over the periods before their stamps and '
                "compared with the replay's mean rates over the same periods",
            )
        )
        done.append(('--difference-rates', FindingKind.FILTERED_RATES, ''))
    if corrections.effort_latency:
        out = _earlier_efforts(out, corrections.effort_latency)
        done.append(
            (
                '--effort-latency',
                FindingKind.EFFORT_DELAY,
                f'efforts read {corrections.effort_latency * 1e3:g} ms earlier',
            )
        )
    if corrections.wrench_latency and out.wrench_t is not None:
        out.wrench_t = out.wrench_t - corrections.wrench_latency
        done.append(
            (
                '--wrench-latency',
                FindingKind.WRENCH_LAG,
                f'wrench stamps moved {corrections.wrench_latency * 1e3:g} ms earlier',
            )
        )
    for option, kind, what in done:
        if what:
            out.notes.append(f'corrected before the fit ({option}): {what}')
        if diagnosis is not None:
            if what:
                diagnosis.corrections.append(f'{option}: {what}')
            diagnosis.findings = [
                dataclasses.replace(f, corrected_by=option) if f.kind == kind else f
                for f in diagnosis.findings
            ]
    return out


def central_rates(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The rate at each stamp from the positions: the derivative of the parabola through the
    sample and its two neighbours (central difference on any stamps; one-sided at the ends)."""
    return np.gradient(q, t, axis=0, edge_order=2)


def _parabola_at(t: np.ndarray, q: np.ndarray, nodes: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Per row i, the parabola through the samples ``nodes[i]`` (three indices) at ``at[i]``
    (Lagrange's form)."""
    x = t[nodes]
    w = np.empty_like(x)
    for j in range(3):
        o1, o2 = (j + 1) % 3, (j + 2) % 3
        w[:, j] = (at - x[:, o1]) * (at - x[:, o2]) / ((x[:, j] - x[:, o1]) * (x[:, j] - x[:, o2]))
    return np.einsum('ij,ijk->ik', w, q[nodes])


def rates_as_period_means(rec: JointRecording) -> JointRecording:
    """A recording whose rates are backward differences of its positions, (q[k] - q[k-1]) /
    period, or those differences through a filter, read for what they are: the mean rate over
    the period before each stamp (``RateMeaning.PERIOD_MEAN``), which the fit compares with
    the replay's own mean over that period. Rates that are not already the differences are
    replaced by them where the sample before is recorded; a sample whose predecessor is lost
    (and the first) is then dropped: its difference is unknown."""
    k, period = _consecutive(rec)
    q, v = rec.position, rec.velocity
    diff = (q[k] - q[k - 1]) / period
    scale = np.maximum(np.abs(v[k]), 1e-12)
    already = float(np.mean(np.all(np.abs(diff - v[k]) <= DIFFERENCE_TOLERANCE * scale, axis=1)))
    out = dataclasses.replace(rec, notes=list(rec.notes), rates=RateMeaning.PERIOD_MEAN)
    if len(k) and already >= DIFFERENCE_SHARE:
        return out  # a lost sample's successor keeps its rate: a difference all the same
    velocity = v.copy()
    velocity[k] = diff
    out = dataclasses.replace(
        out, t=rec.t[k], position=q[k], velocity=velocity[k], effort=rec.effort[k]
    )
    dropped = len(rec.t) - len(k)
    out.notes.append(
        f'rates recomputed as the differences of the positions; {dropped} sample(s) whose '
        f'predecessor is not recorded dropped'
    )
    shift = float(out.t[0])
    out.t = out.t - shift
    if out.wrench_t is not None:
        out.wrench_t = out.wrench_t - shift
    if out.plates_t is not None:
        out.plates_t = out.plates_t - shift
    out.t0_ns = rec.t0_ns + round(shift * 1e9)
    return out


def _regular_stamps(rec: JointRecording) -> JointRecording:
    """Stamps on the least-squares grid t = a + b k, with k counting whole periods (a lost
    sample keeps its place); the wrench's stamps moved to the same grid."""
    period = rec.period
    k = np.concatenate([[0], np.cumsum(np.round(np.diff(rec.t) / period))])
    b, a = np.polyfit(k, rec.t, 1)
    out = dataclasses.replace(rec, t=a + b * k)
    if rec.wrench_t is not None:
        kw = np.round((rec.wrench_t - a) / b)
        out.wrench_t = a + b * kw
    if rec.plates_t is not None:
        out.plates_t = a + b * np.round((rec.plates_t - a) / b)
    shift = out.t[0]
    out.t = out.t - shift
    if out.wrench_t is not None:
        out.wrench_t = out.wrench_t - shift
    if out.plates_t is not None:
        out.plates_t = out.plates_t - shift
    out.t0_ns = rec.t0_ns + round(shift * 1e9)
    return out


def _earlier_efforts(rec: JointRecording, latency: float) -> JointRecording:
    """The effort at each stamp read ``latency`` later in the recording (linear between the
    samples); samples whose effort is not recorded (the last ``latency``) are dropped."""
    t = rec.t
    keep = (t + latency >= t[0]) & (t + latency <= t[-1])
    effort = np.array([np.interp(t[keep] + latency, t, rec.effort[:, j]) for j in range(rec.n)]).T
    out = dataclasses.replace(
        rec,
        t=t[keep],
        position=rec.position[keep],
        velocity=rec.velocity[keep],
        effort=effort.reshape(-1, rec.n),
    )
    shift = out.t[0]
    out.t = out.t - shift
    if out.wrench_t is not None:
        out.wrench_t = out.wrench_t - shift
    if out.plates_t is not None:
        out.plates_t = out.plates_t - shift
    out.t0_ns = rec.t0_ns + round(shift * 1e9)
    return out
