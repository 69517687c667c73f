"""``impact-arm layout RECORDING | --scene S``: the Foxglove / Lichtblick layout made for an arm
(io/viewer_layout.py), printed or written with ``--out``. From a recording: its stored scene
and the topics it holds; from a scene: the topics a recording of it holds."""

from __future__ import annotations

import argparse
import sys

from ..physics.errors import ImpactArmError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('recording', nargs='?', help='MCAP file or rosbag2 folder')
    parser.add_argument(
        '--scene',
        default=None,
        help="scene file or installed scene name (default: the recording's)",
    )
    parser.add_argument('--out', default=None, metavar='FILE', help='write here (default: print)')


def cli(args: argparse.Namespace) -> int:
    from ..io.recording import RecordingInputError
    from ..io.viewer_layout import layout_text, recording_layout, viewer_layout
    from ..physics.scene import load_scene, resolve_scene_path

    if args.recording is None and args.scene is None:
        raise ImpactArmError('give a recording, or --scene S')
    scene = load_scene(resolve_scene_path(args.scene)) if args.scene else None
    try:
        layout = (
            recording_layout(args.recording, scene) if args.recording else viewer_layout(scene)  # type: ignore[arg-type]
        )
    except (RecordingInputError, ValueError) as exc:
        raise ImpactArmError(str(exc)) from None
    text = layout_text(layout)
    if args.out:
        with open(args.out, 'w', encoding='utf-8') as f:
            f.write(text)
        print(f'wrote {args.out}', file=sys.stderr)
    else:
        sys.stdout.write(text)
    return 0
