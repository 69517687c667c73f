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

import math
from typing import Callable, Sequence

import numpy as np

from . import jit
from .control import add_joint_torques
from .model import ArmModel

# the torque step of the finite-difference Jacobian, relative to the torque (at least 1 N m):
# the laws are affine in the state but for gravity, and the state is nearly affine in a
# torque held for a period, so the step's size hardly matters
JACOBIAN_STEP = 1e-3


class StatePredictor:
    """Free motion of ``model`` over whole periods of ``period`` seconds, one classical
    Runge-Kutta step of ``period / substeps`` at a time.

    The state has a few entries: numpy's overhead per operation would dwarf the
    arithmetic, so the steps run on Python floats, in the order ``ArrayStatePredictor`` (the
    plain numpy version) does them; only the compiled acceleration sees arrays, buffers
    reused from call to call (its array signature is compiled already). Two links in closed
    form (the article's arm) run unrolled into scalars.

    Where the scene's kernel module can take the acceleration itself (closed form, or three
    general links), the same steps run compiled there instead (kernel/predict.py), and so
    does the implicit law for the 'q' law: one call from Python per prediction. The float
    steps stay the reference they are tested against, and the path of every other case."""

    def __init__(self, model: ArmModel, period: float, substeps: int = 1):
        if not period > 0 or substeps < 1:
            raise ValueError(f'period = {period} s, substeps = {substeps}: need > 0 and >= 1')
        self.model = model
        self.h = period / substeps
        self.substeps = substeps
        self._generalized = np.zeros(model.n)
        self._q = np.zeros(model.n)
        self._qd = np.zeros(model.n)
        # the scene's compiled q̈, or its mass matrix and right-hand side to solve
        self._accel_of = model.eq.accel if model.eq.HAS_ACCEL else None
        self._mass_and_rhs = model.eq.mass_and_rhs
        # the generated functions take the link geometry (rod lengths, or a general link's
        # lengths, centres of mass, inertias and contact point), not the lengths alone
        self._parameters = (model.geometry, model.m, model.g)
        # the article's two links in closed form: the steps unrolled into scalars
        self._unrolled = model.n == 2 and self._accel_of is not None
        # The same steps compiled into the scene's kernel module (``free_periods``): one call
        # per prediction instead of four accelerations per period, each a compiled call from
        # Python with its arrays filled item by item. Not for accelerations only LAPACK
        # solves (general links beyond three), nor interpreted (numba off), where the float
        # steps above are the faster.
        n = model.n
        compiled = jit.ENABLED and (self._accel_of is not None or n == 3)
        self._compiled = getattr(model.eq, 'free_periods', None) if compiled else None
        # and the implicit law's Newton step, for the 'q' law (``implicit_command``)
        self._compiled_implicit = getattr(model.eq, 'implicit_q_law', None) if compiled else None
        self._y = np.zeros(2 * n)  # the state in and out of the compiled functions
        self._torques = np.zeros((1, n))  # a row per period, grown when needed
        self._tau = np.zeros(n)
        self._law_terms = np.zeros((3, n))  # target, kp, kd
        self._out = np.zeros(n)
        self._work = np.zeros(18 * n + n * n)

    def _accel(self, q: Sequence[float], qd: Sequence[float]) -> Sequence[float]:
        bq, bqd = self._q, self._qd
        for i in range(len(q)):
            bq[i] = q[i]
            bqd[i] = qd[i]
        if self._accel_of is not None:
            return self._accel_of(bq, bqd, self._generalized, *self._parameters)
        n = len(q)
        values = self._mass_and_rhs(bq, bqd, self._generalized, *self._parameters)
        if n == 3:  # three links of any geometry (a URDF arm's usual size): no LAPACK call
            solved = solve3(values)
            if solved is not None:
                return solved
        return np.linalg.solve(
            np.reshape(values[: n * n], (n, n)), np.asarray(values[n * n :])
        ).tolist()

    def _hold(self, tau: Sequence[float]) -> None:
        """The generalized forces of joint torques ``tau`` (as ``add_joint_torques`` adds
        them to zeros)."""
        n = len(tau)
        for i in range(n):
            self._generalized[i] = 0.0 + (tau[i] - (tau[i + 1] if i + 1 < n else 0.0))

    def _periods(
        self, q: list[float], qd: list[float], periods: int
    ) -> tuple[list[float], list[float]]:
        """(``q``, ``qd``) after ``periods`` periods under the torques ``_hold`` set."""
        if self._unrolled:
            return self._periods_two_links(q, qd, periods)
        h = self.h
        half, sixth = 0.5 * h, h / 6.0
        for _ in range(periods * self.substeps):
            a1 = self._accel(q, qd)
            v2 = [v + half * a for v, a in zip(qd, a1)]
            a2 = self._accel([x + half * v for x, v in zip(q, qd)], v2)
            v3 = [v + half * a for v, a in zip(qd, a2)]
            a3 = self._accel([x + half * v for x, v in zip(q, v2)], v3)
            v4 = [v + h * a for v, a in zip(qd, a3)]
            a4 = self._accel([x + h * v for x, v in zip(q, v3)], v4)
            q = [
                x + sixth * (v + 2.0 * w2 + 2.0 * w3 + w4)
                for x, v, w2, w3, w4 in zip(q, qd, v2, v3, v4)
            ]
            qd = [
                v + sixth * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                for v, b1, b2, b3, b4 in zip(qd, a1, a2, a3, a4)
            ]
        return q, qd

    def _periods_two_links(
        self, q: list[float], qd: list[float], periods: int
    ) -> tuple[list[float], list[float]]:
        """``_periods`` for two links written out entry by entry (same operations in the same
        order: the same bits, without the list building)."""
        accel, generalized, (lengths, masses, g) = (
            self._accel_of,
            self._generalized,
            self._parameters,
        )
        assert accel is not None
        bq, bqd = self._q, self._qd
        h = self.h
        half, sixth = 0.5 * h, h / 6.0
        x0, x1 = q
        v0, v1 = qd
        for _ in range(periods * self.substeps):
            bq[0], bq[1], bqd[0], bqd[1] = x0, x1, v0, v1
            a10, a11 = accel(bq, bqd, generalized, lengths, masses, g)
            u0, u1 = v0 + half * a10, v1 + half * a11
            bq[0], bq[1], bqd[0], bqd[1] = x0 + half * v0, x1 + half * v1, u0, u1
            a20, a21 = accel(bq, bqd, generalized, lengths, masses, g)
            w0, w1 = v0 + half * a20, v1 + half * a21
            bq[0], bq[1], bqd[0], bqd[1] = x0 + half * u0, x1 + half * u1, w0, w1
            a30, a31 = accel(bq, bqd, generalized, lengths, masses, g)
            z0, z1 = v0 + h * a30, v1 + h * a31
            bq[0], bq[1], bqd[0], bqd[1] = x0 + h * w0, x1 + h * w1, z0, z1
            a40, a41 = accel(bq, bqd, generalized, lengths, masses, g)
            x0 = x0 + sixth * (v0 + 2.0 * u0 + 2.0 * w0 + z0)
            x1 = x1 + sixth * (v1 + 2.0 * u1 + 2.0 * w1 + z1)
            v0 = v0 + sixth * (a10 + 2.0 * a20 + 2.0 * a30 + a40)
            v1 = v1 + sixth * (a11 + 2.0 * a21 + 2.0 * a31 + a41)
        return [x0, x1], [v0, v1]

    def _state(self, q: Sequence[float], qd: Sequence[float]) -> np.ndarray:
        """(``q``, ``qd``) into the compiled functions' state array."""
        y, n = self._y, self.model.n
        for i in range(n):
            y[i] = q[i]
            y[n + i] = qd[i]
        return y

    def _rows(self, periods: int) -> np.ndarray:
        """The compiled functions' torques, a row per period, at least ``periods`` rows."""
        if self._torques.shape[0] < periods:
            self._torques = np.zeros((periods, self.model.n))
        return self._torques

    def _compiled_implicit_q(
        self,
        q: Sequence[float],
        qd: Sequence[float],
        tau: Sequence[float],
        periods: int,
        terms: tuple[Sequence[float], Sequence[float], Sequence[float]],
    ) -> list[float] | None:
        """``implicit_command`` for the 'q' law of ``terms`` (target, kp, kd) by
        ``implicit_q_law``; None where it needs LAPACK (or is not compiled)."""
        compiled = self._compiled_implicit
        if compiled is None:
            return None
        n, held, law_terms = self.model.n, self._tau, self._law_terms
        for i in range(n):
            held[i] = tau[i]
        for row, values in enumerate(terms):
            for i in range(n):
                law_terms[row, i] = values[i]
        target, kp, kd = law_terms
        lengths, masses, g = self._parameters
        status = compiled(
            self._state(q, qd),
            held,
            periods,
            self.substeps,
            self.h,
            lengths,
            masses,
            g,
            target,
            kp,
            kd,
            JACOBIAN_STEP,
            self._rows(periods),
            self._work,
            self._out,
        )
        if status < 0:
            return None
        return self._out.tolist() if status else held.tolist()

    def _compiled_ahead(
        self, q: Sequence[float], qd: Sequence[float], torques: Sequence[Sequence[float]]
    ) -> tuple[list[float], list[float]] | None:
        """``ahead`` by ``free_periods``; None where it needs LAPACK (or is not compiled)."""
        compiled = self._compiled
        if compiled is None:
            return None
        y, n, periods = self._state(q, qd), self.model.n, len(torques)
        rows = self._rows(periods)
        for k, tau in enumerate(torques):
            for i in range(n):
                rows[k, i] = tau[i]
        lengths, masses, g = self._parameters
        if not compiled(y, rows, periods, self.substeps, self.h, lengths, masses, g, self._work):
            return None
        values = y.tolist()
        return values[:n], values[n:]

    def ahead(
        self, q: Sequence[float], qd: Sequence[float], torques: Sequence[Sequence[float]]
    ) -> tuple[list[float], list[float]]:
        """The absolute link angles and rates one period per entry of ``torques`` (joint
        torques, oldest first) after the state (``q``, ``qd``)."""
        compiled = self._compiled_ahead(q, qd, torques)
        if compiled is not None:
            return compiled
        y_q = [float(x) for x in q]
        y_v = [float(v) for v in qd]
        for tau in torques:
            self._hold([float(t) for t in tau])
            y_q, y_v = self._periods(y_q, y_v, 1)
        return y_q, y_v

    def implicit_command(
        self,
        law: Callable[[list[float], list[float]], Sequence[float]],
        q: Sequence[float],
        qd: Sequence[float],
        tau: Sequence[float],
        periods: int = 1,
        q_law: tuple[Sequence[float], Sequence[float], Sequence[float]] | None = None,
    ) -> list[float]:
        """The joint torques τ that ``law`` (joint torques of absolute angles and rates) gives
        on the state τ itself leads to, held ``periods`` periods from (``q``, ``qd``):
        τ = law(ahead(q, qd, [τ] * periods)), one Newton step from ``tau`` (the law's output
        at (``q``, ``qd``)) with a finite-difference Jacobian. The explicit ``tau`` comes back
        when the step cannot be taken (a singular Jacobian, a result that is not finite).

        ``q_law``: when ``law`` is the 'q' law, its (target, kp, kd)
        (``CycleController.q_law_terms``): then it all runs compiled (``implicit_q_law``),
        to the same bits."""
        if periods < 1:
            raise ValueError(f'periods = {periods}: must be >= 1')
        if q_law is not None:
            compiled = self._compiled_implicit_q(q, qd, tau, periods, q_law)
            if compiled is not None:
                return compiled
        q0 = [float(x) for x in q]
        qd0 = [float(v) for v in qd]
        torque = [float(t) for t in tau]

        def closed(held: list[float]) -> list[float]:
            state = self._compiled_ahead(q0, qd0, [held] * periods)
            if state is None:
                self._hold(held)
                state = self._periods(q0, qd0, periods)
            return [float(t) for t in law(*state)]

        n = len(torque)
        base = closed(torque)
        # (I - J) τ = base - J τ0, row by row; J by forward differences, column by column
        system = [[0.0] * n for _ in range(n)]
        for j in range(n):
            step = JACOBIAN_STEP * max(1.0, abs(torque[j]))
            shifted = list(torque)
            shifted[j] += step
            for i, value in enumerate(closed(shifted)):
                system[i][j] = (value - base[i]) / step
        rhs = [b - _dot(row, torque, 0) for b, row in zip(base, system)]
        for i in range(n):
            system[i] = [(1.0 if i == j else 0.0) - system[i][j] for j in range(n)]
        out = solve_small(system, rhs)
        if out is None or not all(math.isfinite(t) for t in out):
            return torque
        return out


def solve_small(a: list[list[float]], b: list[float]) -> list[float] | None:
    """x with ``a`` x = ``b`` by Gaussian elimination with partial pivoting (LAPACK's
    algorithm, in Python floats: for the two or three joints of an arm numpy's call overhead
    is most of the cost); None when a pivot is zero (a singular matrix). ``a`` and ``b`` are
    overwritten."""
    if len(b) == 2:
        return _solve2(a, b)
    return eliminate(a, b)


def eliminate(a: list[list[float]], b: list[float]) -> list[float] | None:
    """``solve_small``'s elimination for any size, written as the algorithm reads (the
    reference of its two-unknown and compiled forms)."""
    n = len(b)
    for k in range(n):
        pivot = max(range(k, n), key=lambda i: abs(a[i][k]))
        if a[pivot][k] == 0.0:
            return None
        if pivot != k:
            a[k], a[pivot] = a[pivot], a[k]
            b[k], b[pivot] = b[pivot], b[k]
        for i in range(k + 1, n):
            factor = a[i][k] / a[k][k]
            for j in range(k + 1, n):
                a[i][j] -= factor * a[k][j]
            b[i] -= factor * b[k]
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        x[i] = (b[i] - _dot(a[i], x, i + 1)) / a[i][i]
    return x


def _dot(row: Sequence[float], x: Sequence[float], start: int) -> float:
    """Σ row[j] x[j] for j >= ``start``, added left to right from 0.0 (Python 3.11's
    ``sum``; from 3.12 ``sum`` compensates its rounding, which the compiled form does not)."""
    total = 0.0
    for j in range(start, len(x)):
        total += row[j] * x[j]
    return total


def _solve2(a: list[list[float]], b: list[float]) -> list[float] | None:
    """``solve_small`` for two unknowns written out (the same operations in the same order,
    down to the integer 0 its sums start from: the same bits, a third of the time)."""
    (a00, a01), (a10, a11) = a
    b0, b1 = b
    if abs(a10) > abs(a00):  # (``max`` keeps the first of equal pivots)
        a00, a01, a10, a11, b0, b1 = a10, a11, a00, a01, b1, b0
    if a00 == 0.0:
        return None
    factor = a10 / a00
    a11 -= factor * a01
    b1 -= factor * b0
    if a11 == 0.0:
        return None
    x1 = b1 / a11  # (its sum of no terms, 0, changes no float it is subtracted from)
    return [(b0 - (0 + a01 * x1)) / a00, x1]


def solve3(values: Sequence[float]) -> list[float] | None:
    """x with M x = r, M the 3x3 matrix of ``values[:9]`` (row by row), r ``values[9:12]``,
    by the adjugate on floats: a fifth of the time of numpy's solve on a 3x3 (its per-call
    overhead), on the mass matrix a predictor solves four times per period. None where M is
    singular to the last bit or the result is not finite (the caller then asks LAPACK)."""
    a, b, c, d, e, f, g, h, i = values[:9]
    r0, r1, r2 = values[9:12]
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    c10, c11, c12 = f * g - d * i, a * i - c * g, c * d - a * f
    c20, c21, c22 = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * c00 + b * c10 + c * c20
    if det == 0.0:
        return None
    x = [
        (c00 * r0 + c01 * r1 + c02 * r2) / det,
        (c10 * r0 + c11 * r1 + c12 * r2) / det,
        (c20 * r0 + c21 * r1 + c22 * r2) / det,
    ]
    return x if all(math.isfinite(v) for v in x) else None


class ArrayStatePredictor:
    """``StatePredictor`` written with numpy arrays, as it was first: the reference the
    float-by-float ``StatePredictor`` is tested and benchmarked against (same operations in
    the same order; slower by numpy's per-call overhead on arrays of two or three)."""

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
            return np.asarray(m.eq.accel(q, qd, self._generalized, m.geometry, m.m, m.g))
        n = m.n
        values = m.eq.mass_and_rhs(q, qd, self._generalized, m.geometry, m.m, m.g)
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
        """``StatePredictor.implicit_command`` on numpy arrays, solved by LAPACK."""
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
