"""``impact-arm bench tradeoff``: the speed/accuracy trade, measured in one run.

Rows: our integrator presets (reference, accurate, balanced, fast), our Rosenbrock free-flight
step with a tighter contact tolerance at four settings, and scipy ``solve_ivp``
(RK45 — MATLAB's ode45 —, DOP853, LSODA, Radau) at several tolerances, all on the same scene
with events, sharing the compiled right-hand side and the phase machine. Errors are relative to
the ``reference`` preset, each the worst over EVERY impact of the run (sweeps and fits read
the limit-cycle impacts, not only the first): δm, F_max, duration, post-impact tip velocity,
kinematic and (worst link/total) energetic CoR, the impact's time as a fraction of the
limit-cycle period, and that period. Output: a work-precision table, the Pareto front (no
other row is both faster and more accurate), the recommended sweep setting's errors impact by
impact, a log-log plot of error vs wall time, ``--json`` with one row per (method,
tolerance), and the control-rate trade (continuous control vs sampled at 10 kHz ... 100 Hz
with zero-order hold) on the same metrics.
"""

from __future__ import annotations

import math

from . import common

SCIPY_METHODS = ('RK45', 'DOP853', 'LSODA', 'Radau')
# method 'rosenbrock' (linearly implicit in the stiff free flight) with a tighter contact rtol:
# (rtol, contact_rtol); atol = rtol * 1e-2
ROSENBROCK_SETTINGS = ((1e-2, 3e-4), (1e-3, 3e-5), (1e-4, 3e-6), (1e-5, 3e-7))
SWEEP_SETTING = (1e-2, 3e-4)  # the README's recommendation for sweeps
SCIPY_RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
CONTROL_RATES = (0.0, 10000.0, 1000.0, 500.0, 100.0)


def add_arguments(parser):
    parser.add_argument('--scene', default='paper', help='scene file or name (default: paper)')
    parser.add_argument(
        '--repeats',
        type=int,
        default=3,
        help='timed repeats of our runs (best kept); scipy runs once',
    )
    parser.add_argument(
        '--methods',
        default=','.join(SCIPY_METHODS),
        help='solve_ivp methods (default: RK45,DOP853,LSODA,Radau)',
    )
    parser.add_argument(
        '--rtols',
        default=','.join(f'{r:g}' for r in SCIPY_RTOLS),
        help='solve_ivp rtols (atol = rtol * 1e-2)',
    )
    parser.add_argument(
        '--rates',
        default=','.join(f'{r:g}' for r in CONTROL_RATES),
        help='control rates in Hz for the control-rate trade (0 = continuous)',
    )
    parser.add_argument('--json', metavar='FILE', help='write one row per (method, tolerance)')
    parser.add_argument(
        '--plot',
        metavar='FILE',
        default='runs/bench/tradeoff.png',
        help="log-log plot of error vs wall time (default: %(default)s; '' for none)",
    )


def _short(x):
    """1e-2, 3e-4: a tolerance as people write it."""
    mantissa, exponent = f'{x:.0e}'.split('e')
    return f'{mantissa}e{int(exponent)}'


def pareto(rows):
    """Mark rows no other row beats on both wall time and worst error."""
    for r in rows:
        r['pareto'] = not any(
            o is not r
            and o['wall'] <= r['wall']
            and o['worst'] <= r['worst']
            and (o['wall'] < r['wall'] or o['worst'] < r['worst'])
            for o in rows
        )
    return rows


def _row(kind, method, rtol, atol, result, ref):
    errors = common.tradeoff_errors(result['impacts'], ref)
    return {
        'kind': kind,
        'method': method,
        'rtol': rtol,
        'atol': atol,
        'wall': result['wall'],
        'rhs_evaluations': result['rhs_evaluations'],
        'impacts': len(result['impacts']),
        't_end': result['t_end'],
        'errors': errors,
        'worst': common.worst(errors),
        'per_impact': common.per_impact_errors(result['impacts'], ref),
    }


def measure(scene, methods, rtols, repeats, log=common.progress):
    from impact_arm.physics.integrator import PRESET_CONTACT_RTOL, PRESETS

    ref_rtol, ref_atol = PRESETS['reference']
    log('reference preset')
    ref_result = common.time_ours(scene, ref_rtol, ref_atol, repeats=1)
    ref = ref_result['impacts']
    rows = []
    for name, (rtol, atol) in PRESETS.items():
        log(f'ours: preset {name}')
        contact = PRESET_CONTACT_RTOL.get(name)  # the preset as a whole
        r = common.time_ours(scene, rtol, atol, repeats=repeats, contact_rtol=contact)
        rows.append(dict(_row('preset', name, rtol, atol, r, ref), contact_rtol=contact or rtol))
    for rtol, contact in ROSENBROCK_SETTINGS:
        log(f'ours: rosenbrock rtol {rtol:g} / contact {contact:g}')
        r = common.time_ours(
            scene, rtol, rtol * 1e-2, repeats=repeats, method='rosenbrock', contact_rtol=contact
        )
        name = f'rosenbrock {_short(rtol)} / {_short(contact)}'
        if (rtol, contact) == SWEEP_SETTING:
            name += ' (sweeps)'
        rows.append(dict(_row('rosenbrock', name, rtol, rtol * 1e-2, r, ref), contact_rtol=contact))
    for method in methods:
        for rtol in rtols:
            log(f'solve_ivp {method} rtol {rtol:g}')
            try:
                r = common.time_scipy(scene, method, rtol, rtol * 1e-2, repeats=1)
            except Exception as exc:
                rows.append(
                    {
                        'kind': 'scipy',
                        'method': method,
                        'rtol': rtol,
                        'atol': rtol * 1e-2,
                        'wall': math.inf,
                        'rhs_evaluations': 0,
                        'impacts': 0,
                        't_end': 0.0,
                        'errors': {},
                        'worst': math.inf,
                        'failure': str(exc),
                    }
                )
                continue
            rows.append(_row('scipy', method, rtol, rtol * 1e-2, r, ref))
    return ref_result, pareto(rows)


def control_rate_trade(scene, rates, ref, log=common.progress):
    """simulate.run with continuous control (rate 0) or sampled control, preset accurate, so
    the differences are the control rate's, not the integrator's."""
    from impact_arm.physics.simulate import run

    rows = []
    for rate in rates:
        log(f'control rate {rate:g} Hz')
        result = run(scene, control_rate=rate, preset='accurate', keep_samples=False)
        errors = common.tradeoff_errors(result.impacts, ref)
        rows.append(
            {
                'kind': 'control_rate',
                'method': 'continuous' if rate == 0 else f'{rate:g} Hz',
                'control_rate': rate,
                'wall': result.wall_time,
                'rhs_evaluations': result.rhs_evaluations,
                'impacts': len(result.impacts),
                't_end': result.t_end,
                'errors': errors,
                'worst': common.worst(errors),
                'error': result.error,
            }
        )
    return rows


def format_rows(rows, first_col):
    header = (
        [first_col, 'rtol', 'wall [ms]', 'rhs evals', 'impacts']
        + [common.METRIC_LABELS[k] for k in common.TRADEOFF_METRICS]
        + ['worst', 'Pareto']
    )
    body = []
    for r in rows:
        body.append(
            [
                r['method'],
                f'{r["rtol"]:g}' if r.get('rtol') else '',
                f'{r["wall"] * 1e3:.1f}' if math.isfinite(r['wall']) else 'failed',
                r['rhs_evaluations'],
                r['impacts'],
            ]
            + [common.fmt_err(r['errors'].get(k, math.inf)) for k in common.TRADEOFF_METRICS]
            + [common.fmt_err(r['worst']), '*' if r.get('pareto') else '']
        )
    return common.table(header, body, ['<'] + ['>'] * (len(header) - 1))


def plot(rows, path, scene_name):
    """Worst error over every impact vs wall time, log-log. The reference preset (the
    yardstick: error 0 by definition) is left out rather than drawn at an arbitrary floor,
    which would stretch the error axis over decades nothing lies in."""
    import os
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10.5, 5.5))
    series = {}
    for r in rows:
        if math.isfinite(r['wall']) and math.isfinite(r['worst']) and r['worst'] > 0:
            label = {
                'preset': 'ours (presets)',
                'rosenbrock': 'ours (rosenbrock, rtol / contact rtol)',
            }.get(r['kind'], f'solve_ivp {r["method"]}')
            series.setdefault(label, []).append(r)
    for label, rs in series.items():
        ours = label.startswith('ours')
        # ours along the wall time; a scipy method along its tolerance (its timings are noisy
        # enough on a shared machine to zigzag when sorted by wall time)
        rs = sorted(rs, key=lambda r: r['wall'] if ours else -r['rtol'])
        ax.loglog(
            [r['wall'] for r in rs],
            [r['worst'] for r in rs],
            'o-' if ours else 's--',
            label=label,
            ms=6 if ours else 4,
            lw=1.8 if ours else 1.0,
            zorder=3 if ours else 2,
        )
        if ours:
            # presets labelled to the right, Rosenbrock settings above right: the two series
            # lie close together at the fast end, and the lines run down to the right
            right = label == 'ours (presets)'
            for r in rs:
                ax.annotate(
                    r['method'].replace('rosenbrock ', ''),
                    (r['wall'], r['worst']),
                    fontsize=8,
                    xytext=(7, -3) if right else (6, 5),
                    ha='left',
                    textcoords='offset points',
                )
    front = sorted((r for r in rows if r.get('pareto') and r['worst'] > 0), key=lambda r: r['wall'])
    if front:
        ax.loglog(
            [r['wall'] for r in front],
            [r['worst'] for r in front],
            '-',
            color='k',
            lw=5,
            alpha=0.15,
            label='Pareto front',
            zorder=1,
        )
    ax.set_xlabel('wall time for the whole run (15 cycles) [s]')
    ax.set_ylabel('worst relative error over every impact\n(vs preset reference)')
    ax.set_title(
        f"Work-precision, scene '{scene_name}' (lower left is better;\n"
        f'preset reference is the yardstick, not drawn)',
        fontsize=10,
    )
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    print(f'wrote {path}')


def format_per_impact(row):
    """One line per impact of a row: its errors against the reference's same impact."""
    keys = common.TRADEOFF_METRICS[:-1]
    body = [
        [k + 1] + [common.fmt_err(e[key]) for key in keys] for k, e in enumerate(row['per_impact'])
    ]
    return common.table(
        ['impact'] + [common.METRIC_LABELS[k] for k in keys], body, ['>'] * (len(keys) + 1)
    )


def run(args) -> int:
    scene = common.load(args.scene)
    methods = [m.strip() for m in args.methods.split(',') if m.strip()]
    rtols = [float(x) for x in args.rtols.split(',') if x.strip()]
    rates = [float(x) for x in args.rates.split(',') if x.strip()]
    ref_result, rows = measure(scene, methods, rtols, args.repeats)
    ref = ref_result['impacts']
    rate_rows = control_rate_trade(scene, rates, ref)
    common.progress_done()
    print(
        f"Work-precision on scene '{scene.name}' ({len(ref)} impacts, "
        f'{ref_result["t_end"]:.3f} s simulated); each error is the worst over every impact, '
        f"relative to preset reference; 't / period': an impact's time error as a fraction "
        f"of the limit-cycle period; 'period': that period's relative error; wall: the "
        f'integration alone (model built, kernel compiled), best of {args.repeats}.'
    )
    print()
    print(format_rows(rows, 'method'))
    print()
    front = sorted((r for r in rows if r['pareto']), key=lambda r: r['wall'])
    print(
        'Pareto front (fastest first): '
        + ', '.join(
            f'{r["method"]}'
            f'{"" if r["kind"] in ("preset", "rosenbrock") else " " + format(r["rtol"], "g")} '
            f'({r["wall"] * 1e3:.1f} ms, {common.fmt_err(r["worst"])})'
            for r in front
        )
    )
    for r in rows:
        if r['method'].endswith('(sweeps)') or r['method'] == 'balanced':
            print()
            print(f'{r["method"]}: errors impact by impact ({r["wall"] * 1e3:.2f} ms)')
            print()
            print(format_per_impact(r))
    print()
    print(
        "Control-rate trade (simulate.run, preset accurate, sampled output at the scene's "
        'publish rate; errors vs continuous control at preset reference):'
    )
    print()
    print(format_rows(rate_rows, 'control'))
    for r in rate_rows:
        if r['error']:
            print(f'  {r["method"]}: stopped after {r["impacts"]} impacts: {r["error"]}')
    if args.plot:
        plot(rows, args.plot, scene.name)
    if args.json:
        common.write_json(
            args.json,
            {
                'benchmark': 'tradeoff',
                'scene': scene.name,
                'machine': common.machine(),
                'metrics': common.TRADEOFF_METRICS,
                'rows': rows,
                'control_rate': rate_rows,
            },
        )
    return 0
