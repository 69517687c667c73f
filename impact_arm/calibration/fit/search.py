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

from collections.abc import Callable
from typing import Any

import math
import time
from dataclasses import replace

import numpy as np

from ..identify import IdentifyError, JointRecording
from ..study import Study
from ...physics.model import ArmModel
from ...physics.scene import Scene
from .parameters import FitError, parameter_specs
from .problem import PENALTY, FitOptions, ImpactSet, prepare, wrench_lag_range
from .outliers import find_outliers
from .report import FitResult, estimate
from .verdict import DOES_NOT_FIT, MISMATCH


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


def fit(
    recording: JointRecording,
    scene: str | Scene | dict,
    bounds: dict,
    options: FitOptions | None = None,
    progress: Callable[..., Any] | None = None,
) -> FitResult:
    """Fit the scene keys of ``bounds`` ({key: (lo, hi)}) to the impacts of ``recording``.

    ``scene``: path, installed name, Scene or YAML data (the fixed rest and the start).
    An outlier impact is named, and the fit repeated without it (``without_outliers``)."""
    options = options or FitOptions()
    wall0 = time.perf_counter()
    result = _fit_once(recording, scene, bounds, options, progress)
    outliers = find_outliers(result.per_impact) if options.check_outliers else []
    if outliers and result.impacts_used - len(outliers) >= 3:
        say = progress or (lambda text, done=None, total=None: None)
        say(f'refit without {len(outliers)} outlier impact(s)')
        said = '; '.join(o.sentence() for o in outliers)
        try:
            again = _fit_once(
                recording,
                scene,
                bounds,
                replace(options, leave_out=options.leave_out + tuple(o.t for o in outliers)),
                progress,
            )
        except (FitError, IdentifyError) as exc:  # too little left to fit: say so, keep going
            result.warnings.insert(0, f'{said}: no fit without it ({exc})')
            result.outliers = outliers
            result.wall_time = time.perf_counter() - wall0
            return result
        values = ', '.join(f'{k} = {p.interval_text()}' for k, p in again.parameters.items())
        result.warnings.insert(0, f'{said}: without it, {values}; {again.verdict}')
        if not result.fits and again.fits:
            # the outlier is the reason, not the law: said first, and the law is not blamed
            rest = result.verdict.removeprefix(DOES_NOT_FIT).removesuffix(f'; {MISMATCH}')
            result.verdict = f'{DOES_NOT_FIT}{said}, without which the scene fits; {rest}'
        elif not result.fits:
            result.verdict += f'; {said}, without which the scene does not fit either'
        result.outliers, result.without_outliers = outliers, again
    result.wall_time = time.perf_counter() - wall0
    return result


def _fit_once(
    recording: JointRecording,
    scene: str | Scene | dict,
    bounds: dict,
    options: FitOptions,
    progress: Callable[..., Any] | None = None,
) -> FitResult:
    say = progress or (lambda text, done=None, total=None: None)
    wall0 = time.perf_counter()
    study = Study(scene)
    specs = parameter_specs(study, bounds)
    if recording.n != study.scene().n_links:
        raise FitError(
            f'the recording has {recording.n} joints, the scene {study.origin} '
            f'{study.scene().n_links} links'
        )
    if options.wrench_lag == (0.0, 0.0):
        options = replace(options, wrench_lag=wrench_lag_range(study, specs))
    _, noise, windows, notes = prepare(recording, options, ArmModel(study.scene()))
    notes = list(recording.notes) + notes
    if options.leave_out:
        period = recording.period
        for t in options.leave_out:
            if not any(abs(w.t_c - t) <= 2 * period for w in windows):
                near = min(windows, key=lambda w: abs(w.t_c - t) if math.isfinite(t) else 0.0)
                raise FitError(
                    f'--leave-out {t:g}: no impact within {2 * period:.3g} s of it (must be an '
                    f"impact's time in s from the first sample, e.g. {near.t_c:.4f})"
                )
        kept = [w for w in windows if min(abs(w.t_c - t) for t in options.leave_out) > 2 * period]
        notes += [
            f'impact at t = {w.t_c:.4f} s left out as asked' for w in windows if w not in kept
        ]
        windows = kept
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
    start = problem.start_values  # a fitted effort latency starts with its reading's best
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
        # a second start that ends where an earlier one did: that minimum is the basin's
        # of both, and the further starts (ranked worse) are skipped
        again = best is not None and (
            np.max(np.abs(u - best[1])) < 1e-3 and abs(cost - best[0]) <= 1e-6 * best[0] + 1e-9
        )
        if best is None or cost < best[0]:
            best = (cost, u)
        say(
            f'local search {s + 1}/{options.starts}  chi2 {cost:.4g}',
            len(candidates) + s + 1,
            total,
        )
        if again:
            break
    # the full covariance (pre-impact uncertainty through the impact map) is linearised
    # where the model is right: at the optimum, then refined from there, until it settles
    for rounds in range(3):
        problem.calibrate(to_values(best[1]), noise.velocity)
        cost, u = local(best[1])
        moved = np.max(np.abs(u - best[1]))
        best = (cost, u)
        say(
            f'refinement {rounds + 1} at the optimum: chi2 {cost:.4g} over '
            f'{sum(len(L) for L in problem.whiten)} values'
        )
        if moved < 1e-4:
            break
    u_best = best[1]
    values = to_values(u_best)
    problem.best = values
    preds = problem.predict(values)
    start_preds = problem.predict(start)
    return estimate(
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
