"""The residual each peer leaves, as report.md and report.json: every quantity of every
strike, ours beside the exported peer's and the peer's defaults', and in words what the
peer cannot represent."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from .peers import LIMITS, Peer
from .residual import Quantity, Worst, summary
from .strike import Outcome, Strike

UNITS = {
    Quantity.COR: ('e', 1.0, '.3f'),
    Quantity.DURATION: ('duration [µs]', 1e6, '.1f'),
    Quantity.F_MAX: ('F_max [kN]', 1e-3, '.2f'),
    Quantity.V_T_AFTER: ('v_t after [m/s]', 1.0, '.3f'),
}


@dataclass(frozen=True)
class PeerReport:
    peer: Peer
    scene: str
    timestep: float  # [s]
    contact: object  # the tuned contact (a dataclass of the peer's)
    defaults: object  # the peer's default contact at the same step
    strikes: Sequence[Strike]
    ours: Sequence[Outcome]
    tuned: Sequence[Outcome]
    default_outcomes: Sequence[Outcome]
    cost: float
    evaluations: int
    seconds: float  # the export's cost, wall clock

    @property
    def tuned_residual(self) -> list[Worst]:
        return summary(self.ours, self.tuned, self.strikes)

    @property
    def default_residual(self) -> list[Worst]:
        return summary(self.ours, self.default_outcomes, self.strikes)

    def cor_error_at(self, strike: Strike, outcomes: Sequence[Outcome]) -> float:
        """The relative error of e at one strike."""
        k = list(self.strikes).index(strike)
        return (outcomes[k].cor - self.ours[k].cor) / self.ours[k].cor


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _fields(contact: object) -> dict | str:
    if dataclasses.is_dataclass(contact) and not isinstance(contact, type):
        return dataclasses.asdict(contact)
    return str(contact)


def to_json(report: PeerReport) -> dict:
    def worst(items: list[Worst]) -> dict:
        return {
            w.quantity.value: {
                'rms': _number(w.rms),
                'worst': _number(w.worst),
                'at': w.at,
                # None: one phase run (no spread measured); a NaN spread is null too
                'phase_spread': None if w.spread is None else _number(w.spread),
                'phase_spread_at': w.spread_at,
            }
            for w in items
        }

    return {
        'peer': report.peer.value,
        'scene': report.scene,
        'timestep': report.timestep,
        'contact': _fields(report.contact),
        'defaults': _fields(report.defaults),
        'strikes': [
            {
                'strike': s.label,
                'speed': s.speed,
                'v_before': list(s.v_before),
                'ours': dataclasses.asdict(o),
                'exported': dataclasses.asdict(t),
                'defaults': dataclasses.asdict(d),
            }
            for s, o, t, d in zip(
                report.strikes, report.ours, report.tuned, report.default_outcomes
            )
        ],
        'residual': worst(report.tuned_residual),
        'residual_defaults': worst(report.default_residual),
        'cannot_represent': LIMITS[report.peer],
        'cost': _number(report.cost),
        'evaluations': report.evaluations,
        'seconds': report.seconds,
    }


def _cell(outcome: Outcome, quantity: Quantity) -> str:
    _, scale, fmt = UNITS[quantity]
    text = format(getattr(outcome, quantity.value) * scale, fmt)
    return text if outcome.separated else text + ' (stuck)'


def _phase_count(report: PeerReport) -> str:
    counts = {len(o.phases) for o in report.tuned}
    if counts == {0}:
        return 'one phase'
    return ' or '.join(str(c) for c in sorted(counts)) + ' phases'


def _spread(worst: Worst) -> str:
    return 'not measured' if worst.spread is None else f'{worst.spread:.1%} ({worst.spread_at})'


def to_markdown(report: PeerReport) -> str:
    peer = report.peer.value
    lines = [
        f'# {report.scene}: contact exported to {peer}',
        '',
        f'Time step {report.timestep:g} s; {report.evaluations} {peer} evaluations of '
        f'{len(report.strikes)} strikes; export took {report.seconds:.1f} s.',
        '',
        f'Exported contact: `{report.contact}`',
        '',
        f'{peer} defaults (same time step): `{report.defaults}`',
        '',
        '## Residual (relative to ours; v_t relative to the strike speed)',
        '',
        f'Each strike is run at {_phase_count(report)} of the time step (the contact '
        'beginning at that fraction of a step) and the mean is compared; "phase spread" is '
        "the widest range of a quantity over the phases at one strike: the peer's own scatter "
        'from impact to impact in a closed loop, which no contact parameter removes.',
        '',
        '| quantity | exported: rms | exported: worst (strike) | exported: phase spread '
        '(strike) | defaults: rms | defaults: worst (strike) |',
        '|---|---|---|---|---|---|',
    ]
    for tuned, default in zip(report.tuned_residual, report.default_residual):
        lines.append(
            f'| {UNITS[tuned.quantity][0]} | {tuned.rms:.1%} | {tuned.worst:.1%} ({tuned.at}) '
            f'| {_spread(tuned)} | {default.rms:.1%} | {default.worst:.1%} ({default.at}) |'
        )
    lines += ['', '## Every strike (ours / exported / defaults)', '']
    header = '| strike | speed [m/s] | ' + ' | '.join(UNITS[q][0] for q in Quantity) + ' |'
    lines += [header, '|---|---|' + '---|' * len(Quantity)]
    for s, o, t, d in zip(report.strikes, report.ours, report.tuned, report.default_outcomes):
        cells = [' / '.join(_cell(x, q) for x in (o, t, d)) for q in Quantity]
        lines.append(f'| {s.label} | {s.speed:.2f} | ' + ' | '.join(cells) + ' |')
    lines += [
        '',
        '## What the peer cannot represent',
        '',
        LIMITS[report.peer],
        '',
        "Strikes: the whole arm, unpowered, in the posture of the scene's limit-cycle "
        "impact; oblique at that impact's joint rates times the speed ratio, normal at the "
        'rates of least norm giving the same tip speed straight down. "(stuck)": the tip '
        'had not left the surface when the run ended.',
        '',
    ]
    return '\n'.join(lines)
