"""``impact-arm bench <sub-command>``: benchmarks that print figures measured in one run.

They live in the repository's bench/ folder, outside the installed package (``impact-arm
bench`` finds them next to a source checkout: impact_arm/tools/bench_command.py). Benchmarks
are not tests: they time things and print ratios; tests never assert wall-clock times. Each
sub-command is a module with ``add_arguments(parser)`` and ``run(args) -> int``;
``SUBCOMMANDS`` maps its name to (module path, one-line help): to add one, write the module
here and add its line. Modules import their heavy dependencies inside ``run`` (so ``bench
speed`` never loads rclpy). The hostile-input generators the stress benchmarks share with
the tests are ``generators`` here (the tests import this package). Importing the package
changes no path: a worker process that imports it is given this folder where it is started
(``common.worker_environment``).
"""

from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMANDS = {
    'speed': ('impact_arm_bench.speed', 'offline speed at equal accuracy vs scipy solve_ivp'),
    'tradeoff': (
        'impact_arm_bench.tradeoff',
        'work-precision table and plot: presets and solve_ivp methods vs reference',
    ),
    'stress': (
        'impact_arm_bench.stress',
        'stability matrix at the extremes of the parameter space',
    ),
    'rates': (
        'impact_arm_bench.rates',
        'nodes over DDS: realtime jitter/overruns at 1 and 5 kHz, lockstep speed',
    ),
    'sweep': (
        'impact_arm_bench.sweep',
        'studies: per-run cost of the API and a sweep worker, 1 vs 2 workers, 10k runs',
    ),
    'starts': (
        'impact_arm_bench.starts',
        'realtime simulator + controller started N times as a user does',
    ),
    'coldstart': (
        'impact_arm_bench.coldstart',
        'first run of a new arm shape by link count: equations, compile, warm load',
    ),
    'fit': (
        'impact_arm_bench.fit',
        'impact-arm fit: accuracy and interval coverage over drawn cases, cost, growth',
    ),
    'peers': (
        'impact_arm_bench.peers',
        'MuJoCo on the same scene beside this project (optional: pip install mujoco)',
    ),
    'validate': (
        'impact_arm_bench.validate',
        'contact laws vs recorded drops of a square, beside rigid-body impact laws',
    ),
    'oblique': (
        'impact_arm_bench.oblique',
        'a sphere striking a flat obliquely vs measured rebounds (tangential CoR, spin)',
    ),
    'latency': (
        'impact_arm_bench.latency',
        'limit cycle against steady and varying command latency, with and without prediction',
    ),
    'ros2control': (
        'impact_arm_bench.ros2control',
        'the ros2_control set-up with the stand-in stack, realtime 1 kHz: cycles, latency, CPU',
    ),
    'implicit': (
        'impact_arm_bench.implicit',
        "the controller's state prediction and implicit law per call, numpy formula vs floats",
    ),
    'controller_tick': (
        'impact_arm_bench.controller_tick',
        "the controller node's Python per joint-state sample, replayed without ROS",
    ),
    'features': (
        'impact_arm_bench.features',
        'cost per simulated second of free motion, Hertz contact, the article',
    ),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every sub-command's options. Modules keep heavy imports (scipy, matplotlib, rclpy)
    inside ``run`` so building the parser stays cheap."""
    sub = parser.add_subparsers(dest='bench', required=True, metavar='{%s}' % ','.join(SUBCOMMANDS))
    for name, (module, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        mod = importlib.import_module(module)
        mod.add_arguments(p)
        p.set_defaults(bench_run=mod.run)


def cli(args) -> int:
    return args.bench_run(args)


def main(argv=None) -> int:
    """``python bench/run.py speed --json out``: the same as ``impact-arm bench speed ...``."""
    from impact_arm.tools.cli import main as cli_main

    argv = list(sys.argv[1:] if argv is None else argv)
    return cli_main(['bench'] + argv)
