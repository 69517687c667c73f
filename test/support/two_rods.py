"""The article's two rods by hand, for physics tests: a mass matrix written independently of
the model, and a strike whose effective masses are known in closed form."""

import math

import numpy as np

from scenes import scene_from


def mass_matrix_by_hand(q, L=(1.0, 1.0), m=(1.0, 1.0)):
    """Two uniform rods, absolute angles: textbook mass matrix, written independently."""
    c = math.cos(q[0] - q[1])
    return np.array(
        [
            [m[0] * L[0] ** 2 / 3 + m[1] * L[0] ** 2, m[1] * L[0] * L[1] / 2 * c],
            [m[1] * L[0] * L[1] / 2 * c, m[1] * L[1] ** 2 / 3],
        ]
    )


def vertical_strike_scene(v, law='hertz', mu=0.0, qd2=0.0, gap=1e-7):
    """Link 2 hanging straight down (q = 0°, -90°) above the floor, link 1 turning so the tip
    moves straight down at v: at this pose the mass matrix is diagonal and the tip's
    vertical effective mass is M11 = 4/3 kg, its horizontal one M22 = 1/3 kg."""
    return scene_from(
        {
            ('initial', 'q_deg'): [0.0, -90.0],
            ('initial', 'qd'): [-v, qd2],
            ('controller', 'law'): 'none',
        },
        gravity=0.0,
        cycles=0,
        t_max=0.002,
        surfaces=[{'height': -1.0 - gap, 'law': law, 'mu': mu, 'v_d': 0.02, 'material': 'steel'}],
    )


def generalized_momentum(y):
    q, qd = y[:2], y[2:4]
    return mass_matrix_by_hand(q) @ qd
