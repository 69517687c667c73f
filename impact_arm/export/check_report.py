"""What ``export --check`` prints and writes (check.md, check.json): the impact table, ours
beside the peer's with the differences, and the differences' first, mean and worst."""

from __future__ import annotations

import dataclasses
import json
import math

from .check import CheckResult, controller_input
from .files import write
from .impacts import Column, ImpactRow, differences

# per column: heading, scale from SI, format; and the difference's heading and scale
UNITS = {
    Column.T_CONTACT: ('t_contact [s]', 1.0, '.5f', 'Δ [ms]', 1e3),
    Column.V_BEFORE: ('v_n before [m/s]', 1.0, '.3f', 'Δ [%]', 100.0),
    Column.COR: ('e', 1.0, '.3f', 'Δ [%]', 100.0),
    Column.DURATION: ('duration [µs]', 1e6, '.1f', 'Δ [%]', 100.0),
    Column.F_MAX: ('F_max [kN]', 1e-3, '.2f', 'Δ [%]', 100.0),
}


def _number(x: float) -> float | None:
    """JSON has no NaN: null, and the text says NaN."""
    return float(x) if math.isfinite(x) else None


def _value(column: Column, x: float) -> str:
    _, scale, fmt, _, _ = UNITS[column]
    return format(x * scale, fmt)


def _difference(column: Column, x: float, signed: bool = True) -> str:
    return format(x * UNITS[column][4], '+.2f' if signed else '.2f')


def _count(result: CheckResult, rows: tuple[ImpactRow, ...], stopped: str) -> str:
    """How many impacts a side gave, and why it stopped when they are too few."""
    short = len(rows) < result.impacts_wanted
    return f'{len(rows)} impacts' + (f' (stopped: {stopped})' if short else '')


def headline(result: CheckResult) -> list[str]:
    """What ran, in words."""
    peer = result.peer.value
    return [
        f'{result.scene}: {result.cycles} cycles ({result.impacts_wanted} impacts) in closed '
        f"loop with the scene's controller at {result.rate:g} Hz (zero-order hold), ours "
        f"beside {peer} at the export's time step {result.timestep:g} s.",
        f'The controller sees {controller_input(result.peer)}.',
        f'Ours: {_count(result, result.ours, result.our_stopped)}, {result.our_seconds:.1f} s; '
        f'{peer}: {_count(result, result.theirs, result.peer_stopped)}, '
        f'{result.peer_steps} steps, {result.peer_seconds:.1f} s.',
    ]


def table(result: CheckResult) -> list[str]:
    """The impact table (markdown): ours / the peer's / the difference per quantity."""
    peer = result.peer.value
    head = ['k'] + [f'{UNITS[c][0]} ours / {peer} / {UNITS[c][3]}' for c in Column]
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    rows = differences(result.ours, result.theirs)
    for k, (a, b, diff) in enumerate(zip(result.ours, result.theirs, rows)):
        cells = [str(k + 1)] + [
            f'{_value(c, getattr(a, c.value))} / {_value(c, getattr(b, c.value))} / '
            f'{_difference(c, d)}'
            for c, d in zip(Column, diff)
        ]
        lines.append('| ' + ' | '.join(cells) + ' |')
    return lines


def summary(result: CheckResult) -> list[str]:
    """Each quantity's difference at the first impact, mean and worst over all."""
    lines = ['| quantity | first | mean abs | worst abs (impact) |', '|---|---|---|---|']
    for s in result.summary:
        name, unit = UNITS[s.column][0], UNITS[s.column][3]
        lines.append(
            f'| {name.split(" [")[0]} {unit} | {_difference(s.column, s.first)} | '
            f'{_difference(s.column, s.mean, False)} | '
            f'{_difference(s.column, s.worst, False)} ({s.at}) |'
        )
    return lines


def verdict(result: CheckResult) -> str:
    failures = result.failures
    tolerance = f'{result.tolerance * 1e3:g} ms'
    if not failures:
        return (
            f'AGREE: {result.impacts_wanted} impacts on both sides, contact times within '
            f'{tolerance} at every impact.'
        )
    return 'DIFFER: ' + '; '.join(failures) + '.'


def to_markdown(result: CheckResult) -> str:
    return '\n'.join(
        [f'# {result.scene}: {result.peer.value} checked in closed loop', '']
        + headline(result)
        + ['', verdict(result), '', '## Differences (peer minus ours; relative but time)', '']
        + summary(result)
        + ['', '## Every impact', '']
        + table(result)
        + ['']
    )


def to_json(result: CheckResult) -> dict:
    def row(r: ImpactRow) -> dict:
        return {k: _number(v) for k, v in dataclasses.asdict(r).items()}

    return {
        'scene': result.scene,
        'peer': result.peer.value,
        'timestep': result.timestep,
        'rate': result.rate,
        'cycles': result.cycles,
        'controller_input': controller_input(result.peer),
        'ours': [row(r) for r in result.ours],
        'peer_impacts': [row(r) for r in result.theirs],
        'differences': [
            {c.value: _number(d) for c, d in zip(Column, diff)}
            for diff in differences(result.ours, result.theirs)
        ],
        'summary': {
            s.column.value: {
                'first': _number(s.first),
                'mean_abs': _number(s.mean),
                'worst_abs': _number(s.worst),
                'at': s.at,
            }
            for s in result.summary
        },
        'relative': [c.value for c in Column if c.relative],
        'tolerance_t_contact': result.tolerance,
        'agree': not result.failures,
        'failures': result.failures,
        'our_stopped': result.our_stopped,
        'peer_stopped': result.peer_stopped,
        'seconds': {'ours': result.our_seconds, 'peer': result.peer_seconds},
        'peer_steps': result.peer_steps,
    }


def write_check(result: CheckResult) -> list[str]:
    """check.md and check.json into the export's directory; their paths."""
    return [
        write(result.directory, 'check.md', to_markdown(result)),
        write(result.directory, 'check.json', json.dumps(to_json(result), indent=1) + '\n'),
    ]
