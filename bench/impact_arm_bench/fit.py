"""``impact-arm bench fit``: accuracy, interval coverage and cost of ``impact-arm fit``.

* accuracy: ``--cases`` recordings of the article's arm with drawn μ and S_y (12 impacts at
  1 kHz, sensor noise σ 2e-5 rad, 2e-3 rad/s, 0.05 N m, 2 N; 2 % of the samples lost, a
  wall-clock offset), fitted with and without the wrench: relative errors, how often the
  95 % intervals hold the truth, verdicts; ``--sensor KEY=VALUE`` makes them through the
  scene's sensors section instead of that noise (encoder counts, difference rates,
  latencies: docs/scene.md);
* cost: 2 and 8 parameters from 15 impacts in a fresh process (``impact-arm fit`` on a
  rosbag2 folder, as the README starts it: imports, the compiled kernel's loading, reading,
  fitting, writing the report and figures), wall and CPU time with the load average around
  each run, ``--repeats`` runs (median and worst);
* growth: fitting time in one process against the number of impacts and of parameters.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

BOUNDS = {
    'surfaces[0].mu': (0.05, 1.0),
    'materials.steel.S_y': (2e8, 5e9),
    'materials.steel.E': (5e10, 1e12),
    'surfaces[0].v_d': (0.002, 0.2),
}


def add_arguments(parser):
    parser.add_argument('--cases', type=int, default=20, help='drawn cases (default 20)')
    parser.add_argument(
        '--impacts', type=int, default=12, help='impacts per accuracy case (default 12)'
    )
    parser.add_argument('--skip-fresh', action='store_true', help='skip the fresh-process timing')
    parser.add_argument(
        '--fresh-only',
        action='store_true',
        help='only the fresh-process timing (2 and 8 parameters)',
    )
    parser.add_argument(
        '--sensor',
        action='append',
        default=[],
        metavar='KEY=VALUE',
        help="a key of the scene's sensors section for the accuracy recordings (repeat), e.g. "
        "rate=difference, effort_latency=0.002: recordings like a real arm's driver makes "
        '(they then carry only the noise these keys give)',
    )
    parser.add_argument(
        '--repeats',
        type=int,
        default=5,
        help='fresh-process runs of each timing (default 5): median and worst',
    )
    parser.add_argument('--json', default=None, metavar='FILE', help='write the figures here')


def _drawn(rng):
    import numpy as np

    return {
        'surfaces[0].mu': float(rng.uniform(0.1, 0.6)),
        'materials.steel.S_y': float(np.exp(rng.uniform(np.log(4e8), np.log(2.5e9)))),
    }


def sensor_overrides(items) -> dict:
    """'KEY=VALUE' items as scene overrides of the sensors section (values read as YAML)."""
    import yaml

    from impact_arm.physics.errors import ImpactArmError

    out = {}
    for item in items:
        key, eq, value = item.partition('=')
        if not (key and eq):
            raise ImpactArmError(f'--sensor {item!r}: expected KEY=VALUE, e.g. rate=difference')
        out[f'sensors.{key.strip()}'] = yaml.safe_load(value)
    return out


def accuracy(cases, impacts, say, sensors=None):
    import numpy as np

    from impact_arm.calibration.fit import fit
    from impact_arm.io.synthetic import synthetic_recording

    rng = np.random.default_rng(2026)
    rows = []
    for case in range(cases):
        truth = _drawn(rng)
        rec = synthetic_recording(
            'paper',
            {**truth, **(sensors or {})},
            cycles=impacts,
            drop=0.02,
            clock_offset=1.7e9,
            seed=100 + case,
        )
        for wrench in (True, False):
            if not wrench:
                rec.wrench = None
            t0 = time.perf_counter()
            res = fit(rec, 'paper', {k: BOUNDS[k] for k in truth})
            wall = time.perf_counter() - t0
            row = {
                'case': case,
                'wrench': wrench,
                'wall': wall,
                'verdict': res.verdict,
                'impacts': res.impacts_used,
            }
            for k, v in truth.items():
                p = res.parameters[k]
                row[k] = {
                    'truth': v,
                    'value': p.value,
                    'error': p.value / v - 1,
                    'covered': p.ci95[0] <= v <= p.ci95[1],
                }
            rows.append(row)
        say(
            f'  case {case + 1}/{cases}: mu {truth["surfaces[0].mu"]:.3f} -> '
            f'{rows[-2]["surfaces[0].mu"]["value"]:.3f} (wrench) '
            f'{rows[-1]["surfaces[0].mu"]["value"]:.3f} (joints); S_y '
            f'{truth["materials.steel.S_y"]:.3g} -> '
            f'{rows[-2]["materials.steel.S_y"]["value"]:.3g} / '
            f'{rows[-1]["materials.steel.S_y"]["value"]:.3g}'
        )
    return rows


def summarize(rows):
    import numpy as np

    out = {}
    for wrench in (True, False):
        sel = [r for r in rows if r['wrench'] == wrench]
        name = 'with wrench' if wrench else 'joint states only'
        keys = [k for k in sel[0] if k.startswith(('surfaces', 'materials'))]
        out[name] = {
            'cases': len(sel),
            'fits': sum(r['verdict'] == 'fits' for r in sel),
            'wall_median': float(np.median([r['wall'] for r in sel])),
            **{
                k: {
                    'max_abs_error': float(max(abs(r[k]['error']) for r in sel)),
                    'median_abs_error': float(np.median([abs(r[k]['error']) for r in sel])),
                    'coverage': float(np.mean([r[k]['covered'] for r in sel])),
                }
                for k in keys
            },
        }
    return out


# the 8 parameters of the fresh-process timing: every number of the article's scene a fit of
# the contact and the arm's masses may free (several cannot be told apart by a limit cycle:
# the cost is the point)
EIGHT = {
    'surfaces[0].mu': (0.05, 1.0),
    'materials.steel.S_y': (2e8, 5e9),
    'materials.steel.E': (5e10, 1e12),
    'materials.steel.nu': (0.2, 0.45),
    'surfaces[0].v_d': (0.002, 0.2),
    'links[0].mass': (0.5, 2.0),
    'links[1].mass': (0.5, 2.0),
    'tip_radius': (0.002, 0.02),
}


def _command():
    """``impact-arm`` as the README starts it (the venv's console script), else the module."""
    script = os.path.join(os.path.dirname(sys.executable), 'impact-arm')
    if os.access(script, os.X_OK):
        return [script]
    return [sys.executable, '-m', 'impact_arm.tools.cli']


def fresh_process(say, bounds=None, repeats=5):
    """Wall and CPU time of ``impact-arm fit`` (15 impacts; 2 parameters, or ``bounds``) in a
    new interpreter, as a user runs it (imports, the compiled kernel's loading, reading,
    fitting, writing the report and figures: CPU time includes the figures' process), run
    ``repeats`` times: median and worst, with the load average around each run: on a shared
    machine the CPU time is the figure that carries over to a quiet one."""
    import resource
    import statistics

    from impact_arm.io.synthetic import synthetic_recording, write_rosbag2

    bounds = bounds or {k: EIGHT[k] for k in ('surfaces[0].mu', 'materials.steel.S_y')}
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        rec = synthetic_recording(
            'paper',
            {'surfaces[0].mu': 0.33, 'materials.steel.S_y': 8e8},
            cycles=15,
            drop=0.02,
            clock_offset=1.7e9,
            seed=7,
        )
        bag = os.path.join(tmp, 'bag')
        write_rosbag2(rec, bag)
        cmd = _command() + ['fit', bag]
        for key, (lo, hi) in bounds.items():
            cmd += ['--param', f'{key}={lo:g}:{hi:g}']
        cmd += ['--out', os.path.join(tmp, 'out'), '--json', os.path.join(tmp, 'r.json')]
        for k in range(repeats):
            load0 = os.getloadavg()[0]
            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            done = subprocess.run(cmd, capture_output=True, text=True, check=False)
            wall = time.perf_counter() - t0
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            load1 = os.getloadavg()[0]
            if done.returncode not in (0, 1):
                raise RuntimeError(f'fresh fit failed: {done.stderr.strip()[-500:]}')
            with open(os.path.join(tmp, 'r.json'), encoding='utf-8') as f:
                data = json.load(f)
            cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
            runs.append({'wall': wall, 'cpu': cpu, 'load_average': [load0, load1]})
            say(
                f'  fresh process {k + 1}/{repeats}: {wall:.2f} s wall, {cpu:.2f} s CPU for '
                f'{data["impacts_used"]} impacts, {len(bounds)} parameters '
                f'({data["verdict"][:60]}); load average {load0:.1f} -> {load1:.1f} on '
                f'{os.cpu_count()} CPUs'
            )
    walls, cpus = [r['wall'] for r in runs], [r['cpu'] for r in runs]
    say(
        f'  {len(bounds)} parameters, {repeats} runs: wall median {statistics.median(walls):.2f} '
        f's, worst {max(walls):.2f} s; CPU median {statistics.median(cpus):.2f} s, worst '
        f'{max(cpus):.2f} s'
    )
    return {
        'wall': statistics.median(walls),
        'wall_worst': max(walls),
        'cpu': statistics.median(cpus),
        'cpu_worst': max(cpus),
        'runs': runs,
        'params': len(bounds),
        'impacts': data['impacts_used'],
        'verdict': data['verdict'],
        'cpus': os.cpu_count(),
    }


def growth(say):
    from impact_arm.calibration.fit import fit
    from impact_arm.io.synthetic import synthetic_recording

    truth = {'surfaces[0].mu': 0.3, 'materials.steel.S_y': 9e8}
    out = {'impacts': [], 'params': []}
    fit(
        synthetic_recording('paper', truth, cycles=3, seed=1),
        'paper',
        {'surfaces[0].mu': BOUNDS['surfaces[0].mu']},
    )  # warm: kernels loaded
    for cycles in (5, 10, 15, 30):
        rec = synthetic_recording('paper', truth, cycles=cycles, seed=cycles)
        t0 = time.perf_counter()
        res = fit(rec, 'paper', {k: BOUNDS[k] for k in truth})
        wall = time.perf_counter() - t0
        out['impacts'].append(
            {'impacts': res.impacts_used, 'wall': wall, 'evaluations': res.evaluations}
        )
        say(
            f'  {res.impacts_used:3d} impacts, 2 parameters: {wall:.2f} s '
            f'({res.evaluations} evaluations)'
        )
    rec = synthetic_recording('paper', truth, cycles=15, seed=15)
    for count in (1, 2, 3, 4):
        keys = list(BOUNDS)[:count]
        t0 = time.perf_counter()
        res = fit(rec, 'paper', {k: BOUNDS[k] for k in keys})
        wall = time.perf_counter() - t0
        out['params'].append(
            {
                'params': count,
                'wall': wall,
                'evaluations': res.evaluations,
                'identified': [k for k in keys if res.parameters[k].identifiable],
            }
        )
        say(
            f'  {res.impacts_used:3d} impacts, {count} parameters: {wall:.2f} s '
            f'({res.evaluations} evaluations; identified: '
            f'{", ".join(out["params"][-1]["identified"]) or "none"})'
        )
    return out


def run(args) -> int:
    def say(text):
        print(text, flush=True)

    sensors = sensor_overrides(args.sensor)
    if sensors:  # a bad key or value refused now, in one line, not after the timings
        from impact_arm.calibration.study import Study

        Study('paper').scene(sensors)
    report = {}
    if not args.skip_fresh:
        if args.repeats < 1:
            from impact_arm.physics.errors import ImpactArmError

            raise ImpactArmError(f'--repeats {args.repeats}: must be at least 1')
        say('fresh process (15 impacts; 2 parameters, then 8):')
        report['fresh'] = fresh_process(say, repeats=args.repeats)
        report['fresh_8'] = fresh_process(say, EIGHT, repeats=args.repeats)
    if args.fresh_only:
        if args.json:
            from impact_arm.tools.cli import write_json

            write_json(args.json, report)
            say(f'wrote {args.json}')
        return 0
    say('growth:')
    report['growth'] = growth(say)
    say(f'accuracy over {args.cases} drawn cases ({args.impacts} impacts each):')
    if sensors:
        say(f'  recordings through the sensors {sensors}')
    rows = accuracy(args.cases, args.impacts, say, sensors)
    report['accuracy'] = summarize(rows)
    for name, s in report['accuracy'].items():
        say(f'{name}: {s["fits"]}/{s["cases"]} fit, median {s["wall_median"]:.2f} s')
        for k, v in s.items():
            if isinstance(v, dict):
                say(
                    f'  {k}: max |error| {100 * v["max_abs_error"]:.2f} %, median '
                    f'{100 * v["median_abs_error"]:.2f} %, 95 % interval holds the truth in '
                    f'{100 * v["coverage"]:.0f} %'
                )
    if args.json:
        from impact_arm.tools.cli import write_json

        report['cases'] = rows
        write_json(args.json, report)
        say(f'wrote {args.json}')
    return 0
