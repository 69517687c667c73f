"""Resumable Parquet tables: parts written atomically, the runs part last."""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING

from .spec import Spec, SpecError, TABLES

if TYPE_CHECKING:
    import pyarrow as pa


class ResultStore:
    """Part files of one spec under ``out``: ``runs/`` and ``impacts/``, each part written to
    a temporary name and renamed, the runs part last (it marks its runs as finished)."""

    def __init__(self, out: str, spec: Spec) -> None:
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

    def _parts(self, table: str) -> list[str]:
        folder = os.path.join(self.out, table)
        return sorted(n for n in os.listdir(folder) if n.endswith('.parquet'))

    def write(self, tables: list[dict[str, pa.Table]]) -> None:
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


def _write_atomically(path: str, data: bytes) -> None:
    with open(path + '.tmp', 'wb') as f:
        f.write(data)
    os.replace(path + '.tmp', path)


def read_table(out: str, table: str = 'runs') -> pa.Table:
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
