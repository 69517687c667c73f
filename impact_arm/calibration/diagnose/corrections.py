"""The corrections the user asks for (``Corrections``) and ``correct``, which applies them to
a copy of the recording: efforts read earlier, the wrench's stamps moved, difference rates
read as the mean rates of their periods, stamps put back on their regular grid."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..identify import JointRecording, RateMeaning
from .findings import Diagnosis, FindingKind
from .rates import DIFFERENCE_SHARE, DIFFERENCE_TOLERANCE
from .stamps import consecutive

if TYPE_CHECKING:
    from ...physics.scene import SensorSpec


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


def rates_as_period_means(rec: JointRecording) -> JointRecording:
    """A recording whose rates are backward differences of its positions, (q[k] - q[k-1]) /
    period, or those differences through a filter, read for what they are: the mean rate over
    the period before each stamp (``RateMeaning.PERIOD_MEAN``), which the fit compares with
    the replay's own mean over that period. Rates that are not already the differences are
    replaced by them where the sample before is recorded; a sample whose predecessor is lost
    (and the first) is then dropped: its difference is unknown."""
    k, period = consecutive(rec)
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
    return _from_zero(out, rec.t0_ns)


def _from_zero(out: JointRecording, t0_ns: int) -> JointRecording:
    """``out`` with its first stamp moved to 0 (and its wrench and plate stamps with it),
    ``t0_ns`` (the source's origin) advanced by as much."""
    shift = out.t[0]
    out.t = out.t - shift
    if out.wrench_t is not None:
        out.wrench_t = out.wrench_t - shift
    if out.plates_t is not None:
        out.plates_t = out.plates_t - shift
    out.t0_ns = t0_ns + round(shift * 1e9)
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
    return _from_zero(out, rec.t0_ns)
