"""Scene parameters from a recording: each impact replayed on the model, least squares.

Method (docs/fit.md): ``identify`` finds the impacts and fits the free flight on both sides of
each. For a parameter vector, every impact is simulated on the event path from the recorded
state just before the contact (the pre-impact fit, extrapolated; the recorded effort held)
through its last separation; the prediction is the joint rates at separation and the contact
impulse, compared with the post-impact fit at the same instant and the recorded wrench
impulse. Residuals are whitened by their covariance (post-fit, pre-fit propagated through the
impact map, wrench noise), so the sum of squares is a chi-square when the model is right. A
coarse global stage picks starting points for a bounded trust-region search in log space
(positive parameters); the Jacobian at the optimum gives the covariance, the 95 % intervals,
correlations and the verdict.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..physics.errors import ImpactArmError, SceneError, SimulationError
from .identify import (
    IdentifyError,
    ImpactWindow,
    JointRecording,
    Noise,
    estimate_noise,
    find_impacts,
    impact_windows,
    joint_to_absolute_matrix,
    tip_normal_speed,
)
from ..physics.integrator import PRESETS, PhaseIntegrator, options_from_spec
from ..physics.model import ArmModel
from ..physics.scene import Scene
from .study import Study, apply_overrides, parse_key_path

# The whitened residual of an impact the model cannot replay at some values (no contact, a
# contact outside the law's validity): well above any misfit near the start, so that the
# search never prefers losing impacts to fitting them (30x that for values the scene refuses)
PENALTY = 30.0
FIT_RTOL = 1e-8  # loosest tolerance a replay may use (finite-difference Jacobians)


def window_options(model: ArmModel) -> dict:
    """Integrator options of the replays: the scene's own (the fitted scene will run with
    them, and a second contact on the edge of happening is found or missed as the scene's
    runs find or miss it), tightened to 'balanced' when looser than FIT_RTOL."""
    opts = getattr(model, '_fit_options', None)
    if opts is None:
        spec = model.scene.integrator
        opts = options_from_spec(spec)
        rtol = opts['rtol'] if opts['rtol'] is not None else PRESETS[opts['preset']][0]
        if max(rtol, opts['contact_rtol'] or rtol) > FIT_RTOL:
            opts = options_from_spec(spec, preset='balanced')
        model._fit_options = opts  # type: ignore[attr-defined]  # cached per model instance
    return opts


class FitError(ImpactArmError):
    """Bad fit input (parameter keys, bounds, options): one line naming what is wrong."""


@dataclass
class Parameter:
    key: str
    lo: float
    hi: float
    start: float
    log: bool  # fitted in log space (positive bounds)

    def to_unit(self, value: float) -> float:
        if self.log:
            return (math.log(value) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (value - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        if self.log:
            return math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + u * (self.hi - self.lo)

    def to_native(self, value: float) -> float:
        """The coordinate the covariance is stated in: log(value) or value."""
        return math.log(value) if self.log else value


# link keys with a default that follows from the others (docs/scene.md): a fit may start
# from it without the scene stating it
_LINK_DEFAULTS: dict[str, Callable[[Scene, int], float]] = {
    'com_x': lambda scene, k: scene.link_com[k][0],
    'com_y': lambda scene, k: scene.link_com[k][1],
    'inertia': lambda scene, k: scene.link_inertias[k],
}


_LINK_DEFAULTS['mass'] = lambda scene, k: scene.masses[k]  # a URDF arm's: the file's


def _link_default_key(parts: Sequence, depth: int) -> bool:
    """``links[i].KEY`` left to a rod's default, or ``arm.links[i].KEY`` to the URDF's."""
    head = ('links',) if parts[0] == 'links' else ('arm', 'links')
    return (
        tuple(parts[: len(head)]) == head
        and len(parts) == len(head) + 2
        and depth == len(parts) - 1
        and isinstance(parts[-2], int)
        and parts[-1] in _LINK_DEFAULTS
        and (head == ('arm', 'links') or parts[-1] != 'mass')
    )


def _link_default(study: Study, parts: Sequence) -> float:
    try:
        scene = study.scene()
    except SceneError as exc:
        raise FitError(f'--param {parts[0]}: {exc}') from None
    return _LINK_DEFAULTS[parts[-1]](scene, parts[-2])


def _state_arm_links(study: Study, parts: Sequence) -> None:
    """A fit of ``arm.links[i].KEY`` of a scene that states no ``arm.links``: the study's
    data gets one empty entry per link (the URDF's values stand), for the fit to set."""
    arm = study.data.get('arm') if isinstance(study.data, dict) else None
    if tuple(parts[:2]) != ('arm', 'links') or not isinstance(arm, dict) or 'links' in arm:
        return
    try:
        n = study.scene().n_links
    except SceneError as exc:
        raise FitError(f'--param arm.links: {exc}') from None
    study.data = apply_overrides(study.data, {'arm.links': [{} for _ in range(n)]})


def parameter_specs(study: Study, bounds: dict) -> list:
    """Check each key against the scene (it must exist and hold a number) and its bounds
    (finite, lo < hi, containing the scene's value, which is the starting point)."""
    if not bounds:
        raise FitError('no parameter to fit: give at least one --param KEY=LO:HI')
    specs: list[Parameter] = []
    for key, (lo, hi) in bounds.items():
        try:
            parts = parse_key_path(key)
        except SceneError as exc:
            raise FitError(f'--param {key}: {exc}') from None
        _state_arm_links(study, parts)
        node = study.data
        for depth, part in enumerate(parts):
            ok = (
                (isinstance(node, dict) and part in node)
                if isinstance(part, str)
                else (isinstance(node, list) and part < len(node))
            )
            if not ok and isinstance(node, dict) and _link_default_key(parts, depth):
                # a link key the scene leaves to its default (a rod's): fitted from there
                node = {part: _link_default(study, parts)}
                ok = True
            if not ok:
                where = (
                    ''.join(
                        f'[{p}]' if isinstance(p, int) else f'.{p}' for p in parts[:depth]
                    ).lstrip('.')
                    or 'the scene'
                )
                raise FitError(
                    f'--param {key}: the scene {study.origin} has no {part!r} in '
                    f'{where} (fit keys the scene states, e.g. surfaces[0].mu, '
                    f'materials.steel.S_y)'
                )
            node = node[part]
        if isinstance(node, bool) or not isinstance(node, (int, float)):
            raise FitError(f"--param {key}: the scene's value {node!r} is not a number")
        lo, hi, start = float(lo), float(hi), float(node)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise FitError(f'--param {key}={lo:g}:{hi:g}: bounds must be finite with LO < HI')
        if not lo <= start <= hi:
            raise FitError(
                f"--param {key}={lo:g}:{hi:g}: the bounds exclude the scene's value "
                f'{start:g}, the starting point; widen them or edit the scene'
            )
        specs.append(Parameter(key, lo, hi, start, log=lo > 0))
    return specs


@dataclass
class Prediction:
    qd: np.ndarray  # joint rates at the compared post-impact samples (m, n) [rad/s]
    impulse: np.ndarray  # contact impulse (tangential, normal) [N s]
    v_in: float  # tip normal speed at first contact [m/s]
    v_out: float  # ... at last separation
    contacts: int
    qd_sep: np.ndarray | None = None  # joint rates at the last separation
    error: str = ''
    if TYPE_CHECKING:  # set after construction by predict_impact (not dataclass fields)
        path: np.ndarray = field(init=False)
        t_sep: float = field(init=False)
        y_sep: np.ndarray = field(init=False)


EFFORT_TIMINGS = ('linear', 'previous', 'next')
SUBSTEPS = 8  # torque pieces per sample period (linear timing)


class TorqueSchedule:
    """The joint torque between samples from the recorded efforts, by how a driver reports
    them: 'linear' (the effort at a stamp is the torque at that instant; continuous between),
    'previous' (it is the command held over the period that ends at the stamp, as our
    simulator reports it), 'next' (held from the stamp to the next one). Before the contact
    only efforts recorded before it are used, after it only those after it (a controller that
    reacts to the impact changes its torque there)."""

    def __init__(self, win: ImpactWindow, timing: str):
        self.t, self.tau, self.timing = win.effort_t, win.effort.copy(), timing
        self.ib = ib = getattr(win, 'effort_ib', 2)
        # A sample taken during the contact with the actuators off shows no torque, not the
        # command: read as 'previous', that command acted before the contact began (the one
        # after it is reported at b), so the command of the last free sample stands in.
        off = getattr(win, 'effort_off', [])
        for k in range(2, ib):
            if off[k]:
                self.tau[k] = self.tau[1] if timing == 'previous' else self.tau[ib]

    def __call__(self, t0: float, t1: float, side: str) -> np.ndarray:
        t, tau, mid, last = self.t, self.tau, 0.5 * (t0 + t1), len(self.t) - 1
        if self.timing == 'previous':
            return tau[min(max(int(np.searchsorted(t, mid, side='left')), 2), last)]
        if self.timing == 'next':
            return tau[min(max(int(np.searchsorted(t, mid, side='right')) - 1, 1), last)]
        if side == 'pre':
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
        if self.timing == 'linear':
            edges = np.concatenate([[t_from], grid, [t_to]])
            grid = np.concatenate(
                [np.linspace(lo, hi, SUBSTEPS + 1)[1:-1] for lo, hi in itertools.pairwise(edges)]
                + [grid]
            )
        return sorted({float(x) for x in grid} | {float(t_to)})


def predict_impact(
    model: ArmModel,
    win: ImpactWindow,
    timing: str = 'linear',
    pre_state: tuple[np.ndarray, np.ndarray] | None = None,
    dense: Sequence[float] | None = None,
) -> Prediction:
    """Simulate one impact from the recorded state at the last sample before it (the
    pre-impact fit, or ``pre_state`` = (q, q̇) in joint space) under the recorded efforts,
    through every contact, to the compared samples after it. ``dense`` (a list of extra
    times) makes ``Prediction.path`` rows (t, q̇ joint space..., cumulative impulse t, n)
    at every boundary, for plots."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    heights = [s.height for s in model.surfaces]
    t0 = win.t_a
    q, qd, _ = win.pre.state(t0)
    if pre_state is not None:
        q, qd = pre_state
    if heights and tip_y(model, T @ q) <= max(heights):
        return _failed(n, "the scene's surface is above the arm's tip before the recorded contact")
    state = model.initial_state()
    state.t = t0
    state.y[:n], state.y[n : 2 * n] = T @ q, T @ qd
    held = timing != 'controller'
    state.mode = 'down'  # the scene's controller, if used, is approaching the surface
    integ = PhaseIntegrator(
        model, state, control='held' if held else 'continuous', **window_options(model)
    )
    torque = TorqueSchedule(win, timing)
    first: Any = None  # the first and last contact events, once found
    last: Any = None
    contacts, side, rates, path, impulse = 0, 'pre', [], [], np.zeros(2)
    targets = list(win.post_t)
    edges = torque.boundaries(t0, targets[-1])
    if dense is not None:
        edges = sorted(set(edges) | {float(x) for x in dense if t0 < x < targets[-1]})
    try:
        for edge in edges:
            while integ.state.t < edge:
                if held:  # (ignored by the kernel while actuators are off in contact)
                    integ.set_held_torque(
                        torque(integ.state.t, edge, 'pre' if side == 'pre' else 'post')
                    )
                for event in integ.advance(edge, stop_at_event=('contact', 'separation')):
                    if event.kind == 'contact':
                        contacts += 1
                        first = first or event
                        side = 'contact'
                    elif event.kind == 'separation':
                        last, side = event, 'post'
            if dense is not None:
                impulse += integ.take_impulse()
                path.append(
                    [integ.state.t, *np.linalg.solve(T, integ.state.y[n : 2 * n]), *impulse]
                )
            if targets and abs(edge - targets[0]) < 1e-12:
                if side == 'contact':
                    # a contact ending just after the sample in the model, just before it in
                    # the recording (the start state is uncertain by microseconds): let it
                    # end within a tenth of a period and compare there
                    for event in integ.advance(
                        edge + 0.1 * (win.t_b - win.t_a), stop_at_event=('separation',)
                    ):
                        if event.kind == 'separation':
                            last, side = event, 'post'
                if side == 'pre' or last is None:
                    return _failed(
                        n,
                        'no contact predicted across the recorded impact'
                        if side == 'pre'
                        else 'the contact outlasts the first sample after it',
                    )
                # else in a further contact begun since: the rates there are continuous in
                # the parameters (it has only just begun when it appears), compare them
                rates.append(np.linalg.solve(T, integ.state.y[n : 2 * n]))
                targets.pop(0)
    except SimulationError as exc:
        return _failed(n, str(exc))
    impulse += integ.take_impulse()
    pred = Prediction(
        np.array(rates),
        impulse,
        tip_normal_speed(model, first.y[:n], first.y[n : 2 * n]),
        tip_normal_speed(model, last.y[:n], last.y[n : 2 * n]),
        contacts,
        np.linalg.solve(T, last.y[n : 2 * n]),
    )
    pred.path = np.array(path)
    pred.t_sep, pred.y_sep = last.t, last.y[: 2 * n].copy()
    return pred


def free_flight(
    model: ArmModel, win: ImpactWindow, timing: str, t0: float, y0: np.ndarray, t1: float
) -> np.ndarray | None:
    """Joint rates at ``t1`` after free flight from absolute state ``y0`` at ``t0`` under
    the torque ``timing`` uses after the impact (None if a contact intervenes)."""
    n = model.n
    state = model.initial_state()
    state.t, state.y[: 2 * n] = t0, y0
    held = timing != 'controller'
    state.mode = 'up'
    integ = PhaseIntegrator(
        model, state, control='held' if held else 'continuous', **window_options(model)
    )
    torque = TorqueSchedule(win, timing)
    try:
        for edge in torque.boundaries(t0, t1):
            if held:
                integ.set_held_torque(torque(integ.state.t, edge, 'post'))
            integ.advance(edge)
    except SimulationError:
        return None
    if integ.state.phase != 0:
        return None
    return np.linalg.solve(joint_to_absolute_matrix(n), integ.state.y[n : 2 * n])


def recorded_separation_rates(
    model: ArmModel, win: ImpactWindow, pred: Prediction, timing: str
) -> np.ndarray | None:
    """The joint rates at the predicted separation that carry the model's free flight onto
    the recorded first sample after the impact (Newton step through the flight's
    sensitivity): the recorded side of the post-impact state, for its CoR."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    t1 = win.post_t[0]
    base = free_flight(model, win, timing, pred.t_sep, pred.y_sep, t1)
    if base is None:
        return None
    A = np.zeros((n, n))
    for k in range(n):
        y = pred.y_sep.copy()
        y[n : 2 * n] += T[:, k] * 1e-4  # one joint rate up by 1e-4 rad/s
        moved = free_flight(model, win, timing, pred.t_sep, y, t1)
        if moved is None:
            return None
        A[:, k] = (moved - base) / 1e-4
    qd_sep = np.linalg.solve(T, pred.y_sep[n : 2 * n])
    return qd_sep + np.linalg.solve(A, win.post_qd[0] - base)


def recorded_cor(
    model: ArmModel, win: ImpactWindow, pred: Prediction, timing: str, v_in: float
) -> float:
    n = model.n
    qd = recorded_separation_rates(model, win, pred, timing)
    if qd is None or not v_in:
        return math.nan
    T = joint_to_absolute_matrix(n)
    return -tip_normal_speed(model, pred.y_sep[:n], T @ qd) / v_in


def tip_y(model: ArmModel, q_abs: np.ndarray) -> float:
    return float(model.tip(q_abs, np.zeros_like(q_abs))[1])


def _failed(n, why) -> Prediction:
    return Prediction(np.full((1, n), np.nan), np.full(2, np.nan), math.nan, math.nan, 0, None, why)


def free_flight_error(model: ArmModel, win: ImpactWindow, timing: str) -> float:
    """Squared error of one-period predictions between the compared post-impact samples,
    from the recorded state, under ``timing``: how well that reading of the efforts explains
    the free motion where the torque changes fastest."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    torque = TorqueSchedule(win, timing)
    q_post = [win.post.state(t)[0] for t in win.post_t]
    err = 0.0
    for k in range(len(win.post_t) - 1):
        state = model.initial_state()
        state.t = win.post_t[k]
        state.y[:n], state.y[n : 2 * n] = T @ q_post[k], T @ win.post_qd[k]
        held = timing != 'controller'
        state.mode = 'up'  # after an impact the scene's controller lifts the arm
        integ = PhaseIntegrator(
            model, state, control='held' if held else 'continuous', preset='balanced'
        )
        try:
            for edge in torque.boundaries(win.post_t[k], win.post_t[k + 1]):
                if held:
                    integ.set_held_torque(torque(integ.state.t, edge, 'post'))
                integ.advance(edge)
        except SimulationError:
            return math.inf
        if integ.state.phase != 0:
            return math.inf
        err += float(
            np.sum((np.linalg.solve(T, integ.state.y[n : 2 * n]) - win.post_qd[k + 1]) ** 2)
        )
    return err


def effort_timing(model: ArmModel, windows: Sequence[ImpactWindow]) -> tuple[str, dict[str, float]]:
    """The reading of the efforts that best predicts the free motion after the impacts, and
    the error of each: the three readings of the recorded efforts, and the scene's own
    controller when it is a continuous state feedback (a stiff controller changes its torque
    within a sample period faster than any interpolation of the samples follows)."""
    timings = list(EFFORT_TIMINGS)
    ctrl = model.scene.controller
    if ctrl.rate == 0 and ctrl.law in ('q', 'pd') and model.n_integral == 0:
        timings.append('controller')
    errors = {t: sum(free_flight_error(model, w, t) for w in windows) for t in timings}
    return min(errors, key=errors.get), errors  # type: ignore[arg-type]  # every key is present


@dataclass
class FitOptions:
    window: int = 15  # samples per side for the free-flight fits
    use_wrench: bool = True  # when the recording has one
    starts: int = 3  # local searches from the best points of the global stage
    global_points: int = 0  # 0: 6 + 4 per parameter
    z_min: float = 30.0  # impact detection threshold (robust z of the rate step)
    max_nfev: int = 25  # per local search and parameter
    post_samples: int = 3  # samples after each impact compared with the model


class ImpactSet:
    """The recorded impacts and how a scene variant predicts them, as whitened residuals."""

    best: np.ndarray  # the fitted values, set by fit

    def __init__(self, study: Study, specs: list, windows: list, use_wrench: bool):
        self.study, self.specs, self.windows = study, specs, windows
        self.use_wrench = use_wrench and any(w.impulse is not None for w in windows)
        self.evaluations = 0
        self.timing = 'linear'
        self.penalty = PENALTY

    def model(self, values: Sequence[float] | np.ndarray) -> ArmModel:
        overrides = {p.key: float(v) for p, v in zip(self.specs, values)}
        try:
            return ArmModel(self.study.scene(overrides))
        except SceneError as exc:
            raise FitError(f'the scene refuses {overrides}: {exc}') from None

    def wrench_at(self, win: ImpactWindow) -> bool:
        """Whether the wrench impulse of this impact is compared (recorded in full there)."""
        return self.use_wrench and win.impulse is not None

    def outputs(self, pred: Prediction, win: ImpactWindow) -> np.ndarray:
        qd = pred.qd.ravel()
        return np.concatenate([qd, pred.impulse]) if self.wrench_at(win) else qd

    def recorded(self, win: ImpactWindow) -> np.ndarray:
        qd = win.post_qd.ravel()
        return np.concatenate([qd, win.impulse]) if self.wrench_at(win) else qd

    def predict(self, values: Sequence[float] | np.ndarray) -> list[Prediction]:
        self.evaluations += 1
        try:
            model = self.model(values)
        except FitError as exc:  # a combination the scene's schema refuses: a penalty
            n = self.windows[0].post_qd.shape[1] if self.windows else 1
            return [_failed(n, str(exc)) for _ in self.windows]
        return [predict_impact(model, w, self.timing) for w in self.windows]

    def select(self, values: Sequence[float] | np.ndarray, sigma_qd: np.ndarray) -> list[str]:
        """At the starting ``values``: choose the reading of the efforts, move samples taken
        in a contact out of each impact's comparison, keep the impacts the scene replays and
        give them robust diagonal weights (``calibrate`` refines them at the optimum)."""
        model = self.model(values)
        self.timing, self.timing_errors = effort_timing(model, self.windows)
        kept, self.whiten, notes = [], [], []
        for w in self.windows:
            w, base = self._widen(model, w, predict_impact(model, w, self.timing))
            if base.error:
                notes.append(
                    f'impact at t = {w.t_c:.4f} s left out: {base.error} with the starting scene'
                )
                continue
            ib = getattr(w, 'effort_ib', 2)
            if self.timing == 'next' and any(w.effort_off[k] for k in range(2, ib)):
                notes.append(
                    f'impact at t = {w.t_c:.4f} s left out: a sample taken during '
                    f'the contact shows no torque, so the command held after the '
                    f'contact is not recorded'
                )
                continue
            # robust weights for the global stage (no linearisation, which a bounce that
            # comes and goes with the parameters would spoil): each recorded rate's noise
            # plus the pre-impact rates' uncertainty, the impulse's noise
            cov_pre = w.pre.state(w.t_a)[2]
            var = np.tile(sigma_qd**2 + np.diag(cov_pre)[model.n :], len(w.post_t))
            if self.wrench_at(w):
                var = np.concatenate([var, w.impulse_var])
            kept.append(w)
            self.whiten.append(np.diag(1.0 / np.sqrt(var)))
            w.sigma = np.sqrt(var)
        self.windows = kept
        return notes

    def _widen(self, model, w, base):
        """A contact under way at the last sample before the impact, or still at the first
        after it (a long contact can span several samples): that sample leaves the free
        flight, as long as the model says so."""
        for _ in range(6):
            side = (
                'pre'
                if 'above the arm' in base.error
                else 'post'
                if 'outlasts' in base.error
                else ''
            )
            wider = w.widened(side) if side and getattr(w, 'widened', None) else None
            if wider is None:
                break
            wider.index = w.index
            w, base = wider, predict_impact(model, wider, self.timing)
        return w, base

    def calibrate(self, values: Sequence[float] | np.ndarray, sigma_qd: np.ndarray) -> None:
        """The full whitening of each impact's residual at ``values`` (the optimum so far):
        the recorded rates' noise (``sigma_qd`` per joint), the wrench noise, and the
        pre-impact fit's covariance carried through the impact (sensitivities by finite
        differences). An impact the model cannot replay at ``values`` keeps its weights."""
        try:
            model = self.model(values)
        except FitError:
            return
        n = model.n
        for i, w in enumerate(self.windows):
            base = predict_impact(model, w, self.timing)
            w, base = self._widen(model, w, base)
            if base.error:
                continue
            self.windows[i] = w
            q, qd, cov_pre = w.pre.state(w.t_a)
            x0 = np.concatenate([q, qd])
            y0 = self.outputs(base, w)
            m = len(w.post_t)
            S = np.zeros((len(y0), 2 * n))
            steps = np.sqrt(np.diag(cov_pre)) + 1e-9
            for k in range(2 * n):
                x = x0.copy()
                x[k] += steps[k]
                p = predict_impact(model, w, self.timing, (x[:n], x[n:]))
                if not p.error:
                    S[:, k] = (self.outputs(p, w) - y0) / steps[k]
            C = S @ cov_pre @ S.T
            C[: m * n, : m * n] += np.diag(np.tile(sigma_qd**2, m))
            if self.wrench_at(w):
                C[m * n :, m * n :] += np.diag(w.impulse_var)
            # noise-free data (a simulation) leave C singular: a relative floor keeps it usable
            C += np.eye(len(C)) * max(1e-12 * np.trace(C) / len(C), 1e-30)
            self.whiten[i] = np.linalg.inv(np.linalg.cholesky(C))
            w.sigma = np.sqrt(np.diag(C))

    def residuals(
        self, values: Sequence[float] | np.ndarray, predictions: list[Prediction] | None = None
    ) -> np.ndarray:
        preds = predictions if predictions is not None else self.predict(values)
        out = []
        for w, L, p in zip(self.windows, self.whiten, preds):
            if p.error:
                refused = p.error.startswith('the scene refuses')
                out.append(np.full(L.shape[0], self.penalty * (30 if refused else 1)))
            else:
                out.append(L @ (self.outputs(p, w) - self.recorded(w)))
        return np.concatenate(out) if out else np.zeros(0)


@dataclass
class FitResult:
    parameters: dict  # key -> {value, ci95, identifiable, start, bounds, sigma}
    verdict: str
    residual_rms: float  # rms of the raw residuals of the joint rates [rad/s]
    noise_rms: float  # rms of their expected standard deviation [rad/s]
    chi2: float
    dof: int
    impacts_used: int
    per_impact: list
    noise: dict
    correlations: dict
    cannot_tell_apart: list
    notes: list
    evaluations: int
    wall_time: float
    used_wrench: bool
    scene_overrides: dict = field(default_factory=dict)
    windows: list = field(default_factory=list, repr=False)
    predictions: list = field(default_factory=list, repr=False)
    start_predictions: list = field(default_factory=list, repr=False)
    recording: JointRecording | None = field(default=None, repr=False)
    scene_path: str = ''
    timing: str = ''  # how the efforts were read between samples
    problem: object = field(default=None, repr=False)

    @property
    def fits(self) -> bool:
        return self.verdict == 'fits'

    def to_json(self) -> dict:
        return {
            'parameters': {
                k: {'value': v['value'], 'ci95': v['ci95'], 'identifiable': v['identifiable']}
                for k, v in self.parameters.items()
            },
            'verdict': self.verdict,
            'residual_rms': self.residual_rms,
            'noise_rms': self.noise_rms,
            'impacts_used': self.impacts_used,
            'scene': self.scene_path,
            # beyond the schema: what a reader needs to judge the fit
            'chi2': self.chi2,
            'dof': self.dof,
            'used_wrench': self.used_wrench,
            'effort_timing': self.timing,
            'cannot_tell_apart': self.cannot_tell_apart,
            'correlations': self.correlations,
            'noise': self.noise,
            'per_impact': self.per_impact,
            'notes': self.notes,
            'details': {
                k: {kk: v[kk] for kk in ('start', 'bounds', 'sigma_native', 'at_bound')}
                for k, v in self.parameters.items()
            },
        }


def _halton(count, dims, offset=1):
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37][:dims]
    out = np.zeros((count, dims))
    for j, base in enumerate(primes):
        for i in range(count):
            k, f, x = i + offset, 1.0, 0.0
            while k:
                f /= base
                x += f * (k % base)
                k //= base
            out[i, j] = x
    return out


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
        y = tip_y(model, T @ q)
        v0 = tip_normal_speed(model, T @ q, T @ qd_before)
        v1 = tip_normal_speed(model, T @ q, T @ qd_after)
        return any(abs(y - h) < tolerance * reach for h in heights) and v0 < 0 and v1 > v0

    return is_contact


def prepare(
    recording: JointRecording, options: FitOptions, model: ArmModel | None = None
) -> tuple[list, Noise, list[ImpactWindow], list[str]]:
    """Impacts, noise and impact windows of a recording (refused if it has no impact);
    ``model`` (the scene's kinematics) tells contacts from other steps of the rates."""
    impacts = find_impacts(
        recording, options.z_min, contact_test(model) if model is not None else None
    )
    if not impacts:
        steps = len(find_impacts(recording, options.z_min)) if model is not None else 0
        why = (
            f'{steps} step(s) of the joint rates, none with the tip near a surface of the '
            f"scene (check --joints order, the scene's links and surface heights)"
            if steps
            else 'no step in the joint rates stands out of the noise'
        )
        raise IdentifyError(f'no impact in the recording {recording.source}: {why}')
    noise = estimate_noise(recording, impacts, options.window)
    windows, notes = impact_windows(
        recording, noise, impacts, options.window, post_samples=options.post_samples
    )
    normal = [w.impulse[1] for w in windows if w.impulse is not None]
    if normal and np.median(normal) < 0:
        # a wrench published as the force on the surface, not on the arm: same law
        for w in windows:
            if w.impulse is not None:
                w.impulse = -w.impulse
        notes.append(
            'the recorded wrench points into the surface: its sign is reversed '
            '(the simulator publishes the force on the arm)'
        )
    if not windows:
        raise IdentifyError(f'{len(impacts)} impact(s) found but none usable: ' + '; '.join(notes))
    return impacts, noise, windows, notes


def fit(
    recording: JointRecording,
    scene: str | Scene | dict,
    bounds: dict,
    options: FitOptions | None = None,
    progress: Callable[..., Any] | None = None,
) -> FitResult:
    """Fit the scene keys of ``bounds`` ({key: (lo, hi)}) to the impacts of ``recording``.

    ``scene``: path, installed name, Scene or YAML data (the fixed rest and the start)."""
    options = options or FitOptions()
    say = progress or (lambda text, done=None, total=None: None)
    wall0 = time.perf_counter()
    study = Study(scene)
    specs = parameter_specs(study, bounds)
    if recording.n != study.scene().n_links:
        raise FitError(
            f'the recording has {recording.n} joints, the scene {study.origin} '
            f'{study.scene().n_links} links'
        )
    _, noise, windows, notes = prepare(recording, options, ArmModel(study.scene()))
    notes = list(recording.notes) + notes
    if options.use_wrench and recording.wrench is not None:
        missing = sum(w.impulse is None for w in windows)
        if missing:
            notes.append(
                f'wrench impulse unusable at {missing} impact(s) (wrench samples '
                f'missing there): joint rates only at those'
            )
    problem = ImpactSet(study, specs, windows, options.use_wrench)
    start = np.array([p.start for p in specs])
    say(f'{len(windows)} impacts; reading of the efforts', 0, None)
    start_notes = problem.select(start, noise.velocity)
    notes += start_notes
    if not problem.windows:
        raise IdentifyError(
            'the starting scene reproduces none of the recorded impacts: '
            + '; '.join(start_notes[-3:])
        )
    if len(problem.windows) * problem.windows[0].post_qd.size <= len(specs):
        raise FitError(
            f'{len(problem.windows)} usable impact(s) cannot determine {len(specs)} parameters'
        )

    def to_values(u: np.ndarray) -> np.ndarray:
        return np.array([p.from_unit(x) for p, x in zip(specs, u)])

    r0 = problem.residuals(start)
    problem.penalty = max(PENALTY, 10 * float(np.sqrt(np.mean(r0**2))))
    u_start = np.array([p.to_unit(p.start) for p in specs])
    n_global = options.global_points or 6 + 4 * len(specs)
    candidates = [u_start] + list(0.02 + 0.96 * _halton(n_global, len(specs)))
    total = len(candidates) + options.starts + 2
    costs = []
    for k, u in enumerate(candidates):
        r = problem.residuals(to_values(u))
        costs.append(float(r @ r))
        say(f'global stage {k + 1}/{len(candidates)}  best chi2 {min(costs):.4g}', k + 1, total)
    from scipy.optimize import least_squares

    def local(u0: np.ndarray) -> tuple[float, np.ndarray]:
        sol = least_squares(
            lambda u: problem.residuals(to_values(u)),
            u0,
            bounds=(0.0, 1.0),
            diff_step=1e-5,
            x_scale=0.1,
            max_nfev=options.max_nfev * len(specs),
            xtol=1e-10,
            ftol=1e-12,
        )
        return 2 * sol.cost, sol.x

    order = np.argsort(costs)
    best: Any = None  # (cost, u) of the best local search so far
    for s, idx in enumerate(order[: options.starts]):
        cost, u = local(candidates[idx])
        if best is None or cost < best[0]:
            best = (cost, u)
        say(
            f'local search {s + 1}/{options.starts}  chi2 {cost:.4g}',
            len(candidates) + s + 1,
            total,
        )
    # the full covariance (pre-impact uncertainty through the impact map) is linearised
    # where the model is right: at the optimum, then refined from there, until it settles
    for rounds in range(3):
        problem.calibrate(to_values(best[1]), noise.velocity)
        cost, u = local(best[1])
        moved = np.max(np.abs(u - best[1]))
        best = (cost, u)
        say(
            f'refinement {rounds + 1} at the optimum: chi2 {cost:.4g} over '
            f'{len(problem.residuals(to_values(u)))} values'
        )
        if moved < 1e-4:
            break
    u_best = best[1]
    values = to_values(u_best)
    problem.best = values
    preds = problem.predict(values)
    start_preds = problem.predict(start)
    return _result(
        problem,
        specs,
        values,
        u_best,
        preds,
        start_preds,
        noise,
        notes,
        recording,
        time.perf_counter() - wall0,
    )


def _jacobian(problem, specs, values):
    """d(whitened residuals)/d(native coordinate), central differences."""
    base = np.array([p.to_native(v) for p, v in zip(specs, values)])
    cols = []
    for k, p in enumerate(specs):
        h = 1e-4 * (1.0 if p.log else max(abs(values[k]), (p.hi - p.lo) * 1e-2))
        pair = []
        for sign in (1, -1):
            x = base.copy()
            x[k] += sign * h
            v = np.array([math.exp(x[i]) if s.log else x[i] for i, s in enumerate(specs)])
            pair.append(problem.residuals(v))
        cols.append((pair[0] - pair[1]) / (2 * h))
    return np.array(cols).T


def _result(problem, specs, values, u_best, preds, start_preds, noise, notes, recording, wall):
    from scipy.stats import chi2 as chi2_dist

    failing = [i for i, p in enumerate(preds) if p.error]
    if failing and len(failing) <= len(preds) // 3:
        # a few impacts the optimum cannot replay (typically a second contact on the edge of
        # happening, which the recording just missed): left out, said so
        for i in reversed(failing):
            notes.append(
                f'impact at t = {problem.windows[i].t_c:.4f} s left out at the '
                f'optimum: {preds[i].error}'
            )
            for seq in (problem.windows, problem.whiten, preds, start_preds):
                del seq[i]
    r = problem.residuals(values, preds)
    chi2 = float(r @ r)
    dof = max(len(r) - len(specs), 1)
    red = chi2 / dof
    J = _jacobian(problem, specs, values)
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    tiny = s <= (s.max() if s.size else 0.0) * 1e-8
    keep = ~tiny
    cov = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    if tiny.any():  # directions the data do not constrain: infinite variance along them
        loose = np.abs(Vt[tiny]).max(axis=0) > 1e-3
        cov[np.ix_(loose, loose)] = np.inf
    cov = cov * max(1.0, red)  # a fit worse than its noise widens its own intervals
    sigma = np.sqrt(np.abs(np.diag(cov)))
    params, corr_out = {}, {}
    d = np.where(np.isfinite(sigma) & (sigma > 0), sigma, np.nan)
    with np.errstate(invalid='ignore'):
        corr = cov / np.outer(d, d)
    pairs = []
    for i, p in enumerate(specs):
        native = p.to_native(values[i])
        lo_n, hi_n = native - 1.96 * sigma[i], native + 1.96 * sigma[i]
        ci = [math.exp(lo_n), math.exp(hi_n)] if p.log else [lo_n, hi_n]
        span = (math.log(p.hi) - math.log(p.lo)) if p.log else (p.hi - p.lo)
        identifiable = bool(np.isfinite(sigma[i]) and 2 * 1.96 * sigma[i] < 0.5 * span)
        at_bound = u_best[i] < 1e-3 or u_best[i] > 1 - 1e-3
        params[p.key] = {
            'value': float(values[i]),
            'ci95': [float(ci[0]), float(ci[1])],
            'identifiable': identifiable,
            'start': p.start,
            'bounds': [p.lo, p.hi],
            'sigma_native': float(sigma[i]),
            'at_bound': bool(at_bound),
        }
        for j in range(i + 1, len(specs)):
            rho = float(corr[i, j]) if np.isfinite(corr[i, j]) else math.nan
            corr_out[f'{p.key} ~ {specs[j].key}'] = rho
            if not math.isfinite(rho) or abs(rho) > 0.95:
                pairs.append([p.key, specs[j].key])
    for p in specs:
        if not params[p.key]['identifiable'] and not any(p.key in pair for pair in pairs):
            params[p.key]['why'] = 'the impacts barely depend on it'
    per_impact, raw_rate, sd_rate = _per_impact(problem, preds, start_preds)
    residual_rms = float(np.sqrt(np.mean(np.square(raw_rate)))) if raw_rate else math.nan
    noise_rms = float(np.sqrt(np.mean(np.square(sd_rate)))) if sd_rate else math.nan
    p_value = float(chi2_dist.sf(chi2, dof))
    verdict = 'fits'
    failed = [x for x in per_impact if x.get('error')]
    if failed:
        verdict = (
            f'does not fit: the fitted scene reproduces no contact at {len(failed)} of '
            f'{len(per_impact)} impacts ({failed[0]["error"]})'
        )
    elif p_value < 1e-3 and math.sqrt(red) > 1.5:
        verdict = 'does not fit: ' + _why(problem, per_impact, params, red, dof)
    return FitResult(
        params,
        verdict,
        residual_rms,
        noise_rms,
        chi2,
        dof,
        len(problem.windows),
        per_impact,
        noise.as_dict(),
        corr_out,
        pairs,
        notes,
        problem.evaluations,
        wall,
        problem.use_wrench,
        {p.key: float(v) for p, v in zip(specs, values)},
        problem.windows,
        preds,
        start_preds,
        recording,
        timing=problem.timing,
        problem=problem,
    )


def _why(problem, per_impact, params, red, dof) -> str:
    parts = [
        (
            f'residuals {math.sqrt(red):.1f}x the noise (chi2/dof = {red:.3g} over {dof} '
            f'degrees of freedom)'
        )
    ]
    with_wrench = [x for x in per_impact if 'residual_impulse' in x]
    if with_wrench:
        rate = np.mean([np.sum(np.square(x['whitened'][:-2])) for x in with_wrench])
        imp = np.mean([np.sum(np.square(x['whitened'][-2:])) for x in with_wrench])
        parts.append('mostly in the ' + ('wrench impulse' if imp > rate else 'joint rates'))
    bounded = [k for k, v in params.items() if v['at_bound']]
    if bounded:
        parts.append(f'{", ".join(bounded)} at a bound')
    cors = [x['cor_recorded'] - x['cor_fitted'] for x in per_impact]
    if cors and abs(np.mean(cors)) > 2 * (np.std(cors) / math.sqrt(len(cors)) + 1e-12):
        parts.append(
            f'recorded CoR {"above" if np.mean(cors) > 0 else "below"} the fitted by '
            f'{abs(np.mean(cors)):.3f} on average'
        )
    parts.append('the contact law or a fixed parameter does not match the arm')
    return '; '.join(parts)


def _per_impact(problem, preds, start_preds):
    out, raw, sd = [], [], []
    n = problem.windows[0].effort.shape[1] if problem.windows else 0
    model = problem.model(problem.best)  # the fitted scene's free flight and kinematics
    for w, L, p, p0 in zip(problem.windows, problem.whiten, preds, start_preds):
        T = joint_to_absolute_matrix(n)
        q, qd_pre, _ = w.pre.state(w.t_c)
        v_in = tip_normal_speed(model, T @ q, T @ qd_pre)
        row = {
            't': w.t_c,
            'impact_speed': -v_in,
            'qd_before': qd_pre.tolist(),
            'qd_after_recorded': w.post_qd[0].tolist(),
        }
        if w.impulse is not None:
            row['impulse_recorded'] = w.impulse.tolist()
        if p.error:
            row['error'] = p.error
            out.append(row)
            continue
        rec = problem.recorded(w)
        diff = problem.outputs(p, w) - rec
        m = len(w.post_t)
        row.update(
            {
                'qd_after_fitted': p.qd[0].tolist(),
                'qd_separation': p.qd_sep.tolist(),
                'impulse_fitted': p.impulse.tolist(),
                'cor_recorded': recorded_cor(model, w, p, problem.timing, v_in),
                'cor_fitted': -p.v_out / p.v_in if p.v_in else math.nan,
                'cor_start': -p0.v_out / p0.v_in if p0.v_in and not p0.error else math.nan,
                'residual_rates': diff[: m * n].reshape(m, n).tolist(),
                'whitened': (L @ diff).tolist(),
                'contacts': p.contacts,
            }
        )
        if problem.wrench_at(w):
            row['residual_impulse'] = diff[m * n :].tolist()
        raw.extend(diff[: m * n].tolist())
        sd.extend(w.sigma[: m * n].tolist())
        out.append(row)
    return out, raw, sd
