"""MuJoCo as the peer of ``export --check`` (``closed_loop``): the exported MJCF stepped at
the export's time step, the held efforts on its motors, the normal contact force of a step
from ``mj_contactForce``. Near the surface a step is split (``mj_step1``, ``mj_step2``) so
that the motors are set from the contacts of the state the step starts from."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..physics.errors import SimulationError
from ..physics.scene import Scene
from . import closed_loop
from .closed_loop import PeerRun, Step, TipState


class MujocoLoop:
    """The exported model of ``scene`` in MuJoCo with the scene's controller at ``rate``."""

    name = 'MuJoCo'

    def __init__(self, model_path: str, scene: Scene, timestep: float, rate: float):
        import mujoco

        self.mujoco = mujoco
        self.scene = scene
        self.rate = rate
        self.model: Any = mujoco.MjModel.from_xml_path(model_path)
        self.model.opt.timestep = timestep
        self.timestep = float(timestep)
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
        self._wrench = np.zeros(6)
        self._velocity = np.zeros(6)

    def run(self, impacts: int, t_max: float) -> PeerRun:
        """Step until ``impacts`` impacts have ended or ``t_max`` simulated seconds."""
        return closed_loop.run(self, self.scene, self.rate, impacts, t_max)

    # --- the stepper (closed_loop.PeerStepper)
    def start(self, joints: list[float], rates: list[float]) -> None:
        m, d = self.model, self.data
        self.mujoco.mj_resetData(m, d)
        for i, v in zip(self.qpos_at, joints):
            d.qpos[i] = v
        for i, v in zip(self.qvel_at, rates):
            d.qvel[i] = v
        self.mujoco.mj_forward(m, d)

    def time(self) -> float:
        return float(self.data.time)

    def joints(self) -> tuple[list[float], list[float]]:
        d = self.data
        theta = [float(d.qpos[i]) for i in self.qpos_at]
        theta_d = [float(d.qvel[i]) for i in self.qvel_at]
        if not all(math.isfinite(x) for x in theta + theta_d):
            raise SimulationError(f'MuJoCo state not finite at t = {d.time:.6f} s: {theta}')
        return theta, theta_d

    def advance(self, efforts: list[float], steps: int) -> bool:
        self._set_motors(efforts)
        self.mujoco.mj_step(self.model, self.data, steps)
        return bool(self._tip_contacts())

    def step(self, efforts: list[float], motors_in_contact: bool) -> Step:
        mujoco, m, d = self.mujoco, self.model, self.data
        mujoco.mj_step1(m, d)  # positions, velocities, contacts of this state
        contacts = self._tip_contacts()
        before = self._tip_state(contacts)
        touching = bool(contacts)
        self._set_motors([0.0] * len(efforts) if touching and not motors_in_contact else efforts)
        mujoco.mj_step2(m, d)  # the force of this state acts over the step
        return Step(before, touching, self._normal_force(contacts))

    # --- contacts
    def _set_motors(self, efforts: list[float]) -> None:
        for i, v in zip(self.motor_at, efforts):
            self.data.ctrl[i] = v

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

    def _tip_state(self, contacts: list[int]) -> TipState:
        m, d = self.model, self.data
        self.mujoco.mj_objectVelocity(
            m, d, self.mujoco.mjtObj.mjOBJ_SITE, self.site, self._velocity, 0
        )
        depth = max((-float(d.contact[i].dist) for i in contacts), default=0.0)
        # mj_objectVelocity gives (angular, linear): the world x and z of the linear part
        return TipState(
            float(d.time), max(depth, 0.0), float(self._velocity[3]), float(self._velocity[5])
        )
