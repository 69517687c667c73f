"""The Dormand-Prince 5(4) method both compiled integrators step with: its tableau, its
quartic continuous extension, one step of it over any right-hand side, and the error norm.

The arm's kernel (``kernel/steps.py``, generated per scene shape) and the free body's
(``bodies/kernel.py``) differ in their state and right-hand side only, so the step takes the
right-hand side as an argument: ``rhs(t, y, out, *args)`` writes ẏ into ``out``. The step is
inlined into its caller (``jit_leaf``): there the function is a compile-time constant, which
keeps the caller cacheable (a compiled function handed a function as a run-time value is not:
numba refuses to cache it) and calls the right-hand side directly. The right-hand side must be
called, not inlined (``jit``, not ``jit_leaf``): numba cannot inline a call with ``*args``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .jit import jit, jit_leaf

A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
# the error estimate: the fifth-order weights minus the embedded fourth-order ones
E1 = 35 / 384 - 5179 / 57600
E3 = 500 / 1113 - 7571 / 16695
E4 = 125 / 192 - 393 / 640
E5 = -2187 / 6784 + 92097 / 339200
E6 = 11 / 84 - 187 / 2100
E7 = -1 / 40
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
# Dormand-Prince continuous extension of order 4 (Shampine's quartic): over a step of size h,
# y(t + s h) = y + h sum_j b_j(s) k_j, b_j(s) = s^2 (D_j2 + s (D_j3 + s D_j4)) (+ s for j = 1),
# for the stages k_1 = f0, k_3 ... k_6 (K[1] ... K[4]), k_7 = f1 (k_2's weights are zero).
D12, D13, D14 = -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432
D32, D33, D34 = 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799
D42, D43, D44 = -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072
D52, D53, D54 = 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632
D62, D63, D64 = -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844
D72, D73, D74 = 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423


@jit_leaf
def dormand_prince_step(
    rhs: Callable[..., None],
    args: tuple[Any, ...],
    t: float,
    y: np.ndarray,
    f0: np.ndarray,
    h: float,
    y1: np.ndarray,
    f1: np.ndarray,
    err: np.ndarray,
    K: np.ndarray,
    work: np.ndarray,
) -> None:
    """One step of size h from (t, y) with f0 = ẏ there: y1, f1 = ẏ at (t + h, y1) (first
    same as last: the next step's f0) and the error vector ``err``. K (5 rows) keeps the
    stages k_2 ... k_6 for the continuous extension; ``work`` is scratch for the stage states.
    The right-hand side is ``rhs(t, y, out, *args)``."""
    size = y.shape[0]
    for i in range(size):
        work[i] = y[i] + h * A21 * f0[i]
    rhs(t + C2 * h, work, K[0], *args)
    for i in range(size):
        work[i] = y[i] + h * (A31 * f0[i] + A32 * K[0, i])
    rhs(t + C3 * h, work, K[1], *args)
    for i in range(size):
        work[i] = y[i] + h * (A41 * f0[i] + A42 * K[0, i] + A43 * K[1, i])
    rhs(t + C4 * h, work, K[2], *args)
    for i in range(size):
        work[i] = y[i] + h * (A51 * f0[i] + A52 * K[0, i] + A53 * K[1, i] + A54 * K[2, i])
    rhs(t + C5 * h, work, K[3], *args)
    for i in range(size):
        work[i] = y[i] + h * (
            A61 * f0[i] + A62 * K[0, i] + A63 * K[1, i] + A64 * K[2, i] + A65 * K[3, i]
        )
    rhs(t + h, work, K[4], *args)
    for i in range(size):
        y1[i] = y[i] + h * (B1 * f0[i] + B3 * K[1, i] + B4 * K[2, i] + B5 * K[3, i] + B6 * K[4, i])
    rhs(t + h, y1, f1, *args)
    for i in range(size):
        err[i] = h * (
            E1 * f0[i] + E3 * K[1, i] + E4 * K[2, i] + E5 * K[3, i] + E6 * K[4, i] + E7 * f1[i]
        )


@jit
def error_norm(err: np.ndarray, y0: np.ndarray, y1: np.ndarray, rtol: float, atol: float) -> float:
    """The root mean square of the error vector in units of each component's tolerance
    atol + rtol max(|y0|, |y1|): a step is accepted when it is at most 1."""
    total = 0.0
    size = err.shape[0]
    for i in range(size):
        scale = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        total += (err[i] / scale) ** 2
    return math.sqrt(total / size)
