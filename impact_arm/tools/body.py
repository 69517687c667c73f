"""``impact-arm body --scene S``: run a free-body scene (docs/scene.md, "Free bodies") and
print its located contact events and the final state.

    impact-arm body --scene square_drop                 # the shipped spinning square
    impact-arm body --scene my_body.yaml --t-end 0.2 --json runs/body.json

One row per event: time, corner, surface, kind, and at maximum compression δm, Pm, δr; at
separation the peak force. Angles print in degrees (the user-facing edge).
"""

from __future__ import annotations

import argparse
import json
import math
import os

from ..physics.errors import ImpactArmError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--scene', required=True, help='a free-body scene file or installed name')
    parser.add_argument('--t-end', type=float, help="end time [s] (default: the scene's t_max)")
    parser.add_argument('--json', metavar='FILE', help='write the events and end state as JSON')


def cli(args: argparse.Namespace) -> int:
    from ..physics.bodies.model import build_model, simulate_body
    from ..physics.bodies.scene import load_body_scene
    from ..physics.kinds import EventKind

    scene = load_body_scene(args.scene)
    t_end = scene.t_max if args.t_end is None else args.t_end
    if not (math.isfinite(t_end) and 0.0 < t_end <= 1e4):
        raise ImpactArmError(f'--t-end = {t_end:g} is out of range: must be > 0 and <= 1e4 (s)')
    run = simulate_body(build_model(scene), t_end=t_end)
    print(f'{scene.name}: {len(run.events)} events in {run.t:.6g} s ({run.steps} steps)')
    print(f'{"t [s]":>12} {"corner":>6} {"surface":>7}  {"event":<16} details')
    for e in run.events:
        details = ''
        if e.kind == EventKind.MAX_COMPRESSION:
            dm, pm, dr = e.values
            details = f'delta_m {dm * 1e6:.3f} um, P_m {pm:.4g} N, delta_r {dr * 1e6:.3f} um'
        elif e.kind == EventKind.SEPARATION:
            details = f'F_max {e.values[0]:.4g} N'
        elif e.kind == EventKind.YIELD:
            details = f'delta {e.values[0] * 1e6:.3f} um'
        print(f'{e.t:12.7f} {e.corner:6d} {e.surface:7d}  {e.kind.value:<16} {details}')
    s = run.state
    print(
        f'end: x {s.x:.6g} m, z {s.z:.6g} m, theta {math.degrees(s.theta):.6g} deg, '
        f'vx {s.vx:.6g} m/s, vz {s.vz:.6g} m/s, omega {s.omega:.6g} rad/s'
    )
    if args.json:
        data = {
            'scene': scene.name,
            't': run.t,
            'events': [
                {
                    'kind': e.kind.value,
                    't': e.t,
                    'corner': e.corner,
                    'surface': e.surface,
                    'values': list(e.values),
                }
                for e in run.events
            ],
            'end': dict(zip(('x', 'z', 'theta', 'vx', 'vz', 'omega'), s.as_tuple(), strict=True)),
        }
        folder = os.path.dirname(os.path.abspath(args.json))
        if not os.path.isdir(folder):
            raise ImpactArmError(f'--json {args.json}: folder {folder} does not exist')
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(data, f, indent=1, allow_nan=False)
        print(f'wrote {args.json}')
    return 0
