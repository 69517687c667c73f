"""Index layout of the arrays shared by the Python layer and the compiled kernel.

The kernel works on flat float/int arrays (numba compiles them to plain memory access); these
names keep both sides reading the same slots.
"""
# contact phases (also ``model.Phase``)
FREE, ELASTIC, ELASTOPLASTIC, RESTITUTION = 0, 1, 2, 3
LAW_HELD, LAW_Q, LAW_PID, LAW_NONE = 0, 1, 2, 3
# contact-state array C: phase, surface, cycle mode (0 down, 1 up), restitution
# parameters, peak force, last impulse point, accumulated impulses
C_PHASE, C_SURF, C_MODE, C_DR, C_RR, C_DM, C_PM, C_PEAK = 0, 1, 2, 3, 4, 5, 6, 7
C_IMP_T, C_IMP_FF, C_IMP_FN, C_JT, C_JN = 8, 9, 10, 11, 12
C_SIZE = 13
# surface table columns
S_H, S_LAW, S_MU, S_VD, S_E, S_R, S_SY, S_CJ, S_DC, S_PC, S_B = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10
S_SIZE = 11
# integer options I
I_LAW, I_SPACE, I_ACT, I_TRACE, I_METHOD = 0, 1, 2, 3, 4
I_SIZE = 5
# step methods (I_METHOD): Dormand-Prince everywhere, or a Rosenbrock step in free flight
METHOD_DOPRI5, METHOD_ROSENBROCK = 0, 1
# kernel status
DONE, EVENT, TRACE_FULL, ERR_UNDERFLOW, ERR_PENETRATION, ERR_NONFINITE, OUTPUT_FULL = \
    0, 1, 2, 3, 4, 5, 6
EVENT_LOG_FULL, ERR_RESIDUAL = 7, 8
# event slots: contact per surface, then switch, yield, max_compression, separation
EV_SWITCH, EV_YIELD, EV_MAX, EV_SEP = 0, 1, 2, 3
# event kinds as bits of the stop mask (the kernel returns after an event whose bit is set
# and crosses the others itself): contact on any surface, then 1 << (1 + EV_*)
KIND_BIT_CONTACT = 1
# integer array ev: slot of the event just located, events logged, stop mask
EV_SLOT, EV_COUNT, EV_MASK = 0, 1, 2
# a row of the event log: slot, surface, t, four values (max_compression: δm, Pm, δr, Rr;
# separation: F_max, δm, δr), then the state after the switch
E_SLOT, E_SURF, E_T, E_INFO, E_Y = 0, 1, 2, 3, 7

