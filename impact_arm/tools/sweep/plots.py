"""Plots of a sweep's tables: a metric against one or two swept parameters."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

from ...physics.errors import ImpactArmError
from ...calibration.study import parse_key_path
from .spec import SpecError
from .store import read_table


# units of the run and impact columns (docs/outputs.md); parameters take theirs from the schema
COLUMN_UNITS = {
    'impacts': '',
    't_end': 's',
    'period': 's',
    'settled_after': 'impacts',
    'impacts_per_cycle': 'impacts',
    'cor_kinematic': '',
    'cor_energetic': '',
    'rhs_evaluations': '',
    'steps': '',
    'wall_time': 's',
    't_contact': 's',
    'duration': 's',
    'delta_m': 'm',
    'delta_r': 'm',
    'F_max': 'N',
    'v_before': 'm/s',
    'v_after': 'm/s',
    'T_before': 'J',
    'T_after': 'J',
    'q_contact_deg': 'deg',
    'phase_durations': 's',
    'index': '',
}


def column_unit(name: str) -> str:
    """The unit of a table column: a metric's, or a swept key path's from the scene schema
    ('' when dimensionless or unknown)."""
    from ...physics.scene import SCHEMA

    base = name.split('[', 1)[0]
    if base in COLUMN_UNITS:
        return COLUMN_UNITS[base]
    try:
        parts = parse_key_path(name)
    except ImpactArmError:
        return ''
    node = ('dict', SCHEMA, '', None)
    for part in parts:
        kind, inner = node[0], node[1]
        if isinstance(part, int):
            if kind == 'vec':
                continue
            if kind != 'list':
                return ''
            node = ('dict', inner, '', None)
        elif kind == 'map':
            node = ('dict', inner, '', None)  # materials.<name>
        elif kind == 'dict' and part in inner:
            node = inner[part]
        else:
            return ''
    unit = node[2] if isinstance(node[2], str) else ''
    return '' if unit == '-' else unit


def axis_label(name: str) -> str:
    unit = column_unit(name)
    return f'{name} [{unit}]' if unit else f'{name} [-]'


def plot_file_name(metric, x, y=None) -> str:
    """'cor_kinematic_vs_surfaces_0_.mu' style names without brackets or dots to trip a
    shell: key paths become words joined by '_'."""
    import re

    words = [re.sub(r'[^A-Za-z0-9]+', '_', w).strip('_') for w in (metric, x, y) if w]
    return '_vs_'.join(words[:2]) + (f'_and_{words[2]}' if len(words) > 2 else '') + '.png'


def plot(
    out: str,
    metric: str,
    x: str,
    y: str | None = None,
    table: str = 'runs',
    impact: int | None = None,
    path: str | None = None,
) -> str:
    """``metric`` against one swept parameter (points) or two (points coloured by the metric);
    failed runs are left out. For the impacts table, one impact number (default: the last of
    each run). Returns the PNG's path."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = read_table(out, table)
    names = rows.column_names
    for role, name in (('metric', metric), ('x', x), ('y', y)):
        if name is not None and name not in names:
            raise SpecError(
                f'sweep plot: {role} {name!r} is not a column of the {table} '
                f'table; columns: {", ".join(names)}'
            )
    data = rows.to_pydict()
    keep: Sequence[int] = range(rows.num_rows)
    if table == 'runs':
        keep = [i for i in keep if not data['error'][i]]
    else:
        last = {}
        for i in keep:
            if impact is None or data['index'][i] == impact:
                last[data['run'][i]] = i
        keep = sorted(last.values())
    xs = [data[x][i] for i in keep]
    values = [data[metric][i] for i in keep]
    fig, ax = plt.subplots(figsize=(6.4, 4.8), constrained_layout=True)
    if y is None:
        # runs that share an x (one grid node, several random/LHS draws of other
        # parameters) are spread a little sideways so that they do not hide each other
        ax.plot(_spread(xs), values, 'o', ms=3, alpha=0.7)
        ax.set_ylabel(axis_label(metric))
    else:
        points = ax.scatter(
            xs, [data[y][i] for i in keep], c=values, s=12, cmap='viridis', alpha=0.8
        )
        fig.colorbar(points, ax=ax, label=axis_label(metric))
        ax.set_ylabel(axis_label(y))
    ax.set_xlabel(axis_label(x))
    which = '' if table == 'runs' else f' (impact {impact})' if impact else ' (last impact)'
    stacked = y is None and len(set(xs)) < len(xs)
    ax.set_title(
        f'{metric}{which}: {len(keep)} runs'
        + ('\n(runs sharing an x value are spread sideways by up to 1 %)' if stacked else ''),
        fontsize=10,
    )
    path = path or os.path.join(out, plot_file_name(metric, x, y))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _spread(xs):
    """x values with repeated ones offset by up to ±1 % of the x range (or of the value),
    evenly, so that points stacked on one grid node show as a short row."""
    counts: dict[object, int] = {}
    seen: dict[object, int] = {}
    for v in xs:
        counts[v] = counts.get(v, 0) + 1
    finite = [v for v in xs if isinstance(v, (int, float)) and math.isfinite(v)]
    span = (max(finite) - min(finite)) if len(finite) > 1 else 0.0
    out = []
    for v in xs:
        n = counts[v]
        if n == 1 or not isinstance(v, (int, float)):
            out.append(v)
            continue
        k = seen[v] = seen.get(v, -1) + 1
        width = 0.02 * (span or abs(v) or 1.0)
        out.append(v + width * (k / (n - 1) - 0.5))
    return out
