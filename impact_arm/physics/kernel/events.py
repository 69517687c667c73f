# Kernel part: event functions of the current phase and the location of their zero crossings
# (physics/roots.py's ``locate_crossing``, shared with the free body's kernel: Newton on real
# steps inside an Illinois bracket).
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
from ..contact_phases import phase_events
from ..jit import jit
from ..layout import *
from ..roots import event_tolerance, locate_crossing
from .injected import *
from .rhs import surface_level, surface_rate
from .steps import trial_step
# --- template: equations.py copies what follows into the generated module ---


@jit
def event_values(y, P, I, SURF, C, levels, g):
    """Event functions of the current phase; a switch happens when one rises through zero.
    Slots that are not armed in this phase hold -1."""
    ns = SURF.shape[0]
    for k in range(g.shape[0]):
        g[k] = -1.0
    tip_state = tip(y[:N], y[N : 2 * N], P[P_L : P_L + NL])
    y_tip = tip_state[1]
    phase = int(C[C_PHASE])
    if phase == FREE:
        for s in range(ns):
            delta = surface_level(y, SURF, levels, s) - y_tip
            g[s] = phase_events(FREE, int(SURF[s, S_LAW]), delta, 0.0, 0.0, 0.0)[0]
        if (I[I_LAW] == LAW_Q or I[I_LAW] == LAW_PID) and C[C_MODE] > 0.5:
            g[ns + EV_SWITCH] = y_tip - P[P_SWITCH]
        return
    s = int(C[C_SURF])
    delta = surface_level(y, SURF, levels, s) - y_tip
    # δ̇ = ż - ẏ_B (ż: the plate's rate, 0 on a rigid mount) turns from + to -
    closing = tip_state[3] - surface_rate(y, SURF, s) if HAS_MOUNT else tip_state[3]
    _, yielding, maximum, separation = phase_events(
        phase, int(SURF[s, S_LAW]), delta, closing, SURF[s, S_DC], C[C_DR]
    )
    g[ns + EV_YIELD], g[ns + EV_MAX], g[ns + EV_SEP] = yielding, maximum, separation


@jit
def event_rate(y, f, k, P, SURF, C):
    """Time derivative of event function k at state y with derivative f (for Newton)."""
    ns = SURF.shape[0]
    L = P[P_L : P_L + NL]
    vy = tip(y[:N], y[N : 2 * N], L)[3]
    if HAS_MOUNT:
        # the surface's plate moves: δ̇ = ż - ẏ_B, and at maximum compression z̈ counts
        s = k if k < ns else int(C[C_SURF])
        plate = int(SURF[s, S_MOUNT]) if s >= 0 else -1
        zd = y[plate + 1] if plate >= 0 else 0.0
        if k < ns or k == ns + EV_YIELD:
            return zd - vy
        if k == ns + EV_MAX:
            zdd = f[plate + 1] if plate >= 0 else 0.0
            return tip_acceleration(y[:N], y[N : 2 * N], f[N : 2 * N], L)[1] - zdd
        if k == ns + EV_SEP:
            return vy - zd
        return vy  # switch height
    if k < ns or k == ns + EV_YIELD:
        return -vy  # δ grows as the tip moves down
    if k == ns + EV_MAX:
        return tip_acceleration(y[:N], y[N : 2 * N], f[N : 2 * N], L)[1]
    return vy  # switch height, separation


@jit
def step_to(
    s, t, y0, f0, y_out, f_tmp, err, K, work, g, P, I, SURF, C, levels, tau_held, stats, W, JW
):
    """``locate_crossing``'s trial: the real step of size s from (t, y0) into y_out, f_tmp."""
    trial_step(
        t, y0, f0, s, y_out, f_tmp, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW
    )


@jit
def event_at(
    k, t, y0, f0, y_out, f_tmp, err, K, work, g, P, I, SURF, C, levels, tau_held, stats, W, JW
):
    """``locate_crossing``'s event function k at the trial state."""
    event_values(y_out, P, I, SURF, C, levels, g)
    return g[k]


@jit
def event_rate_at(
    k, t, y0, f0, y_out, f_tmp, err, K, work, g, P, I, SURF, C, levels, tau_held, stats, W, JW
):
    """``locate_crossing``'s ġ_k at the trial state, from the step's end derivative."""
    return event_rate(y_out, f_tmp, k, P, SURF, C)


@jit
def locate(
    t,
    y0,
    f0,
    h,
    k,
    ga,
    gb,
    y_out,
    f_tmp,
    err,
    K,
    work,
    g,
    P,
    I,
    SURF,
    C,
    levels,
    tau_held,
    stats,
    W,
    JW,
):
    """Smallest s in (0, h] with g_k(RK step of size s) >= 0; y_out holds the state there
    (``locate_crossing``, Newton inside an Illinois bracket)."""
    # a tighter tolerance took 5-8 extra real steps at each yield and separation of the
    # article's impacts, bisecting rounding noise
    tol = event_tolerance(h, t)
    args = (t, y0, f0, y_out, f_tmp, err, K, work, g, P, I, SURF, C, levels, tau_held, stats, W, JW)
    return locate_crossing(step_to, event_at, event_rate_at, k, h, ga, gb, tol, args)
