"""Index layout of the arrays shared by the Python layer and the compiled kernel.

The kernel works on flat float/int arrays (numba compiles them to plain memory access); these
names keep both sides reading the same slots.
"""

# contact phases (also ``model.Phase``)
FREE, ELASTIC, ELASTOPLASTIC, RESTITUTION = 0, 1, 2, 3
LAW_HELD, LAW_Q, LAW_PID, LAW_NONE = 0, 1, 2, 3
# contact-state array C: phase, surface, cycle mode (0 down, 1 up), restitution
# parameters, peak force of the impact, last impulse point, accumulated impulses, peak normal
# force since the last output row or take_peak (the period's peak: /contact_force_peak)
C_PHASE, C_SURF, C_MODE, C_DR, C_RR, C_DM, C_PM, C_PEAK = 0, 1, 2, 3, 4, 5, 6, 7
C_IMP_T, C_IMP_FF, C_IMP_FN, C_JT, C_JN, C_PERIOD_PEAK = 8, 9, 10, 11, 12, 13
C_SIZE = 14
# surface table columns; a mounted surface's plate: index of its displacement z in the state
# (its rate follows; -1: rigidly mounted), mass, stiffness, damping coefficient
S_H, S_LAW, S_MU, S_VD, S_E, S_R, S_SY, S_CJ, S_DC, S_PC, S_B = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10
S_MOUNT, S_MM, S_MK, S_MC = 11, 12, 13, 14
S_SIZE = 15
# integer options I
I_LAW, I_SPACE, I_ACT, I_TRACE, I_METHOD = 0, 1, 2, 3, 4
I_SIZE = 5
# step methods (I_METHOD): Dormand-Prince everywhere, or a Rosenbrock step in free flight
METHOD_DOPRI5, METHOD_ROSENBROCK = 0, 1
# kernel status
DONE, EVENT, TRACE_FULL, ERR_UNDERFLOW, ERR_PENETRATION, ERR_NONFINITE, OUTPUT_FULL = (
    0,
    1,
    2,
    3,
    4,
    5,
    6,
)
EVENT_LOG_FULL, ERR_RESIDUAL = 7, 8
# STEP_BUDGET: the call took ev[EV_STEPS] steps and returns, so that a caller regains control
# (Ctrl-C, its run budget) within a bounded time
STEP_BUDGET = 9
# event slots: contact per surface, then switch, yield, max_compression, separation
EV_SWITCH, EV_YIELD, EV_MAX, EV_SEP = 0, 1, 2, 3
# event kinds as bits of the stop mask (the kernel returns after an event whose bit is set
# and crosses the others itself): contact on any surface, then 1 << (1 + EV_*)
KIND_BIT_CONTACT = 1
# integer array ev: slot of the event just located, events logged, stop mask
EV_SLOT, EV_COUNT, EV_MASK, EV_STEPS = 0, 1, 2, 3
# a row of the event log: slot, surface, t, four values (max_compression: δm, Pm, δr, Rr;
# separation: F_max, δm, δr), then the state after the switch
E_SLOT, E_SURF, E_T, E_INFO, E_Y = 0, 1, 2, 3, 7

# time array T of ``advance``: time, next step size (<= 0: choose one), derivative stale flag
T_TIME, T_STEP, T_STALE = 0, 1, 2
# output control array O: next grid index k, grid period dt (0: no output), rows written
O_NEXT, O_DT, O_ROWS = 0, 1, 2
# counters ``stats``: right-hand side evaluations, accepted steps, rejected steps
ST_RHS, ST_STEPS, ST_REJECTED = 0, 1, 2
# a trace row (one per contact step): t, phase, δ, F_n, F_f, tip velocity, then the N link
# kinetic energies
TR_T, TR_PHASE, TR_DELTA, TR_FN, TR_FF, TR_VX, TR_VY, TR_ENERGY = 0, 1, 2, 3, 4, 5, 6, 7


def geometry_size(n: int, general: bool) -> int:
    """Entries of the link-geometry block P_L: the n lengths for uniform rods; for general
    links also each link's centre of mass (along, across) and inertia about it, then the
    contact point on the last link (along, across): ``equations.GEOMETRY``."""
    return 4 * n + 2 if general else n


def shape_offsets(n: int, general: bool = False, n_mount: int = 0) -> dict:
    """Offsets that depend on the scene shape (n links, general links or uniform rods,
    n_mount mounted surfaces). The generator writes them into each kernel module as
    compile-time constants; Python code reads them from that module (``model.eq``) or from
    here.

    The state is q, q̇, the PID integral states (n of them for a continuous PID, else none),
    then each mounted plate's z, ż (``SurfaceModel.mount_state``). Whether the integrals are
    there is a value, not shape: the kernel reads it from the state's length
    (``integral_states``), so a continuous PID runs on its arm's kernel, and a state without
    them is stepped and error-normed exactly as before. SIZE is the longest state of the
    shape (integrals included): an output row reserves that many columns.

    P_*: the flat parameter array (link geometry (NL values), masses, g, gains, targets,
    switch height, tolerances, maximum step, then the joints' damping, Coulomb friction, its
    smoothing rate and armature, and two switches: P_JFRIC_ON (some joint has damping or
    friction) and P_ARM_ON (some joint has armature)). Joint values are values, not shape:
    zero is off, and a scene that changes them never compiles a new kernel. R_*: an output
    row (``emit_output``): t, the state (SIZE columns, those past the state's length 0), the
    contact impulse since the previous row (tangential, normal), the torque acting, actuators
    acting (1/0), the tip velocity (x, y), the peak normal contact force since the previous
    row. W_*: the right-hand side's scratch
    (generalized forces, torques, PID error and rate, then N*N for the mass matrix factor)."""
    size = 3 * n + 2 * n_mount
    nl = geometry_size(n, general)
    p = nl - n  # the parameters after the geometry block move by its extra entries
    return {
        'SIZE': size,
        'NL': nl,
        'P_L': 0,
        'P_M': p + n,
        'P_G': p + 2 * n,
        'P_KP': p + 2 * n + 1,
        'P_KD': p + 3 * n + 1,
        'P_KI': p + 4 * n + 1,
        'P_TDOWN': p + 5 * n + 1,
        'P_TUP': p + 6 * n + 1,
        'P_SWITCH': p + 7 * n + 1,
        'P_RTOL': p + 7 * n + 2,
        'P_ATOL': p + 7 * n + 3,
        'P_MAXSTEP': p + 7 * n + 4,
        'P_CRTOL': p + 7 * n + 5,
        'P_CATOL': p + 7 * n + 6,
        'P_DAMP': p + 7 * n + 7,
        'P_FRIC': p + 8 * n + 7,
        'P_FVD': p + 9 * n + 7,
        'P_ARM': p + 10 * n + 7,
        'P_JFRIC_ON': p + 11 * n + 7,
        'P_ARM_ON': p + 11 * n + 8,
        'P_SIZE': p + 11 * n + 9,
        'R_T': 0,
        'R_Y': 1,
        'R_JT': 1 + size,
        'R_JN': 2 + size,
        'R_TAU': 3 + size,
        'R_ACT': 3 + size + n,
        'R_VTIP': 4 + size + n,
        'R_FPEAK': 6 + size + n,
        'R_SIZE': 7 + size + n,
        'W_GEN': 0,
        'W_TAU': n,
        'W_ERR': 2 * n,
        'W_RATE': 3 * n,
        'W_MASS': 4 * n,
        'SCRATCH': 4 * n + n * n,
        'TR_SIZE': TR_ENERGY + n,
    }
