"""Running a spec: chunks to local worker processes or to a Dask scheduler."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING

from ...calibration.study import Study
from ..progress import Progress
from .rows import run_chunk
from .spec import Spec
from .store import ResultStore

if TYPE_CHECKING:
    import pyarrow as pa

# (run index, overrides) of each run of a chunk, and the chunk's tables (run_chunk's)
Chunk = list[tuple[int, dict]]
Task = Callable[[Chunk], 'dict[str, pa.Table]']


def _chunks(items: Chunk, workers: int) -> list[Chunk]:
    """Chunks small enough to balance the workers, large enough to amortise a hand-over."""
    size = max(1, min(50, len(items) // (8 * max(1, workers))))
    return [items[i : i + size] for i in range(0, len(items), size)]


def _exit_with_parent() -> None:
    """Pool worker initializer: when the sweep dies (SIGKILL included), its workers stop
    too instead of computing runs that nobody will record."""
    import threading

    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _local_pool(workers: int, task: Task, chunks: Iterable[Chunk]) -> Iterator[dict[str, pa.Table]]:
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


def _dask(address: str, task: Task, chunks: Iterable[Chunk]) -> Iterator[dict[str, pa.Table]]:
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
