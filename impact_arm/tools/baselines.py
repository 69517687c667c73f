"""The same scene integrated by scipy's ``solve_ivp`` (RK45 = MATLAB's ode45, DOP853, LSODA,
Radau) with terminal events, restarting at every phase switch exactly as the article does.

Used only by benchmarks, as the baseline our integrator is measured against. It shares the
model, the right-hand side and the phase machine's transitions with ``PhaseIntegrator``, so the
two differ only in how they step and locate events.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
from scipy.integrate import solve_ivp

from ..physics import layout
from ..physics.cycle_count import CycleCount
from ..physics.integrator import Event, PhaseIntegrator
from ..physics.impact import Impact
from ..physics.metrics import ImpactBuilder
from ..physics.model import ArmModel, Phase
from ..physics.scene import Scene

SCIPY_METHODS = ('RK45', 'DOP853', 'LSODA', 'Radau')


def _armed_slots(integ: PhaseIntegrator) -> list[int]:
    """Event slots that can fire in the current phase (the others hold a constant -1)."""
    st, n_surf = integ.state, len(integ.model.surfaces)
    if st.phase == Phase.FREE:
        slots = list(range(n_surf))
        if integ._I[layout.I_LAW] in (layout.LAW_Q, layout.LAW_PID) and st.mode == 'up':
            slots.append(n_surf + layout.EV_SWITCH)
        return slots
    if st.phase == Phase.ELASTIC:
        yields = integ.model.surfaces[st.surface].law == 'elastoplastic'
        return ([n_surf + layout.EV_YIELD] if yields else []) + [n_surf + layout.EV_MAX]
    if st.phase == Phase.ELASTOPLASTIC:
        return [n_surf + layout.EV_MAX]
    return [n_surf + layout.EV_SEP]


_Event = TypeVar('_Event', bound=Callable[..., Any])


def _terminal_rising(event: _Event) -> _Event:
    """Mark ``event`` for solve_ivp as stopping the integration at a rising zero crossing:
    solve_ivp reads these two attributes of the function itself."""
    event.terminal = True  # type: ignore[attr-defined]  # solve_ivp's event attributes
    event.direction = 1.0  # type: ignore[attr-defined]
    return event


def run_scipy(
    scene: Scene,
    method: str = 'RK45',
    rtol: float = 1e-6,
    atol: float | None = None,
    t_max: float | None = None,
    contact_rtol: float | None = None,
) -> tuple[list[Impact], float, int, float]:
    """Run ``scene`` for its cycles with solve_ivp; returns (impacts, t_end, nfev, wall).
    ``contact_rtol`` (default rtol) is the tolerance of contact phases, as in PhaseIntegrator;
    the contact atol keeps the atol/rtol ratio."""
    model = ArmModel(scene)
    atol = rtol * 1e-2 if atol is None else atol
    # the integrator derives the contact atol exactly as for our own runs
    integ = PhaseIntegrator(
        model, control='continuous', rtol=rtol, atol=atol, contact_rtol=contact_rtol
    )
    contact_rtol, contact_atol = integ.contact_rtol, integ.contact_atol
    st = integ.state
    builder = ImpactBuilder(model)
    t_max = scene.t_max if t_max is None else t_max
    g = np.zeros(len(model.surfaces) + 4)
    eq, P, I, surf = model.eq, integ._P, integ._I, model.surface_table
    nfev = 0
    count = CycleCount(scene.cycles)  # completed at each switch, as in our own event path
    wall0 = time.perf_counter()

    def make_event(slot: int) -> Callable[[float, np.ndarray], float]:
        def event(t: float, y: np.ndarray) -> float:
            eq.event_values(y, P, I, surf, st.c, st.levels, g)
            return g[slot]

        return _terminal_rising(event)

    L = model.geometry
    heights = [s.height for s in model.surfaces]

    def make_rise(s: int) -> Callable[[float, np.ndarray], float]:
        # the kernel forgets a surface's dent once the tip is back above the surface
        def event(t: float, y: np.ndarray) -> float:
            return eq.tip(y[: model.n], y[model.n : 2 * model.n], L)[1] - heights[s]

        return _terminal_rising(event)

    while st.t < t_max and not count.done:
        slots = _armed_slots(integ)
        if st.phase == Phase.FREE:
            slots += [-1 - s for s in range(len(heights)) if st.levels[s] != heights[s]]
        free = st.phase == Phase.FREE
        sol = solve_ivp(
            integ.rhs,
            (st.t, t_max),
            st.y,
            method=method,
            rtol=rtol if free else contact_rtol,
            atol=atol if free else contact_atol,
            events=[make_event(s) if s >= 0 else make_rise(-1 - s) for s in slots],
        )
        nfev += sol.nfev
        if sol.status == -1:
            raise RuntimeError(f'solve_ivp {method} failed at t = {sol.t[-1]}: {sol.message}')
        fired = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
        if not fired:
            st.t, st.y = float(sol.t[-1]), sol.y[:, -1].copy()
            break
        t_event, i = min(fired)
        st.t, st.y = float(t_event), sol.y_events[i][0].copy()
        if slots[i] < 0:
            st.levels[-1 - slots[i]] = heights[-1 - slots[i]]
            continue
        kind, surface, info = integ._apply_event(slots[i])
        event = Event(kind, st.t, surface, st.y.copy(), info)
        count.on_event(event)
        builder.feed(event)
    return builder.impacts, st.t, nfev, time.perf_counter() - wall0
