"""``impact-arm sweep SPEC.yaml``: many runs of a scene on the event-only path, to Parquet.

A spec names a base scene, fixed overrides, swept parameters by key path and the tables
wanted (docs/studies.md)::

    scene: paper                       # path (relative to this file) or installed name
    set: {integrator.rtol: 1.0e-2}     # applied to every run
    parameters:
      surfaces[0].mu: {grid: [0.0, 0.6, 4]}          # start, stop, count
      controller.kp[0]: {list: [400, 600, 800]}
      materials.steel.E: {random: [1.0e11, 3.0e11], scale: log}
      controller.kd[0]: {lhs: [50, 150]}            # Latin hypercube
    samples: 100          # draws of the random / lhs parameters (per grid point)
    seed: 1
    outputs: [runs, impacts]

Runs are the Cartesian product of the grid and list values times ``samples`` draws. Results
go to ``OUT/runs/`` and ``OUT/impacts/`` as Parquet part files (a row per run / per impact,
overrides as columns, a failed run is a row with its error). A part is written to a temporary
name and renamed, the runs part last, so a sweep killed at any point and started again with
the same command runs exactly the runs that have no row yet.

Runs go to local worker processes (each keeps its parsed scene and compiled kernels between
chunks of runs) or to a Dask distributed scheduler (``--cluster``). pyarrow and dask are the
``studies`` extra: imported only here, never by the nodes.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import time
from collections.abc import Sequence

from ..physics.errors import ImpactArmError
from ..calibration.study import Study, load_scene_data, parse_key_path
from .progress import Progress

KINDS = ('grid', 'list', 'random', 'lhs')
TABLES = ('runs', 'impacts')
SPEC_KEYS = ('scene', 'set', 'parameters', 'samples', 'seed', 'outputs')


class SpecError(ImpactArmError):
    """A sweep spec with a missing, unknown or out-of-range entry."""


# --- the spec ---------------------------------------------------------------------------
class Spec:
    """A validated sweep spec: base scene data, fixed overrides, parameters and their runs."""

    def __init__(self, data: dict, origin: str = '<spec>', base_dir: str = '.'):
        def fail(key, message):
            raise SpecError(f"sweep '{origin}': {key} {message}")

        if not isinstance(data, dict):
            fail('<top level>', 'must be a mapping')
        unknown = sorted(set(data) - set(SPEC_KEYS))
        if unknown:
            fail(unknown[0], f'is not a known key; allowed: {", ".join(SPEC_KEYS)}')
        scene = data.get('scene', 'paper')
        if isinstance(scene, str) and os.path.exists(os.path.join(base_dir, scene)):
            scene = os.path.join(base_dir, scene)
        self.scene_data, self.scene_origin = load_scene_data(scene)
        self.fixed = dict(data.get('set') or {})
        for key in self.fixed:
            parse_key_path(key)
        self.seed = data.get('seed', 0)
        self.samples = data.get('samples', 1)
        for key, value in (('seed', self.seed), ('samples', self.samples)):
            if isinstance(value, bool) or not isinstance(value, int) or value < (key == 'samples'):
                fail(key, f'= {value!r} must be an integer >= {int(key == "samples")}')
        self.outputs = tuple(data.get('outputs', TABLES))
        if not self.outputs or set(self.outputs) - set(TABLES):
            fail('outputs', f'= {list(self.outputs)!r}: choose from {", ".join(TABLES)}')
        self.parameters = {}
        for key, entry in (data.get('parameters') or {}).items():
            parse_key_path(key)
            self.parameters[key] = _parameter(
                key, entry, lambda m, k=key: fail(f'parameters.{k}', m)
            )
        self.hash = hashlib.sha256(
            json.dumps(
                {
                    'scene': self.scene_data,
                    'set': self.fixed,
                    'parameters': self.parameters,
                    'samples': self.samples,
                    'seed': self.seed,
                    'outputs': self.outputs,
                },
                sort_keys=True,
                default=str,
            ).encode()
        ).hexdigest()[:12]
        self.runs = self._expand()
        self._check_key_paths(origin)

    def _check_key_paths(self, origin):
        """Refuse a key path the scene does not have (``surfaces[0].muu``, an index past the
        end) now, before any run: otherwise every run fails with the same error. Each path is
        tried alone with its first run's value; out-of-range values are the runs' business
        (a sweep may cross the schema's limits on purpose)."""
        from ..physics.errors import SceneError

        first = self.runs[0] if self.runs else {}
        errors = []

        def check(base, key, value):
            try:
                Study(self.scene_data, base).scene({key: value})
            except SceneError as exc:
                text = str(exc)
                if 'is not a known key' in text or text.startswith('override '):
                    errors.append(f'{key}: {text}')

        # the fixed overrides alone first (a parameter's path may need one of them, e.g. a
        # second surface), then each parameter on top of them
        for key, value in self.fixed.items():
            check({}, key, value)
        if not errors:
            for key in self.parameters:
                check(self.fixed, key, first.get(key))
        if errors:
            raise SpecError(
                f"sweep '{origin}': {len(errors)} key path(s) the scene does not "
                f'have, nothing was run:\n  ' + '\n  '.join(errors)
            )

    def _expand(self) -> list[dict]:
        """Each run's overrides, in run order: grid/list product (first parameter slowest)
        times the samples of the random/LHS parameters (seeded)."""
        import numpy as np

        fixed = {k: v for k, v in self.parameters.items() if v['kind'] in ('grid', 'list')}
        drawn = {k: v for k, v in self.parameters.items() if v['kind'] in ('random', 'lhs')}
        samples = self.samples if drawn else 1
        rng = np.random.default_rng(self.seed)
        columns = {}
        for key, p in drawn.items():
            u = rng.random(samples)
            if p['kind'] == 'lhs':  # one draw in each of `samples` equal strata
                u = (rng.permutation(samples) + u) / samples
            low, high = p['range']
            values = low * (high / low) ** u if p['scale'] == 'log' else low + (high - low) * u
            columns[key] = values.tolist()
        runs = []
        for point in itertools.product(*(p['values'] for p in fixed.values())):
            for s in range(samples):
                overrides = dict(zip(fixed, point))
                overrides.update({k: column[s] for k, column in columns.items()})
                runs.append(overrides)
        return runs

    @classmethod
    def load(cls, path: str) -> 'Spec':
        from ..physics.scene import scene_data

        try:
            with open(path, encoding='utf-8') as f:
                text = f.read()
        except OSError as exc:
            raise SpecError(f"sweep '{path}': cannot be read: {exc.strerror}") from None
        return cls(
            scene_data(text, path, 'sweep'),
            origin=path,
            base_dir=os.path.dirname(os.path.abspath(path)),
        )


def _parameter(key, entry, fail) -> dict:
    if (
        not isinstance(entry, dict)
        or len(set(entry) & set(KINDS)) != 1
        or set(entry) - set(KINDS) - {'scale'}
    ):
        fail(
            f'= {entry!r} must be a mapping with one of {", ".join(KINDS)} (and scale for '
            f'random/lhs)'
        )
    kind = next(k for k in KINDS if k in entry)
    value = entry[kind]
    scale = entry.get('scale', 'linear')
    if scale not in ('linear', 'log'):
        fail(f'scale = {scale!r} is not allowed: choose linear or log')
    if kind == 'list':
        if not isinstance(value, list) or not value:
            fail(f'list = {value!r} must be a non-empty list of values')
        return {'kind': kind, 'values': value}
    numbers = isinstance(value, list) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
    )
    if kind == 'grid':
        if not numbers or len(value) != 3 or value[2] < 1 or int(value[2]) != value[2]:
            fail(f'grid = {value!r} must be [start, stop, count] with count an integer >= 1')
        start, stop, count = float(value[0]), float(value[1]), int(value[2])
        values = (
            [start + (stop - start) * i / (count - 1) for i in range(count)]
            if count > 1
            else [start]
        )
        return {'kind': kind, 'values': values}
    if (
        not numbers
        or len(value) != 2
        or not value[0] < value[1]
        or (scale == 'log' and value[0] <= 0)
    ):
        fail(f'{kind} = {value!r} must be [low, high] with low < high (low > 0 for scale log)')
    return {'kind': kind, 'range': (float(value[0]), float(value[1])), 'scale': scale}


# --- rows ------------------------------------------------------------------------------------
def _column_value(value):
    """An override as a table cell: numbers as floats, anything else as its JSON text."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return value if isinstance(value, str) else json.dumps(value)


def _layout(fixed: dict, record: dict) -> tuple:
    """What decides an impact row's columns: the override keys and the record's list
    lengths (the number of links, which an override may change)."""
    return tuple(fixed), tuple(len(v) if isinstance(v, list) else -1 for v in record.values())


def _add_impacts(tables: dict, fixed: dict, records: list):
    """Append one run's impact records to ``tables`` (layout -> {column: values}): ``fixed``
    (run index, overrides) repeated per impact, the records' lists spread over columns
    named by key path (v_before[1]). Filled a column at a time while the records are
    fresh: per-value appends, or columns gathered from the whole chunk's records at the
    end, cost a sweep worker several % of a run."""
    if not records:
        return
    first = records[0]
    layout = _layout(fixed, first)
    if layout not in tables:
        names = list(fixed)
        for key, length in zip(first, layout[1]):
            names += [key] if length < 0 else [f'{key}[{i}]' for i in range(length)]
        tables[layout] = {name: [] for name in names}
    columns = iter(tables[layout].values())
    for value in fixed.values():
        next(columns).extend([value] * len(records))
    for key, length in zip(first, layout[1]):
        if length < 0:
            next(columns).extend([r[key] for r in records])
            continue
        # the records' lists, transposed: one column per entry (every record of a run has
        # the first's lengths)
        for column in zip(*[r[key] for r in records]):
            next(columns).extend(column)


def _impacts_table(tables: dict):
    """The impact rows collected by ``_add_impacts`` as one table (None without impacts);
    runs of different layouts make tables joined by column name."""
    import pyarrow as pa

    parts = [pa.table(columns) for columns in tables.values()]
    if len(parts) > 1:
        return pa.concat_tables(parts, promote_options='default')
    return parts[0] if parts else None


_STUDIES: dict[str, Study] = {}  # spec hash -> Study, kept by each worker process between chunks


def run_chunk(spec_hash: str, scene_data: dict, fixed: dict, outputs: tuple, items: list):
    """Run ``items`` [(run index, overrides)] in this process; returns {table: pyarrow Table}.
    Module-level so that worker processes and Dask workers import it by name."""
    import pyarrow as pa

    study = _STUDIES.get(spec_hash)
    if study is None:
        study = _STUDIES[spec_hash] = Study(scene_data, fixed)
    runs: list[dict] = []
    impacts: dict = {}  # layout -> {column: values} (_add_impacts)
    for index, overrides in items:
        result = study.run(overrides)
        columns = {'run': index, **{k: _column_value(v) for k, v in overrides.items()}}
        runs.append(
            {**columns, **result.summary, 'error': result.error, 'error_kind': result.error_kind}
        )
        if 'impacts' in outputs:
            _add_impacts(impacts, columns, result.impacts)
    # the runs table is always written: it is also the record of which runs are finished
    tables = {'runs': pa.Table.from_pylist(runs)}
    table = _impacts_table(impacts)
    if table is not None:
        tables['impacts'] = table
    return tables


# --- storage -----------------------------------------------------------------------------
class ResultStore:
    """Part files of one spec under ``out``: ``runs/`` and ``impacts/``, each part written to
    a temporary name and renamed, the runs part last (it marks its runs as finished)."""

    def __init__(self, out: str, spec: Spec):
        self.out, self.spec = out, spec
        for table in TABLES:
            os.makedirs(os.path.join(out, table), exist_ok=True)
        marker = os.path.join(out, 'spec.json')
        if os.path.exists(marker):
            with open(marker, encoding='utf-8') as f:
                previous = json.load(f).get('hash')
            if previous != spec.hash:
                raise SpecError(
                    f"'{out}' holds the results of another sweep spec (hash "
                    f'{previous}, this one {spec.hash}): choose another --out'
                )
        else:
            _write_atomically(
                marker,
                json.dumps(
                    {
                        'hash': spec.hash,
                        'scene': spec.scene_origin,
                        'set': spec.fixed,
                        'parameters': spec.parameters,
                        'samples': spec.samples,
                        'seed': spec.seed,
                        'runs': len(spec.runs),
                    },
                    indent=1,
                    default=str,
                ).encode(),
            )
        runs = set(self._parts('runs'))
        for table in TABLES:  # leftovers of a killed writer
            folder = os.path.join(out, table)
            for name in os.listdir(folder):
                if name.endswith('.tmp') or (
                    table != 'runs' and name.endswith('.parquet') and name not in runs
                ):
                    os.remove(os.path.join(folder, name))
        self.done = set()
        if runs:
            import pyarrow.parquet as pq

            for name in runs:
                column = pq.read_table(os.path.join(out, 'runs', name), columns=['run'])
                self.done.update(column.column('run').to_pylist())
        self.sequence = 1 + max((int(n.rsplit('-', 1)[1].split('.')[0]) for n in runs), default=-1)

    def _parts(self, table):
        folder = os.path.join(self.out, table)
        return sorted(n for n in os.listdir(folder) if n.endswith('.parquet'))

    def write(self, tables: list[dict]):
        import pyarrow as pa
        import pyarrow.parquet as pq

        name = f'part-{self.spec.hash}-{self.sequence:06d}.parquet'
        for table in ('impacts', 'runs'):
            parts = [t[table] for t in tables if table in t]
            if not parts:
                continue
            path = os.path.join(self.out, table, name)
            pq.write_table(pa.concat_tables(parts, promote_options='default'), path + '.tmp')
            os.replace(path + '.tmp', path)
        self.sequence += 1


def _write_atomically(path, data: bytes):
    with open(path + '.tmp', 'wb') as f:
        f.write(data)
    os.replace(path + '.tmp', path)


def read_table(out: str, table: str = 'runs'):
    """A sweep's table (all parts), in run order (then impact order): a pyarrow Table."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = os.path.join(out, table)
    names = (
        sorted(n for n in os.listdir(folder) if n.endswith('.parquet'))
        if os.path.isdir(folder)
        else []
    )
    if not names:
        raise SpecError(f"'{out}' has no {table} table (no finished sweep runs there)")
    parts = [pq.read_table(os.path.join(folder, n)) for n in names]
    result = pa.concat_tables(parts, promote_options='default')
    keys = [('run', 'ascending')] + ([('index', 'ascending')] if table == 'impacts' else [])
    return result.sort_by(keys)


# --- execution ---------------------------------------------------------------------------
def _chunks(items, workers):
    """Chunks small enough to balance the workers, large enough to amortise a hand-over."""
    size = max(1, min(50, len(items) // (8 * max(1, workers))))
    return [items[i : i + size] for i in range(0, len(items), size)]


def _exit_with_parent():
    """Pool worker initializer: when the sweep dies (SIGKILL included), its workers stop
    too instead of computing runs that nobody will record."""
    import threading

    parent = os.getppid()

    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _local_pool(workers, task, chunks):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn, not fork: the parent may hold pyarrow's threads, which fork does not copy
    pool = ProcessPoolExecutor(
        workers, mp_context=multiprocessing.get_context('spawn'), initializer=_exit_with_parent
    )
    try:
        futures = [pool.submit(task, chunk) for chunk in chunks]
        for future in as_completed(futures):
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _dask(address, task, chunks):
    from distributed import Client, as_completed

    with Client(address) as client:
        futures = client.map(task, chunks, pure=False)
        for future in as_completed(futures):
            yield future.result()


def execute(
    spec: Spec,
    out: str,
    *,
    workers: int | None = None,
    cluster: str | None = None,
    batch: int = 500,
    flush_seconds: float = 5.0,
    show_progress: bool = True,
) -> dict:
    """Run every run of ``spec`` that ``out`` has no row for; returns counts and wall time.

    ``workers``: local processes (default: all cores; 0 runs in this process); ``cluster``:
    a Dask scheduler address instead. A part file is written every ``batch`` finished runs
    or ``flush_seconds``, and on the way out of an error or interrupt."""
    from functools import partial

    wall0 = time.perf_counter()
    store = ResultStore(out, spec)
    todo = [(i, o) for i, o in enumerate(spec.runs) if i not in store.done]
    workers = (os.cpu_count() or 1) if workers is None else workers
    task = partial(run_chunk, spec.hash, spec.scene_data, spec.fixed, spec.outputs)
    if todo and (workers or cluster):
        # compile the base scene's kernels once, here, before the workers load them from
        # the shared on-disk cache (a cold cache would otherwise compile in every worker)
        Study(spec.scene_data, spec.fixed).run(todo[0][1])
    chunks = _chunks(todo, workers if not cluster else 2)
    if cluster:
        results = _dask(cluster, task, chunks)
    elif workers:
        results = _local_pool(workers, task, chunks)
    else:
        results = map(task, chunks)
    progress = Progress(total=len(todo), prefix='sweep: ', keep=True) if show_progress else None
    done = 0
    pending, pending_runs, last_flush = [], 0, time.perf_counter()
    failed, first_result, after_first = 0, None, 0
    errors: dict[str, int] = {}  # distinct error -> runs that failed with it
    try:
        for tables in results:
            pending.append(tables)
            count = tables['runs'].num_rows
            if first_result is None:
                first_result = time.perf_counter()
            else:
                after_first += count
            pending_runs += count
            for error in tables['runs'].column('error').to_pylist():
                if error:
                    failed += 1
                    errors[error] = errors.get(error, 0) + 1
            done += count
            if progress:
                rate = done / max(time.monotonic() - progress.started, 1e-9)
                progress.show(f'{done}/{len(todo)} runs  {rate:7.0f} runs/s', done=done)
            if pending_runs >= batch or time.perf_counter() - last_flush > flush_seconds:
                store.write(pending)
                pending, pending_runs, last_flush = [], 0, time.perf_counter()
    finally:
        if pending:
            store.write(pending)
        if progress:
            progress.end()
    end = time.perf_counter()
    # start-up: until the first chunk is back (worker start, imports, kernels); then the rate
    return {
        'runs': len(spec.runs),
        'skipped': len(spec.runs) - len(todo),
        'ran': len(todo),
        'failed': failed,
        'errors': errors,
        'wall': end - wall0,
        'startup': (first_result or end) - wall0,
        'rate': (
            after_first / (end - first_result)
            if after_first and first_result is not None
            else math.nan
        ),
    }


def summary_line(stats: dict) -> str:
    """The sweep's closing line. A resumed sweep with nothing left to run says so, and a rate
    is given only when it was measured (results after the first chunk), never as nan."""
    head = (
        f'{stats["runs"]} runs: {stats["ran"]} run now, {stats["skipped"]} already done, '
        f'{stats["failed"]} failed (error column)'
    )
    if not stats['ran']:
        return f'{head}: nothing left to run (every run was in the table already)'
    rate = stats['rate']
    then = f'; then {rate:.0f} runs/s' if math.isfinite(rate) else ''
    return (
        f'{head} in {stats["wall"]:.1f} s wall (first results after {stats["startup"]:.1f} s: '
        f'workers, imports, kernels{then})'
    )


# --- plots -------------------------------------------------------------------------------
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
    from ..physics.scene import SCHEMA

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


# --- command line ------------------------------------------------------------------------
def add_arguments(parser):
    parser.description = (
        'Run a sweep spec (impact-arm sweep SPEC.yaml) or plot its results '
        '(impact-arm sweep plot OUT --metric M --x PARAM [--y PARAM]).'
    )
    parser.add_argument(
        'target', metavar='SPEC.yaml | plot', help='the sweep spec to run, or "plot"'
    )
    parser.add_argument(
        'results', nargs='?', metavar='OUT', help="with plot: the sweep's output directory"
    )
    run = parser.add_argument_group('running a spec')
    run.add_argument(
        '--out', metavar='DIR', help='output directory (default: runs/SPEC_NAME.sweep)'
    )
    run.add_argument(
        '--workers',
        type=int,
        default=None,
        metavar='N',
        help='local worker processes (default: all cores; 0: in this process)',
    )
    run.add_argument(
        '--cluster',
        metavar='ADDRESS',
        help='run on this Dask distributed scheduler (e.g. tcp://host:8786)',
    )
    run.add_argument(
        '--csv',
        action='store_true',
        help='also write OUT/runs.csv (and impacts.csv) when the sweep ends',
    )
    run.add_argument(
        '--batch',
        type=int,
        default=500,
        metavar='N',
        help='runs per Parquet part file (default 500)',
    )
    drawing = parser.add_argument_group('plot')
    drawing.add_argument('--metric', default='cor_kinematic', help='column to plot')
    drawing.add_argument('--x', help='swept parameter on the x axis (its key path)')
    drawing.add_argument('--y', help='second swept parameter (colour shows the metric)')
    drawing.add_argument(
        '--table',
        choices=TABLES,
        default='runs',
        help='plot: the table the metric comes from (default runs; impacts: one row per impact)',
    )
    drawing.add_argument('--impact', type=int, help='impacts table: this impact number')
    drawing.add_argument('-o', '--output', metavar='PNG', help='where to write the plot')


def cli(args) -> int:
    if args.target == 'plot':
        if not args.results or not args.x:
            raise SpecError('sweep plot needs the output directory and --x PARAM')
        print(
            'wrote '
            + plot(args.results, args.metric, args.x, args.y, args.table, args.impact, args.output)
        )
        return 0
    if args.results:
        raise SpecError(f'unexpected argument {args.results!r} (only "plot" takes OUT)')
    if args.batch < 1:
        raise SpecError(f'--batch = {args.batch} must be >= 1')
    if args.workers is not None and args.workers < 0:
        raise SpecError(f'--workers = {args.workers} must be >= 0')
    spec = Spec.load(args.target)
    out = args.out or os.path.join(
        'runs', os.path.splitext(os.path.basename(args.target))[0] + '.sweep'
    )
    stats = execute(spec, out, workers=args.workers, cluster=args.cluster, batch=args.batch)
    print(summary_line(stats))
    print(f'wrote {out}/runs' + ('' if 'impacts' not in spec.outputs else f', {out}/impacts'))
    if args.csv:
        import pyarrow.csv as pcsv

        for table in TABLES:
            try:
                rows = read_table(out, table)
            except SpecError:  # no impacts at all
                continue
            pcsv.write_csv(rows, os.path.join(out, f'{table}.csv'))
            print(f'wrote {os.path.join(out, table + ".csv")}')
    if stats['failed']:
        _print_errors(stats['errors'], stats['failed'])
        return 1
    return 0


def _print_errors(errors: dict, failed: int, show: int = 10):
    """The distinct errors of the failed runs, most frequent first, on stderr."""
    import sys

    ranked = sorted(errors.items(), key=lambda item: -item[1])
    print(f'sweep: {failed} run(s) failed with {len(ranked)} distinct error(s):', file=sys.stderr)
    for error, count in ranked[:show]:
        print(f'  {count} x {error}', file=sys.stderr)
    if len(ranked) > show:
        print(
            f'  ... and {len(ranked) - show} more (the error column of the runs table)',
            file=sys.stderr,
        )
