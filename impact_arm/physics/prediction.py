"""Where the arm will be when a command computed now starts to act: a driver stack delays each
command by a period or more, and a stiff controller acting on the state it sampled acts on the
past (its strike's rebound was answered late enough to strike twice).

``StatePredictor`` integrates the model's free motion (no contact: the prediction spans a few
periods, and an impact is detected from the measured state and wrench) from the sampled state
under the commands still in flight, each held for one period, as the driver holds them.

A latency that varies by a period from command to command (an unsynchronised driver stack)
makes a command act a period early or late, for one period or two (its successor late), or
never (superseded). The article's damping acting on a zero-order hold removes about 0.8 of a
rate error per period at 1 kHz: a command held twice as long as planned reverses the error
(1 - 2 x 0.8), which right after an impact turns the rebound back into the surface.
``implicit_command`` evaluates the law on the state its own command leads to instead (a
backward-Euler step of the law): held one period or two, it never overshoots.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from .control import add_joint_torques
from .model import ArmModel

# the torque step of the finite-difference Jacobian, relative to the torque (at least 1 N m):
# the laws are affine in the state but for gravity, and the state is nearly affine in a
# torque held for a period, so the step's size hardly matters
JACOBIAN_STEP = 1e-3


class StatePredictor:
    """Free motion of ``model`` over whole periods of ``period`` seconds, one classical
    Runge-Kutta step of ``period / substeps`` at a time."""

    def __init__(self, model: ArmModel, period: float, substeps: int = 1):
        if not period > 0 or substeps < 1:
            raise ValueError(f'period = {period} s, substeps = {substeps}: need > 0 and >= 1')
        self.model = model
        self.h = period / substeps
        self.substeps = substeps
        self._generalized = np.zeros(model.n)

    def _accel(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        m = self.model
        if m.eq.HAS_ACCEL:
            return np.asarray(m.eq.accel(q, qd, self._generalized, m.L, m.m, m.g))
        n = m.n
        values = m.eq.mass_and_rhs(q, qd, self._generalized, m.L, m.m, m.g)
        return np.linalg.solve(np.reshape(values[: n * n], (n, n)), np.asarray(values[n * n :]))

    def ahead(
        self, q: Sequence[float], qd: Sequence[float], torques: Sequence[Sequence[float]]
    ) -> tuple[list[float], list[float]]:
        """The absolute link angles and rates one period per entry of ``torques`` (joint
        torques, oldest first) after the state (``q``, ``qd``)."""
        y_q = np.asarray(q, dtype=float)
        y_v = np.asarray(qd, dtype=float)
        h = self.h
        for tau in torques:
            self._generalized[:] = 0.0
            add_joint_torques(np.asarray(tau, dtype=float), self._generalized)
            for _ in range(self.substeps):
                a1 = self._accel(y_q, y_v)
                v2 = y_v + 0.5 * h * a1
                a2 = self._accel(y_q + 0.5 * h * y_v, v2)
                v3 = y_v + 0.5 * h * a2
                a3 = self._accel(y_q + 0.5 * h * v2, v3)
                v4 = y_v + h * a3
                a4 = self._accel(y_q + h * v3, v4)
                y_q = y_q + h / 6.0 * (y_v + 2.0 * v2 + 2.0 * v3 + v4)
                y_v = y_v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return y_q.tolist(), y_v.tolist()

    def implicit_command(
        self,
        law: Callable[[list[float], list[float]], Sequence[float]],
        q: Sequence[float],
        qd: Sequence[float],
        tau: Sequence[float],
        periods: int = 1,
    ) -> list[float]:
        """The joint torques τ that ``law`` (joint torques of absolute angles and rates) gives
        on the state τ itself leads to, held ``periods`` periods from (``q``, ``qd``):
        τ = law(ahead(q, qd, [τ] * periods)), one Newton step from ``tau`` (the law's output
        at (``q``, ``qd``)) with a finite-difference Jacobian. The explicit ``tau`` comes back
        when the step cannot be taken (a singular Jacobian, a result that is not finite)."""
        if periods < 1:
            raise ValueError(f'periods = {periods}: must be >= 1')
        tau0 = np.asarray(tau, dtype=float)

        def closed(torque: np.ndarray) -> np.ndarray:
            q1, qd1 = self.ahead(q, qd, [torque.tolist()] * periods)
            return np.asarray(law(q1, qd1), dtype=float)

        n = tau0.shape[0]
        base = closed(tau0)
        jacobian = np.empty((n, n))
        for j in range(n):
            step = JACOBIAN_STEP * max(1.0, abs(tau0[j]))
            shifted = tau0.copy()
            shifted[j] += step
            jacobian[:, j] = (closed(shifted) - base) / step
        try:  # τ = base + J (τ - τ0)
            out = np.linalg.solve(np.eye(n) - jacobian, base - jacobian @ tau0)
        except np.linalg.LinAlgError:
            return tau0.tolist()
        return out.tolist() if np.all(np.isfinite(out)) else tau0.tolist()
