"""``impact-arm sweep SPEC.yaml`` and ``impact-arm sweep plot``: the command line."""

from __future__ import annotations

import argparse
import os

from .execute import execute, summary_line
from .plots import plot
from .spec import Spec, SpecError, TABLES
from .store import read_table


def add_arguments(parser: argparse.ArgumentParser) -> None:
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


def cli(args: argparse.Namespace) -> int:
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


def _print_errors(errors: dict[str, int], failed: int, show: int = 10) -> None:
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
