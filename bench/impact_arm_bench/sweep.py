"""``impact-arm bench sweep``: what a study costs per run, and how it scales.

On the article's scene at the sweep setting (README, "Choosing a preset": Rosenbrock free
flight, rtol 1e-2, contact_rtol 3e-4) with random μ, E and kp:

1. per-run cost, on the same runs: the event-only kernel (``run(samples=False)``' own wall time on a
   validated scene), the Python API (``Study.run``: overrides, validation, model, integration,
   summary) and a sweep worker's chunk (``run_chunk``: the API plus the rows as a pyarrow
   table), interleaved in blocks of 50 runs, each block's fastest of ``--repeats`` timings
   per path; targets: API and worker within 1.2x of the kernel;
2. ``impact-arm sweep`` with 1 and with 2 local workers on the same spec (target: >= 1.8x);
3. ``impact-arm sweep`` of ``--runs`` runs (default 10 000) with 2 workers as a user starts
   it, a fresh process, wall time including start-up (target < 60 s on 2 cores), and each
   worker's resident memory sampled through the run (target: flat).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time

from . import common

SETTING = {
    'integrator.preset': 'fast',
    'integrator.method': 'rosenbrock',
    'integrator.rtol': 1e-2,
    'integrator.atol': 1e-4,
    'integrator.contact_rtol': 3e-4,
}
# μ, like every value here, is a kernel value: every run has the base scene's kernel
RANGES = {
    'surfaces[0].mu': [0.05, 0.5],
    'materials.steel.E': [1.5e11, 2.5e11],
    'controller.kp[0]': [400.0, 800.0],
    'controller.kp[1]': [200.0, 400.0],
}


def spec_text(runs: int, seed: int = 1) -> str:
    lines = ['scene: paper', 'set:'] + [f'  {k}: {v!r}' for k, v in SETTING.items()]
    lines += ['parameters:'] + [
        f'  {k}: {{random: [{lo!r}, {hi!r}]}}' for k, (lo, hi) in RANGES.items()
    ]
    lines += [f'samples: {runs}', f'seed: {seed}', 'outputs: [runs, impacts]']
    return '\n'.join(lines) + '\n'


def add_arguments(parser):
    parser.add_argument(
        '--runs', type=int, default=10_000, help='runs of the timed sweep (part 3; default 10000)'
    )
    parser.add_argument(
        '--per-run',
        type=int,
        default=400,
        help='runs timed in part 1 (default 400, in blocks of 50)',
    )
    parser.add_argument(
        '--repeats',
        type=int,
        default=3,
        help='part 1: times each block of 50 runs is timed per path, the '
        'fastest kept (default 3; 1: single timings)',
    )
    parser.add_argument(
        '--scaling-runs', type=int, default=2000, help='runs of each sweep in part 2 (default 2000)'
    )
    parser.add_argument('--json', metavar='FILE', help='write the figures as JSON')


def per_run_costs(count: int, repeats: int = 3) -> dict:
    """Per-run cost of the three paths on the same runs, in blocks of 50 (a worker's
    chunk): each block timed ``repeats`` times per path, in turn, and its fastest time
    kept. Other jobs only ever add time, so on a shared machine the minimum is the
    estimate a load spike during one path's turn does not decide; with ``repeats=1``
    every figure is a single timing, as before."""
    from impact_arm.physics.simulate import run
    from impact_arm.calibration.study import Study
    from impact_arm.tools import sweep

    spec = sweep.Spec(common_spec(count), origin='bench')
    study = Study(spec.scene_data, spec.fixed)
    study.run(spec.runs[0])  # load the kernel
    sweep.run_chunk(spec.hash, spec.scene_data, spec.fixed, spec.outputs, [(0, spec.runs[0])])
    block = 50
    totals = {'kernel': 0.0, 'api': 0.0, 'worker': 0.0}
    for start in range(0, count, block):
        items = list(enumerate(spec.runs[start : start + block], start))
        scenes = [study.scene(o) for _, o in items]

        def api():
            t0 = time.perf_counter()
            for _, overrides in items:
                study.run(overrides)
            return time.perf_counter() - t0

        def worker():
            t0 = time.perf_counter()
            sweep.run_chunk(spec.hash, spec.scene_data, spec.fixed, spec.outputs, items)
            return time.perf_counter() - t0

        paths = {
            'kernel': lambda: sum(run(s, samples=False).wall_time for s in scenes),
            'api': api,
            'worker': worker,
        }
        times = {name: [] for name in paths}
        for _ in range(repeats):
            for name, path in paths.items():
                times[name].append(path())
        for name in totals:
            totals[name] += min(times[name])
    kernel, api, worker = totals['kernel'], totals['api'], totals['worker']
    return {
        'runs': count,
        'repeats': repeats,
        'kernel_ms': kernel / count * 1e3,
        'api_ms': api / count * 1e3,
        'worker_ms': worker / count * 1e3,
        'api_ratio': api / kernel,
        'worker_ratio': worker / kernel,
    }


def common_spec(runs: int) -> dict:
    import yaml

    return yaml.safe_load(spec_text(runs))


def sweep_process(runs: int, workers: int, directory: str, label: str) -> dict:
    """``impact-arm sweep`` in a fresh process: wall time including start-up, and the peak
    and first/last resident memory of each of its worker processes."""
    path = os.path.join(directory, f'{label}.yaml')
    with open(path, 'w', encoding='utf-8') as f:
        f.write(spec_text(runs))
    import resource

    def cpu():
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    cpu0 = cpu()
    t0 = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'sweep', path, '--workers', str(workers)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    samples = {}
    done = threading.Event()

    def watch():
        while not done.wait(0.25):
            for pid in live_descendants(child.pid):
                rss = _rss_mb(pid)
                if rss and _is_worker(pid):
                    samples.setdefault(pid, []).append(rss)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    out, err = child.communicate()
    wall = time.perf_counter() - t0
    # CPU of the sweep and its workers (waited for, so counted): on a machine shared with
    # other jobs, cores used = CPU / wall tells a scaling limit from a lack of free cores
    cpu_used = cpu() - cpu0
    done.set()
    watcher.join()
    if child.returncode:
        raise RuntimeError(f'sweep failed: {err.strip()[-400:]}')
    summary = out.strip().splitlines()[0] if out.strip() else ''
    rate = float(summary.split('then ')[1].split(' runs/s')[0]) if 'then ' in summary else 0.0
    # memory at a third of each worker's life (past start-up), two thirds, the end
    return {
        'runs': runs,
        'workers': workers,
        'wall': wall,
        'runs_per_s': runs / wall,
        'cpu': cpu_used,
        'cpu_ms_per_run': cpu_used / runs * 1e3,
        'cores_used': cpu_used / wall,
        'steady_runs_per_s': rate,
        'summary': summary,
        'worker_rss_mb': [
            {
                'third': s[len(s) // 3],
                'two_thirds': s[2 * len(s) // 3],
                'last': s[-1],
                'peak': max(s),
            }
            for s in samples.values()
        ],
    }


def live_descendants(pid):
    """Live (not zombie) processes below ``pid``, from ``/proc``."""
    parents = {}
    for entry in filter(str.isdigit, os.listdir('/proc')):
        try:
            with open(f'/proc/{entry}/stat', encoding='ascii') as f:
                fields = f.read().rsplit(')', 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] != 'Z':
            parents.setdefault(int(fields[1]), []).append(int(entry))
    found, stack = [], [pid]
    while stack:
        for child in parents.get(stack.pop(), []):
            found.append(child)
            stack.append(child)
    return found


def _is_worker(pid):
    """A process of the local pool (multiprocessing's spawn entry), not its resource
    tracker."""
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as f:
            return b'spawn_main' in f.read()
    except OSError:
        return False


def _rss_mb(pid):
    try:
        with open(f'/proc/{pid}/status', encoding='ascii') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def run(args) -> int:
    result = {
        'machine': common.machine(),
        'setting': SETTING,
        'ranges': RANGES,
        'load_average_before': os.getloadavg(),
    }
    print(
        'load average before (1, 5, 15 min): %.2f %.2f %.2f (other jobs share the cores)'
        % result['load_average_before']
    )
    common.progress(f'per-run cost: {args.per_run} runs')
    cost = result['per_run'] = per_run_costs(args.per_run, args.repeats)
    common.progress_done()
    print(
        f"Per run, article's scene at rtol 1e-2 / contact 3e-4, {cost['runs']} random runs "
        f'(mu, E, kp), fastest of {cost["repeats"]} timings of each block of 50:'
    )
    print(
        common.table(
            ['path', 'ms per run', 'vs kernel'],
            [
                ['event-only kernel (run, samples=False)', f'{cost["kernel_ms"]:.3f}', '1.00'],
                ['Python API (Study.run)', f'{cost["api_ms"]:.3f}', f'{cost["api_ratio"]:.2f}'],
                [
                    'sweep worker (run_chunk)',
                    f'{cost["worker_ms"]:.3f}',
                    f'{cost["worker_ratio"]:.2f}',
                ],
            ],
        )
    )
    with tempfile.TemporaryDirectory(prefix='bench_sweep_') as directory:
        rows = []
        for workers in (1, 2):
            common.progress(f'scaling: {args.scaling_runs} runs, {workers} worker(s)')
            rows.append(sweep_process(args.scaling_runs, workers, directory, f'w{workers}'))
        common.progress_done()
        result['scaling'] = rows
        print(
            f'\nimpact-arm sweep, {args.scaling_runs} runs, fresh process (wall includes start-up):'
        )
        print(
            common.table(
                [
                    'workers',
                    'wall [s]',
                    'runs/s overall',
                    'runs/s after start-up',
                    'CPU ms per run',
                    'cores used',
                ],
                [
                    [
                        r['workers'],
                        f'{r["wall"]:.2f}',
                        f'{r["runs_per_s"]:.0f}',
                        f'{r["steady_runs_per_s"]:.0f}',
                        f'{r["cpu_ms_per_run"]:.2f}',
                        f'{r["cores_used"]:.2f}',
                    ]
                    for r in rows
                ],
            )
        )
        print(
            f'2 workers / 1 worker: {rows[1]["runs_per_s"] / rows[0]["runs_per_s"]:.2f}x '
            f'overall, {rows[1]["steady_runs_per_s"] / rows[0]["steady_runs_per_s"]:.2f}x '
            f'after start-up'
        )
        if rows[1]['cores_used'] < 1.5:
            # a ratio near or below 1 here measures the machine, not the sweep
            print(
                f'  (2 workers got only {rows[1]["cores_used"]:.2f} cores: other jobs hold '
                f'the rest, so this ratio cannot show scaling; measure on an idle machine)'
            )
        common.progress(f'{args.runs} runs, 2 workers')
        big = result['big'] = sweep_process(args.runs, 2, directory, 'big')
        common.progress_done()
    print(
        f'\n{args.runs} runs, 2 workers: {big["wall"]:.1f} s wall including start-up '
        f'({big["runs_per_s"]:.0f} runs/s, {big["cores_used"]:.2f} cores used); '
        f'{big["summary"]}'
    )
    for i, rss in enumerate(big['worker_rss_mb']):
        print(
            f'  worker {i + 1}: resident {rss["third"]:.0f} MB at a third of the run, '
            f'{rss["two_thirds"]:.0f} MB at two thirds, {rss["last"]:.0f} MB at the end, '
            f'peak {rss["peak"]:.0f} MB'
        )
    if args.json:
        common.write_json(args.json, result)
    return 0
