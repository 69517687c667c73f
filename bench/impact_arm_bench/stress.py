"""``impact-arm bench stress``: stability at the extremes of the parameter space.

Every case runs a variant of the article's scene (or of a vertical strike, where the impact
speed itself is the parameter) and must either finish with finite, physically consistent
results or stop with a clear error naming the limit it crossed. Checked on every impact:

* the phases come in order (contact, [yield], max_compression, separation), none skipped or
  repeated (yield only on an elasto-plastic surface);
* δm > 0, 0 <= δr < δm, δ >= 0 at every traced contact point, every number finite;
* contact never adds energy: with the motors off during contact only gravity (conservative)
  and the contact act, so E = T + V after separation must not exceed E at contact. The
  "energy-balance error" is that gain relative to E's scale (for a frictionless Hertz contact,
  which conserves energy, |ΔE| itself);
* no impact missed: cases whose geometry forces an impact state how many they expect.

The fast cases (``FAST``) run in ``make test`` (test/integration/test_stress.py); ``bench stress`` runs the
full sweep, including a soak of 10 000 impacts, and prints the matrix as a table.
"""

from __future__ import annotations

import argparse
import copy
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from impact_arm.contract import INTEGRATOR_METHODS
from . import common
from .common import paper_dict

if TYPE_CHECKING:
    from impact_arm.physics.scene import Scene

OK, STOPPED, FAIL = 'ok', 'stopped', 'FAIL'


@dataclass
class Case:
    name: str
    changes: dict = field(default_factory=dict)  # {('controller', 'kp'): [...]} on the base
    top: dict = field(default_factory=dict)  # top-level keys replaced
    base: str = 'paper'  # 'paper' or 'strike' (vertical strike)
    strike_speed: float = 0.0  # m/s, for base 'strike'
    expect: str = 'ok'  # 'ok', 'stop' (a named limit), or 'any'
    expect_impacts: int | None = None  # exact count the geometry forces
    min_impacts: int = 1
    preset: str = 'balanced'
    note: str = ''


def strike_dict(
    v: float, law: str = 'elastoplastic', mu: float = 0.2, qd2: float = 0.0
) -> dict[str, Any]:
    """Link 2 hanging straight down, link 1 turning so the tip moves straight down at v and
    meets the floor 1e-7 m below its start; no gravity, no controller, 1 impact."""
    data = paper_dict()
    data.update(gravity=0.0, cycles=0, t_max=0.01)
    data['initial'] = {'q_deg': [0.0, -90.0], 'qd': [-v, qd2]}
    data['controller']['law'] = 'none'
    data['surfaces'] = [
        {'height': -1.0 - 1e-7, 'law': law, 'mu': mu, 'v_d': 0.02, 'material': 'steel'}
    ]
    return data


def build(case: Case) -> Scene:
    from impact_arm.physics.scene import parse_scene

    data = strike_dict(case.strike_speed) if case.base == 'strike' else paper_dict()
    data = copy.deepcopy(data)
    for path, value in case.changes.items():
        node = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    data.update(case.top)
    return parse_scene(data, origin=f'stress:{case.name}')


def _two(value):
    return {'steel': {'E': value, 'nu': 0.29, 'S_y': 1.12e9}}


def _mat(**kw):
    m = {'E': 210e9, 'nu': 0.29, 'S_y': 1.12e9}
    m.update(kw)
    return {'steel': m}


def _surface(**kw):
    s = {'height': -1.0, 'law': 'elastoplastic', 'mu': 0.2, 'v_d': 0.02, 'material': 'steel'}
    s.update(kw)
    return [s]


def cases(full: bool = False) -> list[Case]:
    """The matrix. ``full`` adds the intermediate values and the soak."""
    c = []
    c2 = {'cycles': 2, 't_max': 5.0}
    moduli = (1e7, 1e8, 1e9, 1e11, 1e12, 1e13) if full else (1e7, 1e13)
    for E in moduli:
        # steel's S_y with a soft modulus is refused at load (yield strain > 0.1); the same
        # modulus with S_y scaled like steel's (S_y/E = 0.0053) is a consistent soft material
        c.append(Case(f'E = {E:g} Pa', top=dict(c2, materials=_two(E)), expect='any'))
        if E < 210e9:
            c.append(
                Case(
                    f'E = {E:g} Pa, S_y = {E * 0.0053:g} Pa',
                    expect='any',
                    top=dict(c2, materials=_mat(E=E, S_y=E * 0.0053)),
                )
            )
    speeds = (1e-3, 1e-2, 0.1, 1.0, 10.0, 50.0) if full else (1e-3, 50.0)
    for v in speeds:
        c.append(
            Case(
                f'impact speed {v:g} m/s',
                base='strike',
                strike_speed=v * 0.75,
                expect='any',
                expect_impacts=1,
            )
        )
    for vd in (1e-6, 1e-4, 0.02, 1.0) if full else (1e-6, 1.0):
        c.append(Case(f'v_d = {vd:g} m/s', top=dict(c2, surfaces=_surface(v_d=vd))))
    for mu in (0.0, 0.5, 1.0, 2.0) if full else (0.0, 2.0):
        if mu == 0.0:  # a frictionless strike (an existing scene shape): Hertz, conserves E
            c.append(
                Case(
                    'mu = 0 (frictionless Hertz strike)',
                    base='strike',
                    strike_speed=0.5,
                    changes={},
                    top={
                        'surfaces': [
                            {'height': -1.0 - 1e-7, 'law': 'hertz', 'mu': 0.0, 'material': 'steel'}
                        ]
                    },
                    expect_impacts=1,
                )
            )
        else:
            c.append(Case(f'mu = {mu:g}', top=dict(c2, surfaces=_surface(mu=mu))))
    for R in (1e-4, 1e-3, 0.01, 0.1) if full else (1e-4, 0.1):
        c.append(Case(f'tip radius {R:g} m', top=dict(c2, tip_radius=R), expect='any'))
    # S_y/E* = 0.096 (the largest yield strain the scene accepts): 1.9 δc > δm, never yields
    c.append(Case('S_y 1.1e10 Pa (stays elastic)', top=dict(c2, materials=_mat(S_y=1.1e10))))
    c.append(Case('S_y 3e8 Pa (yields almost at once)', top=dict(c2, materials=_mat(S_y=3e8))))
    c.append(
        Case('S_y 1e5 Pa (yields at once)', top=dict(c2, materials=_mat(S_y=1e5)), expect='any')
    )
    for gap in (1e-9, 1e-7, 1e-5) if full else (1e-9,):
        # the tip swings through its lowest point, the floor `gap` above it: a grazing touch
        # whose normal approach speed is ~sqrt(2 gap) * 1 rad/s (4.5e-5 m/s for 1e-9 m)
        c.append(
            Case(
                f'grazing, floor {gap:g} m above the lowest point',
                base='strike',
                strike_speed=0.0,
                changes={('initial', 'q_deg'): [0.0, -100.0], ('initial', 'qd'): [0.0, 1.0]},
                top={
                    't_max': 0.4,
                    'surfaces': [
                        {'height': -1.0 + gap, 'law': 'hertz', 'mu': 0.0, 'material': 'steel'}
                    ],
                },
                expect_impacts=1,
            )
        )
    c.append(
        Case(
            'pressing into the surface (PD, motors on in contact)',
            changes={('controller', 'law'): 'pd', ('controller', 'up_target_deg'): [-80.0, -70.0]},
            top={'actuators_during_contact': True, 'cycles': 0, 't_max': 0.6},
            expect='any',
            note='sustained contact / chatter',
        )
    )
    c.append(
        Case(
            'arm stretched (q1 = q2 = 60 deg)', changes={('initial', 'q_deg'): [60.0, 60.0]}, top=c2
        )
    )
    c.append(
        Case(
            'arm folded (q2 = q1 - 180 deg)', changes={('initial', 'q_deg'): [60.0, -120.0]}, top=c2
        )
    )
    c.append(
        Case(
            'gains x100',
            changes={
                ('controller', 'kp'): [60000.0, 30000.0],
                ('controller', 'kd'): [10000.0, 10000.0],
            },
            top=c2,
            expect='any',
        )
    )
    if full:
        c.append(
            Case(
                'soak: 10 000 impacts',
                top={'cycles': 10000, 't_max': 1e5},
                preset='fast',
                min_impacts=10000,
            )
        )
    return c


FAST = cases(full=False)


@dataclass
class Outcome:
    case: str
    outcome: str  # ok | stopped | FAIL
    message: str
    impacts: int
    wall: float
    energy_error: float  # worst energy gain over the impacts (relative); nan if n/a
    t_end: float


def check_run(
    case: Case, scene: Scene, deadline: float | None = None, method: str = 'dopri5'
) -> Outcome:
    """Run one case event to event, checking every impact. Returns an ``Outcome``."""
    from impact_arm.physics.errors import SimulationError
    from impact_arm.physics.integrator import PhaseIntegrator
    from impact_arm.physics.metrics import ImpactBuilder
    from impact_arm.physics.model import ArmModel

    t0 = time.perf_counter()
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, preset=case.preset, trace=True, method=method)
    builder = ImpactBuilder(model)
    n = model.n
    motors_in_contact = scene.actuators_during_contact and scene.controller.law != 'none'
    elastic_frictionless = all(s.law == 'hertz' and s.mu == 0 for s in model.surfaces)
    worst_gain = 0.0 if not motors_in_contact else math.nan
    problems = []
    cycles = 0
    sequence = []
    e_contact = None

    def energy(y: np.ndarray) -> float:
        q, qd = y[:n].tolist(), y[n : 2 * n].tolist()
        return float(sum(model.link_energies(q, qd)) + model.potential_energy(q))

    def stop(outcome: str, message: str) -> Outcome:
        return Outcome(
            case.name,
            outcome,
            message,
            len(builder.impacts),
            time.perf_counter() - t0,
            worst_gain,
            integ.state.t,
        )

    try:
        while integ.state.t < scene.t_max and (not scene.cycles or cycles < scene.cycles):
            if deadline and time.perf_counter() - t0 > deadline:
                return stop(FAIL, f'no result within {deadline:g} s of wall time')
            events = integ.advance(scene.t_max, stop_at_event=True)
            st = integ.state
            if not np.all(np.isfinite(st.y)):
                return stop(FAIL, f'non-finite state at t = {st.t:g} s, not reported')
            if st.phase.name == 'FREE' and len(st.levels):
                y_tip = model.tip(st.y[:n], st.y[n : 2 * n])[1]
                if y_tip < min(st.levels) - 1e-9:
                    return stop(
                        FAIL,
                        f'tip {min(st.levels) - y_tip:.3g} m below a surface '
                        f'in free flight at t = {st.t:.6g} s (impact missed)',
                    )
            for ev in events:
                cycles += ev.kind == 'switch'
                if ev.kind == 'contact':
                    sequence = ['contact']
                    e_contact = energy(ev.y)
                elif ev.kind in ('yield', 'max_compression', 'separation'):
                    sequence.append(ev.kind)
                record = builder.feed(ev)
                if record is None:
                    continue
                surf = model.surfaces[ev.surface]
                want = (
                    ['contact', 'yield', 'max_compression', 'separation']
                    if surf.law == 'elastoplastic'
                    and record.delta_m >= 1.9 * surf.constants.delta_c
                    else ['contact', 'max_compression', 'separation']
                )
                if sequence != want:
                    problems.append(f'impact {record.index}: phases {sequence}, expected {want}')
                rows = integ.trace[:]
                integ.trace.clear()
                deltas = [r[2] for r in rows]
                dm, dr = record.delta_m, record.delta_r
                numbers = [dm, dr, record.F_max, record.duration, *record.v_after, *record.T_after]
                if not all(math.isfinite(x) for x in numbers):
                    problems.append(f'impact {record.index}: non-finite metrics')
                if not dm > 0:
                    problems.append(f'impact {record.index}: δm = {dm:g} <= 0')
                if not 0 <= dr < dm:
                    problems.append(f'impact {record.index}: δr = {dr:g} not in [0, δm)')
                if deltas and min(deltas) < -1e-6 * dm:
                    problems.append(f'impact {record.index}: δ = {min(deltas):g} < 0')
                if not motors_in_contact:
                    e_sep = energy(ev.y)
                    scale = max(abs(e_contact), sum(record.T_before) / 2, 1e-300)
                    gain = (
                        abs(e_sep - e_contact) if elastic_frictionless else e_sep - e_contact
                    ) / scale
                    worst_gain = max(worst_gain, gain)
                    tol = 1e-6 if case.preset != 'fast' else 1e-4
                    if gain > tol:
                        problems.append(
                            f'impact {record.index}: contact added energy ({gain:.2e} of E)'
                        )
                if problems:
                    return stop(FAIL, '; '.join(problems[:3]))
    except SimulationError as exc:
        if case.expect == 'ok':
            return stop(FAIL, f'stopped unexpectedly: {exc}')
        return stop(STOPPED, str(exc))
    except Exception as exc:  # anything else is a defect, reported as such
        return stop(FAIL, f'{type(exc).__name__}: {exc}')
    n_imp = len(builder.impacts)
    if case.expect == 'stop':
        return stop(FAIL, 'expected a named stop, finished instead')
    if case.expect_impacts is not None and n_imp != case.expect_impacts:
        return stop(
            FAIL,
            f'{n_imp} impacts, the geometry forces {case.expect_impacts} '
            '(impact missed or repeated)',
        )
    if n_imp < case.min_impacts:
        return stop(FAIL, f'only {n_imp} impacts (expected at least {case.min_impacts})')
    phase = integ.state.phase.name.lower()
    return stop(
        OK,
        f'{n_imp} impacts, t = {integ.state.t:.4g} s, ends in phase {phase}'
        + (' (sustained contact)' if phase != 'free' else ''),
    )


def run_case(case: Case, deadline: float | None = None, method: str = 'dopri5') -> Outcome:
    from impact_arm.physics.errors import SceneError

    try:
        scene = build(case)
    except SceneError as exc:  # refused at load: a named limit, too
        return Outcome(
            case.name, STOPPED if case.expect != 'ok' else FAIL, str(exc), 0, 0.0, math.nan, 0.0
        )
    return check_run(case, scene, deadline, method)


def format_matrix(outcomes: Iterable[Outcome]) -> str:
    body = [
        [
            o.case,
            o.outcome,
            o.impacts,
            f'{o.wall:.3f}',
            'n/a' if math.isnan(o.energy_error) else f'{o.energy_error:.1e}',
            o.message,
        ]
        for o in outcomes
    ]
    return common.table(
        ['case', 'outcome', 'impacts', 'wall [s]', 'worst energy gain', 'detail'],
        body,
        ['<', '<', '>', '>', '>', '<'],
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--quick', action='store_true', help='only the fast cases (the ones make test runs)'
    )
    parser.add_argument('--only', metavar='TEXT', help='cases whose name contains TEXT')
    parser.add_argument(
        '--deadline',
        type=float,
        default=300.0,
        help='wall seconds allowed per case before it counts as a failure',
    )
    parser.add_argument('--json', metavar='FILE', help='write the matrix as JSON')
    parser.add_argument(
        '--method',
        choices=INTEGRATOR_METHODS,
        default='dopri5',
        help='step method in free flight (integrator.method)',
    )
    parser.add_argument(
        '--fuzz',
        type=int,
        metavar='N',
        default=0,
        help='instead of the matrix: N scenes mutated from paper.yaml, each '
        'classified (bench/impact_arm_bench/fuzz.py)',
    )
    parser.add_argument('--seed', type=int, default=0, help='seed of --fuzz')
    parser.add_argument(
        '--fuzz-timeout',
        type=float,
        default=20.0,
        metavar='S',
        help='seconds a fuzzed scene may run before it counts as a hang',
    )
    from .flood import add_arguments as flood_arguments

    flood_arguments(parser)


def run(args: argparse.Namespace) -> int:
    if args.fuzz:
        from .fuzz import report

        return report(args)
    if args.flood:
        from .flood import report

        return report(args)
    selected = cases(full=not args.quick)
    if args.only:
        selected = [c for c in selected if args.only in c.name]
    outcomes = []
    for i, case in enumerate(selected, 1):
        common.progress(f'[{i}/{len(selected)}] {case.name}', i - 1, len(selected))
        outcomes.append(run_case(case, args.deadline, args.method))
    common.progress_done()
    print(format_matrix(outcomes))
    failed = [o for o in outcomes if o.outcome == FAIL]
    print(
        f'\n{len(outcomes)} cases: {len(outcomes) - len(failed)} finished or stopped with a '
        f'named limit, {len(failed)} failed'
    )
    if args.json:
        common.write_json(
            args.json,
            {
                'benchmark': 'stress',
                'machine': common.machine(),
                'cases': [o.__dict__ for o in outcomes],
            },
        )
    return 1 if failed else 0
