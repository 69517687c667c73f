"""A free body's model (its scene turned into the kernel's tables) and its runs.

``BodyModel`` is what does not change during a run (mass, inertia, corners, the pair table
with each pairing's contact constants); ``simulate_body`` integrates a ``BodyState`` on it
and returns a ``BodyRun``: the end state, the located events and, on request, every
accepted step. Plain numpy around the compiled ``kernel``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact import CONTACT_LAW_CODES, contact_constants
from ..errors import SimulationError
from ..kinds import EventKind
from ..scene import reduced_modulus
from . import kernel as K
from .scene import BodyScene, BodySpec, BodyState, LineSurface

_EVENT_KINDS = {
    K.EV_CONTACT: EventKind.CONTACT,
    K.EV_YIELD: EventKind.YIELD,
    K.EV_MAX: EventKind.MAX_COMPRESSION,
    K.EV_SEPARATION: EventKind.SEPARATION,
}
_FAILURES = {
    K.UNDERFLOW: 'step size underflow',
    K.BAD_RESIDUAL: 'the residual indentation left [0, delta_m): beyond its fit',
    K.BUDGET: 'run budget exceeded',
    K.NOT_FINITE: 'the state is no longer finite',
}
LOG_CAPACITY = 256
STEP_BUDGET = 2_000_000
MAX_EVENTS = 100_000


@dataclass(frozen=True)
class BodyModel:
    scene: BodyScene
    P: np.ndarray  # mass, inertia, gravity
    corners: np.ndarray  # (corners, 2) body-frame centres
    pairs: np.ndarray  # kernel pair table, one row per corner x surface

    @property
    def n_pairs(self) -> int:
        return int(self.pairs.shape[0])


@dataclass(frozen=True)
class BodyEvent:
    kind: EventKind
    t: float
    corner: int
    surface: int
    values: tuple[float, float, float]  # max compression: δm, Pm, δr; separation: F_max, δm, δr


@dataclass(frozen=True)
class BodyRun:
    t: float
    state: BodyState
    events: tuple[BodyEvent, ...]
    settled: bool  # stopped because every contact had ended (``settle``)
    trace: np.ndarray  # (rows, 7): t, x, z, θ, ẋ, ż, ω at accepted steps (empty unless asked)
    steps: int


def pair_row(body: BodySpec, surface: LineSurface, corner: int, index: int) -> np.ndarray:
    """The kernel's table row of one corner against one surface."""
    row = np.zeros(K.PT_COLUMNS)
    c = contact_constants(body.material, surface.material, body.corner_radius)
    row[K.PT_CORNER], row[K.PT_SURFACE] = corner, index
    row[K.PT_PX], row[K.PT_PZ] = surface.point
    row[K.PT_NX], row[K.PT_NZ] = surface.normal
    row[K.PT_LAW] = CONTACT_LAW_CODES[surface.law]
    row[K.PT_E] = reduced_modulus(body.material, surface.material)
    row[K.PT_R], row[K.PT_SY], row[K.PT_CJ] = c.R, c.S_y, c.C_j
    row[K.PT_PC], row[K.PT_DC], row[K.PT_B] = c.P_c, c.delta_c, c.B
    row[K.PT_MU], row[K.PT_VD], row[K.PT_COR] = surface.mu, surface.v_d, surface.cor
    return row


def build_model(scene: BodyScene) -> BodyModel:
    body = scene.body
    rows = [
        pair_row(body, s, j, i)
        for i, s in enumerate(scene.surfaces)
        for j in range(len(body.corners))
    ]
    return BodyModel(
        scene=scene,
        P=np.array([body.mass, body.inertia, scene.gravity]),
        corners=np.array(body.corners, dtype=float).reshape(-1, 2),
        pairs=np.array(rows).reshape(-1, K.PT_COLUMNS),
    )


def simulate_body(
    model: BodyModel,
    state: BodyState | None = None,
    t_end: float | None = None,
    *,
    settle: float = 0.0,
    trace: int = 0,
    rtol: float | None = None,
    atol: float | None = None,
) -> BodyRun:
    """Integrate from ``state`` (the scene's initial state) at t = 0 until ``t_end`` (the
    scene's t_max), or, with ``settle`` > 0, until every contact has been over for ``settle``
    seconds. ``trace``: how many accepted steps to keep. ``SimulationError`` when the
    integration cannot go on."""
    spec = model.scene.integrator
    y = np.array((state or model.scene.initial).as_tuple(), dtype=float)
    CS = np.zeros((model.n_pairs, K.CS_COLUMNS))
    log = np.zeros((LOG_CAPACITY, K.LOG_COLUMNS))
    nlog = np.zeros(1)
    rows = np.zeros((trace, 7))
    ntrace = np.zeros(1)
    W = np.zeros((12, 6))
    G = np.zeros((3, K.EVENTS_PER_PAIR * model.n_pairs))
    stats = np.zeros(4)
    memory = np.array([-1.0, 0.0])
    booked: list[np.ndarray] = []
    t, status = 0.0, K.LOG_FULL
    while status == K.LOG_FULL:
        t, status = K.advance(
            t,
            y,
            float(t_end if t_end is not None else model.scene.t_max),
            model.P,
            model.corners,
            model.pairs,
            CS,
            float(rtol if rtol is not None else spec.rtol),
            float(atol if atol is not None else spec.atol),
            float(spec.max_step),
            float(settle),
            STEP_BUDGET,
            log,
            nlog,
            rows,
            ntrace,
            W,
            G,
            stats,
            memory,
        )
        booked.append(log[: int(nlog[0])].copy())
        nlog[0] = 0
        if len(booked) * LOG_CAPACITY > MAX_EVENTS:
            raise SimulationError(
                f'free body at t = {t:.6g} s: more than {MAX_EVENTS} contact events (a body '
                f'coming to rest on its corners: shorten t_max)',
                t,
                y.copy(),
            )
    if status in _FAILURES:
        raise SimulationError(f'free body at t = {t:.6g} s: {_FAILURES[status]}', t, y.copy())
    n_corners = model.corners.shape[0]
    events = tuple(
        BodyEvent(
            kind=_EVENT_KINDS[int(row[2])],
            t=float(row[0]),
            corner=int(row[1]) % n_corners,
            surface=int(row[1]) // n_corners,
            values=(float(row[3]), float(row[4]), float(row[5])),
        )
        for row in np.concatenate(booked)
    )
    return BodyRun(
        t=float(t),
        state=BodyState(*(float(v) for v in y)),
        events=events,
        settled=status == K.SETTLED,
        trace=rows[: int(ntrace[0])],
        steps=int(stats[K.ST_STEPS]),
    )


def kinetic_energy(model: BodyModel, state: BodyState) -> float:
    m, inertia = model.P[K.P_MASS], model.P[K.P_INERTIA]
    return float(0.5 * m * (state.vx**2 + state.vz**2) + 0.5 * inertia * state.omega**2)


def energy(model: BodyModel, state: BodyState) -> float:
    """Kinetic plus gravitational energy (zero at z = 0)."""
    return kinetic_energy(model, state) + float(model.P[K.P_MASS] * model.P[K.P_GRAVITY] * state.z)
