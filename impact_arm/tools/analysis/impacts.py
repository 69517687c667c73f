"""Each impact of a recording at full resolution: the file's ``/impact_trace``, or in a live
recording the impact integrated again from its ``/impact_report`` contact state
(physics/replay.py), and the elastic (Hertz) curve of Figure 10."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ...physics.impact import Impact
from ..run_data import AnalysisError, Run, _quiet

if TYPE_CHECKING:
    from ...physics.contact import ContactConstants
    from ...physics.model import ArmModel
    from ...physics.replay import ElasticCurve, ImpactReplay
    from ...physics.scene import Scene

# an impact's points for Figures 8-11: (columns, rows, record, note)
ImpactPoints = tuple[list[str], np.ndarray, Impact, str]


def trace_missing_reason(run: Run) -> str:
    """Why impact ``k``'s points cannot be re-integrated from /impact_report ('' if they
    can): the re-integration starts from the reported contact state and needs the scene."""
    if not run.impacts:
        return 'the recording has no /impact_report'
    if run.scene is None:
        return 'the recording stores no scene'
    n = run.scene.n_links
    if n > 2 and not all(len(record.T_before) >= n for record in run.impacts):
        return (
            f'its reports lack the link energies that give the joint rates of {n} links at contact'
        )
    if run.scene.actuators_during_contact:
        return 'its scene keeps the actuators on during contact (their torque is not reported)'
    return ''


def contact_state(
    model: ArmModel, record: Impact, guess: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(q, q̇) at an impact's contact from its /impact_report: the angles it gives, and the
    joint rates that give its tip velocity (and, beyond two links, every link's kinetic
    energy ``T_before``; ``guess``: the recording's last joint rates before the contact),
    ``physics.replay.contact_rates``. Refused (AnalysisError) when no rates give both."""
    from ...physics.errors import ContactStateError
    from ...physics.replay import contact_rates

    q = np.radians(np.asarray(record.q_contact_deg, float))
    v = np.asarray(record.v_before, float)
    energies = np.asarray(record.T_before[: model.n], float) if model.n > 2 else None
    try:
        return q, contact_rates(model, q, v, energies, guess)
    except ContactStateError as exc:
        raise AnalysisError(f'impact {record.index}: {exc}') from None


def rates_before(run: Run, t: float) -> np.ndarray | None:
    """The joint rates of ``run``'s last joint state at or before time ``t`` (None if none)."""
    i = int(np.searchsorted(run.t, t, side='right')) - 1
    return run.qd[i] if i >= 0 and np.all(np.isfinite(run.qd[i])) else None


def _contact_replay(
    scene: Scene, record: Impact, guess: np.ndarray | None, **kwargs: Any
) -> tuple[ArmModel, ImpactReplay]:
    """Impact ``record`` integrated again from its reported contact state
    (``physics.replay.replay_impact``, from a moment before the contact, with the scene's
    integrator options); given up after ten times its reported duration."""
    from ...physics.integrator import IntegratorOptions
    from ...physics.model import ArmModel
    from ...physics.replay import ReplayStart, replay_impact

    model = ArmModel(scene)
    q, qd = contact_state(model, record, guess)
    start = ReplayStart.before_contact(float(record.t_contact), q, qd)
    horizon = start.t + 10 * max(float(record.duration), 1e-6)
    options = IntegratorOptions.of_scene(scene.integrator)
    return model, replay_impact(model, start, options, horizon, **kwargs)


def reintegrated_trace(
    scene: Scene, record: Impact, guess: np.ndarray | None = None
) -> tuple[tuple[list[str], np.ndarray], Impact]:
    """The points of one impact, integrated again from the state its /impact_report gives at
    contact (``contact_state``; ``guess``: the joint rates just before it, for more than two
    links). With the actuators off during contact (the article's eq. 7) nothing else acts,
    so the impact is the recorded one to the integrator's tolerance. Returns (columns, rows)
    as /impact_trace carries them and the re-integrated record (to compare with the
    reported one)."""
    from ...io.offline_mcap import trace_columns

    model, replay = _contact_replay(scene, record, guess, trace=True)
    if replay.record is None:
        raise AnalysisError(
            f'impact {record.index} did not end when integrated again from '
            f'its reported contact state'
        )
    return (trace_columns(model.n), replay.trace), replay.record


def elastic_curve(
    scene: Scene | None, record: Impact, points: int = 80, guess: np.ndarray | None = None
) -> ElasticCurve | None:
    """Integrate impact ``record`` again from its reported contact state (as
    ``reintegrated_trace``, ``guess`` as there) with output on a grid of ``points`` times
    over its elastic phase (the integrator's continuous extension; contact steps end on the
    grid). None when the record cannot be integrated again (``trace_missing_reason``; a
    record read off a trace has no contact angles) or has no elastic phase."""
    from ...physics.kinds import EventKind
    from ...physics.replay import OutputGrid, elastic_phase

    if scene is None or scene.actuators_during_contact:
        return None
    durations = record.phase_durations
    if not durations or not durations[0] > 0 or not record.q_contact_deg:
        return None
    if scene.n_links > 2 and len(record.T_before) < scene.n_links:
        return None
    dt = float(durations[0]) / points
    try:
        model, replay = _contact_replay(
            scene,
            record,
            guess,
            end_at=(EventKind.YIELD, EventKind.MAX_COMPRESSION),
            output=OutputGrid.from_time(dt, float(record.t_contact)),
        )
    except AnalysisError:
        return None
    return elastic_phase(model, replay)


def with_contact_point(columns: Sequence[str], rows: np.ndarray, record: Impact) -> np.ndarray:
    """The trace with its first point at contact (δ = 0, no force, the velocities and
    energies before impact from the record): the kernel records points at step ends, so the
    phase boundaries it crosses are there, but the contact itself is not."""
    col = {name: i for i, name in enumerate(columns)}
    first = np.zeros(len(columns))
    first[col['t']], first[col['phase']] = record.t_contact, 1
    first[col['v_x']], first[col['v_y']] = record.v_before[:2]
    for i, energy in enumerate(record.T_before[:-1]):
        if f'T{i + 1}' in col:
            first[col[f'T{i + 1}']] = energy
    if len(rows) and rows[0][col['t']] <= record.t_contact:
        return rows
    return np.vstack([first[None, :], rows])


def impact_points(
    run: Run, k: int, progress: Callable[[str], Any] = _quiet
) -> tuple[ImpactPoints | None, ContactConstants | None]:
    """(columns, rows, record, note) of impact ``k`` for Figures 8-11, and the contact
    constants of the surface it struck (None without a scene). From /impact_trace when the
    file has it (offline recordings); otherwise integrated again from /impact_report's
    contact state (live recordings), the note saying so; (None, None) if neither."""
    record = run.impacts[k - 1] if 0 < k <= len(run.impacts) else None
    constants = None
    if run.scene is not None and record is not None:
        constants = _struck_surface(run.scene, record)
    if run.traces and 0 < k <= len(run.traces):
        columns, rows = run.traces[k - 1]
        if record is None:
            record = _record_from_trace(columns, rows, k)
        return (columns, with_contact_point(columns, rows, record), record, ''), constants
    if record is None or trace_missing_reason(run):
        return None, constants
    assert run.scene is not None  # trace_missing_reason refuses a recording without one
    progress(f'integrating impact {k} again from its /impact_report (no /impact_trace)')
    guess = rates_before(run, float(record.t_contact))
    (columns, rows), made = reintegrated_trace(run.scene, record, guess)
    worst = max(
        abs(getattr(made, key) / getattr(record, key) - 1)
        for key in ('delta_m', 'F_max', 'duration')
    )
    note = (
        f're-integrated from /impact_report (no /impact_trace in the file); δm, F_max '
        f'and duration within {max(worst, 1e-12):.0e} of the report'
    )
    return (columns, with_contact_point(columns, rows, record), record, note), constants


def _struck_surface(scene: Scene, record: Impact) -> ContactConstants | None:
    """Contact constants of the surface the tip met at contact (the nearest height)."""
    from ...physics.model import ArmModel

    model = ArmModel(scene)
    if not model.surfaces:
        return None
    q = np.radians(np.asarray(record.q_contact_deg, float))
    y_tip = float(model.tip(q, np.zeros_like(q))[1])
    return min(model.surfaces, key=lambda s: abs(s.height - y_tip)).constants


def _record_from_trace(columns: Sequence[str], rows: np.ndarray, k: int) -> Impact:
    """The record fields the figures need, read off a trace without its report: its number,
    contact time, tip velocity and link energies before, δm, δr and F_max. What a trace does
    not give is NaN, or empty for the angles and the energies after (so nothing integrates
    it again: ``elastic_curve``)."""
    col = {name: rows[:, i] for i, name in enumerate(columns)}
    energies = [float(col[c][0]) for c in columns if c.startswith('T') and c[1:].isdigit()]
    nan = math.nan
    return Impact(
        index=k,
        t_contact=float(col['t'][0]),
        q_contact_deg=(),
        joints_contact_deg=(),
        duration=nan,
        delta_m=float(np.max(col['delta'])),
        delta_r=float(col['delta'][-1]),
        F_max=float(np.max(col['F_n'])),
        v_before=(float(col['v_x'][0]), float(col['v_y'][0])),
        v_after=(nan, nan),
        cor_kinematic=nan,
        T_before=(*energies, sum(energies)),
        T_after=(),
        cor_energetic=(),
        phase_durations=(nan, nan, nan),
        q_max_compression_deg=(),
        q_separation_deg=(),
    )
