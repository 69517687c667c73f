"""``impact-arm study contact``: the contact laws against published results, no arm.

(a) Hertz: the benchmark's aluminium sphere (R = 0.1 m, E = 70 GPa, ν = 0.3, ρ = 2699 kg/m³)
    at 0.2 m/s onto a rigid wall (Chung & Ooi 2011's elastic normal impact), δmax, Fmax and
    contact time against Hertz's closed form.
(b) Steel on steel (the article's steel, a sphere of the tip's radius): the coefficient of
    restitution against V / V_y, with Thornton's (1997) closed form and the same laws
    evaluated by an energy balance instead of a time integration.

Prints both tables, writes ``cor.csv`` and ``cor.png`` to ``--out``. Discussion: docs/studies.md.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable

from ..physics.contact import ContactConstants, contact_constants
from ..physics.scene import Material
from ..physics.sphere_drop import (
    RIGID,
    drop,
    energy_balance_cor,
    hertz_closed_form,
    sphere_mass,
    thornton_cor,
    yield_speed,
)

ALUMINIUM = Material(E=70e9, nu=0.3, S_y=3e8)  # S_y unused: Hertz law
ALUMINIUM_DENSITY, ALUMINIUM_RADIUS, ALUMINIUM_SPEED = 2699.0, 0.1, 0.2
STEEL = Material(E=210e9, nu=0.29, S_y=1.12e9)  # config/paper.yaml
STEEL_DENSITY, TIP_RADIUS = 7850.0, 0.005
RATIOS = (
    0.25,
    0.5,
    0.9,
    1.0,
    1.1,
    1.5,
    2.0,
    3.0,
    5.0,
    10.0,
    20.0,
    50.0,
    100.0,
    200.0,
    500.0,
    1000.0,
)


def hertz_case() -> dict:
    """(a): the integrated impact and Hertz's numbers, keyed by quantity."""
    c = contact_constants(ALUMINIUM, RIGID, ALUMINIUM_RADIUS)
    mass = sphere_mass(ALUMINIUM_RADIUS, ALUMINIUM_DENSITY)
    model = drop(c, mass, ALUMINIUM_SPEED, law='hertz')
    theory = hertz_closed_form(c, mass, ALUMINIUM_SPEED)
    return {key: (getattr(model, key), theory[key]) for key in ('delta_m', 'F_max', 'duration')}


def steel_pairing() -> tuple[ContactConstants, float, float]:
    c = contact_constants(STEEL, STEEL, TIP_RADIUS)
    mass = sphere_mass(TIP_RADIUS, STEEL_DENSITY)
    return c, mass, yield_speed(c, mass)


def cor_table(ratios: Iterable[float] = RATIOS) -> list[dict]:
    """(b): a row per V / V_y: the integrated CoR, the energy-balance CoR, Thornton's."""
    c, mass, v_y = steel_pairing()
    rows = []
    for ratio in ratios:
        d = drop(c, mass, ratio * v_y)
        rows.append(
            {
                'V_over_Vy': ratio,
                'V': ratio * v_y,
                'cor': d.cor,
                'cor_energy_balance': energy_balance_cor(c, mass, ratio * v_y),
                'cor_thornton': thornton_cor(ratio),
                'delta_m_over_delta_c': d.delta_m / c.delta_c,
                'yielded': d.yielded,
            }
        )
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('name', choices=['contact'], help='the study to run')
    parser.add_argument(
        '--out',
        default=os.path.join('runs', 'contact_study'),
        metavar='DIR',
        help='where cor.csv and cor.png go (default: runs/contact_study)',
    )


def cli(args: argparse.Namespace) -> int:
    print('(a) Hertz, aluminium sphere R = 0.1 m at 0.2 m/s on a rigid wall')
    print(f'{"":10} {"model":>13} {"Hertz":>13} {"rel. diff":>10}')
    for key, (model, theory) in hertz_case().items():
        print(f'{key:10} {model:13.6e} {theory:13.6e} {model / theory - 1:10.2e}')
    c, mass, v_y = steel_pairing()
    print(
        f'\n(b) steel on steel, sphere R = {TIP_RADIUS} m, m = {mass * 1e3:.3f} g: '
        f'V_y = {v_y:.4f} m/s, delta_c = {c.delta_c * 1e6:.3f} um'
    )
    rows = cor_table()
    print(
        f'{"V/V_y":>8} {"V [m/s]":>9} {"e model":>9} {"e energy":>9} {"e Thornton":>10} '
        f'{"dm/dc":>8}'
    )
    for r in rows:
        print(
            f'{r["V_over_Vy"]:8.3g} {r["V"]:9.4f} {r["cor"]:9.5f} '
            f'{r["cor_energy_balance"]:9.5f} {r["cor_thornton"]:10.5f} '
            f'{r["delta_m_over_delta_c"]:8.3g}'
        )
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, 'cor.csv'), 'w', encoding='utf-8') as f:
        f.write(','.join(rows[0]) + '\n')
        f.writelines(','.join(str(v) for v in r.values()) + '\n' for r in rows)
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fine = [10 ** (k / 20) for k in range(-12, 61)]
    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    ax.semilogx(
        [r['V_over_Vy'] for r in rows],
        [r['cor'] for r in rows],
        'o-',
        label='this model (Hertz / Jackson-Green / Etsion unloading)',
    )
    ax.semilogx(fine, [thornton_cor(x) for x in fine], '--', label='Thornton (1997)')
    ax.semilogx(
        fine,
        [min(1.0, 1.185 * x**-0.25) for x in fine],
        ':',
        label='Thornton, large-V asymptote 1.185 (V_y/V)^1/4',
    )
    ax.set_xlabel('impact velocity / yield velocity, V / V_y [-]')
    ax.set_ylabel('coefficient of restitution e [-]')
    ax.set_title('steel sphere on steel, normal impact')
    ax.legend(loc='upper right', fontsize=8)  # the curves fall to the lower right
    path = os.path.join(args.out, 'cor.png')
    fig.savefig(path, dpi=120)
    plt.close(fig)
    print(f'\nwrote {os.path.join(args.out, "cor.csv")} and {path}')
    return 0
