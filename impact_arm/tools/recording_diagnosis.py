"""``impact-arm fit``'s options that correct a recording before the fit (the corrections of
``calibration/diagnose/``): none is applied unless given."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ..physics.errors import ImpactArmError

if TYPE_CHECKING:
    from ..calibration.diagnose import Corrections


def add_correction_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--effort-latency',
        type=float,
        default=0.0,
        metavar='S',
        help='the efforts are reported S seconds late: read each one S earlier before the '
        'fit (the diagnosis estimates it; default 0: nothing changed). Refused with a scene '
        'that states sensors.effort_latency (less sensors.state_latency) or a fit that frees '
        'it: the fit replays that latency too, and the efforts would be shifted twice',
    )
    parser.add_argument(
        '--wrench-latency',
        type=float,
        default=0.0,
        metavar='S',
        help='the wrench is stamped S seconds late: move its stamps S earlier. Refused, as '
        '--effort-latency, with a scene that states or a fit that frees '
        'sensors.wrench_latency',
    )
    parser.add_argument(
        '--difference-rates',
        action='store_true',
        help='the rates are backward differences of the positions (the diagnosis says so): '
        'read each as the mean rate over the period before its stamp',
    )
    parser.add_argument(
        '--regular-stamps',
        action='store_true',
        help='put the stamps on the regular grid the samples were taken on (for stamps '
        'taken on arrival)',
    )


def corrections_from(args: argparse.Namespace) -> Corrections:
    """The ``Corrections`` the options ask for; a bad value refused in one line."""
    from ..calibration.diagnose import Corrections

    try:
        return Corrections(
            effort_latency=args.effort_latency,
            wrench_latency=args.wrench_latency,
            difference_rates=args.difference_rates,
            regular_stamps=args.regular_stamps,
        )
    except ValueError as exc:
        raise ImpactArmError(str(exc)) from None
