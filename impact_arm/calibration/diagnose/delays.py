"""Signals late (or early) against the joint states: the efforts, from the power balance of
the free flight (``EFFORT_DELAY``), and the wrench, from its rise at the impacts
(``WRENCH_LAG``); the advice when the scene states a delay of its own."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..identify import JointRecording, joint_to_absolute_matrix
from .findings import Finding, FindingKind
from .stamps import consecutive

if TYPE_CHECKING:
    from ...physics.model import ArmModel

# A delay or a lag is reported from this many sample periods on: within one period the fit's
# own reading of the efforts (the effort at the stamp, or held over the period before or
# after it) already absorbs it, and a period-averaged wrench may rise one period after the
# step of the rates when the contact begins late in a period.
DELAY_PERIODS = 1.5
FREE_MARGIN = 15  # samples either side of an impact left out of the free flight
SEARCH_PERIODS = 20  # effort delays searched within +- this many periods
# F statistic a delay must reach against none (1 parameter over thousands of intervals: the
# 0.1 % tail is F ~ 11; the intervals share their samples, so well beyond it)
DELAY_F_MIN = 100.0


def _free(rec: JointRecording, impacts: list[int]) -> np.ndarray:
    free = np.ones(len(rec.t), bool)
    for a in impacts:
        free[max(0, a - FREE_MARGIN) : a + FREE_MARGIN + 2] = False
    return free


def effort_delay(
    rec: JointRecording, model: ArmModel, impacts: list[int]
) -> tuple[float, float] | None:
    """(delay of the efforts behind the joint states [s], F statistic of the delay against
    the best reading within half a period of none), or None when the free flight holds too
    little work of the torques. Between two consecutive free samples the change of the arm's
    energy equals the joint torques' work, tau(t_mid + delay) . (q[k] - q[k-1]); the delay
    is the one that balances it best (least squares). F = (cost(none) - cost(delay)) /
    (cost(delay) / (intervals - 1)): how much more the delay explains than the noise does."""
    k, period = consecutive(rec)
    free = _free(rec, impacts)
    k = k[free[k] & free[k - 1]]
    if len(k) < 50:
        return None
    T = joint_to_absolute_matrix(rec.n)
    qa, va = rec.position @ T.T, rec.velocity @ T.T
    energy = np.array(
        [
            float(np.sum(model.link_energies(qa[i], va[i]))) + model.potential_energy(qa[i])
            for i in range(len(rec.t))
        ]
    )
    d_energy = energy[k] - energy[k - 1]
    dq = rec.position[k] - rec.position[k - 1]
    mid = 0.5 * (rec.t[k] + rec.t[k - 1])
    if not np.any(rec.effort[k]) or not np.any(dq):
        return None
    shifts = np.arange(-SEARCH_PERIODS, SEARCH_PERIODS + 0.01, 0.25) * period

    def cost(shift: float) -> float:
        w = sum(np.interp(mid + shift, rec.t, rec.effort[:, j]) * dq[:, j] for j in range(rec.n))
        return float(np.sum((d_energy - w) ** 2))

    costs = np.array([cost(s) for s in shifts])
    # no delay: the best reading within half a period, as finely searched as the delay
    at_zero = min(cost(s) for s in np.linspace(-0.5, 0.5, 41) * period)
    # then finer around the best of the coarse grid
    coarse = float(shifts[int(np.argmin(costs))])
    fine = coarse + np.linspace(-0.25, 0.25, 26) * period
    fine_costs = np.array([cost(s) for s in fine])
    best = int(np.argmin(fine_costs))
    residual = max(float(fine_costs[best]), 1e-300) / (len(k) - 1)
    return float(fine[best]), (at_zero - float(fine_costs[best])) / residual


def check_effort_delay(
    rec: JointRecording, model: ArmModel, impacts: list[int]
) -> tuple[Finding | None, float | None]:
    found = effort_delay(rec, model, impacts)
    if found is None:
        return None, None
    delay, f_stat = found
    period = rec.period
    # a real delay explains the power balance far better than any reading within half a
    # period (the fit's readings of the efforts cover that much) and than noise could
    if abs(delay) < DELAY_PERIODS * period or f_stat < DELAY_F_MIN:
        return None, delay
    late = 'late' if delay > 0 else 'early'
    return (
        Finding(
            FindingKind.EFFORT_DELAY,
            delay,
            's',
            f'the efforts are {abs(delay) * 1e3:.3g} ms {late} against the joint states '
            f'({abs(delay) / period:.2g} periods; from the power balance of the free flight: '
            f'F = {f_stat:.3g} against no delay)',
            _latency_advice(
                model,
                'effort',
                delay,
                period,
                f'fit with --effort-latency {delay:.6g} (if the delay is known, give its value); '
                f'mid-contact samples would otherwise be read with the wrong torque',
            ),
        ),
        delay,
    )


def _latency_advice(
    model: ArmModel | None, signal: str, found: float, period: float, otherwise: str
) -> str:
    """The advice for a delay of the efforts or the wrench found in the recording: the
    option (``otherwise``), or, when the scene states a delay of that signal (which the fit
    replays, so the option would shift it twice), that the scene's is used, and whether it
    agrees with the one found."""
    if model is None:
        return otherwise
    sensors = model.scene.sensors
    stated = getattr(sensors, f'{signal}_latency') - sensors.state_latency
    if not stated:
        return otherwise
    key = f'sensors.{signal}_latency'
    said = (
        f'the scene states it ({key} less sensors.state_latency = {stated:.6g} s), which the '
        f'fit replays: give no --{signal}-latency'
    )
    if abs(found - stated) <= DELAY_PERIODS * period:
        return said
    return (
        f"{said}, but it differs from the delay found: correct the scene's {key}, or fit it "
        f'(--param {key}=LO:HI)'
    )


def wrench_lag(rec: JointRecording, impacts: list[int]) -> float | None:
    """Median over the impacts of how late the wrench rises (its first sample above half its
    peak) after the first joint sample after the step of the rates [s]; negative: how early
    before one period after the last sample before the step."""
    if rec.wrench is None or rec.wrench_t is None or not impacts:
        return None
    period = rec.period
    lags = []
    normal = np.abs(rec.wrench[:, 1])
    for a in impacts:
        t_a, t_b = rec.t[a], rec.t[a + 1]
        sel = np.flatnonzero(
            (rec.wrench_t > t_b - SEARCH_PERIODS * period)
            & (rec.wrench_t < t_b + SEARCH_PERIODS * period)
        )
        if len(sel) < 3:
            continue
        peak = float(np.max(normal[sel]))
        if peak <= 0:
            continue
        rise = float(rec.wrench_t[sel[np.flatnonzero(normal[sel] >= 0.5 * peak)[0]]])
        # on time: stamped from one period after the last sample before the contact to the
        # first sample after it (later when samples around the contact are lost)
        lags.append(rise - t_b if rise > t_b else min(rise - (t_a + period), 0.0))
    return float(np.median(lags)) if lags else None


def check_wrench_lag(
    rec: JointRecording, impacts: list[int], model: ArmModel | None = None
) -> tuple[Finding | None, float | None]:
    lag = wrench_lag(rec, impacts)
    if lag is None:
        return None, None
    period = rec.period
    if abs(lag) < DELAY_PERIODS * period:
        return None, lag
    late = 'after' if lag > 0 else 'before'
    return (
        Finding(
            FindingKind.WRENCH_LAG,
            lag,
            's',
            f'the wrench rises {abs(lag) * 1e3:.3g} ms ({abs(lag) / period:.2g} periods) {late} '
            f'the impacts the joint rates show (median over {len(impacts)} impacts)',
            _latency_advice(
                model,
                'wrench',
                lag,
                period,
                f"fit with --wrench-latency {lag:.6g} (the force sensor's latency, if known), "
                f'or --no-wrench; the wrench impulse of each impact is otherwise summed over '
                f'the wrong periods',
            ),
        ),
        lag,
    )
