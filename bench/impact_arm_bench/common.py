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
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from impact_arm.tools.progress import Progress

if TYPE_CHECKING:
    from impact_arm.physics.impact import Impact
    from impact_arm.physics.scene import Scene

LEVELS_DOC = 'relative error vs the reference preset'

# the folder holding this package: it is not installed, so a worker process is told where it is
BENCH_FOLDER = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


_status = []  # the benchmark's status line, made on first use (stderr as it is then)


def progress(message: str, done: float | None = None, total: float | None = None) -> None:
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


def worker_environment(env: dict | None = None) -> dict:
    """``env`` (default: this process's environment) with the benchmarks' folder first on
    PYTHONPATH, for a worker process that imports impact_arm_bench."""
    env = dict(os.environ if env is None else env)
    others = [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p and p != BENCH_FOLDER]
    env['PYTHONPATH'] = os.pathsep.join([BENCH_FOLDER, *others])
    return env


def load(scene_name: str) -> Scene:
    from impact_arm.physics.scene import load_scene

    return load_scene(scene_name)


# --- timed runs -----------------------------------------------------------------------------
def time_ours(
    scene: Scene,
    rtol: float,
    atol: float | None,
    repeats: int = 3,
    max_step: float | None = None,
    method: str = 'dopri5',
    contact_rtol: float | None = None,
) -> dict[str, Any]:
    """Best-of-``repeats`` event-to-event run (continuous control, no sampled output)."""
    from impact_arm.physics.simulate import run

    best = math.inf
    out = None
    for _ in range(max(1, repeats)):
        result = run(
            scene,
            samples=False,
            rtol=rtol,
            atol=atol,
            max_step=max_step,
            method=method,
            contact_rtol=contact_rtol,
        )
        if result.exception:
            raise result.exception
        if result.wall_time < best:
            best = result.wall_time
        out = result.impacts, result.t_end, result.rhs_evaluations
    impacts, t_end, nfev = out
    return {'impacts': impacts, 't_end': t_end, 'rhs_evaluations': nfev, 'wall': best}


def time_scipy(
    scene: Scene,
    method: str,
    rtol: float,
    atol: float | None,
    repeats: int = 3,
    contact_rtol: float | None = None,
) -> dict[str, Any]:
    from impact_arm.tools.baselines import run_scipy

    best = math.inf
    out = None
    for _ in range(max(1, repeats)):
        with warnings.catch_warnings():
            # rejected trial steps of the explicit methods overflow harmlessly inside contact
            warnings.simplefilter('ignore', RuntimeWarning)
            impacts, t_end, nfev, wall = run_scipy(
                scene, method, rtol, atol, contact_rtol=contact_rtol
            )
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


# The trade-off metrics, each the worst over EVERY impact of the run (a sweep or a fit reads the
# limit-cycle impacts, not only the first): relative errors of δm, F_max, duration, post-impact
# tip velocity (vector norm), kinematic CoR, energetic CoRs (worst of links and total); each
# impact's time as a fraction of the reference's limit-cycle period; and that period (the last
# interval between impacts), relative. A run with another number of impacts than the
# reference misses (inf).
TRADEOFF_METRICS = (
    'delta_m',
    'F_max',
    'duration',
    'v_after',
    'cor_kin',
    'cor_energy',
    't_impact',
    'period',
)
METRIC_LABELS = {
    'delta_m': 'δm',
    'F_max': 'F_max',
    'duration': 'duration',
    'v_after': 'v after',
    'cor_kin': 'e',
    'cor_energy': 'e_energy',
    't_impact': 't / period',
    'period': 'period',
}


def _impact_errors(a: Impact, b: Impact) -> dict[str, float]:
    """One impact's relative errors against its reference (keys of TRADEOFF_METRICS); both
    ``Impact`` records."""
    return {
        'delta_m': _rel(a.delta_m, b.delta_m),
        'F_max': _rel(a.F_max, b.F_max),
        'duration': _rel(a.duration, b.duration),
        'v_after': _rel_vec(a.v_after, b.v_after),
        'cor_kin': _rel(a.cor_kinematic, b.cor_kinematic),
        'cor_energy': max(_rel(x, y) for x, y in zip(a.cor_energetic, b.cor_energetic)),
    }


def _period(impacts: Sequence[Impact]) -> float:
    return impacts[-1].t_contact - impacts[-2].t_contact if len(impacts) > 1 else math.nan


def per_impact_errors(
    impacts: Sequence[Impact], ref_impacts: Sequence[Impact]
) -> list[dict[str, float]]:
    """One dict of errors per impact (``TRADEOFF_METRICS`` but the period), in order."""
    period = _period(ref_impacts)
    rows = []
    for a, b in zip(impacts, ref_impacts):
        row = _impact_errors(a, b)
        row['t_impact'] = (
            abs(a.t_contact - b.t_contact) / period if math.isfinite(period) else math.nan
        )
        rows.append(row)
    return rows


def tradeoff_errors(impacts: Sequence[Impact], ref_impacts: Sequence[Impact]) -> dict[str, float]:
    """Each metric's worst error over every impact (and the limit-cycle period's error);
    inf everywhere when the run has another number of impacts than the reference."""
    out = {k: math.inf for k in TRADEOFF_METRICS}
    if not impacts or len(impacts) != len(ref_impacts):
        return out
    rows = per_impact_errors(impacts, ref_impacts)
    for key in TRADEOFF_METRICS[:-1]:
        values = [r[key] for r in rows if not math.isnan(r[key])]
        out[key] = max(values) if values else math.nan
    out['period'] = _rel(_period(impacts), _period(ref_impacts)) if len(impacts) > 1 else math.nan
    return out


def every_impact_error(impacts: Sequence[Impact], ref_impacts: Sequence[Impact]) -> float:
    """The worst of ``tradeoff_errors``: the level a setting reaches."""
    return worst(tradeoff_errors(impacts, ref_impacts))


def worst(errors: dict) -> float:
    values = [v for v in errors.values() if not math.isnan(v)]
    return max(values) if values else math.inf


# --- output ---------------------------------------------------------------------------------
def fmt_err(x: float) -> str:
    if x is None or not math.isfinite(x):
        return 'miss'
    if x == 0:
        return '0'
    return f'{x:.1e}'


def table(
    header: Sequence[Any], rows: Iterable[Sequence[Any]], align: Sequence[str] | None = None
) -> str:
    """Plain-text table (also valid Markdown)."""
    cells = [list(map(str, header))] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    align = align or ['<'] + ['>'] * (len(header) - 1)

    def line(r: Sequence[str]) -> str:
        return '| ' + ' | '.join(f'{c:{a}{w}}' for c, a, w in zip(r, align, widths)) + ' |'

    sep = (
        '|'
        + '|'.join(
            ('-' * (w + 1) + ':') if a == '>' else ('-' * (w + 2)) for a, w in zip(align, widths)
        )
        + '|'
    )
    return '\n'.join([line(cells[0]), sep] + [line(r) for r in cells[1:]])


def write_json(path: str, data: Any) -> None:
    """The CLI's atomic JSON writer (non-finite numbers as null), creating the directory."""
    from impact_arm.tools.cli import write_json as write_atomically

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
    from impact_arm.physics import jit

    return {
        'python': platform.python_version(),
        'numpy': numpy.__version__,
        'scipy': scipy.__version__,
        'numba': nb,
        'jit': jit.AVAILABLE,
        'cpus': os.cpu_count(),
        'time': time.strftime('%Y-%m-%dT%H:%M:%S'),
    }


def cpu_seconds(stat_path: str) -> float:
    """User + system CPU seconds from a /proc ``stat`` file (a process's or a thread's)."""
    with open(stat_path) as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def paper_dict() -> dict[str, Any]:
    """The article's scene file as YAML data, to vary in the benchmarks."""
    import yaml
    from impact_arm.physics.scene import resolve_scene_path
    from impact_arm.physics.scene.files import _SceneLoader

    with open(resolve_scene_path('paper'), encoding='utf-8') as f:
        return yaml.load(f.read(), Loader=_SceneLoader)
