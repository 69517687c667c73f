"""Is a sampled control law stable at its rate, and did a run chatter? Plain numpy.

A digital controller samples the joint state every h = 1/rate seconds and holds its torque
until the next sample (zero-order hold), as ``simulate.run(control_rate=...)`` and the
controller node in lockstep do. Damping that a continuous law tolerates at any value is
bounded under sampling: a loop ``I q̈ = -kd q̇`` held over h multiplies q̇ by 1 - kd h / I
every period, so beyond kd = 2 I / h the torque alternates in sign each period and grows
(chatter). On an arm the links are coupled through the mass matrix and the joint torques
(Q = Tᵀ τ), so one link's loop limits another's: the three-link arm's outer link chatters at
1 kHz with half the damping its own inertia alone would allow.

``analyse`` linearises the arm about rest at the postures the scene visits (its start, both
targets, the strike posture and the straight paths between them), discretises it exactly
(zero-order hold, matrix exponential, the joints' viscous damping included) and closes the
sampled law's loop, integral state included; the law is stable at that rate when every
posture's closed-loop spectral radius is below 1. Per joint it reports the largest damping kd
that keeps it so with the other gains as they are. Gravity is left out of the linearisation:
the Q law cancels it exactly, and for PD/PID its stiffness (~ m g L) acts on the slow modes,
not on the period-rate mode sampling destabilises. Coulomb friction is left out too
(it saturates at the chattering rates). Velocities computed from differenced positions
(``sensors.rate``) add lag the analysis does not have: it is the exact-rate driver's.

``ChatterWatch`` finds chatter in a run's command series: a joint whose command steps
alternate in sign for many consecutive periods while growing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import math
import warnings
from collections import deque
from dataclasses import dataclass

import numpy as np

from .errors import SceneError, UnstableControlWarning

if TYPE_CHECKING:
    from .model import ArmModel
    from .scene.types import Scene

# a spectral radius above 1 + this is unstable (round-off of the eigenvalues of a marginal
# loop, e.g. the integrator pole of kp = 0, stays far below it)
RHO_TOLERANCE = 1e-9
PATH_POINTS = 9  # postures sampled on each straight path between the scene's postures
KD_SEARCH_STEPS = 60  # bisection steps of the largest stable kd (relative precision ~1e-9)


@dataclass(frozen=True)
class JointMargin:
    """One joint's damping against the largest its loop keeps stable at the rate.

    ``kd_max``: the largest kd of this joint, the other gains as they are, for which every
    posture is stable (N m s/rad); None when no kd of this joint alone makes it stable (the
    instability is another joint's); inf when any kd does (within the search's 1e9)."""

    index: int
    name: str
    kd: float
    kd_max: float | None

    @property
    def margin(self) -> float:
        """1 - kd / kd_max: the fraction of the largest stable damping left unused; negative
        when this joint's kd is beyond it, -inf when no kd of this joint is stable."""
        if self.kd_max is None:
            return -math.inf
        if math.isinf(self.kd_max) or self.kd_max == 0:
            return 1.0 if self.kd <= self.kd_max else -math.inf
        return 1.0 - self.kd / self.kd_max

    @property
    def offending(self) -> bool:
        """Is this joint's kd beyond the largest stable one?"""
        return self.kd_max is None or self.kd > self.kd_max

    def text(self) -> str:
        limit = (
            'none stable'
            if self.kd_max is None
            else ('any' if math.isinf(self.kd_max) else f'{self.kd_max:.4g}')
        )
        return f'{self.name}: kd {self.kd:g}, largest stable {limit} (margin {self.margin:+.0%})'


@dataclass(frozen=True)
class StabilityReport:
    """The sampled law's stability at ``rate`` Hz over the scene's postures."""

    rate: float  # Hz
    law: str
    spectral_radius: float  # the largest over the postures
    posture: tuple[float, ...]  # absolute link angles [rad] where it is largest
    joints: tuple[JointMargin, ...]  # empty when the law was stable and margins not asked
    kd_scale: float | None = None  # largest common factor on every kd that is stable

    @property
    def stable(self) -> bool:
        return self.spectral_radius <= 1.0 + RHO_TOLERANCE

    @property
    def margin(self) -> float:
        """1 - spectral radius: > 0 stable (how much each period shrinks the worst mode)."""
        return 1.0 - self.spectral_radius

    def offending(self) -> list[JointMargin]:
        """The joints whose kd is beyond their largest stable value, those a smaller kd of
        their own makes stable first (a joint no kd of its own stabilises suffers another's
        instability; it is named only when every joint is such)."""
        over = [j for j in self.joints if j.offending]
        return [j for j in over if j.kd_max is not None] or over

    def worst_joint(self) -> JointMargin | None:
        """The joint whose kd is furthest beyond its largest stable value (None if none
        is beyond it)."""
        over = self.offending()
        return min(over, key=lambda j: j.margin) if over else None

    def key(self) -> str:
        """The scene key the refusal names: the worst joint's ``controller.kd[i]``."""
        worst = self.worst_joint()
        return f'controller.kd[{worst.index}]' if worst is not None else 'controller.law'

    def refusal(self, rate_source: str = '') -> str:
        """The rest of the one-line refusal after ``key()``: '= 50 is unstable at 1000 Hz:
        joint3 ...', with each offending joint's margin and largest stable kd.
        ``rate_source``: where the rate came from when not the scene's (e.g. '--control-rate')."""
        rate = f'{self.rate:g} Hz' + (f' ({rate_source})' if rate_source else '')
        worst = self.worst_joint()
        over = self.offending()
        posture = ', '.join(f'{math.degrees(a):.0f}' for a in self.posture)
        head = (
            f'= {worst.kd:g} is unstable at {rate}'
            if worst is not None
            else f'= {self.law!r} is unstable at {rate}'
        )
        text = (
            f'{head}: spectral radius {self.spectral_radius:.4g} (margin {self.margin:+.3g}) '
            f'at q = ({posture}) deg: the commands would alternate in sign every period and grow'
        )
        if over:
            text += '; ' + '; '.join(j.text() for j in over)
            text += ' (largest stable kd at this rate: per joint, the other gains as they are'
            if self.kd_scale is not None and 0 < self.kd_scale < 1:
                text += f'; or every kd times {self.kd_scale:.3g}'
            text += ')'
        else:
            text += '; every kd is within its largest stable value: the loop needs more damping'
        return text


def _expm(a: np.ndarray) -> np.ndarray:
    """exp(a) by scaling and squaring a Taylor series (small matrices; no scipy.linalg in
    the nodes' processes)."""
    norm = float(np.max(np.sum(np.abs(a), axis=1))) if a.size else 0.0
    squarings = max(0, int(math.ceil(math.log2(norm))) + 1) if norm > 0.5 else 0
    scaled = a / 2.0**squarings
    result = np.eye(a.shape[0])
    term = np.eye(a.shape[0])
    for k in range(1, 20):
        term = term @ scaled / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def zoh_arm(mass: np.ndarray, damping: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) of x = (q, q̇) over one held period h of M q̈ = Tᵀ τ - Tᵀ D T q̇ (joint torques τ,
    absolute angles q, joint viscous damping D): x_(k+1) = Φ x_k + Γ τ_k, exactly."""
    n = mass.shape[0]
    T = np.eye(n) - np.eye(n, k=-1)  # joint rates ω = T q̇
    inverse = np.linalg.inv(mass)
    F = np.zeros((3 * n, 3 * n))  # [[0, I, 0], [0, -M⁻¹TᵀDT, M⁻¹Tᵀ], [0, 0, 0]]
    F[:n, n : 2 * n] = np.eye(n)
    F[n : 2 * n, n : 2 * n] = -inverse @ T.T @ np.diag(damping) @ T
    F[n : 2 * n, 2 * n :] = inverse @ T.T
    E = _expm(F * h)
    return E[: 2 * n, : 2 * n], E[: 2 * n, 2 * n :]


def closed_loop(
    phi: np.ndarray,
    gamma: np.ndarray,
    kp: np.ndarray,
    kd: np.ndarray,
    ki: np.ndarray,
    joint_space: bool,
    h: float,
) -> np.ndarray:
    """The sampled law's closed loop on (q, q̇[, w]) with w the integral before the sample's
    update, as ``CycleController`` computes it: w ← w + h e, τ = -Kp e - Kd ė - Ki w."""
    n = kp.shape[0]
    P = np.eye(n) - (np.eye(n, k=-1) if joint_space else 0.0)  # error coordinates e = P q
    gain = np.hstack([np.diag(kp + h * ki) @ P, np.diag(kd) @ P])
    if not ki.any():
        return phi - gamma @ gain
    A = np.zeros((3 * n, 3 * n))
    A[: 2 * n, : 2 * n] = phi - gamma @ gain
    A[: 2 * n, 2 * n :] = -gamma @ np.diag(ki)
    A[2 * n :, :n] = h * P
    A[2 * n :, 2 * n :] = np.eye(n)
    return A


def spectral_radius(a: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def visited_postures(model: ArmModel) -> list[tuple[float, ...]]:
    """The postures a scene's cycle passes: its start, both targets, the strike posture (where
    the straight path from the up target to the down target brings the tip to the lowest
    struck surface) and points on the straight paths start → down and up → down."""
    c = model.scene.controller
    start = np.asarray(model.scene.q0, float)
    down, up = np.asarray(c.down_target, float), np.asarray(c.up_target, float)
    postures = [start, down, up]
    for a in (start, up):
        postures += [a + s * (down - a) for s in np.linspace(0, 1, PATH_POINTS)[1:-1]]
    heights = [s.height for s in model.surfaces]
    if heights:
        floor = min(heights)

        def tip_y(s: float) -> float:
            return float(model.tip(up + s * (down - up), np.zeros(model.n))[1])

        if tip_y(0.0) > floor > tip_y(1.0):
            lo, hi = 0.0, 1.0
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if tip_y(mid) > floor else (lo, mid)
            postures.append(up + lo * (down - up))
    return [tuple(float(x) for x in p) for p in postures]


class _Loops:
    """The held arm (Φ, Γ) at each posture, for evaluating many gain sets."""

    def __init__(self, model: ArmModel, postures: Sequence[Sequence[float]], h: float):
        self.h = h
        self.postures = [tuple(p) for p in postures]
        self.held = [zoh_arm(model.mass_matrix(p), model.damping, h) for p in self.postures]

    def radii(self, kp: np.ndarray, kd: np.ndarray, ki: np.ndarray, joint: bool) -> list[float]:
        return [
            spectral_radius(closed_loop(phi, gamma, kp, kd, ki, joint, self.h))
            for phi, gamma in self.held
        ]

    def stable(self, kp: np.ndarray, kd: np.ndarray, ki: np.ndarray, joint: bool) -> bool:
        return all(r <= 1.0 + RHO_TOLERANCE for r in self.radii(kp, kd, ki, joint))


def _largest_stable(stable, start: float, ceiling: float = 1e9) -> float | None:
    """The largest x with stable(x), searched from ``start`` (stable or not) over a stable
    set that is an interval: up by doubling from a stable start, down by 0.8 steps from an
    unstable one, then bisection. None when nothing down to start·1e-6 is stable."""
    if stable(start):
        lo = start if start > 0 else 1e-6
        if not stable(lo):
            return start
        hi = lo * 2
        while stable(hi):
            lo, hi = hi, hi * 2
            if hi > ceiling:
                return math.inf
    else:
        hi, lo = start, start * 0.8
        while not stable(lo):
            hi, lo = lo, lo * 0.8
            if lo < start * 1e-6:
                return None
    for _ in range(KD_SEARCH_STEPS):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        if hi - lo <= 1e-9 * hi:
            break
    return lo


def analyse(
    scene: Scene,
    rate: float | None = None,
    law: str | None = None,
    *,
    margins: bool = True,
    model: ArmModel | None = None,
) -> StabilityReport | None:
    """The stability of ``scene``'s sampled law at ``rate`` Hz (default: the scene's
    ``controller.rate``) and ``law`` (default: the scene's); None when there is nothing
    sampled to check (rate 0: continuous control; law ``none``).

    ``margins``: also each joint's largest stable kd (a few thousand small eigenvalue
    problems); without it they are computed only when the law is unstable, for the message."""
    c = scene.controller
    rate = c.rate if rate is None else rate
    law = law or c.law
    if not rate or law == 'none':
        return None
    if model is None:
        from .model import ArmModel

        model = ArmModel(scene)
    h = 1.0 / rate
    loops = _Loops(model, visited_postures(model), h)
    kp, kd = np.asarray(c.kp, float), np.asarray(c.kd, float)
    ki = np.asarray(c.ki, float) if law == 'pid' else np.zeros(model.n)
    joint = law != 'q' and c.space == 'joint'
    radii = loops.radii(kp, kd, ki, joint)
    worst = int(np.argmax(radii))
    joints: tuple[JointMargin, ...] = ()
    scale = None
    if margins or radii[worst] > 1.0 + RHO_TOLERANCE:
        names = scene.joint_names
        found = []
        for i in range(model.n):

            def with_kd(x: float, i: int = i) -> bool:
                trial = kd.copy()
                trial[i] = x
                return loops.stable(kp, trial, ki, joint)

            found.append(JointMargin(i, names[i], float(kd[i]), _largest_stable(with_kd, kd[i])))
        joints = tuple(found)
        if kd.any():
            scale = _largest_stable(lambda s: loops.stable(kp, kd * s, ki, joint), 1.0)
    return StabilityReport(rate, law, radii[worst], loops.postures[worst], joints, scale)


def check_stability(
    scene: Scene,
    rate: float | None = None,
    law: str | None = None,
    *,
    rate_source: str = '',
    origin: str = '',
    model: ArmModel | None = None,
) -> StabilityReport | None:
    """Refuse ``scene``'s law if it is unstable at ``rate`` (default: the scene's own), with a
    ``SceneError`` naming the joint, its margin and the largest stable kd; with
    ``controller.allow_unstable`` the same sentence is an ``UnstableControlWarning`` and the
    run goes on. The report, or None when nothing is sampled. ``origin``: the scene's name in
    the message (default: its file, else its name)."""
    report = analyse(scene, rate, law, margins=False, model=model)
    if report is None or report.stable:
        return report
    origin = origin or scene.source_path or scene.name
    text = f"scene '{origin}': {report.key()} {report.refusal(rate_source)}"
    if scene.controller.allow_unstable:
        warnings.warn(
            f'{text}; run anyway (controller.allow_unstable: true)',
            UnstableControlWarning,
            stacklevel=2,
        )
        return report
    raise SceneError(f'{text}; lower it, or set controller.allow_unstable: true to run it anyway')


# --- chatter in a run's commands ---

CHATTER_PERIODS = 24  # consecutive alternating command steps that make chatter
CHATTER_GROWTH = 4.0  # the alternation's amplitude over those periods grows at least this much
CHATTER_FIT = 0.9  # ... steadily: correlation of its logarithm with time at least this
CHATTER_WINDOW = 64  # the latest alternation amplitudes kept per joint


@dataclass(frozen=True)
class Chatter:
    """A joint whose commands alternated in sign and grew over consecutive periods."""

    joint: int
    name: str
    t_start: float  # s, the first command of the alternation
    periods: int  # consecutive alternating steps seen
    growth: float  # the alternation's amplitude over the periods it was found in (a fit)
    peak: float  # the largest |command| during it [N m]

    def text(self) -> str:
        return (
            f'{self.name} chatters from t = {self.t_start:.4g} s: its command alternates in '
            f'sign every period for {self.periods} periods and grows x{self.growth:.3g} '
            f'(to {self.peak:.4g} N m)'
        )

    def to_json(self) -> dict:
        return {
            'joint': self.name,
            't_start': self.t_start,
            'periods': self.periods,
            'growth': self.growth,
            'peak': self.peak,
        }


class _JointWatch:
    """One joint's run of alternating command steps (bounded memory). The alternation's
    amplitude is read from the difference of consecutive steps, |d_k - d_(k-1)| (twice the
    amplitude): a slow drift of the command adds the same to both steps and cancels. Growth is
    the straight-line fit of its logarithm over the run's latest periods: chatter grows
    geometrically (a fit close to a line); noise, whose steps also alternate (two times in
    three for white noise), does not."""

    def __init__(self) -> None:
        self.last: float | None = None
        self.step = 0.0  # the last nonzero step
        self.run = 0  # alternating steps in a row
        self.t_start = 0.0
        self.swings: deque[float] = deque(maxlen=CHATTER_WINDOW)
        self.peak = 0.0
        self.found: Chatter | None = None

    def add(self, t: float, u: float, joint: int, name: str, t_prev: float) -> None:
        if self.last is None or u == self.last:  # a held command repeated: no new period
            self.last = u
            return
        step = u - self.last
        if self.run and step * self.step < 0:
            self.run += 1
            self.swings.append(abs(step - self.step))
        else:
            self.run, self.t_start, self.peak = 1, t_prev, 0.0
            self.swings.clear()
        self.step, self.last = step, u
        self.peak = max(self.peak, abs(u))
        if self.found is not None and self.found.t_start == self.t_start:
            # the run that was found goes on: followed to its end
            self.found = Chatter(joint, name, self.t_start, self.run, self.found.growth, self.peak)
        elif self.found is None and self.run >= CHATTER_PERIODS:
            growth = _steady_growth(self.swings)
            if growth >= CHATTER_GROWTH:
                self.found = Chatter(joint, name, self.t_start, self.run, growth, self.peak)


def _steady_growth(swings: Sequence[float]) -> float:
    """The growth over ``swings`` of a line fitted to their logarithm, 0 unless the fit is
    close (correlation >= CHATTER_FIT)."""
    values = np.log(np.maximum(np.asarray(swings, float), 1e-300))
    k = np.arange(values.size, dtype=float)
    if values.std() == 0:
        return 1.0
    r = float(np.corrcoef(k, values)[0, 1])
    if r < CHATTER_FIT:
        return 0.0
    slope = float(np.polyfit(k, values, 1)[0])
    return math.exp(slope * (values.size - 1))


class ChatterWatch:
    """Feed it each command (time, one torque per joint) in order; ``found`` lists the joints
    that chattered: their commands alternated in sign step to step for at least
    ``CHATTER_PERIODS`` periods while the alternation grew steadily, ``CHATTER_GROWTH`` times
    at least. The first such run of each joint is kept. A held command repeated at a faster
    sample rate is one period. Smooth motion, an oscillation of several periods per swing, a
    decaying alternation and noise (its steps alternate too, but do not grow steadily) are
    not chatter."""

    def __init__(self, names: Sequence[str]):
        self.names = tuple(names)
        self._joints = [_JointWatch() for _ in self.names]
        self._t_prev = 0.0

    def add(self, t: float, command: Sequence[float]) -> None:
        for k, (watch, u) in enumerate(zip(self._joints, command)):
            watch.add(t, float(u), k, self.names[k], self._t_prev)
        self._t_prev = t

    @property
    def found(self) -> list[Chatter]:
        return [w.found for w in self._joints if w.found is not None]

    def summary(self) -> str:
        """'' when nothing chattered, else one sentence per joint."""
        return '; '.join(c.text() for c in self.found)


def find_chatter(
    times: Sequence[float] | np.ndarray,
    commands: Sequence[Sequence[float]] | np.ndarray,
    names: Sequence[str],
) -> list[Chatter]:
    """``ChatterWatch`` over a whole series: one row of joint torques per time."""
    watch = ChatterWatch(names)
    for t, row in zip(times, commands):
        watch.add(t, row)
    return watch.found
