"""The problem: the recorded impacts, how a scene variant predicts them, and the whitened
residuals whose sum of squares is a chi-square when the scene is right."""

from __future__ import annotations

from collections.abc import Sequence

from dataclasses import dataclass, replace
import copy
import operator

import numpy as np

from ...physics.model import ArmModel
from ...physics.errors import SceneError
from ...physics.kinds import ImpactSide
from ..identify import (
    IdentifyError,
    ImpactWindow,
    contact_test,
    JointRecording,
    Noise,
    estimate_noise,
    find_impacts,
    impact_windows,
)
from ..study import Study
from .efforts import (
    EffortTiming,
    controller_reproduces,
    effort_timing,
    effort_timing_and_latency,
    wrench_shift,
)
from .parameters import FitError
from .prestate import shot_start
from .replay import FailureKind, Prediction, failed, predict_impact

# The whitened residual of an impact the model cannot replay at some values (no contact, a
# contact outside the law's validity): well above any misfit near the start, so that the
# search never prefers losing impacts to fitting them (30x that for values the scene refuses)
PENALTY = 30.0
EFFORT_LATENCY = 'sensors.effort_latency'  # a fitted key the reading of the efforts depends on


def wrench_lag_range(study: Study, specs: Sequence) -> tuple[float, float]:
    """The range [s] of the wrench's delay behind the joint states: the scene's sensors'
    wrench latency less their state latency, each over its bounds when fitted."""
    sensors = study.scene().sensors
    ranges = {
        'sensors.wrench_latency': (sensors.wrench_latency, sensors.wrench_latency),
        'sensors.state_latency': (sensors.state_latency, sensors.state_latency),
    }
    for p in specs:
        if p.key in ranges:
            ranges[p.key] = (min(p.lo, p.start), max(p.hi, p.start))
    wrench, state = ranges['sensors.wrench_latency'], ranges['sensors.state_latency']
    return (wrench[0] - state[1], wrench[1] - state[0])


@dataclass
class FitOptions:
    window: int = 15  # samples per side for the free-flight fits
    use_wrench: bool = True  # when the recording has one
    starts: int = 3  # local searches from the best points of the global stage
    global_points: int = 0  # 0: 6 + 4 per parameter
    z_min: float = 30.0  # impact detection threshold (robust z of the rate step)
    max_nfev: int = 25  # per local search and parameter
    post_samples: int = 3  # samples after each impact compared with the model
    leave_out: tuple[float, ...] = ()  # contact times [s] of impacts not to fit
    check_outliers: bool = True  # refit without an outlier impact and report both
    # range [s] of the wrench's delay behind the joint states the impacts' wrench must cover
    # (set by the fit from a fitted or stated sensors.wrench_latency / state_latency)
    wrench_lag: tuple[float, float] = (0.0, 0.0)


class ImpactSet:
    """The recorded impacts and how a scene variant predicts them, as whitened residuals."""

    best: np.ndarray  # the fitted values, set by fit

    def __init__(self, study: Study, specs: list, windows: list, use_wrench: bool):
        self.study, self.specs, self.windows = study, specs, windows
        self.use_wrench = use_wrench and any(w.impulse is not None for w in windows)
        self.evaluations = 0  # replays of every impact (a point asked for again is not)
        self._replayed: dict = {}  # (values, moved keys, reading) -> (windows, predictions)
        self.timing = EffortTiming.LINEAR  # until select chooses the reading
        self.timing_misfit: float | None = None  # set by select
        self.penalty = PENALTY

    def model(
        self, values: Sequence[float] | np.ndarray, fixed: dict[str, float] | None = None
    ) -> ArmModel:
        """The scene with the fitted keys at ``values`` and ``fixed`` keys moved too."""
        overrides = {p.key: float(v) for p, v in zip(self.specs, values)} | (fixed or {})
        try:
            return ArmModel(self.study.scene(overrides))
        except SceneError as exc:
            raise FitError(f'the scene refuses {overrides}: {exc}') from None

    def wrench_at(self, win: ImpactWindow) -> bool:
        """Whether the wrench impulse of this impact is compared (recorded in full there)."""
        return self.use_wrench and win.impulse is not None

    def outputs(self, pred: Prediction, win: ImpactWindow) -> np.ndarray:
        qd = pred.qd.ravel()
        if not self.wrench_at(win):
            return qd
        if win.wrench_timing is None:
            return np.concatenate([qd, pred.impulse])
        return np.concatenate([qd, pred.impulse, [pred.wrench_timing]])

    def recorded(self, win: ImpactWindow) -> np.ndarray:
        qd = win.post_qd.ravel()
        if not self.wrench_at(win):
            return qd
        assert win.impulse is not None
        if win.wrench_timing is None:
            return np.concatenate([qd, win.impulse])
        return np.concatenate([qd, win.impulse, [win.wrench_timing]])

    @staticmethod
    def wrench_var(win: ImpactWindow) -> np.ndarray:
        """The noise variances of the wrench outputs: impulse, and its timing when kept."""
        assert win.impulse_var is not None
        var = np.broadcast_to(win.impulse_var, (2,))
        return var if win.wrench_timing is None else np.append(var, win.wrench_timing_var)

    def predict(
        self, values: Sequence[float] | np.ndarray, fixed: dict[str, float] | None = None
    ) -> list[Prediction]:
        # the replays are a function of the values, the moved keys, the reading of the
        # efforts and the windows: a point replayed before (each local search's and each
        # refinement's start, their difference steps, the optimum) is not replayed again
        key = (
            np.asarray(values, float).tobytes(),
            tuple(sorted((fixed or {}).items())),
            self.timing,
        )
        replayed = self._replayed.get(key)
        if replayed is not None and len(replayed[0]) == len(self.windows):
            if all(map(operator.is_, replayed[0], self.windows)):  # the same impacts
                return list(replayed[1])
        self.evaluations += 1
        try:
            model = self.model(values, fixed)
        except FitError as exc:  # a combination the scene's schema refuses: a penalty
            n = self.windows[0].post_qd.shape[1] if self.windows else 1
            preds = [failed(n, FailureKind.SCENE_REFUSED, str(exc)) for _ in self.windows]
        else:
            preds = [predict_impact(model, w, self.timing) for w in self.windows]
        self._replayed[key] = (tuple(self.windows), preds)
        return list(preds)

    def select(self, values: Sequence[float] | np.ndarray, sigma_qd: np.ndarray) -> list[str]:
        """At the starting ``values``: choose the reading of the efforts, move samples taken
        in a contact out of each impact's comparison, keep the impacts the scene replays and
        give them robust diagonal weights (``calibrate`` refines them at the optimum)."""
        model = self.model(values)
        kept, self.whiten, notes = [], [], []
        self.start_values = np.array(values, float)
        fitted = [i for i, p in enumerate(self.specs) if p.key == EFFORT_LATENCY]
        if fitted and self.windows:
            # the latency and the reading of the efforts are one timing of the torque: chosen
            # together, the latency's start where they predict the free flight best
            i, spec = fitted[0], self.specs[fitted[0]]
            period = float(np.median(np.concatenate([np.diff(w.effort_t) for w in self.windows])))
            reading, latency, errors = effort_timing_and_latency(
                model, self.windows, model.scene.sensors.state_latency, (spec.lo, spec.hi), period
            )
            own, own_errors = effort_timing(model, self.windows)
            if own is EffortTiming.CONTROLLER and own_errors[own] < errors[reading]:
                # a stiff continuous controller the replay recomputes beats every reading of
                # the recorded efforts at every latency: their latency does not enter it
                self.timing, self.timing_errors = own, own_errors
                notes.append(
                    f"{spec.key} does not enter the replay: the scene's own controller "
                    f'predicts the free flight after the impacts better than any reading of '
                    f'the recorded efforts at any latency within the bounds, and reads none '
                    f'of them'
                )
            else:
                self.timing, self.timing_errors = reading, errors
                notes.append(
                    f'{spec.key} started at {latency:.6g} s (not {spec.start:g}), with the '
                    f"reading '{reading}' of the efforts: together they best predict the "
                    f'free flight after the impacts'
                )
                spec.start = latency
                self.start_values[i] = latency
                model = self.model(self.start_values)
        else:
            self.timing, self.timing_errors = effort_timing(model, self.windows)
        # the best reading's error over what the rates' noise alone leaves (two noisy rates
        # per one-period prediction): far above 1 when no reading explains the free flight
        expected = sum(len(w.post_t) - 1 for w in self.windows) * 2 * float(np.sum(sigma_qd**2))
        self.timing_misfit = (
            self.timing_errors[self.timing] / expected
            if self.timing.reads_efforts and expected > 0
            else None
        )
        for w in self.windows:
            w = self._prepare(model, w)
            w, base = self._widen(model, w, predict_impact(model, w, self.timing))
            if base.error:
                notes.append(
                    f'impact at t = {w.t_c:.4f} s left out: {base.error} with the starting scene'
                )
                continue
            ib = getattr(w, 'effort_ib', 2)
            if self.timing is EffortTiming.NEXT and any(w.effort_off[k] for k in range(2, ib)):
                notes.append(
                    f'impact at t = {w.t_c:.4f} s left out: a sample taken during '
                    f'the contact shows no torque, so the command held after the '
                    f'contact is not recorded'
                )
                continue
            # robust weights for the global stage (no linearisation, which a bounce that
            # comes and goes with the parameters would spoil): each recorded rate's noise
            # plus the pre-impact rates' uncertainty, the impulse's noise
            cov_pre = w.start_state()[2]
            var = np.tile(sigma_qd**2 + np.diag(cov_pre)[model.n :], len(w.post_t))
            if self.wrench_at(w):
                var = np.concatenate([var, self.wrench_var(w)])
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
            side = {
                FailureKind.SURFACE_ABOVE_TIP: ImpactSide.BEFORE,
                FailureKind.CONTACT_OUTLASTS: ImpactSide.AFTER,
            }.get(base.failure)
            wider = w.widened(side) if side and getattr(w, 'widened', None) else None
            if wider is None:
                break
            wider.index = w.index
            wider = self._prepare(model, wider)
            w, base = wider, predict_impact(model, wider, self.timing)
        return w, base

    def _prepare(self, model: ArmModel, w: ImpactWindow) -> ImpactWindow:
        """The window as the replays of ``model`` use it (a new one): whether the scene's
        sampled controller is the recording's (it then gives the command the contact's
        period does not record, ``contact_period_command``), and the start of the replay."""
        ready = copy.copy(w)
        ready.own_command = controller_reproduces(model, w)
        return self._shoot(model, ready)

    def _shoot(self, model: ArmModel, w: ImpactWindow) -> ImpactWindow:
        """Rates that are period means, or efforts held over each period (a sampled
        controller's commands, the torque jumping from period to period): the window whose
        replay starts from the state the model's flight under the recorded efforts gives at
        the last sample before the impact (fitted to the positions before it), not from the
        cubic's (``prestate.py`` says why; a cubic through a held torque's flight is off the
        same way at every impact of a limit cycle, which the verdict's sign test then
        reads as a misfit). A new window when the start is set: one replayed before keeps
        its start."""
        if w.rate_period is None and not self.timing.held:
            return w
        shot = copy.copy(w)
        shot.start = shot_start(model, w, self.timing)
        return shot

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
            w = self._shoot(model, w)  # the flight before the impact, with ``values``' model
            base = predict_impact(model, w, self.timing)
            w, base = self._widen(model, w, base)
            if base.error:
                continue
            self.windows[i] = w
            q, qd, cov_pre = w.start_state()
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
                C[m * n :, m * n :] += np.diag(self.wrench_var(w))
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
                refused = p.failure is FailureKind.SCENE_REFUSED
                out.append(np.full(L.shape[0], self.penalty * (30 if refused else 1)))
            else:
                out.append(L @ (self.outputs(p, w) - self.recorded(w)))
        return np.concatenate(out) if out else np.zeros(0)


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
        recording,
        noise,
        impacts,
        options.window,
        post_samples=options.post_samples,
        wrench_lag=options.wrench_lag,
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


@dataclass
class RecordedImpacts:
    """The impacts of a recording as a scene reads them: the windows its model replays, how
    the efforts are read between samples, the sensor noise and what was noted on the way."""

    windows: list[ImpactWindow]
    timing: EffortTiming
    noise: Noise
    notes: list[str]


def read_impacts(
    recording: JointRecording, study: Study, options: FitOptions | None = None
) -> RecordedImpacts:
    """The impacts of ``recording`` that the scene of ``study`` replays at its own values."""
    model = ArmModel(study.scene())
    options = options or FitOptions()
    if options.wrench_lag == (0.0, 0.0):
        options = replace(options, wrench_lag=(wrench_shift(model),) * 2)
    _, noise, windows, notes = prepare(recording, options, model)
    problem = ImpactSet(study, [], windows, options.use_wrench)
    notes += problem.select([], noise.velocity)
    return RecordedImpacts(problem.windows, problem.timing, noise, notes)
