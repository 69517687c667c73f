"""Where the arm will be when a command computed now starts to act: a driver stack delays each
command by a period or more, and a stiff controller acting on the state it sampled acts on the
past (its strike's rebound was answered late enough to strike twice).

``StatePredictor`` integrates the model's free motion (no contact: the prediction spans a few
periods, and an impact is detected from the measured state and wrench) from the sampled state
under the commands still in flight, each held for one period, as the driver holds them.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .control import add_joint_torques
from .model import ArmModel


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
