"""What a diagnosis reports: the kinds of finding, one finding (what was seen, its estimate,
what to do) and the diagnosis of a recording (the findings, the checks that ran and those
that could not, the corrections applied)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum


class FindingKind(str, Enum):
    DIFFERENCE_RATES = 'difference_rates'
    FILTERED_RATES = 'filtered_rates'
    STAMP_JITTER = 'stamp_jitter'
    EFFORT_DELAY = 'effort_delay'
    POSITION_NOISE = 'position_noise'
    WRENCH_LAG = 'wrench_lag'


@dataclass(frozen=True)
class Finding:
    """One effect found: what was seen (with its estimate) and what to do."""

    kind: FindingKind
    estimate: float  # in ``unit``: the delay, the jitter rms, the noise, the share of rates
    unit: str
    seen: str  # one sentence with the numbers
    advice: str  # what to do about it
    corrected_by: str = ''  # the option that corrects it, when given

    def text(self) -> str:
        done = f' (corrected: {self.corrected_by})' if self.corrected_by else ''
        return f'{self.seen}{done}; {self.advice}'

    def to_json(self) -> dict:
        return {
            'kind': self.kind.value,
            'estimate': self.estimate,
            'unit': self.unit,
            'seen': self.seen,
            'advice': self.advice,
            'corrected_by': self.corrected_by,
        }


@dataclass
class Diagnosis:
    """The findings of every check that could run, and why the others could not."""

    findings: list[Finding] = field(default_factory=list)
    checked: list[FindingKind] = field(default_factory=list)
    skipped: dict[FindingKind, str] = field(default_factory=dict)
    estimates: dict[FindingKind, float] = field(default_factory=dict)  # also when quiet
    corrections: list[str] = field(default_factory=list)

    def kinds(self) -> set[FindingKind]:
        return {f.kind for f in self.findings}

    def lines(self) -> list[str]:
        """What the command line says: each finding, or that there is none, and the checks
        that could not run."""
        out = [f'recording diagnosis: {f.text()}' for f in self.findings] or [
            f'recording diagnosis: nothing found ({len(self.checked)} checks)'
        ]
        if self.skipped:
            out.append(
                'recording diagnosis: not checked: '
                + '; '.join(f'{k.value} ({why})' for k, why in self.skipped.items())
            )
        return out

    def markdown(self) -> list[str]:
        """The fit report's section on the recording itself."""
        lines = ['## The recording', '']
        if self.findings:
            lines += [f'- **{f.kind.value}**: {f.text()}.' for f in self.findings]
        else:
            lines.append(f'Nothing found by the {len(self.checked)} checks that could run.')
        lines += [f'- not checked, {k.value}: {why}' for k, why in self.skipped.items()]
        lines += [f'- corrected before the fit, {c}' for c in self.corrections]
        return lines + ['']

    def to_json(self) -> dict:
        return {
            'findings': [f.to_json() for f in self.findings],
            'checked': [k.value for k in self.checked],
            'skipped': {k.value: why for k, why in self.skipped.items()},
            'estimates': {k.value: v for k, v in self.estimates.items()},
            'corrections': list(self.corrections),
        }
