"""What a recording says about its impacts, before any model is involved.

From sampled joint states alone (any clock, missing and jittered samples): the sensor noise,
the impacts (a step in the joint rates that the positions do not show), and around each
impact a local polynomial fit of the free flight on either side, from which the state just
before and just after the contact follow with their uncertainty. ``calibration/fit/`` then asks a
scene to reproduce the step. Everything here is plain numpy in joint space (relative angles,
as drivers publish them).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from ..physics.errors import ImpactArmError
from ..physics.kinds import ImpactSide

if TYPE_CHECKING:
    from ..physics.model import ArmModel


class IdentifyError(ImpactArmError):
    """A recording that does not allow an identification (no impact, too few samples)."""


class RateMeaning(str, enum.Enum):
    """What a recorded joint rate is."""

    INSTANT = 'instant'  # the rate at the stamp (a drive's own velocity)
    # (q(t) - q(t - period)) / period: a backward difference of the positions, the mean rate
    # over the period before the stamp (a driver that differentiates its encoder)
    PERIOD_MEAN = 'period_mean'


@dataclass
class JointRecording:
    t: np.ndarray  # [s] from the first sample (stamps of any clock)
    position: np.ndarray  # (N, n) joint angles [rad], relative convention
    velocity: np.ndarray  # (N, n) joint rates [rad/s]
    effort: np.ndarray  # (N, n) joint torques [N m]
    wrench_t: np.ndarray | None = None  # [s] same origin as t
    wrench: np.ndarray | None = None  # (M, 2): tangential, normal force [N], period-averaged
    joints: list = field(default_factory=list)
    source: str = ''
    t0_ns: int = 0  # stamp of the first sample
    notes: list = field(default_factory=list)
    rates: RateMeaning = RateMeaning.INSTANT
    # the mounted surfaces' plates, when recorded (/surface_mounts): stamps [s] (same origin
    # as t) and (z, ż) of each plate, flat, in surface order [m, m/s]
    plates_t: np.ndarray | None = None
    plates: np.ndarray | None = None
    # the rate-step statistic per sample gap, set by find_impacts (make_window stops its
    # comparison at a further contact); None before
    step_z: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.position.shape[1]

    @property
    def period(self) -> float:
        return float(np.median(np.diff(self.t)))

    @property
    def rate_period(self) -> float | None:
        """The period each recorded rate is the mean over, None for rates at the stamps."""
        return self.period if self.rates is RateMeaning.PERIOD_MEAN else None


@dataclass
class Noise:
    position: np.ndarray  # per joint [rad]
    velocity: np.ndarray  # per joint [rad/s]
    effort: np.ndarray  # per joint [N m]
    wrench: np.ndarray | None  # tangential, normal [N]

    def as_dict(self) -> dict:
        out = {
            'position': self.position.tolist(),
            'velocity': self.velocity.tolist(),
            'effort': self.effort.tolist(),
        }
        if self.wrench is not None:
            out['wrench'] = self.wrench.tolist()
        return out


class LocalFit:
    """A cubic per joint through positions and rates together (rates are the positions'
    derivative), weighted by their noise; ``state(t)`` gives q, q̇ and their covariance.
    With ``rate_period`` (rates that are backward differences of the positions) the rates
    hold nothing the positions do not: the cubic goes through the positions alone."""

    DEGREE = 3

    def __init__(self, t, q, qd, t_ref, sigma_q, sigma_qd, rate_period: float | None = None):
        self.t_ref, self.scale = t_ref, max(float(np.ptp(t)), 1e-6)
        tau = (np.asarray(t) - t_ref) / self.scale
        powers = np.arange(self.DEGREE + 1)
        V = tau[:, None] ** powers
        D = np.zeros_like(V)
        D[:, 1:] = powers[1:] * tau[:, None] ** (powers[1:] - 1) / self.scale
        n = q.shape[1]
        self.coef = np.zeros((n, self.DEGREE + 1))
        self.cov = np.zeros((n, self.DEGREE + 1, self.DEGREE + 1))
        self.chi2 = 0.0
        self._states: dict = {}  # t -> (q, q̇, cov): see state()
        with_rates = rate_period is None
        dof = (2 if with_rates else 1) * len(tau) - (self.DEGREE + 1)
        for j in range(n):
            if with_rates:
                A = np.vstack([V / sigma_q[j], D / sigma_qd[j]])
                b = np.concatenate([q[:, j] / sigma_q[j], qd[:, j] / sigma_qd[j]])
            else:
                A, b = V / sigma_q[j], q[:, j] / sigma_q[j]
            coef, *_ = np.linalg.lstsq(A, b, rcond=None)
            chi2 = float(np.sum((A @ coef - b) ** 2))
            # a window the cubic cannot follow (unmodelled jerk) widens its own uncertainty
            inflate = max(1.0, chi2 / dof) if dof > 0 else 1.0
            self.coef[j], self.cov[j] = coef, np.linalg.inv(A.T @ A) * inflate
            self.chi2 += chi2
        self.dof = dof * n

    def _rows(self, t):
        tau = (t - self.t_ref) / self.scale
        p = np.arange(self.DEGREE + 1)
        v = tau**p
        d = np.zeros_like(v)
        d[1:] = p[1:] * tau ** (p[1:] - 1) / self.scale
        return v, d

    def positions(self, t: np.ndarray) -> np.ndarray:
        """q at each of the times ``t``: (len(t), n)."""
        tau = (np.asarray(t, float) - self.t_ref) / self.scale
        return (tau[:, None] ** np.arange(self.DEGREE + 1)) @ self.coef.T

    def mean_rates(self, t: np.ndarray, period: float) -> np.ndarray:
        """(q(t) - q(t - period)) / period at each of the times ``t``: (len(t), n)."""
        t = np.asarray(t, float)
        return (self.positions(t) - self.positions(t - period)) / period

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, cov) at ``t``: cov is (2n, 2n) over [q, q̇] (joints independent)."""
        # a fit replays each impact from the same instant hundreds of times: each instant's
        # state is computed once, and handed out as copies
        known = self._states.get(t)
        if known is None:
            known = self._states[t] = self._state(t)
        return known[0].copy(), known[1].copy(), known[2].copy()

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v, d = self._rows(t)
        n = self.coef.shape[0]
        q, qd = self.coef @ v, self.coef @ d
        cov = np.zeros((2 * n, 2 * n))
        for j in range(n):
            rows = np.vstack([v, d])
            c = rows @ self.cov[j] @ rows.T
            cov[j, j], cov[n + j, n + j] = c[0, 0], c[1, 1]
            cov[j, n + j] = cov[n + j, j] = c[0, 1]
        return q, qd, cov


def _no_series() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.empty(0), np.empty((0, 0)), np.empty(0)


def _not_widened(side: ImpactSide) -> ImpactWindow | None:
    return None


@dataclass
class ImpactWindow:
    """One impact seen in the recording: the last sample before (index a), the first after
    (b), the contact time t_c where the two sides' positions meet, the fits of both sides,
    the effort held before, and the wrench impulse when a wrench was recorded."""

    index: int
    a: int
    b: int
    t_a: float
    t_b: float
    t_c: float
    pre: LocalFit
    post: LocalFit
    effort: np.ndarray  # (a-1, a, ..., b, ... b+m) efforts [N m]
    effort_t: np.ndarray  # their times
    post_t: np.ndarray  # first m samples after the impact
    post_qd: np.ndarray  # their rates (m, n)
    # rates that are means over the period before their stamps (``RateMeaning.PERIOD_MEAN``):
    # that period [s]; None: rates at the stamps
    rate_period: float | None = None
    impulse: np.ndarray | None = None  # (tangential, normal) [N s]
    impulse_var: np.ndarray | None = None
    rate_sigma: np.ndarray | None = None  # the rates' noise per joint [rad/s]
    # a wrench that may be late (``_add_impulse``): its stamps and period, and the centroid
    # of its normal force [s after t_a] with its variance; None: the impulse alone
    wrench_stamps: np.ndarray | None = None
    wrench_period: float = 0.0
    wrench_timing: float | None = None
    wrench_timing_var: float = 0.0
    wrench_after: bool = False  # most of the normal force after the periods summed
    plate: np.ndarray | None = None  # the plates' recorded (z, ż) at t_a, flat; None: not recorded
    # (q, q̇, cov) at t_a from the model's flight under the recorded efforts (fit/prestate.py,
    # rates that are period means); None: the pre-impact cubic's
    start: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    # what make_window adds from the recording around the impact:
    effort_ib: int = 0  # index in ``effort`` of the sample b
    # per effort sample: zero torque within the noise (actuators off during the contact)
    effort_off: list[bool] = field(default_factory=list)
    # the whole series (t, efforts, noise), for a replay that reads them by a fitted latency
    effort_source: tuple[np.ndarray, np.ndarray, np.ndarray] = field(default_factory=_no_series)
    # the window one sample wider on a side (before or after the impact), or None where it
    # cannot be
    widened: Callable[[ImpactSide], ImpactWindow | None] = _not_widened
    # (t, positions, noise) before the impact: a start state shot through the model's flight
    pre_samples: tuple[np.ndarray, np.ndarray, np.ndarray] = field(default_factory=_no_series)
    # (t, positions, rates) before the impact as recorded: what a sampled controller saw
    controller_inputs: tuple[np.ndarray, np.ndarray, np.ndarray] = field(default_factory=_no_series)
    own_command: bool = False  # the scene's controller gives the efforts (fit/problem.py)

    def start_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, q̇, cov) at the last sample before the impact, where the replay starts."""
        return self.start if self.start is not None else self.pre.state(self.t_a)

    def jump(self) -> np.ndarray:
        """Recorded joint-rate step at the contact time (post minus pre)."""
        return self.post.state(self.t_c)[1] - self.pre.state(self.t_c)[1]


def _window_noise(t, y, starts, length):
    """Per-column noise from cubic fits over free-flight windows: the median window variance,
    corrected for the median of a chi-square (robust to the odd window with a kink)."""
    variances = []
    for s in starts:
        tt = t[s : s + length]
        tau = (tt - tt[0]) / max(np.ptp(tt), 1e-9)
        V = tau[:, None] ** np.arange(4)
        coef, *_ = np.linalg.lstsq(V, y[s : s + length], rcond=None)
        r = y[s : s + length] - V @ coef
        variances.append(np.sum(r**2, axis=0) / (length - 4))
    if not variances:
        return None
    dof = length - 4
    median_of_chi2 = (1 - 2 / (9 * dof)) ** 3
    return np.sqrt(np.median(np.array(variances), axis=0) / median_of_chi2)


def rate_steps(rec: JointRecording) -> tuple[np.ndarray, np.ndarray]:
    """For each gap k (between samples k and k+1, k = 2..N-4): how far apart the rate lines
    of both sides stay at their closest within the gap, in units of each joint's robust
    scale (normed over the joints). A kink of the rates (a torque step: the controller
    switching targets) has lines that cross inside the gap, at one time for every joint; an
    impact's step leaves them apart. Returns (z per gap, step per gap and joint)."""
    t, v = rec.t, rec.velocity
    ta, tb = t[2:-3], t[3:-2]
    va, vb = v[2:-3], v[3:-2]
    a1 = (va - v[:-5]) / (ta - t[:-5])[:, None]
    a2 = (v[5:] - vb) / (t[5:] - tb)[:, None]
    # R(t) - L(t) = c0 + c1 (t - ta), minimised over t in [ta, tb] in scaled units
    c0 = vb - va - a2 * (tb - ta)[:, None]
    c1 = a2 - a1
    raw_step = vb - va - 0.5 * (a1 + a2) * (tb - ta)[:, None]
    # the robust scale over the gaps where something moves: a noise-free recording that
    # rests for a while (a start-up hold) would otherwise have a scale of zero
    moving = np.any(v[3:-2] != v[2:-3], axis=1)
    pool = raw_step[moving] if np.count_nonzero(moving) > 10 else raw_step
    dev = np.abs(pool - np.median(pool, axis=0))
    scale = 1.4826 * np.median(dev, axis=0)
    scale = np.where(scale > 0, scale, max(float(np.max(scale)), 1e-12))
    c0s, c1s = c0 / scale, c1 / scale
    denom = np.sum(c1s**2, axis=1)
    s = np.where(denom > 0, -np.sum(c0s * c1s, axis=1) / np.where(denom > 0, denom, 1.0), 0.0)
    s = np.clip(s, 0.0, (tb - ta))
    gap = c0s + c1s * s[:, None]
    z = np.zeros(len(t) - 1)
    z[2:-2] = np.sqrt(np.sum(gap**2, axis=1))
    step = np.zeros((len(t) - 1, v.shape[1]))
    step[2:-2] = raw_step
    return z, step


def find_impacts(
    rec: JointRecording,
    z_min: float = 30.0,
    is_contact: Callable[[np.ndarray, np.ndarray, np.ndarray], bool] | None = None,
) -> list[int]:
    """Gaps (a, a+1) holding an impact: a rate step far outside what noise and smooth motion
    give (robust z-score > ``z_min``); neighbouring candidates (the step leaks into the
    slopes of the gaps next to it) are one impact, the strongest gap. ``is_contact(q, qd_before,
    qd_after)`` (joint space) may reject steps that cannot be contacts (a controller switching
    its target far from any surface makes a torque step, which can look alike at 1 kHz)."""
    if rec.velocity is None:
        raise IdentifyError(
            'the joint states carry no rates (velocity): impacts are found and '
            'fitted from the joint rates'
        )
    z, _ = rate_steps(rec)
    rec.step_z = z  # kept: make_window stops its comparison at a further contact
    candidates = np.flatnonzero(z > z_min)  # gap k lies after sample k
    gaps: list[list] = []  # groups of numpy integers
    for k in candidates:
        if gaps and k - gaps[-1][-1] <= 3:
            gaps[-1].append(k)
        else:
            gaps.append([k])
    v = rec.velocity
    found: list = []  # numpy integers
    for group in gaps:
        # the strongest gap of the group that can be a contact (a stiff sampled controller
        # makes steps of its own right after an impact, some larger than the impact's)
        if is_contact is not None:
            group = [k for k in group if is_contact(rec.position[k], v[k], v[k + 1])]
        if group:
            found.append(max(group, key=lambda k: z[k]))
    return found


def estimate_noise(rec: JointRecording, impacts: Sequence[int], window: int = 15) -> Noise:
    """Sensor noise from free-flight windows (none within ``window`` samples of an impact)."""
    N = len(rec.t)
    free = np.ones(N, bool)
    for a in impacts:
        free[max(0, a - window) : a + window + 2] = False
    starts = [s for s in range(0, N - window, window) if free[s : s + window].all()]
    if len(starts) < 3:
        raise IdentifyError(
            f'{len(starts)} free-flight windows of {window} samples between the '
            f'impacts: too few to estimate the sensor noise (record longer or '
            f'at a higher rate)'
        )
    # noise-free input (a simulation): floors far below any sensor keep the weights finite
    floor = 1e-12
    sq = np.maximum(_window_noise(rec.t, rec.position, starts, window), 1e-10)
    sqd = np.maximum(_window_noise(rec.t, rec.velocity, starts, window), 1e-8)
    se = _window_noise(rec.t, rec.effort, starts, window)
    sw = None
    if rec.wrench is not None and len(rec.wrench_t) > 4 * window:  # type: ignore[arg-type]
        # wrench samples away from the impacts (their own clock grid)
        near: np.ndarray = np.zeros(len(rec.wrench_t), bool)  # type: ignore[arg-type]  # wrench_t comes with wrench
        for a in impacts:
            near |= np.abs(rec.wrench_t - rec.t[a]) < window * rec.period
        idx = np.flatnonzero(~near)
        w_starts = [
            idx[i]
            for i in range(0, len(idx) - window, window)
            if idx[i + window - 1] - idx[i] == window - 1
        ]
        if len(w_starts) >= 3:
            sw = np.maximum(_window_noise(rec.wrench_t, rec.wrench, w_starts, window), floor)
    return Noise(sq, sqd, se, sw)


def _contact_time(pre: LocalFit, post: LocalFit, t_a, t_b, sigma_q):
    """Where the positions of both sides meet (rates step at the contact, positions do not)."""

    def miss(t: np.ndarray) -> np.ndarray:
        return np.sum(((pre.positions(t) - post.positions(t)) / sigma_q) ** 2, axis=1)

    grid = np.linspace(t_a, t_b, 201)
    k = int(np.argmin(miss(grid)))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    fine = np.linspace(lo, hi, 41)
    return float(fine[int(np.argmin(miss(fine)))])


def impact_windows(
    rec: JointRecording,
    noise: Noise,
    impacts: Sequence[int],
    window: int = 15,
    min_samples: int = 5,
    max_gap: float = 5.0,
    post_samples: int = 3,
    wrench_lag: tuple[float, float] = (0.0, 0.0),
) -> tuple[list[ImpactWindow], list[str]]:
    """An ``ImpactWindow`` per usable impact and a note per impact left out (too few free
    samples between impacts, a gap of more than ``max_gap`` periods across the contact).
    ``wrench_lag``: the range [s] of the wrench's delay behind the joint states (a latency
    fitted or stated): each impact's wrench is taken over every period that can then hold
    the contact, with its timing (``_add_impulse``)."""
    out: list[ImpactWindow]
    notes: list[str]
    out, notes = [], []
    N, _dt = len(rec.t), rec.period
    for i, a in enumerate(impacts):
        lo = impacts[i - 1] + 1 if i else 0
        hi = impacts[i + 1] if i + 1 < len(impacts) else N - 1
        win, why = make_window(
            rec, noise, a, a + 1, lo, hi, window, min_samples, max_gap, post_samples, wrench_lag
        )
        if win is None:
            notes.append(f'impact at t = {rec.t[a]:.4f} s left out: {why}')
            continue
        win.index = len(out)
        out.append(win)
    return out, notes


def make_window(
    rec: JointRecording,
    noise: Noise,
    a: int,
    b: int,
    lo: int,
    hi: int,
    window: int = 15,
    min_samples: int = 5,
    max_gap: float = 5.0,
    post_samples: int = 3,
    wrench_lag: tuple[float, float] = (0.0, 0.0),
) -> tuple[ImpactWindow | None, str]:
    """(ImpactWindow, '') for an impact between samples a and b (free samples from lo to
    hi), or (None, why not). ``window.widened(side)`` rebuilds it with one more sample
    given to the impact on that side, for a contact that spans a sample."""
    N, dt = len(rec.t), rec.period

    def off(k: int) -> bool:
        return bool(np.all(np.abs(rec.effort[k]) < 6 * noise.effort + 1e-12))

    while b < min(hi, a + 4) and off(b) and not off(a):
        b += 1  # actuators off at b while driven before: b was taken in the contact
    v = rec.velocity
    while b < min(hi - 1, a + 4):
        # the step still going on after b in its own direction (by more than a tenth of
        # it): b was taken in the contact too
        jump = v[b] - v[a]
        size = float(np.linalg.norm(jump))
        if not size or float((v[b + 1] - v[b]) @ jump) / size < 0.1 * size:
            break
        b += 1
    pre_idx = np.arange(max(lo, a - window + 1), a + 1)
    post_idx = np.arange(b, min(hi, b + window - 1) + 1)
    if rec.t[b] - rec.t[a] > max_gap * dt:
        return None, f'{rec.t[b] - rec.t[a]:.4g} s without samples across it'
    if len(pre_idx) < min_samples or len(post_idx) < max(min_samples, post_samples + 1):
        return None, (
            f'{min(len(pre_idx), len(post_idx))} free samples on one side (another '
            f'impact or the end of the recording too close)'
        )
    if len(pre_idx) > min_samples and _contact_under_way(rec, noise, pre_idx, b):
        # the contact began before sample a: it is no free-flight sample
        return make_window(
            rec, noise, a - 1, b, lo, hi, window, min_samples, max_gap, post_samples, wrench_lag
        )
    fits = [
        LocalFit(
            rec.t[idx],
            rec.position[idx],
            rec.velocity[idx],
            rec.t[ref],
            noise.position,
            noise.velocity,
            rec.rate_period,
        )
        for idx, ref in ((pre_idx, a), (post_idx, b))
    ]
    # ignored [call-arg], [misc]: mypy cannot count the items of the list ``fits`` (pre, post)
    t_c = _contact_time(*fits, rec.t[a], rec.t[b], noise.position)  # type: ignore[call-arg]
    # a wrench published late shows this impact's force after b: not a further contact
    own_wrench = rec.t[b] + max(wrench_lag[1], 0.0) + 1.25 * dt if any(wrench_lag) else None
    compare = post_idx[: _before_next_contact(rec, noise, post_idx[:post_samples], own_wrench)]
    # efforts from the sample before a to the one after the last compared sample, including
    # any taken during the contact (between a and b)
    e_idx = np.concatenate([[max(a - 1, 0)], np.arange(a, min(compare[-1] + 2, N))])
    win = ImpactWindow(  # type: ignore[misc]
        0,
        a,
        b,
        float(rec.t[a]),
        float(rec.t[b]),
        t_c,
        *fits,  # type: ignore[arg-type]
        effort=rec.effort[e_idx].copy(),
        effort_t=rec.t[e_idx].copy(),
        post_t=rec.t[compare].copy(),
        post_qd=rec.velocity[compare].copy(),
        rate_period=rec.rate_period,
        rate_sigma=noise.velocity,
    )
    win.effort_ib = int(np.flatnonzero(e_idx == b)[0])
    # the whole series, for a replay that reads the efforts later by a latency it fits
    win.effort_source = (rec.t, rec.effort, 6 * noise.effort + 1e-12)
    # the samples before the impact, for a start state shot through the model's flight
    win.pre_samples = (rec.t[pre_idx].copy(), rec.position[pre_idx].copy(), noise.position)
    # the samples before the impact as recorded: what a sampled controller saw there
    win.controller_inputs = (
        rec.t[pre_idx].copy(),
        rec.position[pre_idx].copy(),
        rec.velocity[pre_idx].copy(),
    )
    # samples during the contact whose torque is zero within the noise: actuators off
    win.effort_off = [
        bool(np.all(np.abs(win.effort[k]) < 6 * noise.effort + 1e-12)) for k in range(len(e_idx))
    ]
    _add_impulse(rec, noise, win, wrench_lag)
    win.plate = _plate_at(rec, rec.t[a])

    def widened(side: ImpactSide) -> ImpactWindow | None:
        a2, b2 = (a - 1, b) if side is ImpactSide.BEFORE else (a, b + 1)
        return make_window(
            rec, noise, a2, b2, lo, hi, window, min_samples, max_gap, post_samples, wrench_lag
        )[0]

    win.widened = widened
    return win, ''


def _before_next_contact(rec, noise, idx, own_wrench=None, z_min=30.0) -> int:
    """How many of the post-impact samples ``idx`` come before a further contact (a bounce:
    a rate step, or wrench in the period that ends at the sample, unless stamped up to
    ``own_wrench``, the impact's own wrench published late); at least one."""
    z = rec.step_z
    dt = rec.period
    for count, j in enumerate(idx[1:], start=1):
        # the step statistic of the two gaps after an impact still sees that impact
        if z is not None and j - 1 >= idx[0] + 2 and j - 1 < len(z) and z[j - 1] > z_min:
            return count
        # a joint torque of zero (within the noise) between driven samples: actuators off,
        # as they are in a contact
        if np.all(np.abs(rec.effort[j]) < 6 * noise.effort + 1e-12) and np.any(
            np.abs(rec.effort[idx[0]]) > 6 * noise.effort + 1e-12
        ):
            return count
        if rec.wrench is not None and noise.wrench is not None:
            near = (rec.wrench_t > rec.t[j - 1] + 0.5 * dt) & (rec.wrench_t <= rec.t[j] + 0.5 * dt)
            if own_wrench is not None:
                near &= rec.wrench_t > own_wrench
            if np.any(np.abs(rec.wrench[near]) > 8 * noise.wrench):
                return count
    return len(idx)


def _contact_under_way(rec, noise, pre_idx, b, limit=6.0) -> bool:
    """Whether the last pre-impact sample's rates leave the free flight the samples before
    it predict (by more than ``limit`` standard deviations, and more than 1e-3 of the rate
    step across the impact: noise-free data leave only the cubic's own error): a contact
    already under way."""
    head, last = pre_idx[:-1], pre_idx[-1]
    period = rec.rate_period
    fit = LocalFit(
        rec.t[head],
        rec.position[head],
        rec.velocity[head],
        rec.t[head[-1]],
        noise.position,
        noise.velocity,
        period,
    )
    _, qd, cov = fit.state(rec.t[last])
    n = rec.n
    sd = np.sqrt(np.diag(cov)[n:] + noise.velocity**2)
    if period is not None:  # the recorded rate is the mean over the period before the stamp
        qd = fit.mean_rates(np.array([rec.t[last]]), period)[0]
    floor = 1e-3 * float(np.max(np.abs(rec.velocity[b] - rec.velocity[last])))
    return bool(np.any(np.abs(rec.velocity[last] - qd) > np.maximum(limit * sd, floor)))


def _add_impulse(rec, noise, win, wrench_lag=(0.0, 0.0)):
    """The wrench impulse over the periods that can hold the contact, if every one of them
    was recorded (a lost wrench sample would lose part of the impulse). With a wrench that
    may be late (``wrench_lag`` = its delay's range [s], not (0, 0)) the periods cover every
    delay in that range, and the impulse's timing is kept too: the stamps and the normal
    force of each period, and their centroid (sum s F / sum F, from the last sample before
    the impact), which a replay that knows the delay gives alike."""
    if rec.wrench is None or noise.wrench is None:
        return
    wt = rec.wrench_t
    dtw = float(np.median(np.diff(wt)))
    lo, hi = wrench_lag
    # every period that can overlap the contact, which lies between the joint samples a, b
    sel = np.flatnonzero((wt > win.t_a + lo - 0.25 * dtw) & (wt <= win.t_b + hi + 1.25 * dtw))
    if len(sel) < 2:
        return
    around = np.arange(max(sel[0] - 1, 0), min(sel[-1] + 2, len(wt)))
    if np.any(np.diff(wt[around]) > 1.5 * dtw):
        return
    win.impulse = rec.wrench[sel].sum(axis=0) * dtw
    win.impulse_var = len(sel) * (noise.wrench * dtw) ** 2
    if not any(wrench_lag):
        # most of the normal force after these periods: a wrench published late
        after = rec.wrench[sel[-1] + 1 : sel[-1] + 1 + 2 * len(sel), 1].sum() * dtw
        win.wrench_after = bool(
            abs(after) > abs(win.impulse[1]) and abs(after) > 8 * noise.wrench[1] * dtw
        )
        return
    force = rec.wrench[sel, 1]
    total = float(force.sum())
    if total <= 0:
        return
    centroid = float(wt[sel] @ force) / total
    win.wrench_stamps, win.wrench_period = wt[sel].copy(), dtw
    win.wrench_timing = centroid - win.t_a
    win.wrench_timing_var = float(noise.wrench[1] ** 2 * np.sum((wt[sel] - centroid) ** 2)) / (
        total**2
    )


def _plate_at(rec: JointRecording, t: float) -> np.ndarray | None:
    """The plates' recorded state at the joint sample stamped ``t`` (a plate sample of the
    same period: the simulator publishes both with the period's stamp), None when there is
    none such."""
    if rec.plates is None or rec.plates_t is None or not len(rec.plates_t):
        return None
    k = int(np.argmin(np.abs(rec.plates_t - t)))
    if abs(rec.plates_t[k] - t) > 1e-3 * rec.period:
        return None
    return rec.plates[k].copy()


def joint_to_absolute_matrix(n: int) -> np.ndarray:
    """T with absolute = T @ relative (cumulative sum): the relative convention's inverse."""
    return np.tril(np.ones((n, n)))


def tip_normal_speed(model: ArmModel, q_abs: np.ndarray, qd_abs: np.ndarray) -> float:
    """ẏ of the tip (positive up) for the CoR of a horizontal surface."""
    return float(model.tip(q_abs, qd_abs)[3])


def summarize_jump(model: ArmModel, win: ImpactWindow) -> tuple[float, float]:
    """Recorded impact speed (normal, before) and kinematic CoR, from the fits at t_c."""
    T = joint_to_absolute_matrix(win.effort.shape[1])
    q, qd_pre, _ = win.pre.state(win.t_c)
    _, qd_post, _ = win.post.state(win.t_c)
    v_in = tip_normal_speed(model, T @ q, T @ qd_pre)
    v_out = tip_normal_speed(model, T @ q, T @ qd_post)
    return v_in, (-v_out / v_in if v_in else math.nan)


def contact_test(
    model: ArmModel, tolerance: float = 0.05
) -> Callable[[np.ndarray, np.ndarray, np.ndarray], bool]:
    """``is_contact`` for ``find_impacts``: the tip is within ``tolerance`` x the arm's reach
    of a surface's height, moving down before the step and less so after it."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    heights = [s.height for s in model.surfaces]
    reach = float(np.sum(model.L))

    def is_contact(q: np.ndarray, qd_before: np.ndarray, qd_after: np.ndarray) -> bool:
        y = float(model.tip(T @ q, np.zeros(n))[1])
        v0 = tip_normal_speed(model, T @ q, T @ qd_before)
        v1 = tip_normal_speed(model, T @ q, T @ qd_after)
        return any(abs(y - h) < tolerance * reach for h in heights) and v0 < 0 and v1 > v0

    return is_contact
