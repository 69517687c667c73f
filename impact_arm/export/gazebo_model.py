"""A small model of Gazebo's ODE contact, for tuning without Gazebo (not on PyPI; the
export's Gazebo parameters were never run in Gazebo, docs/export.md says so).

The tip is a point of the arm with the inverse effective mass W = J M⁻¹ Jᵀ at the strike's
posture (tangential x, normal y), free of other forces over the contact. Each step of
length h, while the sphere overlaps the surface (depth p ≥ 0), ODE's contact rows are
solved as its solver does for one contact:

- the spring-damper (kp, kd) becomes ERP = h kp / (h kp + kd), CFM = 1 / (h kp + kd);
- the normal row's target speed is c = min(ERP max(p - min_depth, 0) / h, max_vel), raised
  to the bounce speed e |u_n| when the approach is faster than the bounce threshold;
- normal force λ_n = max(0, (c - u_n) / (h W_nn + CFM)); friction λ_t = -u_t / (h W_tt)
  within ±μ λ_n (a few Gauss-Seidel sweeps for the coupling W_tn);
- u += h W λ, then p -= h u_n (semi-implicit Euler, as ODE)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..physics.model import ArmModel
from ..physics.scene import Scene
from .sdf import GazeboContact
from .strike import Outcome, Strike

SWEEPS = 4  # Gauss-Seidel sweeps of the two rows (enough for two rows to converge)
MAX_CONTACT_TIME = 0.005  # [s] 30 times the contacts of a stiff surface


def tip_inverse_mass(scene: Scene, strike: Strike) -> np.ndarray:
    """W = J M⁻¹ Jᵀ of the tip at the strike's posture [1/kg], rows (x, y)."""
    model = ArmModel(scene)
    q = np.asarray(strike.q)
    jacobian = np.asarray(model.tip_jacobian(q), float).reshape(2, model.n)
    return np.asarray(jacobian @ np.linalg.solve(model.mass_matrix(q), jacobian.T), float)


def ode_outcome(contact: GazeboContact, strike: Strike, inverse_mass: np.ndarray) -> Outcome:
    h = contact.timestep
    (w_tt, w_tn), (w_nt, w_nn) = (
        (float(x) for x in inverse_mass[0]),
        (float(x) for x in inverse_mass[1]),
    )
    erp = h * contact.kp / (h * contact.kp + contact.kd)
    cfm = 1.0 / (h * contact.kp + contact.kd)
    u_t, u_n = strike.v_before  # (tangential, normal)
    depth = 0.0
    first = last = -1
    peak = 0.0
    steps = int(MAX_CONTACT_TIME / h)
    for k in range(steps):
        if depth < 0.0:
            break  # left the surface
        target = min(erp * max(depth - contact.min_depth, 0.0) / h, contact.max_vel)
        if -u_n > contact.bounce_threshold:
            target = max(target, -contact.restitution * u_n)
        f_t = f_n = 0.0
        for _ in range(SWEEPS):
            moved_n = u_n + h * (w_nt * f_t + w_nn * f_n)
            f_n = max(0.0, f_n + (target - moved_n) / (h * w_nn + cfm))
            moved_t = u_t + h * (w_tt * f_t + w_tn * f_n)
            bound = contact.mu * f_n
            f_t = min(bound, max(-bound, f_t - moved_t / (h * w_tt)))
        u_t, u_n = u_t + h * (w_tt * f_t + w_tn * f_n), u_n + h * (w_nt * f_t + w_nn * f_n)
        depth -= h * u_n
        if f_n > 0.0:
            first = k if first < 0 else first
            last, peak = k, max(peak, f_n)
    separated = depth < 0.0
    duration = (last - first + 1) * h if first >= 0 else 0.0
    return Outcome(-u_n / strike.v_before[1], duration, peak, u_t, separated)


def gazebo_problem(
    scene: Scene, timestep: float, stiffness: float, strikes: Sequence[Strike], mu: float
) -> Any:
    """The Gazebo search: kp (from ``stiffness``), kd, the restitution coefficient,
    friction and max_vel (at its default, 0.01 m/s, the spring cannot push the tip back:
    only the bounce would); min_depth stays at its default, 0."""
    import math

    from .tuning import Parameter, PeerProblem

    masses = {id(s): tip_inverse_mass(scene, s) for s in strikes}
    start = math.log10(stiffness)
    parameters = (
        Parameter('kp', start, start - 3.0, start + 3.0, log=True),
        Parameter('kd', 1.0, -2.0, 5.0, log=True),
        Parameter('restitution', 0.4, 0.0, 1.0),
        Parameter('mu', mu, 0.0, 2.0),
        Parameter('max_vel', 1.0, -3.0, 2.0, log=True),
    )

    def contact(v: dict[str, float]) -> GazeboContact:
        return GazeboContact(min_depth=0.0, timestep=timestep, **v)

    def outcomes(c: GazeboContact, chosen: Sequence[Strike]) -> list[Outcome]:
        return [ode_outcome(c, s, masses[id(s)]) for s in chosen]

    return PeerProblem(parameters, contact, outcomes)
