# Kernel part: the contact phase machine (physics/contact_phases.py's, shared with the free
# body's kernel) applied to the arm: what each located event switches (apply_event), the
# controller's cycle half, and the impulse, peak force and trace booked at each contact point.
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
import numpy as np

from ..contact_phases import max_compression
from ..jit import jit
from ..layout import *
from .injected import *
from .rhs import contact_forces, integral_states, plate_displacement
# --- template: equations.py copies what follows into the generated module ---


@jit
def record_point(t, y, P, I, SURF, C, levels, trace, tcount, y_mid):
    """Peak force, contact impulse since the previous point and (optionally) a trace row at a
    contact point. The impulse is Simpson's rule with the force at ``y_mid``, the state midway
    (from the step's continuous extension): the trapezoid rule read 1 % low on the article's
    impacts at rtol 1e-5 (the force pulse is concave), Simpson's follows the step's accuracy."""
    delta, fn, ff, vx, vy = contact_forces(y, P, SURF, C, levels)
    if fn > C[C_PEAK]:
        C[C_PEAK] = fn
    if fn > C[C_PERIOD_PEAK]:
        C[C_PERIOD_PEAK] = fn
    dt = t - C[C_IMP_T]
    _, fn_mid, ff_mid, _, _ = contact_forces(y_mid, P, SURF, C, levels)
    C[C_JT] += (ff + 4.0 * ff_mid + C[C_IMP_FF]) * dt / 6.0
    C[C_JN] += (fn + 4.0 * fn_mid + C[C_IMP_FN]) * dt / 6.0
    C[C_IMP_T], C[C_IMP_FF], C[C_IMP_FN] = t, ff, fn
    if I[I_TRACE] != 0 and tcount[0] < trace.shape[0]:
        row = trace[tcount[0]]
        row[TR_T], row[TR_PHASE], row[TR_DELTA] = t, C[C_PHASE], delta
        row[TR_FN], row[TR_FF], row[TR_VX], row[TR_VY] = fn, ff, vx, vy
        energies = link_energies(y[:N], y[N : 2 * N], P[P_L : P_L + NL], P[P_M : P_M + N])
        previous = 0.0
        for i in range(N):
            # a joint's rotor (armature) turns with its link: its energy is booked there
            omega = y[N + i] - previous
            previous = y[N + i]
            row[TR_ENERGY + i] = energies[i] + 0.5 * P[P_ARM + i] * omega * omega
        tcount[0] += 1
    return delta


@jit
def set_mode(mode, y, C):
    """Cycle half of the continuous controller (0 down, 1 up); integral states restart with
    the new target."""
    C[C_MODE] = mode
    for i in range(2 * N, 2 * N + integral_states(y)):
        y[i] = 0.0


@jit
def apply_event(slot, t, y, P, I, SURF, C, levels, info):
    """Switch the phase machine at event ``slot`` (state y at time t): phase, restitution
    parameters, the dent, the controller's cycle half. ``info`` gets (δm, Pm, δr, Rr) at
    maximum compression and (F_max, δm, δr) at separation. Returns False, with δm, Pm, δr in
    C, when the residual indentation falls outside [0, δm): beyond its fit's range."""
    ns = SURF.shape[0]
    for i in range(info.shape[0]):
        info[i] = 0.0
    if slot < ns:
        C[C_PHASE], C[C_SURF], C[C_PEAK] = ELASTIC, slot, 0.0
        C[C_IMP_T], C[C_IMP_FF], C[C_IMP_FN] = t, 0.0, 0.0
        if (I[I_LAW] == LAW_Q or I[I_LAW] == LAW_PID) and C[C_MODE] <= 0.5:
            set_mode(1.0, y, C)  # struck: the cycle turns upward
        return True
    kind = slot - ns
    if kind == EV_SWITCH:
        set_mode(0.0, y, C)
        return True
    s = int(C[C_SURF])
    if kind == EV_YIELD:
        C[C_PHASE] = ELASTOPLASTIC
    elif kind == EV_MAX:
        delta, fn, _, _, _ = contact_forces(y, P, SURF, C, levels)
        # the arm's laws have no restitution coefficient (no constant-CoR surface): cor 0
        dr, rr, valid = max_compression(
            int(SURF[s, S_LAW]), delta, fn, SURF[s, S_E], SURF[s, S_DC], 0.0
        )
        C[C_DM], C[C_PM], C[C_DR] = delta, fn, dr
        if not valid:
            return False
        C[C_RR] = rr
        C[C_PEAK] = max(C[C_PEAK], fn)
        C[C_PHASE] = RESTITUTION
        info[0], info[1], info[2], info[3] = delta, fn, dr, C[C_RR]
    elif kind == EV_SEP:
        # keep the dent: a re-strike before the tip leaves it meets the dent's floor.
        # The contact event fires when level - y_B rises through zero from below; the
        # located separation leaves y_B on the new level to rounding, and a +1e-20 there
        # made the next contact undetectable (the tip of a controller pressing down
        # tunnelled through the floor). Keep the level strictly below the tip.
        y_tip = tip(y[:N], y[N : 2 * N], P[P_L : P_L + NL])[1]
        if HAS_MOUNT:
            # the dent is in the plate: its level is kept in the plate's frame
            z = plate_displacement(y, SURF, s)
            y_rel = y_tip - z
            scale = max(abs(y_tip), abs(z))
            levels[s] = min(levels[s] - C[C_DR], y_rel - 4.0 * np.spacing(scale))
        else:
            levels[s] = min(levels[s] - C[C_DR], y_tip - 4.0 * np.spacing(abs(y_tip)))
        info[0], info[1], info[2] = C[C_PEAK], C[C_DM], C[C_DR]
        C[C_PHASE], C[C_SURF] = FREE, -1.0
    return True
