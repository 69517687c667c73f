"""The state before an impact shot through the model's free flight under the recorded
efforts, for rates that are period means or efforts held over each period.

A cubic through the positions before an impact (``LocalFit``) is the state when the torque
changes smoothly. A controller that acts on difference rates of a coarse encoder does not:
each period's command carries the quantisation noise of the rates it was computed from, the
arm's acceleration jumps from period to period, and the cubic's rate at the last sample is
off by more than its covariance says, in a way correlated with the recorded positions the
replay is compared with (docs/fit.md, "State before the impact"). The efforts are recorded,
so the flight through the samples before the impact is known up to its initial state: that
state is fitted to the positions (each weighted by its noise) through the model under the
reading of the efforts the fit uses, and the state at the last sample, with its covariance,
starts the replay."""

from __future__ import annotations

import math

import numpy as np

from ...physics.errors import SimulationError
from ...physics.integrator import PhaseIntegrator
from ...physics.model import ArmModel
from ..identify import ImpactWindow, joint_to_absolute_matrix
from .efforts import SUBSTEPS, EffortTiming, effort_shift
from .replay import window_options

NEWTON_STEPS = 3  # the flight over the window is nearly linear in its initial state


def _torque_pieces(
    win: ImpactWindow, timing: EffortTiming, t: np.ndarray, shift: float
) -> list[tuple[float, np.ndarray]]:
    """(end, torque) of each piece of held torque from t[0] to t[-1] under ``timing``: the
    effort of the period's end ('previous') or start ('next'), or the efforts interpolated
    at SUBSTEPS pieces per period ('linear'), each read ``shift`` later in the recording."""
    t_all, effort_all, _ = win.effort_source

    def effort(s: float) -> np.ndarray:
        return np.array(
            [np.interp(s + shift, t_all, effort_all[:, j]) for j in range(effort_all.shape[1])]
        )

    pieces: list[tuple[float, np.ndarray]] = []
    for t0, t1 in zip(t[:-1], t[1:]):
        if timing is EffortTiming.PREVIOUS:
            pieces.append((float(t1), effort(float(t1))))
        elif timing is EffortTiming.NEXT:
            pieces.append((float(t1), effort(float(t0))))
        else:
            edges = np.linspace(t0, t1, SUBSTEPS + 1)
            pieces += [(float(b), effort(0.5 * (a + b))) for a, b in zip(edges[:-1], edges[1:])]
    return pieces


def _flight(
    model: ArmModel, x0: np.ndarray, t: np.ndarray, pieces: list[tuple[float, np.ndarray]]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Joint positions at the stamps ``t`` and the joint state (q, q̇) at the last one, from
    the joint state ``x0`` at t[0] under the held ``pieces``; None when the flight meets a
    surface or the integrator stops."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    state = model.initial_state()
    state.t = float(t[0])
    state.y[:n], state.y[n : 2 * n] = T @ x0[:n], T @ x0[n:]
    integ = PhaseIntegrator(model, state, control='held', options=window_options(model))
    positions = [x0[:n].copy()]
    k = 1
    try:
        for end, tau in pieces:
            integ.set_held_torque(tau)
            integ.advance(end)
            if integ.state.phase != 0:
                return None
            if k < len(t) and abs(end - t[k]) < 1e-12:
                positions.append(np.linalg.solve(T, integ.state.y[:n]))
                k += 1
    except SimulationError:
        return None
    y = integ.state.y
    return np.array(positions), np.concatenate(
        [np.linalg.solve(T, y[:n]), np.linalg.solve(T, y[n : 2 * n])]
    )


def shot_start(
    model: ArmModel, win: ImpactWindow, timing: EffortTiming
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(q, q̇, cov) at the last sample before the impact (joint space; cov over [q, q̇]) from
    the model's flight through the positions before it under the recorded efforts read as
    ``timing``; None when it cannot be made (no recorded positions kept, a reading that
    reads no effort, a flight that meets a surface), the cubic then stands."""
    samples = getattr(win, 'pre_samples', None)
    if samples is None or not timing.reads_efforts:
        return None
    t, q, sigma_q = samples
    n = model.n
    if len(t) < 4 or not np.all(sigma_q > 0):
        return None
    pieces = _torque_pieces(win, timing, t, effort_shift(model))
    q0, qd0, _ = win.pre.state(float(t[0]))
    x = np.concatenate([q0, qd0])
    steps = np.concatenate([np.full(n, 1e-6), np.full(n, 1e-4)])
    J = np.zeros((q.size, 2 * n))
    Phi = np.zeros((2 * n, 2 * n))
    for _ in range(NEWTON_STEPS + 1):
        base = _flight(model, x, t, pieces)
        if base is None:
            return None
        r = ((base[0] - q) / sigma_q).ravel()
        for k in range(2 * n):
            moved_x = x.copy()
            moved_x[k] += steps[k]
            moved = _flight(model, moved_x, t, pieces)
            if moved is None:
                return None
            J[:, k] = ((moved[0] - base[0]) / sigma_q).ravel() / steps[k]
            Phi[:, k] = (moved[1] - base[1]) / steps[k]
        dx, *_ = np.linalg.lstsq(J, -r, rcond=None)
        x = x + dx
    end = _flight(model, x, t, pieces)
    if end is None:
        return None
    r = ((end[0] - q) / sigma_q).ravel()
    dof = r.size - 2 * n
    # a flight the positions do not follow (a wrong reading, an unmodelled torque) widens its
    # own uncertainty, as the cubic's does
    inflate = max(1.0, float(r @ r) / dof) if dof > 0 else 1.0
    cov0 = np.linalg.inv(J.T @ J) * inflate
    cov = Phi @ cov0 @ Phi.T
    if not np.all(np.isfinite(cov)) or not math.isfinite(float(r @ r)):
        return None
    return end[1][:n], end[1][n:], cov
