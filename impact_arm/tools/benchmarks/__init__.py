"""``impact-arm bench <sub-command>``: benchmarks that print figures measured in one run.

Benchmarks are not tests: they time things and print ratios; tests never assert wall-clock
times. Each sub-command is a module with ``add_arguments(parser)`` and ``run(args) -> int``;
``SUBCOMMANDS`` maps its name to (module path, one-line help). To add one (for example the
node benchmark ``rates``), write such a module anywhere in the package and add one line here,
e.g. ``'rates': ('impact_arm.nodes.rates_bench', 'realtime / lockstep node rates')``.
Modules import their heavy dependencies inside ``run`` (so ``bench speed`` never loads rclpy).
"""
from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = {
    'speed': ('impact_arm.tools.benchmarks.speed',
              'offline speed at equal accuracy vs scipy solve_ivp'),
    'tradeoff': ('impact_arm.tools.benchmarks.tradeoff',
                 'work-precision table and plot: presets and solve_ivp methods vs reference'),
    'stress': ('impact_arm.tools.benchmarks.stress',
               'stability matrix at the extremes of the parameter space'),
    'rates': ('impact_arm.tools.benchmarks.rates',
              'nodes over DDS: realtime jitter/overruns at 1 and 5 kHz, lockstep speed'),
    'sweep': ('impact_arm.tools.benchmarks.sweep',
              'studies: per-run cost of the API and a sweep worker, 1 vs 2 workers, 10k runs'),
    'starts': ('impact_arm.tools.benchmarks.starts',
               'realtime simulator + controller started N times as a user does'),
    'coldstart': ('impact_arm.tools.benchmarks.coldstart',
                  'first run of a new arm shape by link count: equations, compile, warm load'),
    'fit': ('impact_arm.tools.benchmarks.fit',
            'impact-arm fit: accuracy and interval coverage over drawn cases, cost, growth'),
    'peers': ('impact_arm.tools.benchmarks.peers',
              'MuJoCo on the same scene beside this project (optional: pip install mujoco)'),
    'features': ('impact_arm.tools.benchmarks.features',
                 'cost per simulated second of free motion, Hertz contact, the article'),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every sub-command's options. Modules keep heavy imports (scipy, matplotlib, rclpy)
    inside ``run`` so building the parser stays cheap."""
    sub = parser.add_subparsers(dest='bench', required=True,
                                metavar='{%s}' % ','.join(SUBCOMMANDS))
    for name, (module, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        mod = importlib.import_module(module)
        mod.add_arguments(p)
        p.set_defaults(bench_run=mod.run)


def cli(args) -> int:
    return args.bench_run(args)


def main(argv=None) -> int:
    """Entry point of the thin scripts in ``bench/``: ``python bench/speed.py --json out``."""
    from ..cli import main as cli_main
    argv = list(sys.argv[1:] if argv is None else argv)
    return cli_main(['bench'] + argv)
