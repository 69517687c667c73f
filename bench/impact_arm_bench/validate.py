"""``impact-arm bench validate --train DIR [--test DIR]``: our contact laws against recorded
drops of a square, beside the rigid-body impact laws (docs/validation.md).

Finds every impact of every drop (impact_arm/calibration/drops.py), fits each model's
parameters on the training drops, predicts the velocities after every impact of the test
drops from the state before it and prints the median and 90th percentile of the errors of
vx, vz, ω and of the lowest corner's normal CoR. Without ``--test`` the folder's drops are
split in two, alternately in natural file order. ``--json OUT`` writes every prediction,
``--plots DIR`` the figures of docs/validation.md.
"""

from __future__ import annotations

import json
import math
import os
import time

QUANTITIES = ('vx', 'vz', 'omega', 'normal_cor')
UNITS = ('m/s', 'm/s', 'rad/s', '-')


def add_arguments(parser):
    parser.add_argument('--train', required=True, metavar='DIR', help='folder of drop CSVs')
    parser.add_argument(
        '--test', metavar='DIR', help='folder of test drops (default: half of --train)'
    )
    parser.add_argument('--side', type=float, default=0.06, help='side of the square [m]')
    parser.add_argument('--dt', type=float, default=0.004, help='time between rows [s]')
    parser.add_argument(
        '--evaluations', type=int, default=80, help='loss evaluations per fit (at most)'
    )
    parser.add_argument('--json', metavar='OUT', help='write every test prediction as JSON')
    parser.add_argument('--plots', metavar='DIR', help='write the figures as PNG files there')


def _impacts(files, side, dt):
    from impact_arm.calibration.drops import find_impacts, read_drop

    found = []
    for path in files:
        found += find_impacts(read_drop(path), dt, side, path)
    return found


def _refuse(message: str) -> int:
    import sys

    print(f'bench validate: {message}', file=sys.stderr)
    return 2


def run(args) -> int:
    import numpy as np

    from impact_arm.calibration.drops import (
        Model,
        drop_files,
        fit,
        normal_cor,
        on_one_floor,
        predict,
    )

    if not (0.0 < args.side < 10.0):
        return _refuse(f'--side = {args.side:g} is out of range: must be > 0 and < 10 (m)')
    if not (0.0 < args.dt < 10.0):
        return _refuse(f'--dt = {args.dt:g} is out of range: must be > 0 and < 10 (s)')
    if args.evaluations < 1:
        return _refuse(f'--evaluations = {args.evaluations} must be >= 1')
    for flag, folder in (('--train', args.train), ('--test', args.test)):
        if folder is not None and not os.path.isdir(folder):
            return _refuse(f'{flag} = {folder!r} is not a folder')
    if args.json and not os.path.isdir(os.path.dirname(os.path.abspath(args.json))):
        return _refuse(f'--json = {args.json!r}: its folder does not exist')
    started = time.perf_counter()
    train_files = drop_files(args.train)
    if args.test is None:
        train_files, test_files = train_files[0::2], train_files[1::2]
    else:
        test_files = drop_files(args.test)
    if not train_files or not test_files:
        return _refuse('no drop files (*.csv) to train and test on')
    try:
        train, floor_train = on_one_floor(_impacts(train_files, args.side, args.dt), args.side)
        test, floor_test = on_one_floor(_impacts(test_files, args.side, args.dt), args.side)
    except (OSError, ValueError) as exc:
        return _refuse(str(exc))
    if not train or not test:
        return _refuse('no impact found in the training or the test drops')
    found = time.perf_counter() - started
    print(
        f'{len(train_files)} training drops ({len(train)} impacts), {len(test_files)} test '
        f'drops ({len(test)} impacts); floor at z = {floor_train * 1e3:.1f} / '
        f'{floor_test * 1e3:.1f} mm (lowest corner, median); found in {found:.1f} s'
    )
    measured = np.array([i.post for i in test])
    fits, predictions, timings = {}, {}, {}
    for model in Model:
        t0 = time.perf_counter()
        fits[model] = fit(model, train, args.side, evaluations=args.evaluations)
        t1 = time.perf_counter()
        predictions[model] = predict(model, fits[model].params, test, args.side)
        t2 = time.perf_counter()
        timings[model] = (t1 - t0, (t2 - t1) / len(test))
    errors = {}
    for model in Model:
        pred = predictions[model]
        cor = np.array(
            [
                normal_cor(i, p, args.side) - normal_cor(i, m, args.side)
                for i, p, m in zip(test, pred, measured, strict=True)
            ]
        )
        errors[model] = np.column_stack([np.abs(pred - measured), np.abs(cor)])
    print()
    print('errors on the test drops: median / 90th percentile (fit time, prediction per impact)')
    head = ''.join(f'{q + " [" + u + "]":>20}' for q, u in zip(QUANTITIES, UNITS, strict=True))
    print(f'{"model":14}{head}')
    for model in Model:
        e = errors[model]
        cells = ''.join(
            f'{np.nanmedian(e[:, k]):>9.3f} / {np.nanpercentile(e[:, k], 90):<8.3f}'
            for k in range(4)
        )
        fit_s, per = timings[model]
        print(f'{model.value:14}{cells}  ({fit_s:.1f} s, {per * 1e3:.3f} ms)')
    print()
    tilt = np.array([tilt_deg(i.pre.theta) for i in test])
    classes = ((0.0, 5.0), (5.0, 15.0), (15.0, 45.0))
    print('median / 90th percentile by tilt (edge to floor before the impact; 0 deg: flat)')
    for low, high in classes:
        chosen = (tilt >= low) & (tilt <= high)
        print(f'  tilt {low:g}-{high:g} deg: {int(chosen.sum())} impacts')
        for model in Model:
            e = errors[model][chosen]
            if not len(e):
                continue
            cells = ''.join(
                f'{np.nanmedian(e[:, k]):>9.3f} / {np.nanpercentile(e[:, k], 90):<8.3f}'
                for k in range(4)
            )
            print(f'    {model.value:14}{cells}')
    print()
    for model in Model:
        params = ', '.join(f'{k} = {v:.4g}' for k, v in fits[model].params.items())
        print(f'fitted {model.value}: {params} ({fits[model].evaluations} evaluations)')
    failed = {m.value: int(np.isnan(predictions[m][:, 0]).sum()) for m in Model}
    if any(failed.values()):
        print(f'predictions that failed (left out of the errors): {failed}')
    print(f'whole benchmark: {time.perf_counter() - started:.1f} s')
    if args.json:
        _write_json(args.json, test, predictions, fits, errors)
    if args.plots:
        _plots(args.plots, test, measured, predictions, errors, args.side)
    return 0


def tilt_deg(theta: float) -> float:
    """Angle between the square's nearest edge and the floor, 0 (flat) to 45 deg (on a
    corner)."""
    a = math.degrees(theta) % 90.0
    return min(a, 90.0 - a)


def _finite(values):
    return [float(v) if math.isfinite(v) else None for v in values]


def _write_json(path, test, predictions, fits, errors):
    import numpy as np

    drops = [
        {
            'file': impact.file,
            'impact': impact.number,
            't': impact.t,
            'pre': [impact.pre.vx, impact.pre.vz, impact.pre.omega],
            'measured': list(impact.post),
            'predicted': {m.value: _finite(p[k]) for m, p in predictions.items()},
        }
        for k, impact in enumerate(test)
    ]
    summary = {
        m.value: {
            q: {'median': float(np.nanmedian(e[:, k])), 'p90': float(np.nanpercentile(e[:, k], 90))}
            for k, q in enumerate(QUANTITIES)
        }
        for m, e in errors.items()
    }
    data = {
        'drops': drops,
        'fitted': {m.value: f.params for m, f in fits.items()},
        'errors': summary,
    }
    with open(path, 'w', encoding='utf-8') as f:
        json.dump(data, f, indent=1, allow_nan=False)
    print(f'wrote {path}')


COLORS = {'ours': 'C0', 'constant_cor': 'C2', 'newton': 'C1', 'poisson': 'C3'}


def _plots(folder, test, measured, predictions, errors, side):
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    from impact_arm.calibration.drops import normal_cor

    os.makedirs(folder, exist_ok=True)
    # predicted against measured, one row per model
    fig, axes = plt.subplots(len(predictions), 4, figsize=(13, 3.0 * len(predictions)))
    for row, (model, pred) in enumerate(predictions.items()):
        cor_m = np.array([normal_cor(i, m, side) for i, m in zip(test, measured, strict=True)])
        cor_p = np.array([normal_cor(i, p, side) for i, p in zip(test, pred, strict=True)])
        pairs = [(measured[:, k], pred[:, k]) for k in range(3)] + [(cor_m, cor_p)]
        for col, (m, p) in enumerate(pairs):
            ax = axes[row, col]
            ax.plot(m, p, '.', ms=2.5, color=COLORS[model.value], alpha=0.6)
            finite = np.isfinite(m) & np.isfinite(p)
            lo, hi = np.percentile(np.concatenate([m[finite], p[finite]]), [0.5, 99.5])
            ax.plot([lo, hi], [lo, hi], 'k-', lw=0.6)
            ax.set_xlim(lo, hi)
            ax.set_ylim(lo, hi)
            ax.set_title(f'{model.value}: {QUANTITIES[col]} [{UNITS[col]}]', fontsize=9)
            if row == len(predictions) - 1:
                ax.set_xlabel('measured')
            if col == 0:
                ax.set_ylabel('predicted')
    fig.tight_layout()
    path = os.path.join(folder, 'validation_predicted_vs_measured.png')
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f'wrote {path}')
    # errors against the impact angle and speed of the lowest corner, binned medians
    approach = np.array([i.approach(side) for i in test])
    angle = np.degrees(np.arctan2(np.abs(approach[:, 0]), -approach[:, 1]))
    speed = np.hypot(approach[:, 0], approach[:, 1])
    fig, axes = plt.subplots(2, 4, figsize=(14, 6.5))
    for r, (x, name) in enumerate(
        ((angle, 'incidence angle of the lowest corner [deg]'), (speed, 'impact speed [m/s]'))
    ):
        edges = np.quantile(x, np.linspace(0, 1, 9))
        centres = 0.5 * (edges[1:] + edges[:-1])
        for k in range(4):
            ax = axes[r, k]
            for model, e in errors.items():
                med = [
                    np.nanmedian(e[(x >= a) & (x <= b), k]) for a, b in zip(edges[:-1], edges[1:])
                ]
                ax.plot(centres, med, 'o-', ms=3, color=COLORS[model.value], label=model.value)
            ax.set_xlabel(name, fontsize=8)
            ax.set_title(f'|error| of {QUANTITIES[k]} [{UNITS[k]}], median per bin', fontsize=9)
            if r == 0 and k == 0:
                ax.legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(folder, 'validation_error_vs_angle_speed.png')
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f'wrote {path}')
    # the normal CoR of corner impacts against their normal speed: what tells the laws apart
    corner = np.array([tilt_deg(i.pre.theta) >= 15.0 for i in test])
    normal_speed = -approach[:, 1]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    x = normal_speed[corner]
    cor_m = np.array([normal_cor(i, m, side) for i, m in zip(test, measured, strict=True)])
    ax.plot(x, cor_m[corner], '.', ms=3, color='0.6', label='measured, each impact')
    edges = np.quantile(x, np.linspace(0, 1, 9))
    centres = 0.5 * (edges[1:] + edges[:-1])
    bins = [(x >= a) & (x <= b) for a, b in zip(edges[:-1], edges[1:])]
    ax.plot(
        centres,
        [np.nanmedian(cor_m[corner][b]) for b in bins],
        'ks-',
        ms=4,
        label='measured, median per bin',
    )
    for model, pred in predictions.items():
        cor_p = np.array([normal_cor(i, p, side) for i, p in zip(test, pred, strict=True)])
        ax.plot(
            centres,
            [np.nanmedian(cor_p[corner][b]) for b in bins],
            'o-',
            ms=3,
            color=COLORS[model.value],
            label=f'{model.value}, median per bin',
        )
    ax.set_ylim(0, 1.2)
    ax.set_xlabel('normal speed of the lowest corner before the impact [m/s]')
    ax.set_ylabel('normal CoR of the lowest corner')
    ax.set_title('corner impacts (tilt >= 15 deg), test drops', fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(folder, 'validation_cor_vs_speed.png')
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f'wrote {path}')
