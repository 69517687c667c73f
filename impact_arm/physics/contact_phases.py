"""The phase machine every contact runs, in the arm's kernel and in the free body's
(docs/model.md)::

    free --δ=0--> elastic --δ=1.9δc--> elasto-plastic --δ̇=0--> restitution --δ=δr--> free
    (elastic --δ̇=0--> restitution for a law that does not yield, or a gentle impact)

``phase_events`` says which switches a phase arms and where each happens, ``max_compression``
what the maximum compression fixes for the restitution. The law-dependent quantities come from
``contact.py`` (``yield_margin``, ``law_residual``; the force of each phase:
``phase_normal_force``). What differs between the kernels stays with them: how δ and δ̇ are
read from their state, the dent a separation leaves, what they log.
"""

from __future__ import annotations

from .contact import CONTACT_NONE, law_residual, restitution_radius, yield_margin
from .jit import jit_leaf
from .layout import ELASTIC, ELASTOPLASTIC, FREE


@jit_leaf
def phase_events(
    phase: int, law: int, delta: float, unloading: float, delta_c: float, delta_r: float
) -> tuple[float, float, float, float]:
    """The contact's event functions in its phase, for indentation δ and ``unloading`` = -δ̇;
    each rises through zero at its switch and is -1 when unarmed. In order: the contact
    (δ, free), the yield onset (elastic, a law that yields), the maximum compression (-δ̇,
    elastic or elasto-plastic), the separation (δr - δ, restitution). A surface of law
    ``none`` arms nothing: the body passes through it."""
    contact, yielding, maximum, separation = -1.0, -1.0, -1.0, -1.0
    if law == CONTACT_NONE:
        return contact, yielding, maximum, separation
    if phase == FREE:
        contact = delta
    elif phase == ELASTIC:
        yielding = yield_margin(law, delta, delta_c)
        maximum = unloading
    elif phase == ELASTOPLASTIC:
        maximum = unloading
    else:
        separation = delta_r - delta
    return contact, yielding, maximum, separation


@jit_leaf
def max_compression(
    law: int, delta_m: float, P_m: float, E: float, delta_c: float, cor: float
) -> tuple[float, float, bool]:
    """(δr, Rr, valid) at the maximum compression (δm, Pm): the dent the restitution unloads
    to and the radius that starts its curve at (δm, Pm). Not valid (Rr = 0) when δr falls
    outside [0, δm): beyond the residual fit's range."""
    delta_r = law_residual(law, delta_m, delta_c, cor)
    if not 0.0 <= delta_r < delta_m:
        return delta_r, 0.0, False
    return delta_r, restitution_radius(delta_m, delta_r, P_m, E), True
