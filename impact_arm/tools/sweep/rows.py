"""The rows of one chunk of runs (run in a worker process): a row per run and per impact."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import dataclasses
import json

from ...calibration.study import Study
from ...physics.impact import Impact

# an impact row's record columns, in the order of the JSON's keys (``Impact.to_dict``)
IMPACT_FIELDS = tuple(f.name for f in dataclasses.fields(Impact))

if TYPE_CHECKING:
    import pyarrow as pa


def column_value(value: object) -> float | str:
    """An override as a table cell: numbers as floats, anything else as its JSON text."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return value if isinstance(value, str) else json.dumps(value)


def _layout(fixed: dict, record: Impact) -> tuple:
    """What decides an impact row's columns: the override keys and the record's sequence
    lengths (the number of links, which an override may change)."""
    return tuple(fixed), tuple(
        len(v) if isinstance(v, tuple) else -1 for v in (getattr(record, k) for k in IMPACT_FIELDS)
    )


def _add_impacts(tables: dict, fixed: dict, records: Sequence[Impact]) -> None:
    """Append one run's impact records to ``tables`` (layout -> {column: values}): ``fixed``
    (run index, overrides) repeated per impact, the records' fields (the keys of their
    ``to_dict``) in columns, their sequences spread over columns named by key path
    (v_before[1]). Filled a column at a time from the records' attributes while the
    records are fresh: per-value appends, columns gathered from the whole chunk's records
    at the end, or a dict per record (``to_dict``, ~5 us an impact) cost a sweep worker
    several % of a run."""
    if not records:
        return
    first = records[0]
    layout = _layout(fixed, first)
    if layout not in tables:
        names = list(fixed)
        for key, length in zip(IMPACT_FIELDS, layout[1]):
            names += [key] if length < 0 else [f'{key}[{i}]' for i in range(length)]
        tables[layout] = {name: [] for name in names}
    columns = iter(tables[layout].values())
    for value in fixed.values():
        next(columns).extend([value] * len(records))
    for key, length in zip(IMPACT_FIELDS, layout[1]):
        if length < 0:
            next(columns).extend([getattr(r, key) for r in records])
            continue
        # the records' sequences, transposed: one column per entry (every record of a run
        # has the first's lengths)
        for column in zip(*[getattr(r, key) for r in records]):
            next(columns).extend(column)


def _impacts_table(tables: dict) -> pa.Table | None:
    """The impact rows collected by ``_add_impacts`` as one table (None without impacts);
    runs of different layouts make tables joined by column name."""
    import pyarrow as pa

    parts = [pa.table(columns) for columns in tables.values()]
    if len(parts) > 1:
        return pa.concat_tables(parts, promote_options='default')
    return parts[0] if parts else None


_STUDIES: dict[str, Study] = {}  # spec hash -> Study, kept by each worker process between chunks


def run_chunk(
    spec_hash: str, scene_data: dict, fixed: dict, outputs: tuple, items: list[tuple[int, dict]]
) -> dict[str, pa.Table]:
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
        columns = {'run': index, **{k: column_value(v) for k, v in overrides.items()}}
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
