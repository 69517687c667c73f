"""What a real arm's driver reports instead of the exact state: encoder counts, noise, rates
computed from the positions, and readings that arrive late. The physics is untouched; this
is the one implementation of the scene's ``sensors`` section, used by the simulated driver
(``driver/arm.py``, hence the simulator node) and by the synthetic recordings
(``io/synthetic.py``).

Each period the driver takes one reading of the true state, in this order:

1. position: the true joint angle plus Gaussian ``position_noise``, then quantised to the
   encoder's counts (a multiple of 2 pi / ``counts_per_revolution``);
2. rate: ``exact`` (the true rate plus ``rate_noise``), ``difference`` (this position minus the
   previous one, times the publish rate) or ``filtered`` (that difference through a discrete
   first-order low-pass with cut-off ``rate_cutoff``);
3. effort and wrench: the true values plus ``effort_noise`` and ``wrench_noise``;
4. latency: what is published at period k is the reading of period k - d, with d the latency
   rounded up to whole periods (the newest reading at least the latency old); joint states,
   efforts and wrench each have their own. Until d readings exist the first one is repeated.

With the default (ideal) section nothing of this runs: the driver publishes the exact state.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..physics.scene import RateReading, SensorSpec

# a latency that is a whole number of periods in decimal (2 ms at 1 kHz) must not round up
# to the next period because of binary floating point
_WHOLE_PERIOD_SLACK = 1e-9


def latency_periods(latency: float, rate: float) -> int:
    """The latency [s] as whole periods at ``rate`` [Hz], rounded up: the newest reading that
    is at least ``latency`` old is the one published."""
    return max(0, math.ceil(latency * rate - _WHOLE_PERIOD_SLACK))


def encoder_step(counts_per_revolution: int) -> float:
    """The encoder's resolution [rad]."""
    return 2.0 * math.pi / counts_per_revolution


@dataclass(frozen=True)
class Reading:
    """What the driver publishes for one period (joint space, SI)."""

    position: list[float]  # [rad]
    velocity: list[float]  # [rad/s]
    effort: list[float]  # [N m]
    wrench: tuple[float, ...]  # (tangential, normal) [N]


class Sensors:
    """The sensor chain of one driver at ``rate`` Hz; ``read`` once per period, in order."""

    def __init__(self, spec: SensorSpec, rate: float, n: int):
        if not rate > 0:
            raise ValueError(f'rate = {rate}: must be > 0 Hz')
        self.spec = spec
        self.rate = float(rate)
        self.n = n
        self.step = encoder_step(spec.counts_per_revolution) if spec.counts_per_revolution else None
        # the discrete first-order low-pass y += alpha (x - y): the exact response of a
        # continuous one to an input held over each period
        self.alpha = (
            1.0 - math.exp(-2.0 * math.pi * spec.rate_cutoff / self.rate)
            if spec.rate is RateReading.FILTERED and spec.rate_cutoff
            else 1.0
        )
        self.delays = tuple(
            latency_periods(x, self.rate)
            for x in (spec.state_latency, spec.effort_latency, spec.wrench_latency)
        )
        self.reset()

    @property
    def ideal(self) -> bool:
        return self.spec.ideal

    def reset(self) -> None:
        """A driver started afresh: the noise sequence from its seed, no history."""
        self.rng = np.random.default_rng(self.spec.seed)
        self._previous: list[float] | None = None  # the last position read
        self._filtered = [0.0] * self.n
        self._states: collections.deque = collections.deque(maxlen=self.delays[0] + 1)
        self._efforts: collections.deque = collections.deque(maxlen=self.delays[1] + 1)
        self._wrenches: collections.deque = collections.deque(maxlen=self.delays[2] + 1)

    # Once per period on two or three values: Python floats, in numpy's order of operations
    # and with its draws (one normal vector per quantity), so the readings are numpy's to the
    # bit; numpy's per-call overhead on such small arrays cost ~1 % of a core at 1 kHz.
    def _noisy(self, x: list[float], sigma: float) -> list[float]:
        if not sigma:
            return x
        draws = self.rng.normal(0.0, sigma, len(x)).tolist()
        return [a + b for a, b in zip(x, draws)]

    def _quantised(self, q: list[float]) -> list[float]:
        """Each angle rounded to the encoder's step (half to even, as numpy's round; a zero
        keeps the sign of the value rounded, as numpy's does)."""
        step = self.step
        assert step is not None
        out = []
        for v in q:
            counts = round(v / step)
            out.append(counts * step if counts else math.copysign(0.0, v) * step)
        return out

    def read(
        self,
        position: Sequence[float] | np.ndarray,
        velocity: Sequence[float] | np.ndarray,
        effort: Sequence[float] | np.ndarray,
        wrench: Sequence[float] | np.ndarray,
    ) -> Reading:
        """The next period's reading of the true joint angles [rad], rates [rad/s], efforts
        [N m] and wrench [N] (joint space, the driver's convention)."""
        spec = self.spec
        q = self._noisy([float(v) for v in position], spec.position_noise)
        if self.step is not None:
            q = self._quantised(q)
        if spec.rate is RateReading.EXACT:
            qd = self._noisy([float(v) for v in velocity], spec.rate_noise)
        else:
            # the first reading has no previous position: a driver starts from rest
            previous, rate = self._previous, self.rate
            if previous is not None:
                diff = [(a - b) * rate for a, b in zip(q, previous)]
            else:
                diff = [a * 0.0 for a in q]
            if spec.rate is RateReading.FILTERED:
                alpha = self.alpha
                self._filtered = [f + alpha * (d - f) for f, d in zip(self._filtered, diff)]
                qd = self._filtered
            else:
                qd = diff
        self._previous = q
        tau = self._noisy([float(v) for v in effort], spec.effort_noise)
        w = self._noisy([float(v) for v in wrench], spec.wrench_noise)
        self._states.append((q, qd))
        self._efforts.append(tau)
        self._wrenches.append(w)
        q_out, qd_out = self._states[0]
        return Reading(list(q_out), list(qd_out), list(self._efforts[0]), tuple(self._wrenches[0]))


def sensed_series(
    spec: SensorSpec,
    rate: float,
    position: np.ndarray,
    velocity: np.ndarray,
    effort: np.ndarray,
    wrench: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A whole sampled run (rows one period apart, joint space) as the driver reports it:
    ``Sensors.read`` row by row. Returns (position, velocity, effort, wrench)."""
    sensors = Sensors(spec, rate, position.shape[1])
    rows = [sensors.read(*row) for row in zip(position, velocity, effort, wrench)]
    return (
        np.array([r.position for r in rows], float).reshape(position.shape),
        np.array([r.velocity for r in rows], float).reshape(velocity.shape),
        np.array([r.effort for r in rows], float).reshape(effort.shape),
        np.array([r.wrench for r in rows], float).reshape(wrench.shape),
    )
