"""impact-arm kernel dump: the generated kernel module of a scene's shape (links, gravity,
contact, friction, PID integral states), as equations.py writes it: the module numba
compiles, for reading or for a debugger. ``--path`` prints where the file is instead."""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest='action', required=True)
    dump = sub.add_parser('dump', help="print the generated kernel module of a scene's shape")
    dump.add_argument('--scene', default='paper', help='scene file or installed scene name')
    dump.add_argument('--path', action='store_true', help='print the file path, not the text')


def cli(args: argparse.Namespace) -> int:
    from ..physics.model import ArmModel
    from ..physics.scene import load_scene, resolve_scene_path

    module = ArmModel(load_scene(resolve_scene_path(args.scene))).eq
    path = module.__file__
    assert path is not None, 'a kernel is loaded from the file it is generated into'
    if args.path:
        print(path)
        return 0
    with open(path, encoding='utf-8') as f:
        sys.stdout.write(f.read())
    return 0
