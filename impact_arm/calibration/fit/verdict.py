"""The verdict of a fit from its statistics: the chi-square against its tail, and each output's
residuals over the impacts (the same sign at most impacts, or a trend with the impact speed),
which a chi-square summed over every output can miss while the parameters come out confidently
wrong."""

from __future__ import annotations

from collections.abc import Sequence

import math
from dataclasses import dataclass

import numpy as np

from ...physics.kinds import TextEnum

CHI2_TAIL = 1e-3  # the chi-square's upper tail beyond which the scene does not fit
SIGN_LEVEL = 1e-2  # two-sided sign test of one output's residuals over the impacts
BIAS_SE = 3.0  # ... and their mean beyond this many standard errors (a bias, not a fluke)
TREND_LEVEL = 1e-3  # two-sided test of the slope of one output's residuals on impact speed
MIN_IMPACTS = 6  # fewer impacts: no per-output test (a sign test cannot reach its level)
MISMATCH = 'the contact law or a fixed parameter does not match the arm'  # the last reason
DOES_NOT_FIT = 'does not fit: '


class Verdict(TextEnum):
    """What a fit's verdict says, as a kind (``FitResult.verdict_kind``; the sentence with
    its reasons is ``FitResult.verdict``). A str: ``Verdict.FITS == 'fits'``."""

    FITS = 'fits'
    REPLAY_FAILED = 'replay failed'  # the fitted scene reproduces no contact at some impacts
    CHI2_TAIL = 'chi-square in its tail'
    SYSTEMATIC = 'systematic residuals'


@dataclass
class OutputTest:
    """One output's residuals (recorded minus fitted, in standard deviations) over the impacts."""

    output: str  # e.g. 'joint2 rate after the impact', 'normal impulse'
    below: int  # impacts where the recorded value is below the fitted one
    count: int
    sign_p: float  # two-sided sign test
    mean: float  # mean residual [standard deviations]
    trend_t: float  # slope on impact speed over its standard error (nan: no speed spread)

    @property
    def biased(self) -> bool:
        # the mean on the side of the majority (one wild impact can pull it the other way)
        majority_below = self.below > self.count - self.below
        return (
            self.count >= MIN_IMPACTS
            and self.sign_p < SIGN_LEVEL
            and (self.mean < 0) == majority_below
            and abs(self.mean) * math.sqrt(self.count) > BIAS_SE
        )

    @property
    def trending(self) -> bool:
        return (
            self.count >= MIN_IMPACTS
            and math.isfinite(self.trend_t)
            and 2 * _normal_sf(abs(self.trend_t)) < TREND_LEVEL
        )

    def sentence(self) -> str:
        if self.biased:
            below = self.below > self.count - self.below
            side, k = ('below', self.below) if below else ('above', self.count - self.below)
            return (
                f'the recorded {self.output} is {side} the fitted one at {k} of {self.count} '
                f'impacts (sign test p = {self.sign_p:.2g}; mean {self.mean:+.2f} σ)'
            )
        way = 'rises' if self.trend_t > 0 else 'falls'
        return (
            f'the recorded minus fitted {self.output} {way} with the impact speed (slope '
            f'{self.trend_t:+.1f} standard errors)'
        )


def sign_test(below: int, count: int) -> float:
    """Two-sided p-value of ``below`` of ``count`` signs under a fair coin."""
    if count == 0:
        return 1.0
    k = min(below, count - below)
    tail = sum(math.comb(count, i) for i in range(k + 1)) / 2.0**count
    return min(1.0, 2.0 * tail)


def _normal_sf(x: float) -> float:
    return 0.5 * math.erfc(x / math.sqrt(2.0))


def output_test(name: str, z_recorded: Sequence[float], speeds: Sequence[float]) -> OutputTest:
    """The tests of one output: ``z_recorded`` is recorded minus fitted over its standard
    deviation at each impact."""
    z = np.asarray(z_recorded, float)
    v = np.asarray(speeds, float)
    ok = np.isfinite(z) & np.isfinite(v)
    z, v = z[ok], v[ok]
    nonzero = z[z != 0]
    below = int(np.sum(nonzero < 0))
    trend = math.nan
    dv = v - v.mean() if v.size else v
    if v.size >= 3 and limit_cycle_spread(v) > SPEED_SPREAD:
        # least-squares slope of z on v; z has unit variance when the scene is right, and more
        # when it is not (the scatter about the line, when larger, is the honest scale)
        slope = float(dv @ z / (dv @ dv))
        scatter = z - z.mean() - slope * dv
        scale = max(1.0, float(np.sqrt(scatter @ scatter / max(len(z) - 2, 1))))
        trend = slope * math.sqrt(float(dv @ dv)) / scale
    return OutputTest(
        name,
        below,
        len(nonzero),
        sign_test(below, len(nonzero)),
        float(z.mean()) if z.size else math.nan,
        trend,
    )


SPEED_SPREAD = 0.02  # impact speeds within 2 % of each other: one speed (a limit cycle)
POSTURE_SPREAD = 0.02  # contact postures within 0.02 rad of each other: one posture


def limit_cycle_spread(speeds: np.ndarray) -> float:
    """Relative spread of the impact speeds (standard deviation over the mean)."""
    mean = float(np.mean(np.abs(speeds)))
    return float(np.std(speeds)) / mean if mean > 0 else 0.0


def output_tests(per_impact: list[dict], joints: Sequence[str]) -> list[OutputTest]:
    """The per-output tests over the impacts that were replayed: each joint's rate at the first
    sample after the impact, the wrench impulse (where recorded) and the restitution (its sign
    only counts: its standard deviation is the rates')."""
    rows = [r for r in per_impact if not r.get('error')]
    speeds = [r['impact_speed'] for r in rows]
    tests = []
    for j, joint in enumerate(joints):
        # standardized residuals are fitted minus recorded: recorded minus fitted is the negative
        z = [-r['standardized_rates'][j] for r in rows]
        tests.append(output_test(f'{joint} rate after the impact', z, speeds))
    wrench = [r for r in rows if 'standardized_impulse' in r]
    for k, name in ((1, 'normal impulse'), (0, 'tangential impulse')):
        if wrench:
            z = [-r['standardized_impulse'][k] for r in wrench]
            tests.append(output_test(name, z, [r['impact_speed'] for r in wrench]))
    return tests


def restitution_sentence(per_impact: list[dict]) -> str:
    """'the recorded restitution is below the fitted one at k of m impacts' when its signs
    are as one-sided as the sign test's level, else ''."""
    d = [r['cor_recorded'] - r['cor_fitted'] for r in per_impact if not r.get('error')]
    d = [x for x in d if math.isfinite(x) and x != 0]
    below = sum(x < 0 for x in d)
    if len(d) < MIN_IMPACTS or sign_test(below, len(d)) >= SIGN_LEVEL:
        return ''
    side, k = ('below', below) if below > len(d) / 2 else ('above', len(d) - below)
    return f'the recorded restitution is {side} the fitted one at {k} of {len(d)} impacts'


@dataclass
class Judgement:
    """The verdict with what it was judged from: the kind, the sentence, the output tests."""

    kind: Verdict
    text: str  # 'fits' or 'does not fit: <why>'
    tests: list[OutputTest]

    @property
    def fits(self) -> bool:
        return self.kind is Verdict.FITS


def judge(
    per_impact: list[dict],
    joints: Sequence[str],
    chi2: float,
    dof: int,
    context: Sequence[str] = (),
) -> Judgement:
    """The verdict: replays that fail at the optimum, then the chi-square's tail, then the
    per-output tests. ``context`` adds what the report knows about where the misfit lies."""
    # scipy.special, not scipy.stats: the same tail, without seconds of import in a fresh
    # process
    from scipy.special import chdtrc

    tests = output_tests(per_impact, joints)
    failed = [x for x in per_impact if x.get('error')]
    if failed:
        return Judgement(
            Verdict.REPLAY_FAILED,
            f'does not fit: the fitted scene reproduces no contact at {len(failed)} of '
            f'{len(per_impact)} impacts ({failed[0]["error"]})',
            tests,
        )
    p_value = float(chdtrc(dof, chi2))
    reasons = []
    kind = Verdict.FITS
    if p_value < CHI2_TAIL:
        kind = Verdict.CHI2_TAIL
        reasons.append(
            f'residuals {math.sqrt(chi2 / dof):.2f}x the noise (chi2 = {chi2:.4g} over {dof} '
            f'degrees of freedom, p = {p_value:.2g} < {CHI2_TAIL:g})'
        )
    systematic = [t.sentence() for t in tests if t.biased or t.trending]
    if systematic:
        kind = Verdict.SYSTEMATIC if kind is Verdict.FITS else kind
        reasons += systematic
    if kind is Verdict.FITS:
        return Judgement(kind, 'fits', tests)
    cor = restitution_sentence(per_impact)
    if cor:
        reasons.append(cor)
    reasons += list(context)
    reasons.append(MISMATCH)
    return Judgement(kind, DOES_NOT_FIT + '; '.join(reasons), tests)
