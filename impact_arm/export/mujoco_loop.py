"""The peer's side of ``export --check``: the exported MJCF stepped in MuJoCo at the export's
time step under the scene's ``CycleController``, whose torques are held (zero-order hold)
for one control period, as in the package's offline sampled loop (``simulate.run`` with a
control rate). The controller reads MuJoCo's joint angles in the scene's joint coordinates
(the export keeps its names, zero and sign) and, as the offline loop gives it, the mean
normal contact force of the period just ended (MuJoCo's ``mj_contactForce``).

An impact lasts from the first step whose tip/surface contact carries a normal force to the
first step without one (the contact's extent the export was tuned on, ``mujoco_strike``).
It is measured on MuJoCo's state: the contact time interpolated back from the first
penetrating state to zero penetration, the tip velocity at that state (before any contact
force acted) and at the first state after the last force, the peak of the steps' forces."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..physics.control import CycleController
from ..physics.errors import SimulationError
from ..physics.model import ArmModel
from ..physics.scene import Scene
from .impacts import ImpactRow

# far from the surface the steps of a control period run in one call: the tip could not
# reach the surface within this many periods at its speed, nor within this distance [m]
FAR_PERIODS = 2.0
FAR_MARGIN = 1e-3


@dataclass(frozen=True)
class PeerRun:
    impacts: tuple[ImpactRow, ...]
    t_end: float  # [s] simulated
    steps: int
    stopped: str  # why the run ended, in words


@dataclass
class _TipState:
    """The tip at the state a step starts from (after ``mj_step1``)."""

    t: float
    depth: float  # deepest penetration of a tip/surface contact [m] (0: none)
    vx: float
    vz: float


@dataclass
class _OpenImpact:
    start: _TipState
    steps: int = 0
    peak: float = 0.0


class MujocoLoop:
    """The exported model of ``scene`` in MuJoCo with the scene's controller at ``rate``."""

    def __init__(self, model_path: str, scene: Scene, timestep: float, rate: float):
        import mujoco

        self.mujoco = mujoco
        self.scene = scene
        self.model: Any = mujoco.MjModel.from_xml_path(model_path)
        self.model.opt.timestep = timestep
        self.data: Any = mujoco.MjData(self.model)
        m = self.model
        self.tip_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, 'tip')
        self.site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, 'tip')
        self.surface_geoms = {
            i
            for i in range(m.ngeom)
            if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, i) or '').startswith('surface')
        }
        names = scene.joint_names
        missing = [
            n
            for n in names
            if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) < 0
            or mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) < 0
        ]
        if self.tip_geom < 0 or self.site < 0 or not self.surface_geoms or missing:
            raise SimulationError(
                f'{model_path}: not the MJCF of scene {scene.name!r} as impact-arm export '
                f'writes it (geom tip, site tip, geoms surface1.., the joints and motors '
                f'{", ".join(names)}; missing joints or motors: {", ".join(missing) or "none"})'
            )
        joints = [m.joint(n) for n in names]
        self.qpos_at = [int(j.qposadr[0]) for j in joints]
        self.qvel_at = [int(j.dofadr[0]) for j in joints]
        self.motor_at = [m.actuator(n).id for n in names]
        self.steps_per_period = round(1.0 / (rate * timestep))
        self.rate = rate
        self.arm = ArmModel(scene)
        self.highest = max(s.height for s in scene.surfaces if s.law != 'none')
        self._wrench = np.zeros(6)
        self._velocity = np.zeros(6)

    # --- the state in the scene's coordinates
    def joint_state(self) -> tuple[list[float], list[float]]:
        """The model's absolute link angles and rates from MuJoCo's joints (the robot's)."""
        d, coordinates = self.data, self.scene.joint_coordinates
        theta = [float(d.qpos[i]) for i in self.qpos_at]
        theta_d = [float(d.qvel[i]) for i in self.qvel_at]
        if not all(math.isfinite(x) for x in theta + theta_d):
            raise SimulationError(f'MuJoCo state not finite at t = {d.time:.6f} s: {theta}')
        return coordinates.absolute(theta), coordinates.absolute_rates(theta_d)

    def _start(self) -> None:
        m, d, coordinates = self.model, self.data, self.scene.joint_coordinates
        self.mujoco.mj_resetData(m, d)
        for i, v in zip(self.qpos_at, coordinates.positions(self.scene.q0)):
            d.qpos[i] = v
        for i, v in zip(self.qvel_at, coordinates.rates(self.scene.qd0)):
            d.qvel[i] = v
        self.mujoco.mj_forward(m, d)

    # --- contacts
    def _tip_contacts(self) -> list[int]:
        d = self.data
        out = []
        for i in range(d.ncon):
            c = d.contact[i]
            pair = {int(c.geom1), int(c.geom2)}
            if self.tip_geom in pair and pair & self.surface_geoms:
                out.append(i)
        return out

    def _normal_force(self, contacts: list[int]) -> float:
        total = 0.0
        for i in contacts:
            self.mujoco.mj_contactForce(self.model, self.data, i, self._wrench)
            total += float(self._wrench[0])
        return total

    def _tip_state(self, contacts: list[int]) -> _TipState:
        m, d = self.model, self.data
        self.mujoco.mj_objectVelocity(
            m, d, self.mujoco.mjtObj.mjOBJ_SITE, self.site, self._velocity, 0
        )
        depth = max((-float(d.contact[i].dist) for i in contacts), default=0.0)
        # mj_objectVelocity gives (angular, linear): the world x and z of the linear part
        return _TipState(
            float(d.time), max(depth, 0.0), float(self._velocity[3]), float(self._velocity[5])
        )

    # --- the run
    def run(self, impacts: int, t_max: float) -> PeerRun:
        """Step until ``impacts`` impacts have ended or ``t_max`` simulated seconds."""
        mujoco, m, d = self.mujoco, self.model, self.data
        self._start()
        ctrl = CycleController.for_scene(self.arm, self.scene.controller)
        limits = self.scene.effort_limits
        coordinates = self.scene.joint_coordinates
        motors_in_contact = self.scene.actuators_during_contact
        dt = float(m.opt.timestep)
        period = 1.0 / self.rate
        found: list[ImpactRow] = []
        open_impact: _OpenImpact | None = None
        impulse = 0.0  # normal impulse over the control period [N s]
        steps = k = 0
        while len(found) < impacts:
            t_ctl = k * period
            if t_ctl > t_max:
                return PeerRun(tuple(found), float(d.time), steps, f't_max = {t_max:g} s reached')
            q, qd = self.joint_state()
            tau = ctrl.update(t_ctl, q, qd, normal_force=impulse / period)
            tau = [min(max(v, -lim), lim) for v, lim in zip(tau, limits)]  # the drive clips
            held = coordinates.efforts(tau)
            impulse = 0.0
            k += 1
            _, y, vx, vy = self.arm.tip(q, qd)
            clearance = y - self.highest
            if open_impact is None and clearance > FAR_PERIODS * math.hypot(vx, vy) * period + (
                FAR_MARGIN
            ):
                for i, v in zip(self.motor_at, held):
                    d.ctrl[i] = v
                mujoco.mj_step(m, d, self.steps_per_period)
                steps += self.steps_per_period
                if self._tip_contacts():
                    raise SimulationError(
                        f'MuJoCo: the tip reached a surface within a period stepped as far from '
                        f'it (t = {d.time:.6f} s): FAR_PERIODS too small'
                    )
                continue
            for _ in range(self.steps_per_period):
                mujoco.mj_step1(m, d)  # positions, velocities, contacts of this state
                contacts = self._tip_contacts()
                state = self._tip_state(contacts) if contacts or open_impact else None
                # the article's contact: the motors off while the tip touches (the scene's
                # actuators_during_contact), as the package's held torque is
                off = bool(contacts) and not motors_in_contact
                for i, v in zip(self.motor_at, held):
                    d.ctrl[i] = 0.0 if off else v
                mujoco.mj_step2(m, d)  # the force of this state acts over the step
                steps += 1
                force = self._normal_force(contacts)
                impulse += force * dt
                if force > 0.0 and state is not None:
                    if open_impact is None:
                        open_impact = _OpenImpact(state)
                    open_impact.steps += 1
                    open_impact.peak = max(open_impact.peak, force)
                elif open_impact is not None and state is not None:
                    found.append(_impact(open_impact, state, dt))
                    open_impact = None
                    if len(found) == impacts:
                        break
        return PeerRun(tuple(found), float(d.time), steps, f'{impacts} impacts')


def _impact(impact: _OpenImpact, after: _TipState, dt: float) -> ImpactRow:
    """The impact from its first penetrating state and the state after its last force."""
    start = impact.start
    # back from the first penetrating state to zero penetration, at the approach speed
    t_contact = start.t - start.depth / -start.vz if start.vz < 0.0 else start.t
    cor = -after.vz / start.vz if start.vz != 0.0 else math.nan
    return ImpactRow(t_contact, -start.vz, cor, impact.steps * dt, impact.peak)
