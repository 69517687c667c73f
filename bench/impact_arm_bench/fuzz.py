"""``impact-arm bench stress --fuzz N [--seed S]``: scenes a hostile user would write.

N scene files are mutated from config/paper.yaml with a seeded generator (deleted keys, wrong
types, huge / tiny / denormal / NaN / inf numbers, integers beyond float64, extra and duplicate
keys, YAML tags, aliases and 1.1-only spellings, 3-8 links, unreachable surfaces, extreme
``sensors`` sections, joint friction and armature, mounted surfaces) and each is loaded and run
offline as ``impact-arm simulate`` would, its sensors section read over a second of states as
the simulated driver would. Every one must end in one of

* accepted-finite: the run finished and every number it reports is finite;
* refused: the scene was refused in one line (SceneError);
* stopped-at-limit: the run stopped with a named SimulationError (e.g. the run budget);

and never in traceback (any other exception, or a crashed process), hang (more than
``--fuzz-timeout`` seconds of running, 20 by default; compiling a new scene shape's kernel is
not counted) or non-finite (a finished run reporting NaN or infinity).

The scenes run in a worker process, one after another; a hang or crash costs a new worker.
"""

from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
import time
import traceback

from . import common
from .generators import mutate

CLASSES = ('accepted-finite', 'refused', 'stopped-at-limit', 'traceback', 'hang', 'non-finite')
GOOD = CLASSES[:3]


# ------------------------------------------------------------------------------- worker
def _finite(value) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    return True


def classify(text: str, warm_up=lambda scene: None) -> dict:
    """Load and run one scene text; the class and a one-line detail."""
    from impact_arm.physics.errors import SceneError
    from impact_arm.physics.scene import scene_from_text
    from impact_arm.physics.simulate import run

    try:
        scene = scene_from_text(text, origin='fuzz')
    except SceneError as exc:
        message = str(exc)
        one_line = '\n' not in message and len(message) < 1000
        return {
            'class': 'refused' if one_line else 'traceback',
            'detail': message[:300].replace('\n', '\\n'),
        }
    try:
        warm_up(scene)
        result = run(scene, keep_samples=False)  # as the command runs it
        if result.error:
            return {'class': 'stopped-at-limit', 'detail': result.error[:300]}
        if not _finite(result.to_json()):
            return {'class': 'non-finite', 'detail': json.dumps(result.summary())[:300]}
        if not sensors_finite(scene):
            return {'class': 'non-finite', 'detail': f'sensor readings of {scene.sensors}'[:300]}
        return {'class': 'accepted-finite', 'detail': f'{len(result.impacts)} impacts'}
    except Exception:  # noqa: BLE001 - that is what this benchmark counts
        return {'class': 'traceback', 'detail': traceback.format_exc()[-300:]}


def sensors_finite(scene) -> bool:
    """The scene's sensors section (the simulated driver's readings, which an offline run does
    not take) turns a second of finite states at the scene's publish rate into finite
    readings."""
    import numpy as np

    from impact_arm.contract import to_joint_space
    from impact_arm.driver.sensors import sensed_series

    if scene.sensors.ideal:
        return True
    rows = min(int(scene.publish_rate), 2000)
    k = np.arange(rows)[:, None] / scene.publish_rate
    q = np.array(to_joint_space(scene.q0)) + k * np.linspace(1.0, 2.0, scene.n_links)
    ones = np.ones((rows, scene.n_links))
    readings = sensed_series(
        scene.sensors, scene.publish_rate, q, 3.0 * ones, -20.0 * ones, 100.0 * np.ones((rows, 2))
    )
    return all(np.isfinite(x).all() for x in readings)


def worker():
    """Reads one JSON-encoded scene text per line; writes 'start' once the scene's kernel is
    compiled and loaded, then the result (both JSON lines)."""
    from impact_arm.physics.errors import SimulationError
    from impact_arm.physics.simulate import run

    shapes = set()

    def ready(scene):
        # compile or load everything a scene of this shape runs (minutes, once per shape):
        # the kernel, and the laws and metrics first called at an impact, so 1 s of the run
        shape = (
            scene.n_links,
            scene.gravity == 0,
            scene.controller.law,
            scene.controller.rate > 0,
            scene.integrator.method,
            tuple((s.law, s.mu > 0, s.mount is not None) for s in scene.surfaces),
        )
        if shape not in shapes:
            shapes.add(shape)
            try:
                run(scene, t_max=min(scene.t_max, 1.0), keep_samples=False)
            except SimulationError:
                pass
        print(json.dumps({'start': True}), flush=True)

    for line in sys.stdin:
        text = json.loads(line)
        outcome = classify(text, warm_up=ready)
        print(json.dumps(outcome), flush=True)


class Worker:
    def __init__(self):
        self.proc = subprocess.Popen(
            [sys.executable, '-c', 'from impact_arm_bench.fuzz import worker; worker()'],
            env=common.worker_environment(),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            bufsize=1,
        )

    def _line(self, deadline):
        """The next JSON line, or None at the deadline or if the worker died."""
        import select

        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                return None
            line = self.proc.stdout.readline()
            if not line:
                return None
            if line.startswith('{'):
                return json.loads(line)

    def classify(self, text, timeout, compile_timeout=300.0):
        self.proc.stdin.write(json.dumps(text) + '\n')
        self.proc.stdin.flush()
        first = self._line(time.monotonic() + compile_timeout)
        if first is not None and 'start' in first:
            first = self._line(time.monotonic() + timeout)
        if first is None:
            hang = self.proc.poll() is None
            self.close()
            return {
                'class': 'hang' if hang else 'traceback',
                'detail': f'no result within {timeout:g} s'
                if hang
                else f'worker died (exit {self.proc.returncode})',
            }
        return first

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def run_fuzz(count, seed, timeout, keep_dir=None) -> tuple[dict, list]:
    """The tally of classes, and the unhandled scenes (each also written to ``keep_dir``
    as soon as it is found, as fuzz_SEED_INDEX.yaml)."""
    from .common import paper_dict

    rng = random.Random(seed)
    base = paper_dict()
    tally = dict.fromkeys(CLASSES, 0)
    bad = []
    worker_proc = Worker()
    try:
        for i in range(count):
            common.progress(
                f'[{i + 1}/{count}] ' + ', '.join(f'{k} {v}' for k, v in tally.items() if v),
                i,
                count,
            )
            text = mutate(base, rng)
            outcome = worker_proc.classify(text, timeout)
            if worker_proc.proc.poll() is not None:
                worker_proc = Worker()
            tally[outcome['class']] += 1
            if outcome['class'] not in GOOD:
                bad.append((i, outcome, text))
                if keep_dir:
                    with open(
                        os.path.join(keep_dir, f'fuzz_{seed}_{i}.yaml'),
                        'w',
                        encoding='utf-8',
                        errors='surrogatepass',
                    ) as f:
                        f.write(f'# {outcome["class"]}: {outcome["detail"][-200:]!r}\n{text}')
    finally:
        worker_proc.close()
        common.progress_done()
    return tally, bad


def report(args) -> int:
    started = time.monotonic()
    keep_dir = os.path.dirname(os.path.abspath(args.json)) if args.json else None
    tally, bad = run_fuzz(args.fuzz, args.seed, args.fuzz_timeout, keep_dir)
    print(common.table(['outcome', 'scenes'], [[k, v] for k, v in tally.items()], ['<', '>']))
    print(f'\n{args.fuzz} scenes (seed {args.seed}) in {time.monotonic() - started:.0f} s')
    for i, outcome, text in bad[:10]:
        print(f'\nscene {i}: {outcome["class"]}: {outcome["detail"]}')
    if args.json:
        common.write_json(
            args.json,
            {
                'benchmark': 'stress --fuzz',
                'seed': args.seed,
                'machine': common.machine(),
                'outcomes': tally,
                'unhandled': [{'scene': i, **o} for i, o, _ in bad],
            },
        )
    return 1 if bad else 0
