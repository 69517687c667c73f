"""Helpers shared by the benchmarks: timed runs (ours and scipy's), error metrics against the
``reference`` preset, tables, JSON output and progress lines.

Every timing is the best of ``repeats`` runs inside the same process, so ratios printed by one
benchmark compare like with like on the same machine at the same moment.
"""
from __future__ import annotations

import math
import os
import time
import warnings

from ..progress import Progress

LEVELS_DOC = 'relative error vs the reference preset'


_status = []   # the benchmark's status line, made on first use (stderr as it is then)


def progress(message: str, done=None, total=None) -> None:
    """The benchmark's status line (``tools.progress``): rewritten on a terminal, one line
    per message otherwise; with ``done`` of ``total``, an ETA on a terminal."""
    if not _status:
        _status.append(Progress())
    _status[0].total = total
    _status[0].show(message, done=done, log=True)


def progress_done() -> None:
    """Erase the status line before the results are printed."""
    if _status:
        _status.pop().end()


def load(scene_name: str):
    from ...core.scene import load_scene
    return load_scene(scene_name)


# --- timed runs -----------------------------------------------------------------------------
def time_ours(scene, rtol, atol, repeats=3, max_step=None, method='dopri5', contact_rtol=None):
    """Best-of-``repeats`` event-to-event run (continuous control, no sampled output)."""
    from ...core.simulate import run_events
    best = math.inf
    out = None
    for _ in range(max(1, repeats)):
        impacts, t_end, integ, wall = run_events(scene, rtol=rtol, atol=atol, max_step=max_step,
                                                 method=method, contact_rtol=contact_rtol)
        if wall < best:
            best = wall
        out = impacts, t_end, integ.stats.rhs_evaluations
    impacts, t_end, nfev = out
    return {'impacts': impacts, 't_end': t_end, 'rhs_evaluations': nfev, 'wall': best}


def time_scipy(scene, method, rtol, atol, repeats=3, contact_rtol=None):
    from ..baselines import run_scipy
    best = math.inf
    out = None
    for _ in range(max(1, repeats)):
        with warnings.catch_warnings():
            # rejected trial steps of the explicit methods overflow harmlessly inside contact
            warnings.simplefilter('ignore', RuntimeWarning)
            impacts, t_end, nfev, wall = run_scipy(scene, method, rtol, atol,
                                                   contact_rtol=contact_rtol)
        best = min(best, wall)
        out = impacts, t_end, nfev
    impacts, t_end, nfev = out
    return {'impacts': impacts, 't_end': t_end, 'rhs_evaluations': nfev, 'wall': best}


# --- metrics --------------------------------------------------------------------------------
def _rel(value, ref):
    if ref == 0:
        return abs(value)
    return abs(value / ref - 1.0)


def _rel_vec(value, ref):
    num = math.sqrt(sum((a - b) ** 2 for a, b in zip(value, ref)))
    den = math.sqrt(sum(b * b for b in ref))
    return num / den if den else num


# "the first impact's metrics (duration, δm, δr, F_max, post-impact tip velocity,
# energies)": each component's own relative error, the level is their maximum
SPEED_KEYS = ('duration', 'delta_m', 'delta_r', 'F_max', 'v_after', 'T_before', 'T_after')


def first_impact_error(impacts, ref_impacts):
    """Worst relative error, component by component, of the first impact's metrics."""
    if not impacts:
        return math.inf
    a, b = impacts[0], ref_impacts[0]
    worst = 0.0
    for key in SPEED_KEYS:
        va, vb = a[key], b[key]
        if isinstance(vb, list):
            worst = max([worst] + [_rel(x, y) for x, y in zip(va, vb)])
        else:
            worst = max(worst, _rel(va, vb))
    return worst


# the trade-off metrics, each a relative error (t15: as a fraction of the period)
TRADEOFF_METRICS = ('delta_m', 'F_max', 'v_after', 'cor_kin', 'cor_energy', 'v15_contact',
                    't15')
METRIC_LABELS = {
    'delta_m': 'δm #1', 'F_max': 'Fmax #1', 'v_after': 'v after #1', 'cor_kin': 'e #1',
    'cor_energy': 'e_energy #1', 'v15_contact': 'v contact #15', 't15': 't #15 / period'}


def tradeoff_errors(impacts, ref_impacts):
    """Relative errors of the trade-off metrics; inf where the run lacks the impact."""
    out = {k: math.inf for k in TRADEOFF_METRICS}
    if impacts:
        a, b = impacts[0], ref_impacts[0]
        out['delta_m'] = _rel(a['delta_m'], b['delta_m'])
        out['F_max'] = _rel(a['F_max'], b['F_max'])
        out['v_after'] = _rel_vec(a['v_after'], b['v_after'])
        out['cor_kin'] = _rel(a['cor_kinematic'], b['cor_kinematic'])
        out['cor_energy'] = max(_rel(x, y) for x, y in zip(a['cor_energetic'],
                                                            b['cor_energetic']))
    k = len(ref_impacts) - 1
    if len(impacts) > k >= 1:
        a, b = impacts[k], ref_impacts[k]
        period = b['t_contact'] - ref_impacts[k - 1]['t_contact']
        out['v15_contact'] = _rel_vec(a['v_before'], b['v_before'])
        out['t15'] = abs(a['t_contact'] - b['t_contact']) / period
    return out


def worst(errors: dict) -> float:
    return max(errors.values()) if errors else math.inf


# --- output ---------------------------------------------------------------------------------
def fmt_err(x: float) -> str:
    if x is None or not math.isfinite(x):
        return 'miss'
    if x == 0:
        return '0'
    return f'{x:.1e}'


def table(header, rows, align=None) -> str:
    """Plain-text table (also valid Markdown)."""
    cells = [list(map(str, header))] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    align = align or ['<'] + ['>'] * (len(header) - 1)

    def line(r):
        return '| ' + ' | '.join(f'{c:{a}{w}}' for c, a, w in zip(r, align, widths)) + ' |'
    sep = '|' + '|'.join(('-' * (w + 1) + ':') if a == '>' else ('-' * (w + 2))
                         for a, w in zip(align, widths)) + '|'
    return '\n'.join([line(cells[0]), sep] + [line(r) for r in cells[1:]])


def write_json(path, data) -> None:
    """The CLI's atomic JSON writer (non-finite numbers as null), creating the directory."""
    from ..cli import write_json as write_atomically
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    write_atomically(path, data)
    print(f'wrote {path}')


def machine() -> dict:
    import platform
    import numpy
    import scipy
    try:
        import numba
        nb = numba.__version__
    except ImportError:
        nb = None
    from ...core import jit
    return {'python': platform.python_version(), 'numpy': numpy.__version__,
            'scipy': scipy.__version__, 'numba': nb, 'jit': jit.AVAILABLE,
            'cpus': os.cpu_count(), 'time': time.strftime('%Y-%m-%dT%H:%M:%S')}


def cpu_seconds(stat_path) -> float:
    """User + system CPU seconds from a /proc ``stat`` file (a process's or a thread's)."""
    with open(stat_path) as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
