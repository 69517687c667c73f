"""``impact-arm export``: the scene's arm and calibrated contact for MuJoCo, Drake or
Gazebo, tuned by running the peer, with the residual report (docs/export.md)."""

from __future__ import annotations

import argparse
import sys

from ..export.peers import Peer


def _budget(value: str) -> int:
    number = int(value)
    if number < 1:
        raise argparse.ArgumentTypeError(f'{value}: the budget must be at least 1 evaluation')
    return number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--scene', default='paper', help='scene file or installed scene name')
    parser.add_argument(
        '--fitted',
        metavar='FILE',
        help='the fitted scene of `impact-arm fit` (its fitted.yaml, or its fit.json, '
        "whose 'scene' names it): exported instead of --scene",
    )
    parser.add_argument(
        '--to', required=True, choices=[p.value for p in Peer], help='the peer simulator'
    )
    parser.add_argument('--out', required=True, metavar='DIR', help='directory written')
    parser.add_argument(
        '--budget',
        type=_budget,
        default=None,
        metavar='N',
        help='peer evaluations of the search (each runs every strike; default 400)',
    )


def cli(args: argparse.Namespace) -> int:
    from ..export.exporter import BUDGET, export

    report = export(args.scene, args.to, args.out, args.fitted, args.budget or BUDGET)
    for line in [
        f'wrote {args.out}: the {args.to} model, README.md, report.md, report.json',
        f'time step {report.timestep:g} s; export took {report.seconds:.1f} s',
    ]:
        print(line)
    print('residual (rms over the strikes; exported vs defaults):')
    for tuned, default in zip(report.tuned_residual, report.default_residual):
        print(f'  {tuned.quantity.value:10s} {tuned.rms:8.1%} {default.rms:10.1%}')
    sys.stdout.flush()
    return 0
