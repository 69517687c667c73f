"""The report of a fit: the covariance at the optimum, intervals, identifiability, the
per-impact table and the verdict, as a ``FitResult``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...physics.model import ArmModel
from ..identify import JointRecording, joint_to_absolute_matrix, tip_normal_speed
from ..identify import Noise
from .dependence import Dependence, dependences, one_impact
from .efforts import EffortTiming
from .outliers import Outlier
from .parameters import Parameter
from .physical import out_of_range
from .problem import ImpactSet
from .replay import Prediction, recorded_cor
from .verdict import OutputTest, Verdict, judge


def interval_digits(value: float, lo: float, hi: float) -> int:
    """Significant digits that tell an interval's ends apart (two digits of its width), at
    least 4."""
    width = abs(hi - lo)
    scale = max(abs(value), abs(lo), abs(hi))
    if math.isfinite(width) and width > 0 and math.isfinite(scale) and scale > 0:
        return min(max(4, math.ceil(math.log10(scale / width)) + 2), 15)
    return 4


@dataclass
class ParameterEstimate:
    """One fitted parameter: its value, 95 % interval and whether the data determine it."""

    key: str
    value: float
    ci95: tuple[float, float]
    identifiable: bool
    start: float
    bounds: tuple[float, float]
    sigma_native: float  # standard deviation in the fitted coordinate (log or linear)
    at_bound: bool
    why: str = ''  # why it is not identified, when it is not

    def as_json(self) -> dict:
        return {'value': self.value, 'ci95': list(self.ci95), 'identifiable': self.identifiable}

    def digits(self) -> int:
        """Significant digits that tell the interval's ends apart (two digits of its width),
        at least 4."""
        return interval_digits(self.value, *self.ci95)

    def interval_text(self) -> str:
        """'value  95 % [lo, hi]' with ``digits`` significant digits."""
        d = self.digits()
        return f'{self.value:.{d}g}  95 % [{self.ci95[0]:.{d}g}, {self.ci95[1]:.{d}g}]'

    def details(self) -> dict:
        return {
            'start': self.start,
            'bounds': list(self.bounds),
            'sigma_native': self.sigma_native,
            'at_bound': self.at_bound,
        }


@dataclass
class FitResult:
    """What a fit found, for the tools: estimates, statistics, verdict, the impacts compared
    (windows and predictions at the optimum and the start) and the fitted model that replays
    them."""

    parameters: dict[str, ParameterEstimate]
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
    # how the efforts were read between samples (the fit always states it: ImpactSet.timing)
    timing: EffortTiming = EffortTiming.LINEAR
    model: ArmModel | None = field(default=None, repr=False)  # the fitted scene's model
    verdict_kind: Verdict = Verdict.FITS
    output_tests: list[OutputTest] = field(default_factory=list)  # per output over the impacts
    dependences: list[Dependence] = field(default_factory=list)  # on the fixed parameters
    warnings: list[str] = field(default_factory=list)  # what limits the values, to read first
    outliers: list[Outlier] = field(default_factory=list)
    without_outliers: FitResult | None = field(default=None, repr=False)  # the refit

    @property
    def fits(self) -> bool:
        return self.verdict == 'fits'

    def to_json(self) -> dict:
        return {
            'parameters': {k: v.as_json() for k, v in self.parameters.items()},
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
            'details': {k: v.details() for k, v in self.parameters.items()},
            'verdict_kind': self.verdict_kind.name.lower(),
            'warnings': self.warnings,
            'outliers': [
                {'impact': o.number, 't': o.t, 'chi2': o.chi2, 'outputs': o.outputs, 'p': o.p_value}
                for o in self.outliers
            ],
            'without_outliers': (
                None
                if self.without_outliers is None
                else {
                    'parameters': {
                        k: v.as_json() for k, v in self.without_outliers.parameters.items()
                    },
                    'verdict': self.without_outliers.verdict,
                    'impacts_used': self.without_outliers.impacts_used,
                }
            ),
            'dependences': [
                {
                    'fitted': d.fitted,
                    'fixed': d.fixed,
                    'change': d.change,
                    'change_unit': '%' if d.relative else 'native',
                    'per': d.step,
                    'per_unit': d.unit,
                    'tolerance': d.tolerance,
                }
                for d in self.dependences
            ],
            'output_tests': [
                {
                    'output': t.output,
                    'recorded_below_fitted': t.below,
                    'impacts': t.count,
                    'sign_test_p': t.sign_p,
                    'mean_sigma': t.mean,
                    'trend_with_speed_se': None if math.isnan(t.trend_t) else t.trend_t,
                }
                for t in self.output_tests
            ],
        }


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


def estimate(
    problem: ImpactSet,
    specs: list[Parameter],
    values: np.ndarray,
    u_best: np.ndarray,
    preds: list[Prediction],
    start_preds: list[Prediction],
    noise: Noise,
    notes: list[str],
    recording: JointRecording,
    wall: float,
) -> FitResult:
    """The result at the optimum ``values`` (``u_best`` in the unit cube): covariance from
    the Jacobian, intervals, correlations, per-impact table and verdict."""
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
    params: dict[str, ParameterEstimate] = {}
    corr_out: dict[str, float] = {}
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
        params[p.key] = ParameterEstimate(
            p.key,
            float(values[i]),
            (float(ci[0]), float(ci[1])),
            identifiable,
            p.start,
            (p.lo, p.hi),
            float(sigma[i]),
            bool(at_bound),
        )
        for j in range(i + 1, len(specs)):
            rho = float(corr[i, j]) if np.isfinite(corr[i, j]) else math.nan
            corr_out[f'{p.key} ~ {specs[j].key}'] = rho
            if not math.isfinite(rho) or abs(rho) > 0.95:
                pairs.append([p.key, specs[j].key])
    for p in specs:
        if not params[p.key].identifiable and not any(p.key in pair for pair in pairs):
            params[p.key].why = 'the impacts barely depend on it'
    per_impact, raw_rate, sd_rate = _per_impact(problem, preds, start_preds)
    residual_rms = float(np.sqrt(np.mean(np.square(raw_rate)))) if raw_rate else math.nan
    noise_rms = float(np.sqrt(np.mean(np.square(sd_rate)))) if sd_rate else math.nan
    deps = dependences(problem, specs, values, J, sigma)
    warnings = [x for x in (one_impact(per_impact),) if x]
    warnings += ringing_plates(problem.model(values), problem.windows)
    warnings += [y for y in (out_of_range(p.key, v) for p, v in zip(specs, values)) if y]
    for p in specs:  # the most demanding fixed parameters of each fitted one
        warnings += [d.sentence() for d in deps if d.fitted == p.key and d.demanding][:3]
    joints = list(recording.joints) or [f'joint{j + 1}' for j in range(recording.n)]
    verdict = judge(per_impact, joints, chi2, dof, _where(per_impact, params, problem))
    return FitResult(
        params,
        verdict.text,
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
        model=problem.model(values),
        verdict_kind=verdict.kind,
        output_tests=verdict.tests,
        dependences=deps,
        warnings=warnings,
    )


# a plate left with more than this share of its ringing at the next impact is not at rest
RINGING = 0.01


def ringing_plates(model: ArmModel, windows: list) -> list[str]:
    """A warning per mounted surface whose plate still rings at the next impact (its decay
    exp(-zeta omega dt) over the shortest time between two impacts above ``RINGING``) when
    the recording has no plate states: the replay then starts it at rest."""
    if not model.n_mount or len(windows) < 2 or any(w.plate is not None for w in windows):
        return []
    gap = float(np.min(np.diff(sorted(w.t_c for w in windows))))
    out = []
    for surface in model.mounted:
        mount = surface.mount
        assert mount is not None  # model.mounted holds the mounted ones
        omega = math.sqrt(mount.stiffness / mount.mass)
        left = math.exp(-mount.damping_ratio * omega * gap)
        if left > RINGING:
            out.append(
                f'the plate of surfaces[{surface.index}] ({mount.mass:g} kg on '
                f'{mount.stiffness:g} N/m, '
                f'damping ratio {mount.damping_ratio:g}) still rings at the next impact '
                f'({left:.2g} of its motion left after {gap:.3g} s): each impact is replayed '
                f'with the plate at rest, as the recording has no plate states (record '
                f'/surface_mounts, as the simulator does)'
            )
    return out


# the best reading of the efforts missing the free flight by this many times what the rates'
# noise leaves: no reading explains it (a right reading stays within tens; efforts two
# periods late miss it by ~1e6)
TIMING_MISFIT = 1e3


def _where(
    per_impact: list[dict], params: dict[str, ParameterEstimate], problem: ImpactSet | None = None
) -> list[str]:
    """Where a misfit lies, for the verdict's reason: rates or impulse, bounds, efforts no
    reading explains."""
    parts = []
    with_wrench = [x for x in per_impact if 'residual_impulse' in x]
    if with_wrench:
        rate = np.mean(
            [np.sum(np.square(x['whitened'][: -len(x['residual_impulse'])])) for x in with_wrench]
        )
        imp = np.mean(
            [np.sum(np.square(x['whitened'][-len(x['residual_impulse']) :])) for x in with_wrench]
        )
        parts.append('mostly in the ' + ('wrench impulse' if imp > rate else 'joint rates'))
    late = [w for w in problem.windows if problem.wrench_at(w)] if problem is not None else []
    after = sum(w.wrench_after for w in late)
    if late and 2 * after > len(late) and 'sensors.wrench_latency' not in params:
        parts.append(
            f'at {after} of {len(late)} impacts most of the recorded normal force comes after '
            f'the periods that can hold the contact: the wrench published late? free '
            f'sensors.wrench_latency too, or give --wrench-latency'
        )
    misfit = problem.timing_misfit if problem is not None else None
    if (
        problem is not None
        and misfit is not None
        and misfit > TIMING_MISFIT
        and 'sensors.effort_latency' not in params
    ):
        parts.append(
            f'no reading of the recorded efforts predicts the free flight after the impacts '
            f"(the best, '{problem.timing}', misses it by {misfit:.3g} times what the rates' "
            f'noise leaves): efforts reported late or early? free sensors.effort_latency too, '
            f'or give --effort-latency'
        )
    bounded = [k for k, v in params.items() if v.at_bound]
    if bounded:
        parts.append(f'{", ".join(bounded)} at a bound')
    return parts


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
            'q_contact': q.tolist(),
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
        # each output over its own standard deviation (noise and the pre-impact state's
        # uncertainty): what the verdict's per-output tests read
        z = diff / w.sigma
        row['standardized_rates'] = z[:n].tolist()  # the first compared sample
        if problem.wrench_at(w):
            row['residual_impulse'] = diff[m * n :].tolist()
            row['standardized_impulse'] = z[m * n :].tolist()
        raw.extend(diff[: m * n].tolist())
        sd.extend(w.sigma[: m * n].tolist())
        out.append(row)
    return out, raw, sd
