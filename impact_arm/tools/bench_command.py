"""``impact-arm bench …``: the benchmarks, which live in the repository's bench/ folder and are
not installed with the package (the package ships the product). Found next to the source
checkout the package runs from (``pip install -e .``, ``colcon build --symlink-install``, or
the work tree itself), or in the folder ``IMPACT_ARM_BENCH`` names."""

from __future__ import annotations

import argparse
import os
import sys
import types

from ..physics.errors import ImpactArmError


def bench_folder() -> str | None:
    here = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for folder in (
        os.environ.get('IMPACT_ARM_BENCH', ''),
        os.path.join(here, 'bench'),
        os.path.join(os.getcwd(), 'bench'),
    ):
        if folder and os.path.isfile(os.path.join(folder, 'impact_arm_bench', '__init__.py')):
            return folder
    return None


def _benchmarks() -> types.ModuleType | None:
    folder = bench_folder()
    if folder is None:
        return None
    if folder not in sys.path:
        sys.path.insert(0, folder)
    import impact_arm_bench

    return impact_arm_bench


def add_arguments(parser: argparse.ArgumentParser) -> None:
    bench = _benchmarks()
    if bench is not None:
        bench.add_arguments(parser)
    else:
        parser.add_argument('args', nargs='*', help='(the benchmarks are not installed)')


def cli(args: argparse.Namespace) -> int:
    if getattr(args, 'bench_run', None) is None:
        raise ImpactArmError(
            'the benchmarks are not installed with the package: run '
            '`impact-arm bench` from a clone of the repository (its bench/ '
            'folder), or set IMPACT_ARM_BENCH to that folder'
        )
    return args.bench_run(args)
