"""A strike run in MuJoCo: the exported MJCF loaded, the arm set at contact with the
strike's joint angles and rates (the robot's coordinates: the MJCF's), stepped with the
motors off until the tip leaves the surface; at each phase of the time step (``phases``),
the outcome their mean."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .arm import PlanarArm
from .mjcf import MujocoContact, mjcf
from .phases import PHASES, over_phases
from .strike import Outcome, Strike

MAX_CONTACT_TIME = 0.1  # [s] a strike still in contact after this is reported unseparated


class MujocoStriker:
    """One compiled model; the pair's contact parameters and the time step are set per
    candidate (no recompilation while tuning)."""

    def __init__(self, arm: PlanarArm, contact: MujocoContact):
        import mujoco

        self.mujoco = mujoco
        self.arm = arm
        self.model: Any = mujoco.MjModel.from_xml_string(mjcf(arm, contact))
        self.data: Any = mujoco.MjData(self.model)
        self.site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, 'tip')
        self.set_contact(contact)

    def set_contact(self, contact: MujocoContact) -> None:
        m = self.model
        m.opt.timestep = contact.timestep
        for k in range(m.npair):
            m.pair_solref[k] = contact.solref
            m.pair_solimp[k] = contact.solimp
            m.pair_friction[k] = (contact.mu, contact.mu, 0.0, 0.0, 0.0)
        self.contact = contact

    def tip_velocity(self) -> tuple[float, float]:
        """The tip's velocity in the model's plane (world x, z)."""
        out = np.zeros(6)
        self.mujoco.mj_objectVelocity(
            self.model, self.data, self.mujoco.mjtObj.mjOBJ_SITE, self.site, out, 0
        )
        return float(out[3]), float(out[5])

    def normal_force(self) -> float:
        """The normal force of the tip's contacts now [N] (computed by the last step)."""
        total, wrench = 0.0, np.zeros(6)
        for i in range(self.data.ncon):
            self.mujoco.mj_contactForce(self.model, self.data, i, wrench)
            total += float(wrench[0])
        return total

    def outcome(self, strike: Strike, phases: int = PHASES) -> Outcome:
        """The mean of the strike over ``phases`` phases of the time step."""
        return over_phases(self.one_phase, strike, self.contact.timestep, phases)

    def one_phase(self, strike: Strike) -> Outcome:
        """The strike from its joint state at time 0 (the phase its start gives)."""
        mujoco, m, d = self.mujoco, self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = strike.joints
        d.qvel[:] = strike.joint_rates
        d.ctrl[:] = 0.0
        mujoco.mj_forward(m, d)
        dt = m.opt.timestep
        steps = int(MAX_CONTACT_TIME / dt)
        first = last = -1
        peak = 0.0
        for k in range(steps):
            mujoco.mj_step(m, d)
            force = self.normal_force()  # the force the step just applied
            if force > 0.0:
                first = k if first < 0 else first
                last, peak = k, max(peak, force)
            elif first >= 0:
                break
        vx, vy = self.tip_velocity()
        separated = first >= 0 and last < steps - 1
        duration = (last - first + 1) * dt if first >= 0 else 0.0
        return Outcome(-vy / strike.v_before[1], duration, peak, vx, separated)


def mujoco_outcomes(arm: PlanarArm, contact: MujocoContact, strikes: list[Strike]) -> list[Outcome]:
    striker = MujocoStriker(arm, contact)
    return [striker.outcome(s) for s in strikes]


def finite(outcomes: list[Outcome]) -> bool:
    return all(math.isfinite(o.cor) for o in outcomes)


def mujoco_problem(arm: PlanarArm, timestep: float, duration: float, mu: float) -> Any:
    """The MuJoCo search: solref (time constant, damping ratio), solimp (dmin, dmax, width)
    and friction, starting from a time constant of a third of our contact's ``duration``.
    MuJoCo refuses time constants below two steps (its ``refsafe``): the lower bound."""
    from .tuning import Parameter, PeerProblem

    striker = MujocoStriker(arm, mujoco_defaults_at(timestep))
    low = math.log10(2.0 * timestep)
    parameters = (
        Parameter('timeconst', max(math.log10(duration / 3.0), low), low, low + 3.0, log=True),
        Parameter('dampratio', 0.3, 0.01, 2.0),
        Parameter('dmin', 0.9, 0.5, 0.9999),
        Parameter('dmax', 0.95, 0.5, 0.9999),
        Parameter('width', -3.0, -6.0, -1.0, log=True),
        Parameter('mu', mu, 0.0, 2.0),
    )

    def contact(v: dict[str, float]) -> MujocoContact:
        return MujocoContact(timestep=timestep, **v)

    def outcomes(c: MujocoContact, strikes: Any) -> list[Outcome]:
        striker.set_contact(c)
        return [striker.outcome(s) for s in strikes]

    return PeerProblem(parameters, contact, outcomes)


def mujoco_defaults_at(timestep: float) -> MujocoContact:
    from .mjcf import mujoco_defaults

    return mujoco_defaults(timestep)
