"""Recorded planar drops of a square: impacts found in the record, contact laws fitted to
some of them and scored on others (``impact-arm bench validate``, docs/validation.md).

A drop is a CSV file with the header ``x,z,th,vx,vz,vth`` (centre of mass and orientation,
rows a fixed time apart). Only the positions are used: the recorded velocities are finite
differences of them and straddle each impact. An impact is found where the vertical
velocity between two rows jumps up; a ballistic fit (x and θ linear, z a parabola under
gravity) of the rows before it and one of the rows after it give the state before and the
velocities after, both at the instant where the two fitted heights meet. Rows next to an
impact are left out of the fits (the record's orientation is unreliable there).

The models predict the velocities after an impact from the state before it:

- ``Model.OURS``: the free body with the elasto-plastic law (Hertz, Jackson-Green,
  restitution) and tanh-Coulomb friction;
- ``Model.CONSTANT_COR``: the same body and friction with the constant-CoR law;
- ``Model.NEWTON``, ``Model.POISSON``: a rigid point impact of the lowest corner with Coulomb
  friction (``physics/bodies/impulse.py``).

The square's mass and materials are unknown. The velocities after an impact depend on the
mass only through I/m (a uniform square: s²/6) and, for the elasto-plastic law, through the
yield speed V_y (the impact speed of the whole mass on one corner that just reaches yield):
so the fit is for V_y, with a nominal mass and moduli, and its result holds for any mass.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..physics.bodies.impulse import Restitution, point_impact
from ..physics.bodies.model import BodyModel, BodyRun, build_model, simulate_body
from ..physics.bodies.scene import BodyIntegratorSpec, BodyScene, BodySpec, BodyState, LineSurface
from ..physics.contact import contact_constants
from ..physics.errors import SimulationError
from ..physics.kinds import EventKind, TextEnum
from ..physics.scene import Material

HEADER = ('x', 'z', 'th', 'vx', 'vz', 'vth')
GRAVITY = 9.81
JUMP = 0.2  # m/s: an upward jump of the vertical velocity between rows beyond this is an impact
WINDOW = 6  # rows in each ballistic fit (fewer when the next impact is closer, at least 3)
SKIP_AFTER = 2  # rows after an impact left out of the fit after it
MAX_Z_RESIDUAL = 1e-3  # m, RMS of a ballistic fit that still counts as free flight
MAX_THETA_RESIDUAL = 0.02  # rad
MAX_FLOOR_OFFSET = 5e-3  # m, lowest corner's distance from the floor at the impact
MIN_APPROACH = 0.05  # m/s, the lowest corner must approach the floor this fast
# nominal body: the fit is for quantities that do not depend on these
NOMINAL_MASS = 0.1  # kg
NOMINAL_MATERIAL = Material(E=70e9, nu=0.3, S_y=0.3e9)
NOMINAL_FLOOR = Material(E=1e30, nu=0.0, S_y=1e30)  # rigid: E* is the body's


class Model(TextEnum):
    OURS = 'ours'
    NEWTON = 'newton'
    POISSON = 'poisson'
    CONSTANT_COR = 'constant_cor'


# parameter names and bounds of each model (the fit's search box)
PARAMETERS = {
    Model.OURS: ('mu', 'yield_speed', 'corner_radius'),
    Model.NEWTON: ('mu', 'e', 'corner_radius'),
    Model.POISSON: ('mu', 'e', 'corner_radius'),
    Model.CONSTANT_COR: ('mu', 'e', 'corner_radius'),
}
BOUNDS = {
    'mu': (0.0, 2.0),
    'e': (0.01, 1.0),
    'yield_speed': (1e-4, 10.0),
    'corner_radius': (1e-4, 0.01),
}
STARTS = {
    'mu': (0.15, 0.4),
    'e': (0.4, 0.7),
    'yield_speed': (0.003, 0.03),
    'corner_radius': (0.002,),
}


@dataclass(frozen=True)
class Impact:
    file: str
    number: int  # 1, 2, ... within its file
    t: float  # [s] from the file's first row
    pre: BodyState  # at the impact
    post: tuple[float, float, float]  # vx, vz, ω after the impact, at the same instant
    # from the impact to the first row of the fit after it: every contact before that row is
    # in the measured velocities after the impact, so a prediction runs this long
    horizon: float = 0.0

    def contact_point(self, side: float, radius: float = 0.0) -> tuple[float, float]:
        """The lowest corner's contact point from the centre of mass."""
        return lowest_corner(self.pre.theta, side, radius)

    def approach(self, side: float) -> tuple[float, float]:
        """Tangential and normal velocity of the lowest corner before the impact."""
        rx, rz = self.contact_point(side)
        p = self.pre
        return p.vx - p.omega * rz, p.vz + p.omega * rx


def lowest_corner(theta: float, side: float, radius: float = 0.0) -> tuple[float, float]:
    """Contact point (from the centre) of the lowest corner of a square of side ``side``
    whose corners are rounded with ``radius``: the corner sphere's centre, less the radius."""
    half = side / 2 - radius
    c, s = math.cos(theta), math.sin(theta)
    rx, rz = min(
        ((c * bx - s * bz, s * bx + c * bz) for bx in (-half, half) for bz in (-half, half)),
        key=lambda r: r[1],
    )
    return rx, rz - radius


def normal_cor(impact: Impact, post: Sequence[float], side: float) -> float:
    """-u_n after / u_n before of the lowest corner (the kinematic, Newton CoR)."""
    rx, _ = impact.contact_point(side)
    _, un = impact.approach(side)
    return -(post[1] + post[2] * rx) / un


def read_drop(path: str) -> np.ndarray:
    """The rows of one drop file as an (n, 6) array; ``ValueError`` naming the file when its
    header or a value is not what the format says."""
    with open(path, newline='', encoding='utf-8') as f:
        rows = list(csv.reader(f))
    if not rows or tuple(c.strip() for c in rows[0]) != HEADER:
        raise ValueError(f'{path}: header must be {",".join(HEADER)}')
    try:
        data = np.array([[float(v) for v in row] for row in rows[1:] if row], dtype=float)
    except ValueError as exc:
        raise ValueError(f'{path}: {exc}') from None
    if data.ndim != 2 or data.shape[1] != 6 or not np.all(np.isfinite(data)):
        raise ValueError(f'{path}: every row must hold 6 finite numbers')
    return data


def drop_files(folder: str) -> list[str]:
    """The CSV files of a folder in natural order (traj_2 before traj_10)."""
    names = [n for n in os.listdir(folder) if n.endswith('.csv')]

    def key(name: str) -> tuple:
        return tuple(int(p) if p.isdigit() else p for p in re.split(r'(\d+)', name))

    return [os.path.join(folder, n) for n in sorted(names, key=key)]


def _ballistic(t: np.ndarray, rows: np.ndarray, g: float) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares x(t), z(t) + g t²/2, θ(t) lines: coefficients (3 x [value at 0, rate])
    and the RMS residuals of z and θ."""
    A = np.stack([np.ones_like(t), t], axis=1)
    target = rows[:, :3].copy()
    target[:, 1] += 0.5 * g * t * t
    coef, *_ = np.linalg.lstsq(A, target, rcond=None)
    resid = target - A @ coef
    return coef.T, np.sqrt(np.mean(resid**2, axis=0))


def find_impacts(
    rows: np.ndarray, dt: float, side: float, file: str = '', g: float = GRAVITY
) -> list[Impact]:
    """The impacts of one drop that a ballistic fit on either side resolves (see the module's
    text); the floor is wherever the lowest corner is at each impact (``floor_offsets``
    checks that it is one floor)."""
    z = rows[:, 1]
    vz = np.diff(z) / dt
    jumps = [j for j in range(1, len(vz)) if vz[j] - vz[j - 1] > JUMP]
    starts: list[int] = []
    for j in jumps:
        if not starts or j - starts[-1] > 2:
            starts.append(j)
    impacts: list[Impact] = []
    t_rows = np.arange(len(rows)) * dt
    for n, j in enumerate(starts):
        previous = starts[n - 1] + 1 + SKIP_AFTER if n else 0
        following = starts[n + 1] if n + 1 < len(starts) else len(rows)
        pre_rows = np.arange(max(previous, j - WINDOW + 1), j + 1)
        post_rows = np.arange(j + 1 + SKIP_AFTER, min(following, j + 1 + SKIP_AFTER + WINDOW))
        if len(pre_rows) < 3 or len(post_rows) < 3:
            continue
        t0 = t_rows[j]
        pre, pre_res = _ballistic(t_rows[pre_rows] - t0, rows[pre_rows], g)
        post, post_res = _ballistic(t_rows[post_rows] - t0, rows[post_rows], g)
        if max(pre_res[1], post_res[1]) > MAX_Z_RESIDUAL:
            continue
        if max(pre_res[2], post_res[2]) > MAX_THETA_RESIDUAL:
            continue
        # the heights meet where the impact is (the -g t²/2 terms cancel)
        rate = pre[1, 1] - post[1, 1]
        if rate == 0.0:
            continue
        s = (post[1, 0] - pre[1, 0]) / rate
        if not -dt <= s <= 2 * dt:
            continue
        state = BodyState(
            x=pre[0, 0] + pre[0, 1] * s,
            z=pre[1, 0] + pre[1, 1] * s - 0.5 * g * s * s,
            theta=pre[2, 0] + pre[2, 1] * s,
            vx=pre[0, 1],
            vz=pre[1, 1] - g * s,
            omega=pre[2, 1],
        )
        after = (post[0, 1], post[1, 1] - g * s, post[2, 1])
        impact = Impact(
            os.path.basename(file),
            len(impacts) + 1,
            t0 + s,
            state,
            after,
            horizon=float(t_rows[post_rows[0]] - t0 - s),
        )
        if impact.approach(side)[1] > -MIN_APPROACH:
            continue
        impacts.append(impact)
    return impacts


def corner_height(impact: Impact, side: float) -> float:
    """Height of the lowest (sharp) corner at the impact: where the floor is."""
    return impact.pre.z + impact.contact_point(side)[1]


def on_one_floor(impacts: Sequence[Impact], side: float) -> tuple[list[Impact], float]:
    """The impacts whose lowest corner is within ``MAX_FLOOR_OFFSET`` of the median floor
    height (others struck something else or were found wrongly), and that height."""
    if not impacts:
        return [], 0.0
    floor = float(np.median([corner_height(i, side) for i in impacts]))
    kept = [i for i in impacts if abs(corner_height(i, side) - floor) <= MAX_FLOOR_OFFSET]
    return kept, floor


# ------------------------------------------------------------------------------ the models
def square_scene(side: float, radius: float, surface: LineSurface) -> BodyScene:
    """The nominal square (``NOMINAL_MASS``, uniform: I = m s²/6) with rounded corners whose
    outline stays ``side`` wide, over one floor."""
    half = side / 2 - radius
    body = BodySpec(
        mass=NOMINAL_MASS,
        inertia=NOMINAL_MASS * side * side / 6,
        corners=((half, half), (-half, half), (-half, -half), (half, -half)),
        corner_radius=radius,
        material=NOMINAL_MATERIAL,
    )
    return BodyScene(
        name='square',
        gravity=GRAVITY,
        body=body,
        initial=BodyState(0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
        surfaces=(surface,),
        t_max=1.0,
        integrator=BodyIntegratorSpec(rtol=1e-8, atol=1e-12, max_step=1e-3),
    )


def yield_strength_for(yield_speed: float, radius: float) -> float:
    """S_y that gives the nominal square's corner the yield speed V_y (the whole mass on one
    corner): ½ m V_y² = (8/15) E* √R δc^{5/2} with δc = R (π C_j S_y / 2E*)²."""
    c = contact_constants(NOMINAL_MATERIAL, NOMINAL_FLOOR, radius)
    delta_c = (15 * NOMINAL_MASS * yield_speed**2 / (16 * c.E * math.sqrt(radius))) ** 0.4
    return 2 * c.E / (math.pi * c.C_j) * math.sqrt(delta_c / radius)


def body_model(model: Model, params: dict[str, float], side: float) -> BodyModel:
    """The free-body model of ``OURS`` or ``CONSTANT_COR`` with these parameters."""
    radius = params['corner_radius']
    material = NOMINAL_MATERIAL
    if model == Model.OURS:
        material = replace(material, S_y=yield_strength_for(params['yield_speed'], radius))
    floor = LineSurface(
        point=(0.0, 0.0),
        normal=(0.0, 1.0),
        law='elastoplastic' if model == Model.OURS else 'constant_cor',
        mu=params['mu'],
        v_d=0.02,
        cor=params.get('e', 1.0),
        material=NOMINAL_FLOOR,
    )
    scene = square_scene(side, radius, floor)
    return build_model(replace(scene, body=replace(scene.body, material=material)))


def predict(
    model: Model,
    params: dict[str, float],
    impacts: Sequence[Impact],
    side: float,
    *,
    settle: float = 2e-3,
) -> np.ndarray:
    """(n, 3) velocities (vx, vz, ω) after each impact as ``model`` predicts them, at the
    impact's instant. The free body runs over the impact's ``horizon`` (the contacts the
    measured velocities after it include), at least until every contact has been over for
    ``settle``; its velocities are carried back ballistically to the impact's instant. NaN
    where the model cannot say (a simulation that fails)."""
    out = np.full((len(impacts), 3), np.nan)
    radius = params['corner_radius']
    if model in (Model.NEWTON, Model.POISSON):
        gyration2 = side * side / 6
        law = Restitution.NEWTON if model == Model.NEWTON else Restitution.POISSON
        for i, impact in enumerate(impacts):
            p = impact.pre
            rx, rz = lowest_corner(p.theta, side, radius)
            r = point_impact(p.vx, p.vz, p.omega, rx, rz, gyration2, params['mu'], params['e'], law)
            out[i] = (r.vx, r.vz, r.omega)
        return out
    body = body_model(model, params, side)
    for i, impact in enumerate(impacts):
        p = impact.pre
        _, rz = lowest_corner(p.theta, side, radius)
        start = BodyState(0.0, -rz + 1e-9, p.theta, p.vx, p.vz, p.omega)
        try:
            run = simulate_body(body, start, impact.horizon, settle=0.0)
            if any(e.kind == EventKind.CONTACT for e in run.events) and not _all_free(run):
                run = simulate_body(body, start, 0.05, settle=settle)
        except SimulationError:
            continue
        s = run.state
        out[i] = (s.vx, s.vz + GRAVITY * run.t, s.omega)
    return out


def _all_free(run: BodyRun) -> bool:
    """Whether no contact is open at the end of ``run`` (each contact has its separation)."""
    opened = sum(e.kind == EventKind.CONTACT for e in run.events)
    return opened == sum(e.kind == EventKind.SEPARATION for e in run.events)


def residuals(
    model: Model, params: dict[str, float], impacts: Sequence[Impact], side: float
) -> np.ndarray:
    """Prediction errors of vx, vz and ω s/2 (all in m/s), one row per impact."""
    measured = np.array([i.post for i in impacts])
    err = predict(model, params, impacts, side) - measured
    err[:, 2] *= side / 2
    return np.nan_to_num(err, nan=10.0)  # a failed prediction counts as a gross error


@dataclass(frozen=True)
class Fit:
    model: Model
    params: dict[str, float]
    cost: float  # the robust loss at the optimum
    evaluations: int


def fit(
    model: Model, impacts: Sequence[Impact], side: float, scale: float = 0.05, evaluations: int = 80
) -> Fit:
    """Parameters that minimise a robust (soft-l1, ``scale`` m/s) sum of the errors of vx, vz
    and ω s/2 over ``impacts``: bounded Nelder-Mead (a simulated impact's outcome is smooth
    only piecewise: its events come and go with the parameters, so finite-difference
    gradients mislead), from the best point of a small grid, ``evaluations`` at most."""
    import itertools

    from scipy.optimize import minimize

    names = PARAMETERS[model]
    log_scaled = {'yield_speed'}
    unit = {'corner_radius': 1e-3}  # the search works in mm, so every axis is of order 1

    def to_params(u: Sequence[float]) -> dict[str, float]:
        return {
            n: float(math.exp(v) if n in log_scaled else v * unit.get(n, 1.0))
            for n, v in zip(names, u, strict=True)
        }

    def to_vector(values: Sequence[float]) -> list[float]:
        return [
            math.log(v) if n in log_scaled else v / unit.get(n, 1.0)
            for n, v in zip(names, values, strict=True)
        ]

    count = [0]

    def loss(u: Sequence[float]) -> float:
        count[0] += 1
        r = residuals(model, to_params(u), impacts, side)
        return float(np.sum(2 * scale**2 * (np.sqrt(1 + (r / scale) ** 2) - 1)))

    starts = [to_vector(v) for v in itertools.product(*(STARTS[n] for n in names))]
    best = min(starts, key=loss)
    bounds = list(
        zip(to_vector([BOUNDS[n][0] for n in names]), to_vector([BOUNDS[n][1] for n in names]))
    )
    result = minimize(
        loss,
        best,
        method='Nelder-Mead',
        bounds=bounds,
        options={'maxfev': max(1, evaluations - len(starts)), 'xatol': 1e-3, 'fatol': 1e-4},
    )
    return Fit(model, to_params(result.x), float(result.fun), count[0])
