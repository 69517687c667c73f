"""``impact-arm bench coldstart``: what the first run of a new arm shape costs, by link count.

Each shape runs in a fresh process with an empty kernel cache (``IMPACT_ARM_CACHE`` set to a
new temporary directory), as a user's first run of a scene with that many links: the
equations (sympy up to ``equations.SYMBOLIC_LINKS`` links, the chain's closed form beyond),
then numba's compilation of the kernel, then one short run. A second process with the now
warm cache shows what every later run pays. Printed: wall and CPU seconds of the whole
process, and its parts as the process measured them.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time

from . import common

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from impact_arm.physics import equations
from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import parse_scene
from impact_arm_bench.coldstart import chain_scene
t1 = time.perf_counter()
scene = parse_scene(chain_scene(int(sys.argv[1])), origin='chain')
t2 = time.perf_counter()
model = ArmModel(scene)
t3 = time.perf_counter()
integ = PhaseIntegrator(model)
t4 = time.perf_counter()
integ.advance(0.5)
t5 = time.perf_counter()
print(json.dumps({'imports': t1 - t0, 'scene': t2 - t1, 'equations': t3 - t2,
                  'kernel': integ.load_time, 'run': t5 - t4}))
"""


def chain_scene(n: int) -> dict:
    """The article's scene with an n-link arm of the same 2 m reach and 2 kg mass."""
    from .common import paper_dict

    data = paper_dict()
    data['links'] = [{'length': 2.0 / n, 'mass': 2.0 / n}] * n
    c = data['controller']
    c.update(
        kp=[600.0 / n] * n,
        kd=[100.0 / n] * n,
        ki=[0.0] * n,
        down_target_deg=[-80.0] * n,
        up_target_deg=[80.0] * n,
    )
    data['initial'] = {'q_deg': [60.0] * n, 'qd': [0.0] * n}
    data['cycles'] = 1
    return data


def add_arguments(parser):
    parser.add_argument(
        '--links', default='2,4,5,8,12', help='link counts to start cold (default: %(default)s)'
    )
    parser.add_argument('--json', metavar='FILE', help='write the rows as JSON')


def _child(n, cache):
    env = common.worker_environment(dict(os.environ, IMPACT_ARM_CACHE=cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, '-c', CHILD, str(n)], env=env, capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f'{n} links: {done.stderr.strip().splitlines()[-1]}')
    parts = json.loads(done.stdout.strip().splitlines()[-1])
    return dict(parts, wall=wall, cpu=cpu)


def run(args) -> int:
    rows = []
    for n in [int(x) for x in args.links.split(',') if x.strip()]:
        with tempfile.TemporaryDirectory(prefix='impact_arm_cold_') as cache:
            common.progress(f'{n} links: cold start (empty cache)')
            cold = _child(n, cache)
            common.progress(f'{n} links: warm start')
            warm = _child(n, cache)
        rows.append({'links': n, 'cold': cold, 'warm': warm})
    common.progress_done()
    from impact_arm.physics.equations import SYMBOLIC_LINKS

    print(
        'First run of a new arm shape, fresh process each, empty kernel cache (cold) and the '
        'same cache again (warm). Parts: equations = generating (sympy up to '
        f'{SYMBOLIC_LINKS} links, closed form beyond) and importing the module; compile / '
        'kernel load = numba compiling (cold) or loading (warm) the kernel; CPU = user + '
        'system seconds of the process (the wall time includes waiting for a busy machine).'
    )
    print()
    body = [
        [
            r['links'],
            f'{r["cold"]["wall"]:.1f}',
            f'{r["cold"]["cpu"]:.1f}',
            f'{r["cold"]["equations"]:.2f}',
            f'{r["cold"]["kernel"]:.1f}',
            f'{r["warm"]["wall"]:.2f}',
            f'{r["warm"]["imports"]:.2f}',
            f'{r["warm"]["kernel"] * 1e3:.0f}',
        ]
        for r in rows
    ]
    print(
        common.table(
            [
                'links',
                'cold wall [s]',
                'cold CPU [s]',
                'equations [s]',
                'compile [s]',
                'warm wall [s]',
                'warm imports [s]',
                'warm kernel load [ms]',
            ],
            body,
        )
    )
    if args.json:
        common.write_json(
            args.json, {'benchmark': 'coldstart', 'machine': common.machine(), 'rows': rows}
        )
    return 0
