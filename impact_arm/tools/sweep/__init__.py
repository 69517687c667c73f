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


The package: ``spec`` (the spec file), ``rows`` (a chunk of runs in a worker), ``store`` (the
Parquet tables), ``execute`` (workers and Dask), ``plots`` and ``command`` (the command line).
"""

from .command import add_arguments, cli
from .execute import execute, summary_line
from .plots import axis_label, column_unit, plot, plot_file_name
from .rows import run_chunk
from .spec import KINDS, SPEC_KEYS, TABLES, Spec, SpecError
from .store import ResultStore, read_table

__all__ = [
    'KINDS',
    'SPEC_KEYS',
    'TABLES',
    'ResultStore',
    'Spec',
    'SpecError',
    'add_arguments',
    'axis_label',
    'cli',
    'column_unit',
    'execute',
    'plot',
    'plot_file_name',
    'read_table',
    'run_chunk',
    'summary_line',
]
