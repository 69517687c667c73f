"""Rigid-body impact laws of one contact point: what users of other simulators know, as the
baselines our contact laws are compared with (``impact-arm bench validate``).

A planar body (mass m, inertia I about its centre of mass) strikes a surface with normal
n = (0, 1) at a contact point r = (r_x, r_z) from its centre of mass. The contact point's
velocity changes linearly with the impulse P = (P_t, P_n): Δu = W P with the inverse
effective mass W (Stronge, *Impact Mechanics*, 2000, ch. 5). Coulomb friction is applied in
impulse space, parametrised by the normal impulse (Routh's method): while sliding,
dP_t = -μ s dP_n; sliding stops, sticks (when |W_tn / W_tt| <= μ) or reverses on the way.
The impact ends

- ``Restitution.NEWTON``: when the normal velocity reaches -e times its value before;
- ``Restitution.POISSON``: when the normal impulse reaches (1 + e) times that of compression.

Without friction both give u_n' = -e u_n. Only the ratio I/m matters for the velocities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..kinds import TextEnum


class Restitution(TextEnum):
    NEWTON = 'newton'
    POISSON = 'poisson'


@dataclass(frozen=True)
class PointImpact:
    vx: float
    vz: float
    omega: float
    normal_impulse: float  # per unit mass [m/s]
    stuck: bool  # sliding stopped during the impact


def point_impact(
    vx: float,
    vz: float,
    omega: float,
    rx: float,
    rz: float,
    gyration2: float,
    mu: float,
    e: float,
    law: Restitution,
) -> PointImpact:
    """Velocities after a rigid-body impact of the contact point (rx, rz) on a horizontal
    surface; ``gyration2`` = I / m. Impulses are per unit mass. A contact point that is not
    approaching (u_n >= 0) leaves the velocities unchanged."""
    w_tt = 1.0 + rz * rz / gyration2
    w_tn = -rx * rz / gyration2
    w_nn = 1.0 + rx * rx / gyration2
    ut, un = vx - omega * rz, vz + omega * rx
    if un >= 0.0:
        return PointImpact(vx, vz, omega, 0.0, False)
    un0 = un
    pt = pn = 0.0
    p_compression = -1.0
    stuck = False
    can_stick = abs(w_tn) <= mu * w_tt
    for _ in range(8):  # at most: slide, stop, stick or reverse, compression end, end, jam
        sticking = ut == 0.0 and can_stick
        if sticking:
            ratio = -w_tn / w_tt  # dP_t/dP_n that keeps u_t = 0
        else:
            s = math.copysign(1.0, ut) if ut != 0.0 else math.copysign(1.0, w_tn)
            ratio = -mu * s
        dut = w_tt * ratio + w_tn
        dun = w_tn * ratio + w_nn
        ends = -1.0  # normal impulse to the end of compression, or of the impact
        if dun > 0.0:
            if un < 0.0:
                ends = -un / dun
            elif law == Restitution.NEWTON:
                ends = (-e * un0 - un) / dun
            else:
                ends = (1.0 + e) * p_compression - pn
            ends = max(ends, 0.0)
        stops = -ut / dut if not sticking and dut != 0.0 and ut * dut < 0.0 else -1.0
        if ends < 0.0 and stops < 0.0:
            # friction so strong that sliding cannot stop the approach (Painleve's jam): a
            # tangential impulse stops the slip at once, then the contact sticks
            jump = -ut / w_tt
            pt += jump
            un += w_tn * jump
            ut = 0.0
            stuck = True
            continue
        if stops >= 0.0 and (ends < 0.0 or stops < ends):
            pn += stops
            pt += ratio * stops
            un += dun * stops
            ut = 0.0
            stuck = True
            continue
        pn += ends
        pt += ratio * ends
        ut += dut * ends
        un += dun * ends
        if p_compression < 0.0:
            un = 0.0  # the end of compression, exactly
            p_compression = pn
            if e == 0.0:
                break
            continue
        break
    # back from the contact point to the body: Δv = P/m, Δω = (r × P)/I
    return PointImpact(vx + pt, vz + pn, omega + (rx * pn - rz * pt) / gyration2, pn, stuck)
