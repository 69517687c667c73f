"""``impact-arm export``: the scene's arm and calibrated contact for MuJoCo, Drake or
Gazebo, tuned by running the peer, with the residual report; ``--check DIR`` reruns an
export's peer in closed loop beside the package's own impacts (docs/export.md)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from ..export.peers import Peer
from ..physics.errors import ImpactArmError


def _at_least_one(what: str) -> Callable[[str], int]:
    def parse(value: str) -> int:
        number = int(value)
        if number < 1:
            raise argparse.ArgumentTypeError(f'{value}: {what} must be at least 1')
        return number

    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--scene', default=None, help='scene file or installed scene name (default paper)'
    )
    parser.add_argument(
        '--fitted',
        metavar='FILE',
        help='the fitted scene of `impact-arm fit` (its fitted.yaml, or its fit.json, '
        "whose 'scene' names it): exported instead of --scene",
    )
    parser.add_argument('--to', choices=[p.value for p in Peer], help='the peer simulator')
    parser.add_argument('--out', metavar='DIR', help='directory written')
    parser.add_argument(
        '--budget',
        type=_at_least_one('the budget (peer evaluations)'),
        default=None,
        metavar='N',
        help='peer evaluations of the search (each runs every strike; default 400)',
    )
    parser.add_argument(
        '--check',
        metavar='DIR',
        help="rerun the export in DIR (mujoco) on the scene's cycles in closed loop with "
        'its controller and print its impact table beside ours; writes DIR/check.md, '
        'check.json; exit status 1 when they differ',
    )
    parser.add_argument(
        '--cycles',
        type=_at_least_one('--cycles'),
        default=None,
        metavar='N',
        help="with --check: cycles run (N + 1 impacts; default the scene's cycles)",
    )
    parser.add_argument(
        '--rate',
        type=float,
        default=None,
        metavar='HZ',
        help="with --check: the controller's rate (default the scene's; 1000 for a scene "
        'with continuous control)',
    )


def _check(args: argparse.Namespace) -> int:
    from ..export.check import check
    from ..export.check_report import headline, summary, table, verdict, write_check

    result = check(args.check, args.cycles, args.rate)
    written = write_check(result)
    for line in headline(result) + [''] + table(result) + [''] + summary(result):
        print(line)
    print(verdict(result))
    print('wrote ' + ', '.join(written))
    sys.stdout.flush()
    return 0 if not result.failures else 1


def cli(args: argparse.Namespace) -> int:
    if args.check:
        given = [f for f in ('scene', 'fitted', 'to', 'out', 'budget') if getattr(args, f)]
        if given:
            raise ImpactArmError(
                f'--check DIR takes the export in DIR as it is: no --{", --".join(given)}'
            )
        return _check(args)
    if args.cycles is not None or args.rate is not None:
        raise ImpactArmError('--cycles and --rate go with --check DIR')
    if not args.to or not args.out:
        raise ImpactArmError('--to mujoco|drake|gazebo and --out DIR are required (or --check DIR)')
    from ..export.exporter import BUDGET, export

    report = export(args.scene or 'paper', args.to, args.out, args.fitted, args.budget or BUDGET)
    for line in [
        f'wrote {args.out}: the {args.to} model, README.md, report.md, report.json, scene.yaml',
        f'time step {report.timestep:g} s; export took {report.seconds:.1f} s',
    ]:
        print(line)
    print('residual (rms over the strikes; exported vs defaults):')
    for tuned, default in zip(report.tuned_residual, report.default_residual):
        print(f'  {tuned.quantity.value:10s} {tuned.rms:8.1%} {default.rms:10.1%}')
    sys.stdout.flush()
    return 0
