"""One impact integrated again on the model from a state before its contact: the one place
where a replay's start state is placed, its integrator set up and its contacts counted.

Two kinds of caller use it. The fit (``calibration/fit/replay.py``) drives a ``Replay`` edge
by edge, since the recorded efforts change the held torque between samples and the compared
samples fall inside and after the contact. The analysis of a recording
(``tools/analysis/impacts.py``) replays a reported impact in one call, ``replay_impact``, from a
moment before its reported contact state (``ReplayStart.before_contact``, with the joint
rates of ``contact_rates``) to the event that ends what it draws.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import math
from dataclasses import dataclass

import numpy as np

from .contact import hertz_force
from .errors import ContactStateError
from .impact import Impact
from .integrator import Event, IntegratorOptions, PhaseIntegrator
from .kinds import EventKind, ImpactSide
from .metrics import ImpactBuilder
from .model import ArmModel

# A replay of a reported contact starts this long before it (0.1 µs: ~0.6 µm above the
# surface at the article's speeds), so that the contact event is located as in the run,
# not taken as already crossed.
CONTACT_LEAD = 1e-7
# what may end a replay once its contact is found: the impact's later events
ENDING_KINDS = frozenset({EventKind.YIELD, EventKind.MAX_COMPRESSION, EventKind.SEPARATION})


@dataclass(frozen=True)
class ReplayStart:
    """Where a replay begins: time [s], absolute link angles and rates, the continuous
    controller's cycle half (None: the scene's initial one) and each mounted plate's (z, ż),
    flat in surface order (None: the plates at rest where the scene puts them)."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    mode: str | None = None
    plates: np.ndarray | None = None

    @classmethod
    def before_contact(cls, t_contact: float, q: np.ndarray, qd: np.ndarray) -> ReplayStart:
        """The start ``CONTACT_LEAD`` before a contact at ``t_contact`` in state (q, q̇),
        moved back along q̇ (the arm is in free flight there)."""
        return cls(t_contact - CONTACT_LEAD, q - qd * CONTACT_LEAD, qd)


@dataclass(frozen=True)
class OutputGrid:
    """Output of the replay's state at the times k dt, k >= ``first`` (the integrator's
    continuous extension; contact steps end on them)."""

    dt: float
    first: int

    @classmethod
    def from_time(cls, dt: float, t: float) -> OutputGrid:
        """The grid of period ``dt`` from its first time at or after ``t``."""
        return cls(dt, math.ceil(t / dt))


def start_replay(
    model: ArmModel,
    start: ReplayStart,
    options: IntegratorOptions,
    *,
    control: str = 'held',
    trace: bool = False,
) -> PhaseIntegrator:
    """An integrator on ``model`` placed at ``start`` (every other state as the scene's
    initial one: integral states, contact phase, held torque zero)."""
    n = model.n
    state = model.initial_state()
    state.t = start.t
    state.y[:n], state.y[n : 2 * n] = start.q, start.qd
    if start.plates is not None:
        if len(start.plates) != 2 * model.n_mount:
            raise ValueError(
                f'{len(start.plates)} plate states for {model.n_mount} mounted surfaces '
                f'(z and ż each)'
            )
        for i, surface in enumerate(model.mounted):
            state.y[surface.mount_state : surface.mount_state + 2] = start.plates[2 * i : 2 * i + 2]
    if start.mode is not None:
        state.mode = start.mode
    return PhaseIntegrator(model, state, control=control, trace=trace, options=options)


class Replay:
    """One impact's replay in progress: its integrator and the contacts it has crossed
    (how many, the first contact, the last separation, and on which side of the impact the
    arm is: ``ImpactSide``)."""

    def __init__(
        self,
        model: ArmModel,
        start: ReplayStart,
        options: IntegratorOptions,
        *,
        control: str = 'held',
        trace: bool = False,
    ):
        self.model = model
        self.integrator = start_replay(model, start, options, control=control, trace=trace)
        self.contacts = 0
        self.first: Event | None = None
        self.last: Event | None = None
        self.side = ImpactSide.BEFORE

    def advance(self, t_end: float, stop_at: bool | Iterable[str]) -> list[Event]:
        """Integrate to ``t_end`` or to the first event of a kind in ``stop_at``
        (``PhaseIntegrator.advance``), counting the contacts crossed; returns the events."""
        events = self.integrator.advance(t_end, stop_at_event=stop_at)
        for event in events:
            if event.kind == EventKind.CONTACT:
                self.contacts += 1
                self.first = self.first or event
                self.side = ImpactSide.CONTACT
            elif event.kind == EventKind.SEPARATION:
                self.last, self.side = event, ImpactSide.AFTER
        return events


@dataclass(frozen=True)
class ImpactReplay:
    """What ``replay_impact`` gives: the events located (in order, up to ``end``), the
    first contact, the event that ended the replay (None when the horizon came first),
    the impact record (as a run reports it; None unless the replay ended at the
    separation), the contact trace rows (empty unless asked for), the output rows on the
    grid (empty unless asked for) and each surface's contact height at the end."""

    events: tuple[Event, ...]
    contact: Event | None
    end: Event | None
    record: Impact | None
    trace: np.ndarray
    output: np.ndarray
    levels: np.ndarray


def replay_impact(
    model: ArmModel,
    start: ReplayStart,
    options: IntegratorOptions,
    horizon: float,
    *,
    end_at: Sequence[str] = (EventKind.SEPARATION,),
    trace: bool = False,
    output: OutputGrid | None = None,
) -> ImpactReplay:
    """Integrate from ``start`` under a held zero torque (the actuators off during contact,
    as the article's eq. 7) until the first event of a kind in ``end_at`` after the first
    contact, or ``horizon`` [s]."""
    unknown = set(end_at) - ENDING_KINDS
    if unknown:
        raise ValueError(f'end_at: {sorted(unknown)} cannot end an impact')
    replay = Replay(model, start, options, trace=trace)
    integ = replay.integrator
    if output is not None:
        integ.start_output(output.dt, output.first)
    builder = ImpactBuilder(model)
    events: list[Event] = []
    contact: Event | None = None
    end: Event | None = None
    record: Impact | None = None
    # every event stops the kernel: the impact record and the trace are read at its end
    while integ.state.t < horizon and end is None:
        for event in replay.advance(horizon, stop_at=True):
            events.append(event)
            made = builder.feed(event)
            if event.kind == EventKind.CONTACT and contact is None:
                contact = event
            elif contact is not None and event.kind in end_at:
                end, record = event, made
                break
    rows = integ.trace if integ.trace is not None else []
    return ImpactReplay(
        tuple(events),
        contact,
        end,
        record,
        np.asarray(rows, float),
        integ.take_output(),
        integ.state.levels.copy(),
    )


def contact_rates(
    model: ArmModel,
    q: np.ndarray,
    v: np.ndarray,
    energies: np.ndarray | None = None,
    guess: np.ndarray | None = None,
) -> np.ndarray:
    """The joint rates at a contact in posture ``q`` (absolute angles) with tip velocity
    ``v``: q̇ = J(q)⁻¹ v for two links. A longer chain has more rates than v has
    components: they are the rates that give v and every link's kinetic energy
    ``energies``, solved by least squares from ``guess`` (the motion's last rates before
    the contact: of the discrete solutions, the one it was on). ContactStateError when no
    rates give both."""
    n = model.n
    jacobian = np.asarray(model.tip_jacobian(q), float).reshape(2, n)
    if n == 2:
        return np.linalg.solve(jacobian, v)
    if energies is None:
        raise ContactStateError(f'{n} links: the joint rates need the link energies at contact')
    from scipy.optimize import least_squares

    v_scale = max(float(np.hypot(*v)), 1e-9)
    t_scale = max(float(np.sum(energies)), 1e-12)

    def residuals(qd: np.ndarray) -> np.ndarray:
        return np.concatenate(
            [(jacobian @ qd - v) / v_scale, (model.link_energies(q, qd) - energies) / t_scale]
        )

    start = np.zeros(n) if guess is None else np.asarray(guess, float)
    fit = least_squares(residuals, start, method='lm', xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if not np.max(np.abs(fit.fun)) < 1e-8:
        raise ContactStateError(
            f'no joint rates give its reported tip velocity and link energies at contact '
            f'(worst relative misfit {np.max(np.abs(fit.fun)):.1e})'
        )
    return np.asarray(fit.x)


@dataclass(frozen=True)
class ElasticCurve:
    """The elastic (Hertz) phase of one impact on a fine time grid: the integrator's output
    between contact and the end of the phase (yield at 1.9 δc, or maximum compression for a
    contact that stays elastic). The phase lasts ~1 µs, a step or two of the integrator: its
    step ends alone draw it as a straight segment."""

    t: np.ndarray  # [s]
    delta: np.ndarray  # indentation [m]
    force: np.ndarray  # normal force [N], Hertz at delta
    end: str  # the event that ends the phase: 'yield' or 'max_compression'


def elastic_phase(model: ArmModel, replay: ImpactReplay) -> ElasticCurve | None:
    """The elastic phase of a ``replay_impact`` that ended at the phase's end (``end_at``
    yield and maximum compression) with output on a grid: the contact, the grid's rows
    inside the phase, and its end. None when the replay found no contact or no end."""
    contact, end = replay.contact, replay.end
    if contact is None or end is None:
        return None
    n = model.n
    surface = model.surfaces[contact.surface]
    level = float(replay.levels[contact.surface])

    def indentation(y: np.ndarray) -> float:
        if model.general:  # the tip B anywhere on the last link
            return level - float(model.tip(y[:n], np.zeros(n))[1])
        return level - float(np.sum(model.L * np.sin(y[:n])))

    rows = replay.output
    inside = [r for r in rows if contact.t < r[0] < end.t]
    t = [contact.t] + [r[0] for r in inside] + [end.t]
    ys = [contact.y] + [r[1 : 1 + model.size] for r in inside] + [end.y]
    delta = np.array([max(indentation(y), 0.0) for y in ys])
    c = surface.constants
    force = np.array([hertz_force(d, c.E, c.R) for d in delta])
    return ElasticCurve(np.asarray(t), delta, force, end.kind)
