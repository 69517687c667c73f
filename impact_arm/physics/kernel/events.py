# Kernel part: event functions of the current phase and the location of their zero crossings
# (Newton on real steps inside an Illinois bracket; the bracket is physics/roots.py's, shared
# with the free body's kernel).
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
from ..contact import YIELD_ONSET_FACTOR as YIELD_ONSET  # the header's name for it
from ..jit import jit
from ..layout import *
from ..roots import event_tolerance, false_position, illinois_update
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
            g[s] = surface_level(y, SURF, levels, s) - y_tip
        if (I[I_LAW] == LAW_Q or I[I_LAW] == LAW_PID) and C[C_MODE] > 0.5:
            g[ns + EV_SWITCH] = y_tip - P[P_SWITCH]
        return
    s = int(C[C_SURF])
    delta = surface_level(y, SURF, levels, s) - y_tip
    # δ̇ = ż - ẏ_B (ż: the plate's rate, 0 on a rigid mount) turns from + to -
    closing = tip_state[3] - surface_rate(y, SURF, s) if HAS_MOUNT else tip_state[3]
    if phase == ELASTIC:
        if SURF[s, S_LAW] == 0:
            g[ns + EV_YIELD] = delta - YIELD_ONSET * SURF[s, S_DC]
        g[ns + EV_MAX] = closing
    elif phase == ELASTOPLASTIC:
        g[ns + EV_MAX] = closing
    else:
        g[ns + EV_SEP] = C[C_DR] - delta  # δ falls through δr


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
    """Smallest s in (0, h] with g_k(RK step of size s) >= 0; y_out holds the state there.

    Newton's method on real Runge-Kutta steps (the step's FSAL derivative gives ġ for free),
    kept inside a shrinking bracket and falling back to Illinois regula falsi when a Newton
    step would leave it."""
    a, b = 0.0, h
    fa, fb = ga, gb
    side = 0
    # a tighter tolerance took 5-8 extra real steps at each yield and separation of the
    # article's impacts, bisecting rounding noise
    tol = event_tolerance(h, t)
    c = false_position(a, b, fa, fb)
    for _ in range(100):
        if not (a < c < b):  # a converged Newton step nudged onto an end of the bracket
            c = 0.5 * (a + b)
        trial_step(
            t, y0, f0, c, y_out, f_tmp, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW
        )
        event_values(y_out, P, I, SURF, C, levels, g)
        fc = g[k]
        a, b, fa, fb, side = illinois_update(a, b, fa, fb, side, c, fc)
        if fc == 0.0 or b - a <= tol:
            break
        rate = event_rate(y_out, f_tmp, k, P, SURF, C)
        newton = c - fc / rate if rate != 0.0 else -1.0
        if abs(newton - c) <= tol:
            # converged: step just past the root so the event has really happened
            c = min(b, newton + tol)
            if c == b:
                break
            continue
        if a < newton < b:
            c = newton
        else:
            c = false_position(a, b, fa, fb)
    if b != c:
        trial_step(
            t, y0, f0, b, y_out, f_tmp, err, K, work, P, I, SURF, C, levels, tau_held, stats, W, JW
        )
    return b
