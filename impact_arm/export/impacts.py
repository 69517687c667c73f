"""The impact table ``--check`` compares: per impact, when the contact began, the tip's
normal speed before it, the coefficient of restitution, the duration and the peak normal
force; and the differences of two such tables, impact by impact, with their first, mean
and worst values."""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class ImpactRow:
    t_contact: float  # when the contact began [s]
    v_before: float  # the tip's speed towards the surface as it began [m/s]
    cor: float  # -v_n,after / v_n,before (kinematic coefficient of restitution)
    duration: float  # [s]
    f_max: float  # peak normal force [N]


class Column(enum.Enum):
    """A compared quantity; contact times differ in seconds, the others relatively."""

    T_CONTACT = 't_contact'
    V_BEFORE = 'v_before'
    COR = 'cor'
    DURATION = 'duration'
    F_MAX = 'f_max'

    @property
    def relative(self) -> bool:
        return self is not Column.T_CONTACT

    def difference(self, ours: ImpactRow, theirs: ImpactRow) -> float:
        """The peer's value minus ours (over ours for a relative quantity); NaN when a value
        is NaN or ours is zero, so that it shows in the means and worsts."""
        a, b = getattr(ours, self.value), getattr(theirs, self.value)
        if not self.relative:
            return b - a
        return (b - a) / a if a != 0.0 else math.nan


@dataclass(frozen=True)
class ColumnSummary:
    column: Column
    first: float  # the difference at the first impact
    mean: float  # mean absolute difference over every compared impact
    worst: float  # the largest absolute difference (NaN if any is)
    at: int  # the impact (1-based) of the worst


def differences(ours: Sequence[ImpactRow], theirs: Sequence[ImpactRow]) -> list[list[float]]:
    """Per impact compared (the first ``min(len)``), the difference of every column."""
    return [[c.difference(a, b) for c in Column] for a, b in zip(ours, theirs)]


def summarise(ours: Sequence[ImpactRow], theirs: Sequence[ImpactRow]) -> list[ColumnSummary]:
    """First, mean and worst of each column's difference over every compared impact."""
    rows = differences(ours, theirs)
    out = []
    for j, column in enumerate(Column):
        values = [abs(row[j]) for row in rows]
        if not values:
            out.append(ColumnSummary(column, math.nan, math.nan, math.nan, 0))
            continue
        if any(math.isnan(v) for v in values):
            # a NaN is not smaller than anything: it is the worst, never skipped
            k = next(i for i, v in enumerate(values) if math.isnan(v))
            out.append(ColumnSummary(column, rows[0][j], math.nan, math.nan, k + 1))
            continue
        k = max(range(len(values)), key=values.__getitem__)
        out.append(
            ColumnSummary(column, rows[0][j], math.fsum(values) / len(values), values[k], k + 1)
        )
    return out
