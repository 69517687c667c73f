# Kernel part: the right-hand side ẏ = f(y): equations of motion, contact forces of the current
# phase, the continuous control law or the held torque.
# Template text (see kernel/__init__.py): the imports above the marker are for
# linters and editors only: the generated module's header provides those names.
# flake8: noqa: F401,F403,F405
import math

from ..contact import friction_force, phase_normal_force
from ..control import add_joint_torques, pid_error, pid_law, q_law
from ..jit import jit, jit_leaf
from ..layout import *
from .injected import *
# --- template: equations.py copies what follows into the generated module ---


@jit_leaf
def integral_states(y):
    """PID integral states in the state y: N for a continuous PID, else 0. The model sizes
    the state (``ArmModel.size``), so this is a value read from its length, not a kernel
    shape; the mounted plates' z, ż come after them."""
    return y.shape[0] - 2 * N - 2 * NM


@jit
def solve_mass_matrix(q, qd, generalized, P, out, S):
    """q̈ into ``out`` from the mass matrix, with the joints' armature added (zero is off):
    M q̈ = b with M symmetric positive definite (it is a kinetic energy): M into S and b into
    out, Cholesky M = G G^T in place in S (row-major, lower triangle), then two triangular
    solves in place in out. S is N*N scratch (no allocation here). Compiled once and called:
    the closed-form path of a short arm needs it only when a joint has armature."""
    mass_and_rhs_into(q, qd, generalized, P[P_L : P_L + NL], P[P_M : P_M + N], P[P_G], S, out)
    if P[P_ARM_ON] != 0.0:
        # a rotor J_k turns at the joint's relative rate ω_k = q̇_k - q̇_(k-1): its energy
        # ½ J_k ω_k² adds J_k (e_k - e_(k-1)) (e_k - e_(k-1))^T to M, and nothing to the
        # velocity terms (ω is linear in q̇ with constant coefficients)
        for k in range(N):
            J = P[P_ARM + k]
            S[k * N + k] += J
            if k > 0:
                S[(k - 1) * N + k - 1] += J
                S[k * N + k - 1] -= J
                S[(k - 1) * N + k] -= J
    for i in range(N):
        for j in range(i + 1):
            s = S[i * N + j]
            for k in range(j):
                s -= S[i * N + k] * S[j * N + k]
            if i == j:
                S[i * N + i] = math.sqrt(s)
            else:
                S[i * N + j] = s / S[j * N + j]
    for i in range(N):
        s = out[i]
        for k in range(i):
            s -= S[i * N + k] * out[k]
        out[i] = s / S[i * N + i]
    for i in range(N - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, N):
            s -= S[k * N + i] * out[k]
        out[i] = s / S[i * N + i]


@jit_leaf
def accelerations(q, qd, generalized, P, out, S):
    """q̈ into ``out``; S is N*N scratch for the general case (no allocation here)."""
    L = P[P_L : P_L + NL]
    m = P[P_M : P_M + N]
    if HAS_ACCEL:
        if P[P_ARM_ON] == 0.0:
            values = accel(q, qd, generalized, L, m, P[P_G])
            for i in range(N):
                out[i] = values[i]
        else:  # the closed form has no armature in it
            solve_mass_matrix(q, qd, generalized, P, out, S)
    else:
        solve_mass_matrix(q, qd, generalized, P, out, S)


@jit_leaf
def add_joint_friction(qd, P, generalized):
    """The joints' viscous damping and smoothed Coulomb friction into the generalized forces.
    Each acts on its joint's relative rate ω_i = q̇_i - q̇_(i-1) as a torque
    τ_i = -(d_i ω_i + f_i tanh(ω_i / v_i)) of link i-1 on link i, mapped like a motor's
    (Q_i += τ_i, Q_(i-1) -= τ_i). It is not part of the control torque: a driver reports
    what its motors apply, not what its bearings take."""
    previous = 0.0
    for i in range(N):
        omega = qd[i] - previous
        previous = qd[i]
        tau = -P[P_DAMP + i] * omega
        if P[P_FRIC + i] != 0.0:
            tau -= P[P_FRIC + i] * math.tanh(omega / P[P_FVD + i])
        generalized[i] += tau
        if i > 0:
            generalized[i - 1] -= tau


@jit_leaf
def plate_displacement(y, SURF, s):
    """z of surface s's plate from its rest height (0 when rigidly mounted)."""
    if HAS_MOUNT:
        k = int(SURF[s, S_MOUNT])
        if k >= 0:
            return y[k]
    return 0.0


@jit_leaf
def surface_level(y, SURF, levels, s):
    """Height of surface s where the tip meets it now: its level (lowered by a dent), moved
    with its plate's displacement z when it is mounted."""
    if HAS_MOUNT:
        k = int(SURF[s, S_MOUNT])
        if k >= 0:
            return levels[s] + y[k]
    return levels[s]


@jit_leaf
def surface_rate(y, SURF, s):
    """ż of surface s's plate (0 when rigidly mounted)."""
    if HAS_MOUNT:
        k = int(SURF[s, S_MOUNT])
        if k >= 0:
            return y[k + 1]
    return 0.0


@jit_leaf
def contact_forces(y, P, SURF, C, levels):
    """(δ, F_n, F_f, ẋ_B) of the current contact phase (never free: the callers are in
    contact). The surface's law is in the phase: ``phase_normal_force`` dispatches it."""
    L = P[P_L : P_L + NL]
    tip_state = tip(y[:N], y[N : 2 * N], L)
    s = int(C[C_SURF])
    phase = int(C[C_PHASE])
    delta = surface_level(y, SURF, levels, s) - tip_state[1]
    fn = phase_normal_force(
        phase,
        delta,
        SURF[s, S_E],
        SURF[s, S_R],
        SURF[s, S_SY],
        SURF[s, S_CJ],
        SURF[s, S_DC],
        SURF[s, S_PC],
        SURF[s, S_B],
        C[C_DR],
        C[C_RR],
    )
    ff = 0.0
    if SURF[s, S_MU] > 0:
        ff = friction_force(fn, tip_state[2], SURF[s, S_MU], SURF[s, S_VD])
    return delta, fn, ff, tip_state[2], tip_state[3]


@jit
def solve_accelerations(q, qd, generalized, P, out, S):
    """``accelerations`` compiled once and called: for ``contact_frequency``, which needs it
    twice per contact step only; each inlined copy of the equations of motion costs
    seconds of compilation for a new arm shape."""
    accelerations(q, qd, generalized, P, out, S)


@jit
def contact_frequency(y, P, SURF, C, levels, work):
    """ω [1/s] of the contact's normal oscillation at state y: sqrt(k / m_eff), with the
    stiffness k = dF_n/dδ bounded by 1.5 F_n / (δ - δ_0) (every force law here grows like
    (δ - δ_0)^p, p <= 1.5; δ_0 = δr in restitution) and 1/m_eff = J_y M⁻¹ J_yᵀ, the tip's
    vertical acceleration per newton (two solves with the mass matrix). 0 without force.
    ``work``: 4 N + N * N scratch."""
    delta, fn, _, _, _ = contact_forces(y, P, SURF, C, levels)
    base = C[C_DR] if int(C[C_PHASE]) == RESTITUTION else 0.0
    if not fn > 0.0 or not delta > base:
        return 0.0
    q = y[:N]
    jac = tip_jacobian(q, P[P_L : P_L + NL])
    zero, gen, a1, a0 = work[:N], work[N : 2 * N], work[2 * N : 3 * N], work[3 * N : 4 * N]
    for i in range(N):
        zero[i] = 0.0
        gen[i] = jac[N + i]
    solve_accelerations(q, zero, gen, P, a1, work[4 * N :])
    for i in range(N):
        gen[i] = 0.0
    solve_accelerations(q, zero, gen, P, a0, work[4 * N :])
    inverse_mass = 0.0
    for i in range(N):
        inverse_mass += jac[N + i] * (a1[i] - a0[i])
    if HAS_MOUNT:
        s = int(C[C_SURF])
        if SURF[s, S_MOUNT] >= 0:
            inverse_mass += 1.0 / SURF[s, S_MM]  # the plate recoils too: two masses in series
    return math.sqrt(max(0.0, 1.5 * fn / (delta - base) * inverse_mass))


@jit_leaf
def control_torque(y, P, I, C, tau_held, tau, error, rate):
    """Joint torques acting now into ``tau``; False when the actuators are off."""
    if int(C[C_PHASE]) != FREE and I[I_ACT] == 0:
        return False
    law = I[I_LAW]
    if law == LAW_NONE:
        return False
    if law == LAW_HELD:
        for i in range(N):
            tau[i] = tau_held[i]
        return True
    q = y[:N]
    qd = y[N : 2 * N]
    target = P[P_TUP : P_TUP + N] if C[C_MODE] > 0.5 else P[P_TDOWN : P_TDOWN + N]
    if law == LAW_Q:
        q_law(
            q,
            qd,
            target,
            P[P_KP : P_KP + N],
            P[P_KD : P_KD + N],
            gravity_forces(q, P[P_L : P_L + NL], P[P_M : P_M + N], P[P_G]),
            tau,
        )
        return True
    pid_error(q, qd, target, I[I_SPACE] == 1, error, rate)
    if integral_states(y) > 0:
        pid_law(
            error,
            rate,
            y[2 * N : 3 * N],
            P[P_KP : P_KP + N],
            P[P_KD : P_KD + N],
            P[P_KI : P_KI + N],
            tau,
        )
    else:
        for i in range(N):  # no integral state: PD (the Ki term has nothing to act on)
            tau[i] = -P[P_KD + i] * rate[i] - P[P_KP + i] * error[i]
    return True


@jit
def rhs(t, y, out, P, I, SURF, C, levels, tau_held, stats, W):
    """ẏ into ``out``. W is scratch space (SCRATCH, layout W_*) so the hot loop never
    allocates."""
    stats[ST_RHS] += 1
    q = y[:N]
    qd = y[N : 2 * N]
    generalized = W[W_GEN : W_GEN + N]
    tau = W[W_TAU : W_TAU + N]
    error = W[W_ERR : W_ERR + N]
    rate = W[W_RATE : W_RATE + N]
    for i in range(N):
        generalized[i] = 0.0
    fn = 0.0
    if int(C[C_PHASE]) != FREE:
        delta, fn, ff, vx, vy = contact_forces(y, P, SURF, C, levels)
        jac = tip_jacobian(q, P[P_L : P_L + NL])
        for i in range(N):
            generalized[i] += jac[i] * ff + jac[N + i] * fn
    acting = control_torque(y, P, I, C, tau_held, tau, error, rate)
    if acting:
        add_joint_torques(tau, generalized)
    if P[P_JFRIC_ON] != 0.0:
        add_joint_friction(qd, P, generalized)
    for i in range(N):
        out[i] = qd[i]
    accelerations(q, qd, generalized, P, out[N : 2 * N], W[W_MASS:])
    ni = integral_states(y)
    if ni > 0:
        # the integral runs only while the controller acts (it is off during contact);
        # control_torque left the PID error in ``error``
        for i in range(ni):
            out[2 * N + i] = error[i] if acting else 0.0
    if HAS_MOUNT:
        # each plate on its spring-damper about rest; the one struck carries the contact force
        struck = int(C[C_SURF]) if int(C[C_PHASE]) != FREE else -1
        for s in range(SURF.shape[0]):
            k = int(SURF[s, S_MOUNT])
            if k >= 0:
                force = -SURF[s, S_MK] * y[k] - SURF[s, S_MC] * y[k + 1]
                if s == struck:
                    force -= fn
                out[k] = y[k + 1]
                out[k + 1] = force / SURF[s, S_MM]
