"""One recorded impact replayed on the model: from the recorded state before the contact,
under the recorded efforts, through every contact phase, to the compared samples after it.
A replay that cannot be made says why by a ``FailureKind``."""

from __future__ import annotations

from collections.abc import Sequence

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from ...physics.errors import SimulationError
from ...physics.integrator import IntegratorOptions
from ...physics.kinds import ImpactSide
from ...physics.model import ArmModel
from ...physics.replay import Replay, ReplayStart, start_replay
from ..identify import ImpactWindow, joint_to_absolute_matrix, tip_normal_speed
from .efforts import (
    EffortTiming,
    TorqueSchedule,
    contact_period_command,
    effort_shift,
    wrench_shift,
)

FIT_RTOL = 1e-8  # loosest tolerance a replay may use (finite-difference Jacobians)
# A sample this many rate standard deviations short of the model's separation is in the contact
INSIDE_SIGMAS = 3.0


def window_options(model: ArmModel) -> IntegratorOptions:
    """Integrator options of the replays: the scene's own (the fitted scene will run with
    them, and a second contact on the edge of happening is found or missed as the scene's
    runs find or miss it), tightened to 'balanced' when looser than FIT_RTOL."""
    spec = model.scene.integrator
    opts = IntegratorOptions.of_scene(spec)
    rtol = opts.free_rtol()
    if max(rtol, opts.contact_rtol or rtol) > FIT_RTOL:
        opts = IntegratorOptions.of_scene(spec, preset='balanced')
    return opts


class FailureKind(enum.Enum):
    """Why an impact could not be replayed at some parameter values."""

    SURFACE_ABOVE_TIP = 'surface above the tip'  # the start sample is already in contact
    NO_CONTACT = 'no contact'  # the model misses the surface across the recorded impact
    CONTACT_OUTLASTS = 'contact outlasts'  # still in contact at the first compared sample
    SIMULATION = 'simulation'  # the integrator stopped (SimulationError)
    SCENE_REFUSED = 'scene refused'  # the parameter values make a scene the schema refuses


@dataclass
class Prediction:
    qd: np.ndarray  # joint rates at the compared post-impact samples (m, n) [rad/s]
    impulse: np.ndarray  # contact impulse (tangential, normal) [N s]
    v_in: float  # tip normal speed at first contact [m/s]
    v_out: float  # ... at last separation
    contacts: int
    qd_sep: np.ndarray | None = None  # joint rates at the last separation
    error: str = ''  # why the replay failed, in words ('' when it did not)
    failure: FailureKind | None = None  # ... and as a kind, for the code that acts on it
    wrench_timing: float = math.nan  # centroid of the normal force in the wrench's periods
    # set by predict_impact once the contacts are through: the dense rows (``dense``), and
    # the time and state (q, q̇ absolute) at the last separation
    path: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    t_sep: float = math.nan
    y_sep: np.ndarray = field(default_factory=lambda: np.empty(0))


def predict_impact(
    model: ArmModel,
    win: ImpactWindow,
    timing: EffortTiming = EffortTiming.LINEAR,
    pre_state: tuple[np.ndarray, np.ndarray] | None = None,
    dense: Sequence[float] | None = None,
) -> Prediction:
    """Simulate one impact from the recorded state at the last sample before it (the
    pre-impact fit, or ``pre_state`` = (q, q̇) in joint space) under the recorded efforts,
    through every contact, to the compared samples after it. ``dense`` (a list of extra
    times) makes ``Prediction.path`` rows (t, q̇ joint space..., cumulative impulse t, n)
    at every boundary, for plots."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    heights = [s.height for s in model.surfaces]
    t0 = win.t_a
    q, qd, _ = win.start_state()
    if pre_state is not None:
        q, qd = pre_state
    if heights and tip_y(model, T @ q) <= max(heights):
        return failed(
            n,
            FailureKind.SURFACE_ABOVE_TIP,
            "the scene's surface is above the arm's tip before the recorded contact",
        )
    # a plate still ringing from the impacts before: from its recorded state
    ringing = win.plate is not None and len(win.plate) == 2 * model.n_mount
    # the scene's controller, if used, is approaching the surface
    start = ReplayStart(t0, T @ q, T @ qd, mode='down', plates=win.plate if ringing else None)
    held = timing.reads_efforts
    replay = Replay(model, start, window_options(model), control='held' if held else 'continuous')
    integ = replay.integrator
    torque = TorqueSchedule(win, timing, effort_shift(model), contact_period_command(model, win))
    rates, path, impulse = [], [], np.zeros(2)
    targets = list(win.post_t)
    edges = torque.boundaries(t0, targets[-1])
    extra: set[float] = set()
    if dense is not None:
        extra |= {float(x) for x in dense if t0 < x < targets[-1]}
    # rates recorded as means over the period before their stamps: the replay's positions
    # one period before each compared sample give the same mean (like compared with like)
    period = win.rate_period
    positions: dict[float, np.ndarray] = {}
    if period is not None:
        extra |= {float(x) - period for x in targets if float(x) - period > t0}
    # a wrench that may be late: the cumulative impulse where each period of it begins and
    # ends, moved back by the scene's delay of the wrench
    lag_ends: np.ndarray | None = None
    cumulative: dict[float, float] = {}
    if win.wrench_stamps is not None:
        ends = win.wrench_stamps - wrench_shift(model)
        lag_ends = np.concatenate([ends - win.wrench_period, ends])
        extra |= {float(x) for x in lag_ends if t0 < x < targets[-1]}
    if extra:
        edges = sorted(set(edges) | extra)
    try:
        for edge in edges:
            while integ.state.t < edge:
                if held:  # (ignored by the kernel while actuators are off in contact)
                    integ.set_held_torque(
                        torque(
                            integ.state.t,
                            edge,
                            ImpactSide.BEFORE
                            if replay.side is ImpactSide.BEFORE
                            else ImpactSide.AFTER,
                        )
                    )
                replay.advance(edge, stop_at=('contact', 'separation'))
            if period is not None:
                positions[edge] = np.linalg.solve(T, integ.state.y[:n])
            if dense is not None or lag_ends is not None:
                impulse += integ.take_impulse()
                cumulative[edge] = float(impulse[1])
                path.append(
                    [integ.state.t, *np.linalg.solve(T, integ.state.y[n : 2 * n]), *impulse]
                )
            if targets and abs(edge - targets[0]) < 1e-12:
                if replay.side is ImpactSide.CONTACT:
                    # a contact ending just after the sample in the model, just before it in
                    # the recording (the start state is uncertain by microseconds): let it
                    # end within a tenth of a period and compare there, unless what is left
                    # of it changes the rates beyond their noise (the sample was then taken
                    # in the contact, and is no free flight)
                    first_contact = replay.last is None
                    at_sample = np.linalg.solve(T, integ.state.y[n : 2 * n])
                    replay.advance(edge + 0.1 * (win.t_b - win.t_a), stop_at=('separation',))
                    if (
                        first_contact
                        and replay.last is not None
                        and replay.side is ImpactSide.AFTER
                        and win.rate_sigma is not None
                    ):
                        rest = np.linalg.solve(T, replay.last.y[n : 2 * n]) - at_sample
                        sigmas = float(np.max(np.abs(rest) / win.rate_sigma))
                        if sigmas > INSIDE_SIGMAS:
                            return failed(
                                n,
                                FailureKind.CONTACT_OUTLASTS,
                                f'the first sample after the impact is taken in the contact '
                                f'(the rest of it changes the rates by {sigmas:.3g} σ)',
                            )
                if replay.side is ImpactSide.BEFORE or replay.last is None:
                    if replay.side is ImpactSide.BEFORE:
                        return failed(
                            n,
                            FailureKind.NO_CONTACT,
                            'no contact predicted across the recorded impact',
                        )
                    return failed(
                        n,
                        FailureKind.CONTACT_OUTLASTS,
                        'the contact outlasts the first sample after it',
                    )
                # else in a further contact begun since: the rates there are continuous in
                # the parameters (it has only just begun when it appears), compare them
                if period is None:
                    rates.append(np.linalg.solve(T, integ.state.y[n : 2 * n]))
                else:
                    rates.append(
                        (
                            np.linalg.solve(T, integ.state.y[:n])
                            - _position_at(positions, edge - period, q, qd, t0)
                        )
                        / period
                    )
                targets.pop(0)
    except SimulationError as exc:
        return failed(n, FailureKind.SIMULATION, str(exc))
    impulse += integ.take_impulse()
    first, last = replay.first, replay.last
    # every compared sample was reached after a separation (or the replay failed above)
    assert first is not None and last is not None
    pred = Prediction(
        np.array(rates),
        impulse,
        tip_normal_speed(model, first.y[:n], first.y[n : 2 * n]),
        tip_normal_speed(model, last.y[:n], last.y[n : 2 * n]),
        replay.contacts,
        np.linalg.solve(T, last.y[n : 2 * n]),
    )
    pred.path = np.array(path)
    pred.t_sep, pred.y_sep = last.t, last.y[: 2 * n].copy()
    if lag_ends is not None:
        pred.wrench_timing = _wrench_timing(win, lag_ends, cumulative, t0, float(impulse[1]))
    return pred


def _wrench_timing(
    win: ImpactWindow, lag_ends: np.ndarray, cumulative: dict[float, float], t0: float, total: float
) -> float:
    """The centroid of the normal force the replay puts into the recorded wrench's periods
    (each the impulse between its moved-back start and end), as the recorded one: sum s F /
    sum F over the periods' stamps, in s after ``t0``."""

    def at(t: float) -> float:
        if t <= t0:
            return 0.0
        if t >= max(cumulative, default=t0):
            return total
        return cumulative[min(cumulative, key=lambda x: abs(x - t))]

    stamps = win.wrench_stamps
    assert stamps is not None
    m = len(stamps)
    gained = np.array([at(float(lag_ends[m + k])) - at(float(lag_ends[k])) for k in range(m)])
    if not gained.sum() > 0:
        return float(np.mean(stamps)) - t0
    return float(stamps @ gained) / float(gained.sum()) - t0


def _position_at(
    positions: dict[float, np.ndarray], t: float, q0: np.ndarray, qd0: np.ndarray, t0: float
) -> np.ndarray:
    """The replay's joint positions at ``t``: recorded at an edge, or (at or before the
    replay's start ``t0``, where stamps a rounding apart put it) from the start state."""
    if t > t0 + 1e-12:
        key = min(positions, key=lambda x: abs(x - t))
        return positions[key]
    return q0 + qd0 * (t - t0)


def free_flight(
    model: ArmModel, win: ImpactWindow, timing: EffortTiming, t0: float, y0: np.ndarray, t1: float
) -> np.ndarray | None:
    """Joint rates at ``t1`` after free flight from absolute state ``y0`` at ``t0`` under
    the torque ``timing`` uses after the impact (None if a contact intervenes)."""
    n = model.n
    held = timing.reads_efforts
    integ = start_replay(
        model,
        ReplayStart(t0, y0[:n], y0[n : 2 * n], mode='up'),
        window_options(model),
        control='held' if held else 'continuous',
    )
    torque = TorqueSchedule(win, timing, effort_shift(model))
    try:
        for edge in torque.boundaries(t0, t1):
            if held:
                integ.set_held_torque(torque(integ.state.t, edge, ImpactSide.AFTER))
            integ.advance(edge)
    except SimulationError:
        return None
    if integ.state.phase != 0:
        return None
    return np.linalg.solve(joint_to_absolute_matrix(n), integ.state.y[n : 2 * n])


def recorded_separation_rates(
    model: ArmModel, win: ImpactWindow, pred: Prediction, timing: EffortTiming
) -> np.ndarray | None:
    """The joint rates at the predicted separation that carry the model's free flight onto
    the recorded first sample after the impact (Newton step through the flight's
    sensitivity): the recorded side of the post-impact state, for its CoR."""
    n = model.n
    T = joint_to_absolute_matrix(n)
    t1 = win.post_t[0]
    base = free_flight(model, win, timing, pred.t_sep, pred.y_sep, t1)
    if base is None:
        return None
    A = np.zeros((n, n))
    for k in range(n):
        y = pred.y_sep.copy()
        y[n : 2 * n] += T[:, k] * 1e-4  # one joint rate up by 1e-4 rad/s
        moved = free_flight(model, win, timing, pred.t_sep, y, t1)
        if moved is None:
            return None
        A[:, k] = (moved - base) / 1e-4
    qd_sep = np.linalg.solve(T, pred.y_sep[n : 2 * n])
    # rates that are period means: the rate at the sample from the fit of its positions
    target = win.post_qd[0] if win.rate_period is None else win.post.state(t1)[1]
    return qd_sep + np.linalg.solve(A, target - base)


def recorded_cor(
    model: ArmModel, win: ImpactWindow, pred: Prediction, timing: EffortTiming, v_in: float
) -> float:
    n = model.n
    qd = recorded_separation_rates(model, win, pred, timing)
    if qd is None or not v_in:
        return math.nan
    T = joint_to_absolute_matrix(n)
    return -tip_normal_speed(model, pred.y_sep[:n], T @ qd) / v_in


def tip_y(model: ArmModel, q_abs: np.ndarray) -> float:
    return float(model.tip(q_abs, np.zeros_like(q_abs))[1])


def failed(n: int, kind: FailureKind, why: str) -> Prediction:
    """The prediction of a replay that could not be made, with its reason."""
    return Prediction(
        np.full((1, n), np.nan), np.full(2, np.nan), math.nan, math.nan, 0, None, why, kind
    )
