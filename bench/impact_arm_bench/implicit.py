"""``impact-arm bench implicit``: what the controller's state prediction and implicit law cost
per command, the plain numpy formula (``ArrayStatePredictor``) against the float one the
controller runs (``StatePredictor``), in one run.

Per call, best of ``--repeats`` rounds of ``--calls`` calls over a fixed set of states (the
scene's arm, angles within ±π, rates within ±10 rad/s, seeded): the prediction over 1 and 3
periods in flight, and the implicit law with the scene's controller (the article's: law 'q')
looking 1 and 2 periods ahead (the realtime set-up's latencies 1-3 give
1 and 2). Also the largest difference between the two, relative to the torque's size (they
agree to rounding; the test suite checks it).
"""

from __future__ import annotations

import time

from . import common

PERIOD = 1e-3
STATES = 64


def add_arguments(parser):
    parser.add_argument(
        '--scene', default='paper', help='scene name or YAML path (default: the article)'
    )
    parser.add_argument(
        '--calls', type=int, default=3000, help='calls per timed round (default 3000)'
    )
    parser.add_argument('--repeats', type=int, default=3, help='timed rounds (default 3)')
    parser.add_argument('--json', metavar='FILE', help='write the measured rows as JSON')


def _best_us(call, states, calls, repeats):
    for state in states[:8]:  # warm: numba dispatch, caches
        call(*state)
    best = float('inf')
    for _ in range(max(1, repeats)):
        start = time.perf_counter()
        for i in range(calls):
            call(*states[i % len(states)])
        best = min(best, (time.perf_counter() - start) / calls)
    return best * 1e6


def run(args):
    import numpy as np

    from impact_arm.physics.control import CycleController
    from impact_arm.physics.model import ArmModel
    from impact_arm.physics.prediction import ArrayStatePredictor, StatePredictor
    from impact_arm.physics.scene import load_scene, resolve_scene_path

    scene = load_scene(resolve_scene_path(args.scene))
    model = ArmModel(scene)
    ctrl = CycleController.for_scene(model, scene.controller)
    rng = np.random.default_rng(1)
    states = []
    for _ in range(STATES):
        q = rng.uniform(-np.pi, np.pi, model.n).tolist()
        qd = rng.uniform(-10.0, 10.0, model.n).tolist()
        states.append((q, qd, ctrl.torque(q, qd)))
    predictors = {
        'numpy arrays (before)': ArrayStatePredictor(model, PERIOD),
        'floats (now)': StatePredictor(model, PERIOD),
    }
    cases = [
        ('prediction, 1 period in flight', lambda p: lambda q, qd, tau: p.ahead(q, qd, [tau])),
        ('prediction, 3 periods in flight', lambda p: lambda q, qd, tau: p.ahead(q, qd, [tau] * 3)),
        (
            'implicit law, 1 period ahead',
            lambda p: lambda q, qd, tau: p.implicit_command(ctrl.torque, q, qd, tau, 1),
        ),
        (
            'implicit law, 2 periods ahead',
            lambda p: lambda q, qd, tau: p.implicit_command(ctrl.torque, q, qd, tau, 2),
        ),
    ]
    law_us = _best_us(lambda q, qd, tau: ctrl.torque(q, qd), states, args.calls, args.repeats)
    rows, records = [], []
    for name, make in cases:
        common.progress(name)
        before, now = (
            _best_us(make(p), states, args.calls, args.repeats) for p in predictors.values()
        )
        worst = 0.0
        for q, qd, tau in states:
            old, new = (make(p)(q, qd, tau) for p in predictors.values())
            old_flat = np.ravel(old)
            size = max(1.0, float(np.max(np.abs(old_flat))))
            worst = max(worst, float(np.max(np.abs(np.ravel(new) - old_flat))) / size)
        rows.append([name, f'{before:.1f}', f'{now:.1f}', f'{before / now:.2f}', f'{worst:.1e}'])
        records.append(
            {
                'case': name,
                'before_us': before,
                'now_us': now,
                'ratio': before / now,
                'worst': worst,
            }
        )
    common.progress_done()
    print(f'scene {args.scene}, {model.n} links, period {PERIOD * 1e3:g} ms, {args.calls} calls')
    print(f'(the law itself, evaluated 1 + n times by the implicit law: {law_us:.1f} µs)')
    header = ['per call', 'before µs', 'now µs', 'ratio', 'largest difference']
    print(common.table(header, rows))
    if args.json:
        common.write_json(
            args.json, {'machine': common.machine(), 'law_us': law_us, 'rows': records}
        )
    return 0
