"""``impact-arm bench peers``: MuJoCo on the article's scene beside this project, in one run.

An optional extra (``pip install mujoco``; not a test dependency): the same two-link arm
(uniform rods, hinge joints, a 5 mm tip sphere), the same floor and the same continuous Q
controller and down/up cycle, stepped by MuJoCo with its own soft contact. MuJoCo is run as a
user would: with its defaults at a 1 ms step, and with ``solref`` tuned on the first impact's
coefficient of restitution at a 10 µs step (the contact lasts ~140 µs; MuJoCo wants its contact
time constant ≥ 2 steps). The controller is evaluated in Python before each MuJoCo step, as a
user's script does; actuators are off during contact, as in the article.

Errors, all against this project's ``reference`` preset: the first impact's F_max and
contact duration, and the worst error over every impact of the kinematic CoR e. Wall time:
the whole 15 cycles (6 s simulated), best of ``--repeats``.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from . import common

if TYPE_CHECKING:
    from impact_arm.physics.impact import Impact
    from impact_arm.physics.scene import Scene

MJCF = """<mujoco model="impact_arm">
  <option timestep="{dt}" gravity="0 {gy} 0" integrator="{integrator}"/>
  <worldbody>
    <geom name="floor" type="plane" pos="0 {floor} 0" zaxis="0 1 0" size="5 5 0.1" friction="{mu} 0.005 0.0001" {contact}/>
    <body name="link1">
      <joint name="j1" type="hinge" axis="0 0 1"/>
      <inertial pos="{c1} 0 0" mass="{m1}" diaginertia="1e-9 {i1} {i1}"/>
      <body name="link2" pos="{L1} 0 0">
        <joint name="j2" type="hinge" axis="0 0 1"/>
        <inertial pos="{c2} 0 0" mass="{m2}" diaginertia="1e-9 {i2} {i2}"/>
        <geom name="tip" type="sphere" pos="{L2} 0 0" size="{radius}" mass="0" friction="{mu} 0.005 0.0001" {contact}/>
      </body>
    </body>
  </worldbody>
</mujoco>"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--scene', default='paper', help='a two-link scene (default: paper)')
    parser.add_argument('--repeats', type=int, default=2, help='timed repeats (best kept)')
    parser.add_argument('--json', metavar='FILE', help='write the rows as JSON')


def build(
    scene: Scene,
    dt: float,
    solref: tuple[float, float] | None = None,
    integrator: str = 'implicitfast',
) -> Any:
    import mujoco

    (L1, L2), (m1, m2) = scene.lengths, scene.masses
    surface = scene.surfaces[0]
    contact = '' if solref is None else f'solref="{solref[0]!r} {solref[1]!r}"'
    # the project's contact starts when the tip *centre* reaches the surface (δ = h - y_B):
    # MuJoCo's sphere touches a plane lowered by its radius at the same moment
    xml = MJCF.format(
        dt=dt,
        gy=-scene.gravity,
        integrator=integrator,
        floor=surface.height - scene.tip_radius,
        contact=contact,
        c1=L1 / 2,
        m1=m1,
        i1=m1 * L1**2 / 12,
        L1=L1,
        c2=L2 / 2,
        m2=m2,
        i2=m2 * L2**2 / 12,
        L2=L2,
        radius=scene.tip_radius,
        mu=surface.mu,
    )
    return mujoco.MjModel.from_xml_string(xml)


def simulate(
    scene: Scene, model: Any, t_end: float, max_impacts: int | None = None
) -> list[dict[str, Any]]:
    """The cycle under MuJoCo; impact records (t, v before/after, F_max, duration, e)."""
    import mujoco
    import numpy as np

    data = mujoco.MjData(model)
    c = scene.controller
    (L1, L2), (m1, m2), g = scene.lengths, scene.masses, scene.gravity
    data.qpos[:] = [scene.q0[0], scene.q0[1] - scene.q0[0]]
    data.qvel[:] = [scene.qd0[0], scene.qd0[1] - scene.qd0[0]]
    kp, kd = c.kp, c.kd
    down, up = c.down_target, c.up_target
    mode_up = False
    impacts, current = [], None
    force = np.zeros(6)
    dt = model.opt.timestep
    steps = int(round(t_end / dt))
    qfrc = data.qfrc_applied
    previous = (0.0, 0.0)
    for _ in range(steps):
        j1, j2 = data.qpos
        w1, w2 = data.qvel
        q1, q2, qd1, qd2 = j1, j1 + j2, w1, w1 + w2
        s1, c1, s2, c2 = math.sin(q1), math.cos(q1), math.sin(q2), math.cos(q2)
        vx = -L1 * s1 * qd1 - L2 * s2 * qd2
        vy = L1 * c1 * qd1 + L2 * c2 * qd2
        # after mj_step, ncon counts the contacts of the step just taken, whose impulse is
        # already in qvel: the velocity before the impact is the previous step's
        touching = data.ncon > 0
        if touching and current is None:
            current = {'t': data.time - dt, 'v_before': previous, 'F_max': 0.0}
            mode_up = True  # struck: the cycle turns upward
        elif not touching and current is not None:
            current['duration'] = data.time - dt - current['t']
            current['v_after'] = (vx, vy)
            current['e'] = -vy / current['v_before'][1]
            impacts.append(current)
            current = None
            if max_impacts and len(impacts) >= max_impacts:
                break
        if touching:
            mujoco.mj_contactForce(model, data, 0, force)
            current['F_max'] = max(current['F_max'], abs(force[0]))
            qfrc[0] = qfrc[1] = 0.0  # actuators off during contact
        else:
            y_tip = L1 * s1 + L2 * s2
            if mode_up and y_tip >= c.switch_height:
                mode_up = False
            target = up if mode_up else down
            # Q law (article eq. 9): PD on absolute angles + exact gravity compensation;
            # joint torques act on MuJoCo's relative hinges directly
            qg2 = -g * m2 * L2 / 2 * c2
            qg1 = -g * (m1 / 2 + m2) * L1 * c1
            tau2 = -kd[1] * qd2 - kp[1] * (q2 - target[1]) - qg2
            tau1 = -kd[0] * qd1 - kp[0] * (q1 - target[0]) - (qg1 + qg2)
            qfrc[0], qfrc[1] = tau1, tau2
        previous = (vx, vy)
        mujoco.mj_step(model, data)
    return impacts


TIMECONSTS = (8e-5, 1.2e-4, 1.6e-4, 2e-4, 2.5e-4, 3e-4)  # MuJoCo solref time constants [s]


def tune_dampratio(scene: Scene, dt: float, timeconst: float, e_target: float) -> float:
    """MuJoCo's damping ratio that gives the first impact's CoR (bisection: more damping,
    less rebound)."""
    lo, hi = 0.0, 1.5
    for _ in range(18):
        mid = 0.5 * (lo + hi)
        first = simulate(scene, build(scene, dt, (timeconst, mid)), 0.5, max_impacts=1)
        if not first:
            hi = mid
            continue
        if first[0]['e'] > e_target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _outcome(record: Impact | dict[str, Any]) -> tuple[float, float, float]:
    """(F_max, duration, kinematic CoR) of one impact: ours (an ``Impact``) or MuJoCo's
    (``simulate``'s dict)."""
    if isinstance(record, dict):
        return record['F_max'], record['duration'], record['e']
    return record.F_max, record.duration, record.cor_kinematic


def errors(impacts: Sequence[Impact | dict[str, Any]], ref: Sequence[Impact]) -> dict[str, float]:
    """``impacts`` (ours or MuJoCo's) against ``ref`` (ours)."""
    out = {
        'F_max #1': math.inf,
        'duration #1': math.inf,
        'e (worst impact)': math.inf,
        'impacts': len(impacts),
    }
    if impacts:
        force, duration, _ = _outcome(impacts[0])
        out['F_max #1'] = abs(force / ref[0].F_max - 1)
        out['duration #1'] = abs(duration / ref[0].duration - 1)
    if len(impacts) >= len(ref):
        out['e (worst impact)'] = max(
            abs(_outcome(a)[2] / b.cor_kinematic - 1) for a, b in zip(impacts, ref)
        )
    return out


def run(args: argparse.Namespace) -> int:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        print('bench peers needs MuJoCo: pip install mujoco (an optional extra)')
        return 2
    from impact_arm.physics.integrator import PRESETS

    scene = common.load(args.scene)
    if scene.n_links != 2 or len(scene.surfaces) != 1:
        print('bench peers models a two-link arm over one floor')
        return 2
    common.progress('ours: reference')
    ref_run = common.time_ours(scene, *PRESETS['reference'], repeats=1)
    ref, t_end = ref_run['impacts'], ref_run['t_end']
    rows = []
    for label, kw in (
        ('impact_arm `balanced`', dict(rtol=1e-8, atol=1e-10)),
        (
            'impact_arm sweep setting (rosenbrock 1e-2, contact 3e-4)',
            dict(rtol=1e-2, atol=1e-4, method='rosenbrock', contact_rtol=3e-4),
        ),
    ):
        common.progress(f'ours: {label}')
        r = common.time_ours(scene, repeats=args.repeats, **kw)
        rows.append(dict(errors(r['impacts'], ref), engine=label, wall=r['wall']))
    # tuned as a user would on the first impact: the damping ratio for its CoR, at the
    # contact time constant whose contact duration comes closest
    best = None
    for timeconst in TIMECONSTS:
        common.progress(
            f'MuJoCo: tuning solref on the first impact (time constant {timeconst:g} s, dt 10 µs)'
        )
        damp = tune_dampratio(scene, 1e-5, timeconst, ref[0].cor_kinematic)
        first = simulate(scene, build(scene, 1e-5, (timeconst, damp)), 0.5, max_impacts=1)
        miss = abs(first[0]['duration'] / ref[0].duration - 1) if first else math.inf
        if best is None or miss < best[0]:
            best = (miss, timeconst, damp)
    _, timeconst, damp = best
    settings = (
        ('MuJoCo defaults, dt 1 ms', 1e-3, None),
        (f'MuJoCo solref ({timeconst:g}, {damp:.3f}) tuned, dt 10 µs', 1e-5, (timeconst, damp)),
    )
    for label, dt, solref in settings:
        common.progress(f'{label}: 15 cycles')
        model = build(scene, dt, solref)
        best, impacts = math.inf, []
        for _ in range(max(1, args.repeats)):
            t0 = time.perf_counter()
            impacts = simulate(scene, model, t_end)
            best = min(best, time.perf_counter() - t0)
        rows.append(dict(errors(impacts, ref), engine=label, wall=best))
    common.progress_done()
    print(
        f"Scene '{scene.name}', {len(ref)} impacts in {t_end:.3f} s simulated; errors "
        f'against impact_arm preset reference; MuJoCo {mujoco.__version__}, its controller '
        f'evaluated in Python before each step; wall: the 15 cycles, best of '
        f'{args.repeats}.'
    )
    print()
    body = [
        [
            r['engine'],
            f'{r["wall"] * 1e3:.1f}',
            r['impacts'],
            common.fmt_err(r['F_max #1']),
            common.fmt_err(r['duration #1']),
            common.fmt_err(r['e (worst impact)']),
        ]
        for r in rows
    ]
    print(
        common.table(
            [
                'engine, setting',
                'wall [ms]',
                'impacts',
                'F_max #1 error',
                'duration #1 error',
                'e error, worst impact',
            ],
            body,
        )
    )
    fastest_tuned = rows[-1]['wall']
    print()
    print(
        f'impact_arm sweep setting vs tuned MuJoCo: {fastest_tuned / rows[1]["wall"]:.0f}x '
        f'faster; balanced: {fastest_tuned / rows[0]["wall"]:.0f}x'
    )
    if args.json:
        common.write_json(
            args.json,
            {'benchmark': 'peers', 'scene': scene.name, 'machine': common.machine(), 'rows': rows},
        )
    return 0
