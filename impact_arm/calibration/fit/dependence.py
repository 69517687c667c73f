"""What the fitted values rest on: how much each moves per 1 % of each fixed physical
parameter of the scene (so that the user knows what to measure better, or to fit too), and
whether the impacts vary enough to test the law at all (a limit cycle repeats one impact)."""

from __future__ import annotations

from collections.abc import Sequence

import math
from dataclasses import dataclass

import numpy as np

from .parameters import Parameter, schema_unit
from .physical import physical_key, stated_parameters
from .problem import ImpactSet

STEP = 2e-3  # relative step of a fixed parameter (its effect is linear over it)
REPORTED = 0.05  # smallest dependence reported [% per %, or its native equivalent]
SAME_SPEED = 0.01  # robust relative spread of the impact speeds under which they are one
SAME_POSTURE = 0.01  # ... of the contact postures [rad]


@dataclass
class Dependence:
    """``fitted`` moves by ``change`` per ``step`` of ``fixed`` (1 %, or an absolute amount
    for a fixed parameter the scene sets to 0): in % of its value for a positive (log-fitted)
    parameter, in its own unit otherwise."""

    fitted: str
    fixed: str
    change: float
    relative: bool  # change in % of the fitted value
    tolerance: float  # how well the fixed one must be known to move the fitted by < 1 σ
    step: float = 1.0  # the step of the fixed one: 1 (%), or an amount in ``unit``
    unit: str = '%'  # of step and tolerance: '%' of the fixed value, or its own unit

    @property
    def fitted_unit(self) -> str:
        """The unit of an absolute change: the fitted parameter's own, from the schema."""
        return schema_unit(self.fitted)

    def change_text(self, signed: bool = False) -> str:
        """The change with its unit: % of the fitted value, or the fitted one's unit."""
        size = self.change if signed else abs(self.change)
        if self.relative:
            return f'{size:{"+" if signed else ""}.3g} %'
        return f'{size:{"+" if signed else ""}.3g} {self.fitted_unit}'.rstrip()

    @property
    def per_percent(self) -> float:
        """The change per 1 % (nan for an absolute step)."""
        return self.change if self.unit == '%' else math.nan

    @property
    def demanding(self) -> bool:
        """A step of the fixed parameter moves the fitted one by more than its σ."""
        return self.tolerance < self.step

    def sentence(self) -> str:
        name = self.fitted.rsplit('.', 1)[-1]
        change = self.change_text()
        way = 'up' if self.change > 0 else 'down'
        per = f'{self.step:g} {self.unit}'.rstrip() if self.unit != '%' else '1 %'
        tol = f'{self.tolerance:.2g} {self.unit}'.rstrip()
        return (
            f'{name} moves {change} {way} per {per} of {self.fixed}: know {self.fixed} to '
            f'{tol} or fit it too'
        )


def dependences(
    problem: ImpactSet,
    specs: Sequence[Parameter],
    values: np.ndarray,
    jacobian: np.ndarray,
    sigma: np.ndarray,
) -> list[Dependence]:
    """The first-order change of the optimum with each fixed parameter the scene states
    (implicit function theorem on the least squares: dθ = −J⁺ ∂r/∂φ dφ, with J the whitened
    residuals' Jacobian in the fitted coordinates), the most demanding first. A fixed
    parameter at 0 (an effect switched off) is stepped by its table's ``zero_step``."""
    fitted = {p.key for p in specs}
    base = problem.residuals(values)
    pinv = np.linalg.pinv(jacobian)
    out = []
    for key, value in stated_parameters(problem.study.data):
        entry = physical_key(key)
        if key in fitted or entry is None:
            continue
        if value == 0.0:  # per an amount of it, not per 1 % of nothing
            if entry.zero_step is None:
                continue
            moved_to, scale, step, unit = entry.zero_step, 1.0, entry.zero_step, entry.unit
        else:
            moved_to, scale, step, unit = value * (1 + STEP), 0.01 / STEP, 1.0, '%'
        moved = problem.residuals(values, problem.predict(values, {key: moved_to}))
        if not np.all(np.isfinite(moved)) or np.max(np.abs(moved)) >= problem.penalty:
            continue  # a step the replays cannot follow: no linear dependence to state
        d_native = -pinv @ (moved - base) * scale  # per step of the fixed value
        for i, p in enumerate(specs):
            change = 100.0 * d_native[i] if p.log else d_native[i]
            if abs(change) < (REPORTED if p.log else REPORTED * 0.01 * abs(values[i])):
                continue
            tol = step * sigma[i] / abs(d_native[i]) if d_native[i] else math.inf
            out.append(Dependence(p.key, key, float(change), p.log, float(tol), step, unit))
    return sorted(out, key=lambda d: d.tolerance / d.step)  # the most demanding first


def one_impact(per_impact: list[dict]) -> str:
    """'' or the note that (nearly) every impact has the same speed and posture: the law's
    speed dependence is then not tested and parameters that change the impact alike cannot
    be told apart."""
    rows = [r for r in per_impact if not r.get('error')]
    if len(rows) < 3:
        return ''
    v = np.array([r['impact_speed'] for r in rows])
    q = np.array([r['q_contact'] for r in rows])
    spread_v = 1.4826 * float(np.median(np.abs(v - np.median(v)))) / abs(float(np.median(v)))
    spread_q = 1.4826 * np.median(np.abs(q - np.median(q, axis=0)), axis=0)
    if spread_v >= SAME_SPEED or np.any(spread_q >= SAME_POSTURE):
        return ''
    same = int(np.sum(np.abs(v / np.median(v) - 1) < 3 * max(spread_v, 1e-6)))
    return (
        f'{same} of {len(rows)} impacts have the same speed ({np.median(v):.3g} m/s, spread '
        f'{100 * spread_v:.2g} %) and posture (a limit cycle): the law is tested at one impact '
        f'only, its dependence on the speed not at all, and parameters that change that impact '
        f'alike cannot be told apart; record impacts at other speeds (other targets, gains or '
        f'start postures)'
    )
