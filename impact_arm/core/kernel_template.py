# flake8: noqa
# Template, not imported directly: equations.py appends this text to the module it generates
# for one scene shape, after the constants (N, NI, HAS_CONTACT, HAS_FRICTION, P_* offsets) and
# the sympy-generated functions (tip, tip_jacobian, gravity_forces, link_energies, accel or
# mass_and_rhs). Written in the numba-compatible subset of Python: compiled with numba when it
# is available, interpreted otherwise. Module-level constants are compile-time constants for
# numba, so a scene without contact or friction has no contact code in its hot loop at all.
#
# The stepped phase integrator kernel: Dormand-Prince 5(4) with error control (or, in free
# flight when I_METHOD asks for it, a linearly implicit Rosenbrock 4(3) step: the controller
# makes the free flight stiff); every step is checked for sign changes of the phase's event
# functions, and a crossing is located by root-finding on real steps from the step start
# (Newton inside an Illinois bracket), so the state at a switch is as accurate as any step
# end. The kernel applies each switch itself (``apply_event``) and logs it for the Python
# wrapper, which asks it to return only after the kinds of event it needs to act on.

EPS = 2.220446049250313e-16      # unit roundoff of a double
A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = 9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656
B1, B3, B4, B5, B6 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1 = 35 / 384 - 5179 / 57600
E3 = 500 / 1113 - 7571 / 16695
E4 = 125 / 192 - 393 / 640
E5 = -2187 / 6784 + 92097 / 339200
E6 = 11 / 84 - 187 / 2100
E7 = -1 / 40
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
# Dormand-Prince continuous extension of order 4 (Shampine's quartic): over a step of size h,
# y(t + s h) = y + h sum_j b_j(s) k_j, b_j(s) = s^2 (D_j2 + s (D_j3 + s D_j4)) (+ s for j = 1),
# for the stages k_1 = f0, k_3 ... k_6 (K[1] ... K[4]), k_7 = f1 (k_2's weights are zero).
D12, D13, D14 = -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432
D32, D33, D34 = 131558114200 / 32700410799, -68118460800 / 10900136933, \
    87487479700 / 32700410799
D42, D43, D44 = -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072
D52, D53, D54 = 127303824393 / 49829197408, -318862633887 / 49829197408, \
    701980252875 / 199316789632
D62, D63, D64 = -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844
D72, D73, D74 = 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423
# Rosenbrock 4(3), Shampine's parameters (Kaps-Rentrop form, as in Numerical Recipes' stiff):
# four stages, three evaluations, A-stable. The right-hand side has no explicit time
# dependence (the control law switches at located events), so the dF/dt terms vanish.
RGAM = 1 / 2
RA21, RA31, RA32 = 2.0, 48 / 25, 6 / 25
RC21, RC31, RC32 = -8.0, 372 / 25, 12 / 5
RC41, RC42, RC43 = -112 / 125, -54 / 125, -2 / 5
RB1, RB2, RB3, RB4 = 19 / 9, 1 / 2, 25 / 108, 125 / 108
RE1, RE2, RE4 = 17 / 54, 7 / 36, 125 / 108
RA2X, RA3X = 1.0, 3 / 5
FD_STEP = 1.4901161193847656e-08   # sqrt(machine epsilon): finite-difference Jacobian
SCRATCH = 4 * N + N * N   # rhs scratch: generalized forces, torques, PID error and rate, M


@jit_leaf
def accelerations(q, qd, generalized, P, out, S):
    """q̈ into ``out``; S is N*N scratch for the general case (no allocation here)."""
    L = P[P_L:P_L + N]
    m = P[P_M:P_M + N]
    if HAS_ACCEL:
        values = accel(q, qd, generalized, L, m, P[P_G])
        for i in range(N):
            out[i] = values[i]
    else:
        # M q̈ = b with M symmetric positive definite (it is a kinetic energy): Cholesky
        # M = G G^T into S (row-major, lower triangle), then two triangular solves
        values = mass_and_rhs(q, qd, generalized, L, m, P[P_G])
        for i in range(N):
            for j in range(i + 1):
                s = values[i * N + j]
                for k in range(j):
                    s -= S[i * N + k] * S[j * N + k]
                if i == j:
                    S[i * N + i] = math.sqrt(s)
                else:
                    S[i * N + j] = s / S[j * N + j]
        for i in range(N):
            s = values[N * N + i]
            for k in range(i):
                s -= S[i * N + k] * out[k]
            out[i] = s / S[i * N + i]
        for i in range(N - 1, -1, -1):
            s = out[i]
            for k in range(i + 1, N):
                s -= S[k * N + i] * out[k]
            out[i] = s / S[i * N + i]


@jit_leaf
def contact_forces(y, P, SURF, C, levels):
    """(δ, F_n, F_f, ẋ_B) of the current contact phase."""
    L = P[P_L:P_L + N]
    tip_state = tip(y[:N], y[N:2 * N], L)
    s = int(C[C_SURF])
    phase = int(C[C_PHASE])
    delta = levels[s] - tip_state[1]
    if phase == ELASTIC:
        fn = hertz_force(delta, SURF[s, S_E], SURF[s, S_R])
    elif phase == ELASTOPLASTIC:
        fn = jackson_green(delta, SURF[s, S_DC], SURF[s, S_R], SURF[s, S_SY], SURF[s, S_CJ],
                           SURF[s, S_PC], SURF[s, S_B])
    else:
        fn = restitution_force(delta, C[C_DR], SURF[s, S_E], C[C_RR])
    ff = 0.0
    if HAS_FRICTION:
        if SURF[s, S_MU] > 0:
            ff = friction_force(fn, tip_state[2], SURF[s, S_MU], SURF[s, S_VD])
    return delta, fn, ff, tip_state[2], tip_state[3]


@jit_leaf
def control_torque(y, P, I, C, tau_held, tau, error, rate):
    """Joint torques acting now into ``tau``; False when the actuators are off."""
    if HAS_CONTACT:
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
    qd = y[N:2 * N]
    target = P[P_TUP:P_TUP + N] if C[C_MODE] > 0.5 else P[P_TDOWN:P_TDOWN + N]
    if law == LAW_Q:
        qg = gravity_forces(q, P[P_L:P_L + N], P[P_M:P_M + N], P[P_G])
        tail = 0.0
        for i in range(N - 1, -1, -1):
            tail += qg[i]
            tau[i] = -P[P_KD + i] * qd[i] - P[P_KP + i] * (q[i] - target[i]) - tail
        return True
    pid_error(q, qd, target, I[I_SPACE] == 1, error, rate)
    if NI > 0:
        pid_law(error, rate, y[2 * N:2 * N + NI], P[P_KP:P_KP + N], P[P_KD:P_KD + N],
                P[P_KI:P_KI + N], tau)
    else:
        for i in range(N):   # no integral state: PD (the Ki term has nothing to act on)
            tau[i] = -P[P_KD + i] * rate[i] - P[P_KP + i] * error[i]
    return True


@jit
def rhs(t, y, out, P, I, SURF, C, levels, tau_held, stats, W):
    """ẏ into ``out``. W is scratch space (SCRATCH) so the hot loop never allocates."""
    stats[0] += 1
    q = y[:N]
    qd = y[N:2 * N]
    generalized = W[:N]
    tau = W[N:2 * N]
    error = W[2 * N:3 * N]
    rate = W[3 * N:4 * N]
    for i in range(N):
        generalized[i] = 0.0
    if HAS_CONTACT:
        if int(C[C_PHASE]) != FREE:
            delta, fn, ff, vx, vy = contact_forces(y, P, SURF, C, levels)
            jac = tip_jacobian(q, P[P_L:P_L + N])
            for i in range(N):
                generalized[i] += jac[i] * ff + jac[N + i] * fn
    acting = control_torque(y, P, I, C, tau_held, tau, error, rate)
    if acting:
        add_joint_torques(tau, generalized)
    for i in range(N):
        out[i] = qd[i]
    accelerations(q, qd, generalized, P, out[N:2 * N], W[4 * N:])
    if NI > 0:
        # the integral runs only while the controller acts (it is off during contact);
        # control_torque left the PID error in ``error``
        for i in range(NI):
            out[2 * N + i] = error[i] if acting else 0.0


@jit
def rk_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W):
    """One Dormand-Prince step of size h: y1, f1 = f(t+h, y1) (FSAL) and the error vector."""
    size = y.shape[0]
    for i in range(size):
        work[i] = y[i] + h * A21 * f0[i]
    rhs(t + C2 * h, work, K[0], P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        work[i] = y[i] + h * (A31 * f0[i] + A32 * K[0, i])
    rhs(t + C3 * h, work, K[1], P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        work[i] = y[i] + h * (A41 * f0[i] + A42 * K[0, i] + A43 * K[1, i])
    rhs(t + C4 * h, work, K[2], P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        work[i] = y[i] + h * (A51 * f0[i] + A52 * K[0, i] + A53 * K[1, i] + A54 * K[2, i])
    rhs(t + C5 * h, work, K[3], P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        work[i] = y[i] + h * (A61 * f0[i] + A62 * K[0, i] + A63 * K[1, i] + A64 * K[2, i]
                              + A65 * K[3, i])
    rhs(t + h, work, K[4], P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        y1[i] = y[i] + h * (B1 * f0[i] + B3 * K[1, i] + B4 * K[2, i] + B5 * K[3, i]
                            + B6 * K[4, i])
    rhs(t + h, y1, f1, P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(size):
        err[i] = h * (E1 * f0[i] + E3 * K[1, i] + E4 * K[2, i] + E5 * K[3, i] + E6 * K[4, i]
                      + E7 * f1[i])


@jit_leaf
def lu_factor(A, piv):
    """In-place LU with partial pivoting (row k swapped with row piv[k]); False if singular."""
    n = A.shape[0]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                p, big = i, abs(A[i, k])
        piv[k] = p
        if big == 0.0 or not math.isfinite(big):
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
        for i in range(k + 1, n):
            A[i, k] /= A[k, k]
            for j in range(k + 1, n):
                A[i, j] -= A[i, k] * A[k, j]
    return True


@jit_leaf
def lu_solve(A, piv, b):
    """b := A⁻¹ b for A factored by lu_factor."""
    n = A.shape[0]
    for k in range(n):
        p = int(piv[k])
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]


@jit
def ros_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W,
             JW):
    """One Rosenbrock 4(3) step of size h: y1, f1 = f(t+h, y1) and the error vector.

    The free flight is stiff (the controller's damping on the links' small inertia puts an
    eigenvalue near -1000 1/s), which caps an explicit step at ~3 ms whatever the tolerance;
    this linearly implicit step is not capped. JW holds the Jacobian (rows 0..n-1, by finite
    differences at (t, y), kept while JW[2n+1, 0] = 1: a rejected step or an event search
    restarts from the same point), the LU factors of I/(γh) - J (rows n..2n-1) and the
    pivots (row 2n)."""
    n = y.shape[0]
    J = JW[:n]
    LU = JW[n:2 * n]
    piv = JW[2 * n]
    if JW[2 * n + 1, 0] == 0.0:
        for j in range(n):
            for i in range(n):
                work[i] = y[i]
            d = FD_STEP * max(1.0, abs(y[j]))
            work[j] = y[j] + d
            d = work[j] - y[j]             # the step actually representable
            rhs(t, work, f1, P, I, SURF, C, levels, tau_held, stats, W)
            for i in range(n):
                J[i, j] = (f1[i] - f0[i]) / d
        JW[2 * n + 1, 0] = 1.0
    diag = 1.0 / (RGAM * h)
    for i in range(n):
        for j in range(n):
            LU[i, j] = -J[i, j]
        LU[i, i] += diag
    if not lu_factor(LU, piv):
        for i in range(n):
            err[i] = math.inf              # rejected: the caller shrinks the step
        return
    g1, g2, g3, g4, tmp = K[0], K[1], K[2], K[3], K[4]
    for i in range(n):
        g1[i] = f0[i]
    lu_solve(LU, piv, g1)
    for i in range(n):
        work[i] = y[i] + RA21 * g1[i]
    rhs(t + RA2X * h, work, tmp, P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(n):
        g2[i] = tmp[i] + RC21 * g1[i] / h
    lu_solve(LU, piv, g2)
    for i in range(n):
        work[i] = y[i] + RA31 * g1[i] + RA32 * g2[i]
    rhs(t + RA3X * h, work, tmp, P, I, SURF, C, levels, tau_held, stats, W)
    for i in range(n):
        g3[i] = tmp[i] + (RC31 * g1[i] + RC32 * g2[i]) / h
    lu_solve(LU, piv, g3)
    for i in range(n):
        g4[i] = tmp[i] + (RC41 * g1[i] + RC42 * g2[i] + RC43 * g3[i]) / h
    lu_solve(LU, piv, g4)
    for i in range(n):
        y1[i] = y[i] + RB1 * g1[i] + RB2 * g2[i] + RB3 * g3[i] + RB4 * g4[i]
        err[i] = RE1 * g1[i] + RE2 * g2[i] + RE4 * g4[i]
    rhs(t + h, y1, f1, P, I, SURF, C, levels, tau_held, stats, W)


@jit_leaf
def rosenbrock_now(I, C):
    """Whether the current phase steps with Rosenbrock (free flight, when chosen)."""
    return I[I_METHOD] == METHOD_ROSENBROCK and int(C[C_PHASE]) == FREE


@jit
def trial_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W,
               JW):
    """The step of the current phase's method: Rosenbrock in free flight when chosen, else
    Dormand-Prince (contact forces are not smooth enough for a linearly implicit step)."""
    if rosenbrock_now(I, C):
        ros_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats,
                 W, JW)
    else:
        rk_step(t, y, f0, h, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats, W)


@jit
def error_norm(err, y0, y1, rtol, atol):
    total = 0.0
    size = err.shape[0]
    for i in range(size):
        scale = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        total += (err[i] / scale) ** 2
    return math.sqrt(total / size)


@jit
def event_values(y, P, I, SURF, C, levels, g):
    """Event functions of the current phase; a switch happens when one rises through zero.
    Slots that are not armed in this phase hold -1."""
    ns = SURF.shape[0]
    for k in range(g.shape[0]):
        g[k] = -1.0
    tip_state = tip(y[:N], y[N:2 * N], P[P_L:P_L + N])
    y_tip = tip_state[1]
    phase = int(C[C_PHASE])
    if phase == FREE:
        if HAS_CONTACT:
            for s in range(ns):
                g[s] = levels[s] - y_tip
        if (I[I_LAW] == LAW_Q or I[I_LAW] == LAW_PID) and C[C_MODE] > 0.5:
            g[ns + EV_SWITCH] = y_tip - P[P_SWITCH]
        return
    s = int(C[C_SURF])
    delta = levels[s] - y_tip
    if phase == ELASTIC:
        if SURF[s, S_LAW] == 0:
            g[ns + EV_YIELD] = delta - YIELD_ONSET * SURF[s, S_DC]
        g[ns + EV_MAX] = tip_state[3]       # δ̇ = -ẏ_B turns from + to -
    elif phase == ELASTOPLASTIC:
        g[ns + EV_MAX] = tip_state[3]
    else:
        g[ns + EV_SEP] = C[C_DR] - delta    # δ falls through δr


@jit
def record_point(t, y, P, I, SURF, C, levels, trace, tcount, y_mid):
    """Peak force, contact impulse since the previous point and (optionally) a trace row at a
    contact point. The impulse is Simpson's rule with the force at ``y_mid``, the state midway
    (from the step's continuous extension): the trapezoid rule read 1 % low on the article's
    impacts at rtol 1e-5 (the force pulse is concave), Simpson's follows the step's accuracy."""
    delta, fn, ff, vx, vy = contact_forces(y, P, SURF, C, levels)
    if fn > C[C_PEAK]:
        C[C_PEAK] = fn
    dt = t - C[C_IMP_T]
    _, fn_mid, ff_mid, _, _ = contact_forces(y_mid, P, SURF, C, levels)
    C[C_JT] += (ff + 4.0 * ff_mid + C[C_IMP_FF]) * dt / 6.0
    C[C_JN] += (fn + 4.0 * fn_mid + C[C_IMP_FN]) * dt / 6.0
    C[C_IMP_T], C[C_IMP_FF], C[C_IMP_FN] = t, ff, fn
    if I[I_TRACE] != 0 and tcount[0] < trace.shape[0]:
        row = trace[tcount[0]]
        row[0], row[1], row[2], row[3], row[4], row[5], row[6] = t, C[C_PHASE], delta, fn, ff, vx, vy
        energies = link_energies(y[:N], y[N:2 * N], P[P_L:P_L + N], P[P_M:P_M + N])
        for i in range(N):
            row[7 + i] = energies[i]
        tcount[0] += 1
    return delta


@jit
def event_rate(y, f, k, P, SURF):
    """Time derivative of event function k at state y with derivative f (for Newton)."""
    ns = SURF.shape[0]
    L = P[P_L:P_L + N]
    vy = tip(y[:N], y[N:2 * N], L)[3]
    if k < ns or k == ns + EV_YIELD:
        return -vy                       # δ grows as the tip moves down
    if k == ns + EV_MAX:
        return tip_acceleration(y[:N], y[N:2 * N], f[N:2 * N], L)[1]
    return vy                            # switch height, separation


@jit
def locate(t, y0, f0, h, k, ga, gb, y_out, f_tmp, err, K, work, g, P, I, SURF, C, levels,
           tau_held, stats, W, JW):
    """Smallest s in (0, h] with g_k(RK step of size s) >= 0; y_out holds the state there.

    Newton's method on real Runge-Kutta steps (the step's FSAL derivative gives ġ for free),
    kept inside a shrinking bracket and falling back to Illinois regula falsi when a Newton
    step would leave it."""
    a, b = 0.0, h
    fa, fb = ga, gb
    side = 0
    # below a few ulps of t the switch time cannot be told apart (t + s rounds) and the event
    # function sits at its rounding floor: iterating further only bisected noise (5-8 extra
    # real steps at each yield and separation of the article's impacts)
    tol = max(h * 1e-12, 2.0 * EPS * abs(t), 1e-18)
    c = (a * fb - b * fa) / (fb - fa)
    for _ in range(100):
        if not (a < c < b):
            c = 0.5 * (a + b)
        trial_step(t, y0, f0, c, y_out, f_tmp, err, K, work, P, I, SURF, C, levels, tau_held,
                   stats, W, JW)
        event_values(y_out, P, I, SURF, C, levels, g)
        fc = g[k]
        if fc >= 0.0:
            b, fb = c, fc
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a, fa = c, fc
            if side == 1:
                fb *= 0.5
            side = 1
        if fc == 0.0 or b - a <= tol:
            break
        rate = event_rate(y_out, f_tmp, k, P, SURF)
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
            c = (a * fb - b * fa) / (fb - fa)
    if b != c:
        trial_step(t, y0, f0, b, y_out, f_tmp, err, K, work, P, I, SURF, C, levels, tau_held,
                   stats, W, JW)
    return b


@jit
def interpolate(t0, h, ts, y0, f0, y1, f1, K, quartic, out, at):
    """The state at ts in [t0, t0 + h] into out[at:at + size]: the Dormand-Prince quartic
    when K holds this step's stages (``quartic``), else the cubic Hermite of the two ends."""
    size = y0.shape[0]
    s = (ts - t0) / h
    if quartic:
        s2 = s * s
        b1 = s + s2 * (D12 + s * (D13 + s * D14))
        b3 = s2 * (D32 + s * (D33 + s * D34))
        b4 = s2 * (D42 + s * (D43 + s * D44))
        b5 = s2 * (D52 + s * (D53 + s * D54))
        b6 = s2 * (D62 + s * (D63 + s * D64))
        b7 = s2 * (D72 + s * (D73 + s * D74))
        for i in range(size):
            out[at + i] = y0[i] + h * (b1 * f0[i] + b3 * K[1, i] + b4 * K[2, i]
                                       + b5 * K[3, i] + b6 * K[4, i] + b7 * f1[i])
    else:
        h00 = (1.0 + 2.0 * s) * (1.0 - s) ** 2
        h10 = s * (1.0 - s) ** 2
        h01 = s * s * (3.0 - 2.0 * s)
        h11 = s * s * (s - 1.0)
        for i in range(size):
            out[at + i] = h00 * y0[i] + h * h10 * f0[i] + h01 * y1[i] + h * h11 * f1[i]


@jit
def emit_output(t0, h, y0, f0, y1, f1, K, quartic, P, I, C, tau_held, O, out, scratch):
    """Output rows for the grid times k dt in (t0, t0 + h] (k = O[0], dt = O[1]; O[2] rows
    used): t, the state, the contact impulse since the previous row (then reset), the torque
    acting, whether the actuators act, and the tip velocity. False when ``out`` is full."""
    size = y0.shape[0]
    dt = O[1]
    t1 = t0 + h
    eps = 4 * EPS * max(1.0, abs(t1))
    while True:
        ts = O[0] * dt
        if ts > t1 + eps:
            return True
        row_index = int(O[2])
        if row_index >= out.shape[0]:
            return False
        row = out[row_index]
        row[0] = ts
        if abs(ts - t1) <= eps:
            for i in range(size):
                row[1 + i] = y1[i]
        else:
            interpolate(t0, h, ts, y0, f0, y1, f1, K, quartic, row, 1)
        at = 1 + size
        row[at], row[at + 1] = C[C_JT], C[C_JN]
        C[C_JT] = 0.0
        C[C_JN] = 0.0
        state = row[1:1 + size]
        acting = control_torque(state, P, I, C, tau_held, row[at + 2:at + 2 + N],
                                scratch[:N], scratch[N:2 * N])
        row[at + 2 + N] = 1.0 if acting else 0.0
        v = tip(state[:N], state[N:2 * N], P[P_L:P_L + N])
        row[at + 3 + N], row[at + 4 + N] = v[2], v[3]
        O[0] += 1.0
        O[2] += 1.0


@jit_leaf
def phase_tolerances(P, C):
    """(rtol, atol) of the current phase: contact phases have their own (see PhaseIntegrator)."""
    if HAS_CONTACT:
        if int(C[C_PHASE]) != FREE:
            return P[P_CRTOL], P[P_CATOL]
    return P[P_RTOL], P[P_ATOL]


@jit
def initial_step(t, y, f0, P, I, SURF, C, levels, tau_held, stats, W, work, f1):
    """Hairer's starting step size: the phase just entered may be far stiffer than the last."""
    rtol, atol = phase_tolerances(P, C)
    max_step = P[P_MAXSTEP]
    size = y.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(size):
        scale = atol + rtol * abs(y[i])
        d0 += (y[i] / scale) ** 2
        d1 += (f0[i] / scale) ** 2
    d0 = math.sqrt(d0 / size)
    d1 = math.sqrt(d1 / size)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    for i in range(size):
        work[i] = y[i] + h0 * f0[i]
    rhs(t + h0, work, f1, P, I, SURF, C, levels, tau_held, stats, W)
    d2 = 0.0
    for i in range(size):
        scale = atol + rtol * abs(y[i])
        d2 += ((f1[i] - f0[i]) / scale) ** 2
    d2 = math.sqrt(d2 / size) / h0
    if max(d1, d2) <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** 0.2
    return min(100 * h0, h1, max_step)


@jit
def set_mode(mode, y, C):
    """Cycle half of the continuous controller (0 down, 1 up); integral states restart with
    the new target."""
    C[C_MODE] = mode
    for i in range(2 * N, y.shape[0]):
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
            set_mode(1.0, y, C)             # struck: the cycle turns upward
        return True
    kind = slot - ns
    if kind == EV_SWITCH:
        set_mode(0.0, y, C)
        return True
    if HAS_CONTACT:
        s = int(C[C_SURF])
        if kind == EV_YIELD:
            C[C_PHASE] = ELASTOPLASTIC
        elif kind == EV_MAX:
            delta, fn, _, _, _ = contact_forces(y, P, SURF, C, levels)
            dr = residual(delta, SURF[s, S_DC]) if SURF[s, S_LAW] == 0 else 0.0
            C[C_DM], C[C_PM], C[C_DR] = delta, fn, dr
            if not 0.0 <= dr < delta:
                return False
            C[C_RR] = restitution_radius(delta, dr, fn, SURF[s, S_E])
            C[C_PEAK] = max(C[C_PEAK], fn)
            C[C_PHASE] = RESTITUTION
            info[0], info[1], info[2], info[3] = delta, fn, dr, C[C_RR]
        elif kind == EV_SEP:
            # keep the dent: a re-strike before the tip leaves it meets the dent's floor.
            # The contact event fires when level - y_B rises through zero from below; the
            # located separation leaves y_B on the new level to rounding, and a +1e-20 there
            # made the next contact undetectable (the tip of a controller pressing down
            # tunnelled through the floor). Keep the level strictly below the tip.
            y_tip = tip(y[:N], y[N:2 * N], P[P_L:P_L + N])[1]
            levels[s] = min(levels[s] - C[C_DR], y_tip - 4.0 * np.spacing(abs(y_tip)))
            info[0], info[1], info[2] = C[C_PEAK], C[C_DM], C[C_DR]
            C[C_PHASE], C[C_SURF] = FREE, -1.0
    return True


@jit_alloc
def advance(T, t_end, y, f, P, I, SURF, C, levels, tau_held, stats, trace, tcount, ev, evlog,
            O, out):
    """Integrate from T[0] to t_end with step T[1]; y, f updated in place. T[2] != 0 asks
    for f to be recomputed first (new phase, new command); T[1] <= 0 for a fresh step size.
    With O[1] = dt > 0, rows of ``out`` are written at the output times k dt (``emit_output``)
    from each step's continuous extension; contact steps end on those times, so the impulse
    of each output period is exact.

    Every located switch is applied here (``apply_event``) and logged in ``evlog`` (row
    ev[EV_COUNT], layout E_*): the phase machine costs no return to Python. Returns DONE at
    t_end, EVENT right after an event whose kind bit is in ev[EV_MASK], EVENT_LOG_FULL,
    TRACE_FULL or OUTPUT_FULL when a buffer needs draining, or an ERR_* status (ERR_RESIDUAL
    at a maximum compression that ``apply_event`` refused, not logged)."""
    size = y.shape[0]
    ns = SURF.shape[0]
    # the only allocation: scratch for the stepping loop, which itself runs without NRT
    y1, f1, err, work = np.empty(size), np.empty(size), np.empty(size), np.empty(size)
    y_root, f_tmp, K = np.empty(size), np.empty(size), np.empty((5, size))
    W, g0, g1, g_tmp = np.empty(SCRATCH), np.empty(ns + 4), np.empty(ns + 4), np.empty(ns + 4)
    JW, y_prev, scratch = np.zeros((2 * size + 2, size)), np.empty(size), np.empty(2 * N)
    while True:
        status = stepping_loop(T, t_end, y, f, P, I, SURF, C, levels, tau_held, stats, trace,
                               tcount, ev, y1, f1, err, work, y_root, f_tmp, K, W, g0, g1,
                               g_tmp, JW, O, out, y_prev, scratch)
        if status != EVENT:
            return status
        slot = ev[EV_SLOT]
        row = evlog[ev[EV_COUNT]]
        surface = slot if slot < ns else C[C_SURF]
        if not apply_event(slot, T[0], y, P, I, SURF, C, levels, row[E_INFO:E_Y]):
            return ERR_RESIDUAL
        row[E_SLOT], row[E_SURF], row[E_T] = slot, surface, T[0]
        for i in range(size):
            row[E_Y + i] = y[i]
        ev[EV_COUNT] += 1
        T[2] = 1.0                          # the right-hand side changed with the phase
        JW[JW.shape[0] - 1, 0] = 0.0        # and so did its Jacobian (Rosenbrock)
        kind_bit = KIND_BIT_CONTACT if slot < ns else 1 << (1 + slot - ns)
        if slot < ns or slot - ns == EV_SEP or slot - ns == EV_SWITCH:
            # and so did its time scale (or, at a switch, the control target jumped): choose
            # a new step. Across yield and maximum compression the force is (nearly)
            # continuous, so the last step size carries over (saves the start-up
            # rejections: ~2-3 % fewer evaluations)
            T[1] = 0.0
        if ev[EV_MASK] & kind_bit:
            return EVENT
        if ev[EV_COUNT] >= evlog.shape[0]:
            return EVENT_LOG_FULL


@jit_leaf
def copy_into(dst, src):
    """dst[:] = src (a slice assignment may allocate a temporary, which needs NRT)."""
    for i in range(dst.shape[0]):
        dst[i] = src[i]


@jit
def stepping_loop(T, t_end, y, f, P, I, SURF, C, levels, tau_held, stats, trace, tcount, ev,
                  y1, f1, err, work, y_root, f_tmp, K, W, g0, g1, g_tmp, JW, O, out, y_prev,
                  scratch):
    """``advance`` with its scratch arrays."""
    output = O[1] > 0.0
    # the phase, hence the step method, stays the same through one call (a switch returns)
    in_contact = HAS_CONTACT and int(C[C_PHASE]) != FREE
    quartic = not rosenbrock_now(I, C)     # Dormand-Prince steps carry a quartic extension
    ns = SURF.shape[0]
    rtol, atol = phase_tolerances(P, C)
    max_step = P[P_MAXSTEP]
    t = T[0]
    if T[2] != 0.0:
        rhs(t, y, f, P, I, SURF, C, levels, tau_held, stats, W)
        T[2] = 0.0
    if T[1] <= 0.0:
        T[1] = initial_step(t, y, f, P, I, SURF, C, levels, tau_held, stats, W, work, f1)
    h = T[1]
    event_values(y, P, I, SURF, C, levels, g0)
    eps4 = 4 * EPS * max(1.0, abs(t_end))
    # step-size exponent: 1 / (order of the error estimate + 1)
    expo = 0.2 if quartic else 0.25
    jac_valid = JW.shape[0] - 1
    status = DONE
    while t < t_end:
        remaining = t_end - t
        if remaining <= eps4:
            t = t_end
            break
        step = min(h, max_step)
        t_stop = t_end
        if output and in_contact:
            # in contact, steps end on the output times: each period's impulse is exact
            t_stop = min(t_end, O[0] * O[1])
            remaining = t_stop - t
        clipped = step >= remaining
        if clipped:
            step = remaining
        trial_step(t, y, f, step, y1, f1, err, K, work, P, I, SURF, C, levels, tau_held, stats,
                   W, JW)
        norm = error_norm(err, y, y1, rtol, atol)
        if not norm <= 1.0:  # also catches NaN
            stats[2] += 1
            if math.isfinite(norm):
                h = step * max(0.2, 0.9 * norm ** -expo)
            else:
                h = step * 0.2
            if h < 1e-15 * max(1.0, abs(t)):
                status = ERR_NONFINITE if not math.isfinite(norm) else ERR_UNDERFLOW
                break
            continue
        stats[1] += 1
        factor = 5.0 if norm == 0.0 else min(5.0, max(0.2, 0.9 * norm ** -expo))
        h = min(h, step * factor) if clipped else step * factor
        event_values(y1, P, I, SURF, C, levels, g1)
        best_s = step + 1.0
        best_k = last_k = -1
        for k in range(ns + 4):
            if g0[k] < 0.0 <= g1[k]:
                s_k = locate(t, y, f, step, k, g0[k], g1[k], y_root, f_tmp, err, K, work,
                             g_tmp, P, I, SURF, C, levels, tau_held, stats, W, JW)
                last_k = k
                if s_k < best_s:
                    best_s, best_k = s_k, k
        if best_k >= 0:
            copy_into(y_prev, y)
            if best_s < step:
                # locate() leaves the step to its root in y_root, f_tmp and K: take it again
                # only when a later slot's search overwrote them
                if last_k != best_k:
                    trial_step(t, y, f, best_s, y_root, f_tmp, err, K, work, P, I, SURF, C,
                               levels, tau_held, stats, W, JW)
                copy_into(y, y_root)
                end_f = f_tmp
            else:
                copy_into(y, y1)
                end_f = f1
            t_prev = t
            t = t + best_s
            # the quartic needs this step's stages; locate() overwrote them if best_s == step
            own_stages = quartic and best_s < step
            if in_contact:
                interpolate(t_prev, best_s, t_prev + 0.5 * best_s, y_prev, f, y, end_f, K,
                            own_stages, work, 0)
                record_point(t, y, P, I, SURF, C, levels, trace, tcount, work)
            if output and not emit_output(t_prev, best_s, y_prev, f, y, end_f, K, own_stages,
                                          P, I, C, tau_held, O, out, scratch):
                status = OUTPUT_FULL
                break
            ev[EV_SLOT] = best_k
            status = EVENT
            break
        if in_contact or output:
            copy_into(y_prev, y)
            copy_into(y_root, f)    # the step's start derivative, for the midpoint and output
        copy_into(y, y1)
        copy_into(f, f1)
        JW[jac_valid, 0] = 0.0      # a new point: the Jacobian is due again
        t_prev = t
        t = t_stop if clipped else t + step
        copy_into(g0, g1)
        delta = 0.0
        if HAS_CONTACT:
            if in_contact:
                # the midpoint state for Simpson's impulse, from the step's extension
                interpolate(t_prev, t - t_prev, 0.5 * (t_prev + t), y_prev, y_root, y, f, K,
                            quartic, work, 0)
                delta = record_point(t, y, P, I, SURF, C, levels, trace, tcount, work)
            else:
                # the dent is forgotten once the tip has risen above the surface again
                y_tip = tip(y[:N], y[N:2 * N], P[P_L:P_L + N])[1]
                for s in range(ns):
                    if levels[s] != SURF[s, S_H] and y_tip > SURF[s, S_H]:
                        levels[s] = SURF[s, S_H]
                        g0[s] = levels[s] - y_tip
        # output after the step's impulse is booked, before any early return
        if output and not emit_output(t_prev, t - t_prev, y_prev, y_root, y, f, K, quartic,
                                      P, I, C, tau_held, O, out, scratch):
            status = OUTPUT_FULL
            break
        if in_contact:
            if delta > SURF[int(C[C_SURF]), S_R]:
                status = ERR_PENETRATION
                break
            if tcount[0] >= trace.shape[0]:
                status = TRACE_FULL
                break
    T[0] = t
    T[1] = h
    return status
