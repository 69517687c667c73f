"""``impact-arm bench features``: what each feature of a scene costs per simulated second.

Scenes (all the article's arm and controller unless said): free motion (no surface; no
controller: the double pendulum swings from the article's start pose), a frictionless Hertz
floor (elastic Hertz phases, μ = 0, no yield) and the article's scene (three-phase elasto-plastic
contact with tanh friction). Optional: the same free motion without gravity, and a three-link
arm (``--three-links``; its first use derives and compiles a new scene shape, ~1-2 min), and
(``--real-arm``) the article with joint damping and Coulomb friction, with joint armature and
with its floor on a compliant mount, each with its cost relative to the article's scene.

Reported per scene, best of ``--repeats``: wall time, simulated time, wall microseconds per
simulated second, right-hand-side evaluations per simulated second and per wall second, and
whether the scene has contact and friction, and the compiled module it ran on: gravity,
surfaces and μ are values, so every two-link rod arm shares the article's kernel.
"""

from __future__ import annotations

import copy

from impact_arm.contract import INTEGRATOR_PRESETS
from . import common
from .common import paper_dict


def _free(data):
    # an uncontrolled double pendulum released from the article's start pose: real motion
    # for the whole 6 s (a controlled arm without a floor would just settle at its target)
    data['controller']['law'] = 'none'
    data['surfaces'] = []
    data['cycles'] = 0
    data['t_max'] = 6.0
    return data


def _hertz(data):
    data['surfaces'] = [{'height': -1.0, 'law': 'hertz', 'mu': 0.0, 'material': 'steel'}]
    return data


def _no_gravity(data):
    data = _free(data)
    data['gravity'] = 0.0
    data['initial']['qd'] = [2.0, -3.0]  # spinning, since nothing would pull it
    return data


def _three_links(data):
    data['links'] = [
        {'length': 0.7, 'mass': 1.0},
        {'length': 0.7, 'mass': 1.0},
        {'length': 0.6, 'mass': 0.5},
    ]
    c = data['controller']
    c.update(
        kp=[600.0, 300.0, 100.0],
        kd=[100.0, 100.0, 30.0],
        ki=[0.0, 0.0, 0.0],
        down_target_deg=[-80.0, -70.0, -60.0],
        up_target_deg=[80.0, 70.0, 60.0],
    )
    data['initial'] = {'q_deg': [60.0, 45.0, 30.0], 'qd': [0.0, 0.0, 0.0]}
    data['cycles'] = 5
    return data


def _joint_friction(data):
    # a geared arm's joints: viscous and Coulomb friction (values of the kernel, no new shape)
    data['joints'] = [
        {'damping': 0.5, 'friction': 1.0, 'friction_v_d': 0.01},
        {'damping': 0.3, 'friction': 0.5, 'friction_v_d': 0.01},
    ]
    return data


def _armature(data):
    # rotor inertias: the closed-form accelerations give way to a Cholesky solve
    data['joints'] = [{'armature': 0.05}, {'armature': 0.02}]
    return data


def _mounted_floor(data):
    # the floor as a 10 kg plate on 1e8 N/m, lightly damped: two more states (a new shape)
    data['surfaces'][0]['mount'] = {'mass': 10.0, 'stiffness': 1e8, 'damping_ratio': 0.05}
    return data


SCENES = {
    'free motion (no surface)': _free,
    'frictionless Hertz floor': _hertz,
    "article's scene (elasto-plastic + friction)": lambda d: d,
}
EXTRA = {'free motion, no gravity': _no_gravity}
REAL_ARM = {  # --real-arm: what a real arm's joints and a compliant floor add to the article
    'article + joint damping and Coulomb friction': _joint_friction,
    'article + joint armature': _armature,
    'article + floor on a mount (10 kg, 1e8 N/m)': _mounted_floor,
}
ARTICLE = "article's scene (elasto-plastic + friction)"


def add_arguments(parser):
    parser.add_argument(
        '--preset',
        default='balanced',
        choices=INTEGRATOR_PRESETS,
        help='integrator preset of every run (default balanced)',
    )
    parser.add_argument('--repeats', type=int, default=5, help='timed runs per feature (default 5)')
    parser.add_argument(
        '--three-links',
        action='store_true',
        help='add a three-link arm (compiles a new scene shape on first use)',
    )
    parser.add_argument(
        '--real-arm',
        action='store_true',
        help='add the article with joint friction, with armature, with a mounted floor (the '
        'mounted floor compiles a new scene shape on first use)',
    )
    parser.add_argument('--json', metavar='FILE', help='write the measured rows as JSON')


def measure(name, make, preset, repeats):
    from impact_arm.physics.integrator import PRESETS
    from impact_arm.physics.model import ArmModel
    from impact_arm.physics.scene import parse_scene

    data = make(copy.deepcopy(paper_dict()))
    scene = parse_scene(data, origin=f'features:{name}')
    rtol, atol = PRESETS[preset]
    common.progress(f'{name}: compile/load')
    common.time_ours(scene, rtol, atol, repeats=1)  # load the compiled module
    common.progress(f'{name}: timing')
    r = common.time_ours(scene, rtol, atol, repeats=repeats)
    model = ArmModel(scene)
    return {
        'scene': name,
        'links': scene.n_links,
        'preset': preset,
        'contact': bool(model.surfaces),
        'friction': any(s.mu > 0 for s in model.surfaces),
        'integral_states': model.n_integral,
        'kernel': model.eq.__name__,
        'gravity': scene.gravity != 0,
        'impacts': len(r['impacts']),
        't_simulated': r['t_end'],
        'wall': r['wall'],
        'us_per_sim_s': r['wall'] / r['t_end'] * 1e6,
        'rhs_per_sim_s': r['rhs_evaluations'] / r['t_end'],
        'rhs_per_wall_s': r['rhs_evaluations'] / r['wall'],
        'ns_per_rhs': r['wall'] / r['rhs_evaluations'] * 1e9,
    }


def run(args) -> int:
    scenes = dict(SCENES, **EXTRA)
    if args.three_links:
        scenes['three links, article floor'] = _three_links
    if args.real_arm:
        scenes.update(REAL_ARM)
    rows = [measure(name, make, args.preset, args.repeats) for name, make in scenes.items()]
    common.progress_done()
    print(
        f'Cost per simulated second, preset {args.preset}, best of {args.repeats} '
        '(event-to-event runs, continuous control, no sampled output):'
    )
    print()
    body = [
        [
            r['scene'],
            r['links'],
            'yes' if r['contact'] else 'no',
            'yes' if r['friction'] else 'no',
            r['kernel'].rsplit('_', 1)[-1],
            r['impacts'],
            f'{r["t_simulated"]:.3f}',
            f'{r["wall"] * 1e3:.2f}',
            f'{r["us_per_sim_s"]:.0f}',
            f'{r["rhs_per_sim_s"]:.0f}',
            f'{r["ns_per_rhs"]:.0f}',
        ]
        for r in rows
    ]
    print(
        common.table(
            [
                'scene',
                'links',
                'contact',
                'friction',
                'kernel',
                'impacts',
                'sim [s]',
                'wall [ms]',
                'wall us / sim s',
                'rhs / sim s',
                'wall ns / rhs eval',
            ],
            body,
        )
    )
    print(
        '\nwall ns / rhs eval: whole run (stepping, events, Python wrapper) per right-hand-side '
        'evaluation, i.e. the per-evaluation price of the features the scene uses.\n'
        'kernel: the compiled module (its hash); gravity, surfaces and friction are values, '
        'so the scenes of one arm share it.'
    )
    if args.real_arm:
        article = next(r for r in rows if r['scene'] == ARTICLE)
        print("\nAgainst the article's scene, same run (ratios of wall per simulated second):")
        for r in rows:
            if r['scene'] in REAL_ARM:
                print(
                    f'  {r["scene"]}: x{r["us_per_sim_s"] / article["us_per_sim_s"]:.2f} '
                    f'(rhs / sim s x{r["rhs_per_sim_s"] / article["rhs_per_sim_s"]:.2f}, '
                    f'ns / rhs x{r["ns_per_rhs"] / article["ns_per_rhs"]:.2f})'
                )
    if args.json:
        common.write_json(
            args.json, {'benchmark': 'features', 'machine': common.machine(), 'rows': rows}
        )
    return 0
