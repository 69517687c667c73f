"""``impact-arm bench oblique --data FILE``: a sphere striking a flat obliquely, our free body
against measured rebounds (docs/validation.md, "Oblique impacts").

The sphere is the scene ``config/oblique_sphere.yaml`` (one contact point at its centre, a
solid sphere's inertia), its radius, density, moduli, μ and normal CoR taken from the data
file; it strikes at the file's speed over the file's incidence angles (from the normal) and
a dense sweep. Printed beside the measurements: the tangential CoR (the centre's tangential
velocity after / before), the spin after the impact and the rebound angle, with the
rigid-body Coulomb values (sliding: 1 - μ (1 + e) / tan α; rolling: 5/7 for a sphere).

The data file is YAML with ``sphere: {radius, E, nu, density}``, ``impact_speed``, ``mu``,
``normal_cor`` and lists of [angle deg, value] under ``tangential_cor``, ``spin_after`` and
``rebound_angle``.
"""

from __future__ import annotations

import math
import os

V_D_SMALL = 1e-3  # m/s: a tanh smoothing twenty times sharper than the default


def add_arguments(parser):
    parser.add_argument('--data', required=True, metavar='FILE', help='measured rebounds (YAML)')
    parser.add_argument(
        '--scene', default='oblique_sphere', help='sphere scene (default: oblique_sphere)'
    )
    parser.add_argument('--plots', metavar='DIR', help='write the figure as a PNG file there')


def _sphere_model(scene, data, v_d):
    from dataclasses import replace

    from impact_arm.physics.bodies.model import build_model
    from impact_arm.physics.scene import Material

    s = data['sphere']
    radius = float(s['radius'])
    mass = 4.0 / 3.0 * math.pi * radius**3 * float(s['density'])
    material = Material(E=float(s['E']), nu=float(s['nu']), S_y=scene.body.material.S_y)
    body = replace(
        scene.body,
        mass=mass,
        inertia=0.4 * mass * radius**2,
        corner_radius=radius,
        corners=((0.0, 0.0),),
        material=material,
    )
    surface = replace(
        scene.surfaces[0],
        law='constant_cor',
        cor=float(data['normal_cor']),
        mu=float(data['mu']),
        v_d=v_d,
        material=material,
    )
    return build_model(replace(scene, body=body, surfaces=(surface,))), radius


def rebound(model, radius: float, speed: float, angle_deg: float) -> tuple[float, float, float]:
    """(tangential CoR, |spin| after [rad/s], rebound angle [deg]) at one incidence angle."""
    from impact_arm.physics.bodies.model import simulate_body
    from impact_arm.physics.bodies.scene import BodyState

    a = math.radians(angle_deg)
    vx, vz = speed * math.sin(a), -speed * math.cos(a)
    run = simulate_body(model, BodyState(0.0, radius + 1e-9, 0.0, vx, vz, 0.0), 1e-3, settle=1e-5)
    s = run.state
    return (s.vx / vx if vx else float('nan'), abs(s.omega), math.degrees(math.atan2(s.vx, s.vz)))


def rigid(mu: float, e: float, angle_deg: float) -> float:
    """Rigid-body Coulomb tangential CoR of a solid sphere: sliding throughout or rolling."""
    if angle_deg <= 0:
        return 5.0 / 7.0
    return max(5.0 / 7.0, 1.0 - mu * (1.0 + e) / math.tan(math.radians(angle_deg)))


def run(args) -> int:
    import sys

    import numpy as np
    import yaml

    from impact_arm.physics.bodies.scene import load_body_scene
    from impact_arm.physics.errors import SceneError

    try:
        with open(args.data, encoding='utf-8') as f:
            data = yaml.safe_load(f)
        scene = load_body_scene(args.scene)
        speed = float(data['impact_speed'])
        mu, e = float(data['mu']), float(data['normal_cor'])
        measured = {k: np.array(data[k], dtype=float) for k in QUANTITIES}
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError, SceneError) as exc:
        print(f'bench oblique: {args.data}: {exc}', file=sys.stderr)
        return 2
    default, radius = _sphere_model(scene, data, scene.surfaces[0].v_d)
    sharp, _ = _sphere_model(scene, data, V_D_SMALL)
    v_d = scene.surfaces[0].v_d
    print(
        f'sphere R = {radius * 1e3:g} mm at {speed:g} m/s, mu = {mu:g}, e = {e:g}; '
        f'rolling from tan(a) < 7/2 mu (1 + e): a < '
        f'{math.degrees(math.atan(3.5 * mu * (1 + e))):.1f} deg'
    )
    for k, (name, unit) in enumerate(zip(QUANTITIES, UNITS, strict=True)):
        print()
        print(
            f'{name} [{unit}]:  angle   measured   ours (v_d {v_d:g})   ours (v_d {V_D_SMALL:g})'
            + ('   rigid Coulomb' if k == 0 else '')
        )
        for angle, value in measured[name]:
            ours = rebound(default, radius, speed, angle)[k]
            ours_sharp = rebound(sharp, radius, speed, angle)[k]
            extra = f'   {rigid(mu, e, angle):13.3f}' if k == 0 else ''
            print(f'{"":22}{angle:6.1f} {value:10.3f} {ours:17.3f} {ours_sharp:17.3f}{extra}')
    if args.plots:
        _plot(args.plots, measured, default, sharp, radius, speed, mu, e, v_d)
    return 0


QUANTITIES = ('tangential_cor', 'spin_after', 'rebound_angle')
UNITS = ('-', 'rad/s', 'deg')


def _plot(folder, measured, default, sharp, radius, speed, mu, e, v_d):
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    os.makedirs(folder, exist_ok=True)
    angles = np.linspace(0.5, 65.0, 80)
    ours = np.array([rebound(default, radius, speed, a) for a in angles])
    ours_sharp = np.array([rebound(sharp, radius, speed, a) for a in angles])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for k, ax in enumerate(axes):
        m = measured[QUANTITIES[k]]
        ax.plot(m[:, 0], m[:, 1], 'ks', ms=5, label='measured (Kharaz et al. 2001)')
        ax.plot(angles, ours[:, k], 'C0-', label=f'ours, tanh-Coulomb v_d = {v_d:g} m/s')
        ax.plot(angles, ours_sharp[:, k], 'C0--', label=f'ours, v_d = {V_D_SMALL:g} m/s')
        if k == 0:
            ax.plot(angles, [rigid(mu, e, a) for a in angles], 'C1:', label='rigid Coulomb')
        ax.set_xlabel('incidence angle from the normal [deg]')
        ax.set_title(f'{QUANTITIES[k]} [{UNITS[k]}]', fontsize=10)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(folder, 'validation_oblique.png')
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f'wrote {path}')
