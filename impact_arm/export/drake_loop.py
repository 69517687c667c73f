"""Drake as the peer of ``export --check`` (``closed_loop``): the exported SDF in Drake's
discrete MultibodyPlant (point contact, the ``lagged`` approximation the export was tuned
with) at the export's time step, as its README loads it. The held efforts are a fixed value
of the plant's actuation input port, set between ``AdvanceTo`` calls; whether the tip
touches a surface is the geometric penetration of the state a step starts from (the motors
are set from it), and a step's normal force is its point-pair contact result, which Drake
reports at the state the step ends in."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..physics.errors import SimulationError
from ..physics.scene import Scene
from . import closed_loop
from .arm import planar_arm
from .closed_loop import PeerRun, Step, TipState
from .drake_strike import plant_config, quiet_drake


class DrakeLoop:
    """The exported model of ``scene`` in Drake with the scene's controller at ``rate``."""

    name = 'Drake'

    def __init__(self, model_path: str, scene: Scene, timestep: float, rate: float):
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import AddMultibodyPlant
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        self.scene = scene
        self.rate = rate
        self.timestep = float(timestep)
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(plant_config(timestep), builder)
        quiet_drake()
        Parser(plant).AddModels(file_name=model_path)  # type: ignore[arg-type]  # stubs: PathLike; a str loads
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -planar_arm(scene).gravity])
        plant.Finalize()
        self.plant: Any = plant
        self.diagram = builder.Build()
        self.simulator: Any = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        inspector = scene_graph.model_inspector()
        names = {inspector.GetName(g).split('::')[-1]: g for g in inspector.GetAllGeometryIds()}
        self.tip_geometry = names.get('tip')
        self.surface_geometries = {g for n, g in names.items() if n.startswith('surface')}
        joint_names = scene.joint_names
        missing = [
            n
            for n in joint_names
            if not plant.HasJointNamed(n) or not plant.HasJointActuatorNamed(n)
        ]
        if self.tip_geometry is None or not self.surface_geometries or missing:
            raise SimulationError(
                f'{model_path}: not the SDF of scene {scene.name!r} as impact-arm export '
                f'writes it (collision tip, collisions surface1.., the joints and actuators '
                f'{", ".join(joint_names)}; missing: {", ".join(missing) or "none"})'
            )
        self.joint_list = [plant.GetJointByName(n) for n in joint_names]
        # the actuation port takes the actuators in their index order: each joint's place
        order = [int(plant.GetJointActuatorByName(n).input_start()) for n in joint_names]
        self.actuation_at = order
        self.actuation = plant.get_actuation_input_port().FixValue(
            self.plant_context, np.zeros(plant.num_actuated_dofs())
        )
        self.tip_frame = plant.GetFrameByName('tip')
        self.contact_port = plant.get_contact_results_output_port()
        self.query_port = plant.get_geometry_query_input_port()

    def run(self, impacts: int, t_max: float) -> PeerRun:
        """Step until ``impacts`` impacts have ended or ``t_max`` simulated seconds."""
        return closed_loop.run(self, self.scene, self.rate, impacts, t_max)

    # --- the stepper (closed_loop.PeerStepper)
    def start(self, joints: list[float], rates: list[float]) -> None:
        self.context.SetTime(0.0)
        for joint, angle, rate in zip(self.joint_list, joints, rates):
            joint.set_angle(self.plant_context, angle)
            joint.set_angular_rate(self.plant_context, rate)
        self._set_motors([0.0] * len(joints))
        self.simulator.Initialize()

    def time(self) -> float:
        return float(self.context.get_time())

    def joints(self) -> tuple[list[float], list[float]]:
        pc = self.plant_context
        theta = [float(j.get_angle(pc)) for j in self.joint_list]
        theta_d = [float(j.get_angular_rate(pc)) for j in self.joint_list]
        if not all(math.isfinite(x) for x in theta + theta_d):
            raise SimulationError(f'Drake state not finite at t = {self.time():.6f} s: {theta}')
        return theta, theta_d

    def advance(self, efforts: list[float], steps: int) -> bool:
        self._set_motors(efforts)
        self._advance(steps)
        return self._depth() is not None

    def step(self, efforts: list[float], motors_in_contact: bool) -> Step:
        depth = self._depth()
        touching = depth is not None
        v = self.tip_frame.CalcSpatialVelocityInWorld(self.plant_context).translational()
        before = TipState(self.time(), depth or 0.0, float(v[0]), float(v[2]))
        self._set_motors([0.0] * len(efforts) if touching and not motors_in_contact else efforts)
        self._advance(1)
        return Step(before, touching, self._normal_force())

    # --- Drake
    def _advance(self, steps: int) -> None:
        # the time of the step's end from the step count, so that rounding does not add a
        # step or drop one over a million
        n = round(self.time() / self.timestep) + steps
        self.simulator.AdvanceTo(n * self.timestep)

    def _set_motors(self, efforts: list[float]) -> None:
        u = np.zeros(len(self.actuation_at))
        for at, v in zip(self.actuation_at, efforts):
            u[at] = v
        self.actuation.GetMutableData().set_value(u)

    def _tip_pair(self, a: Any, b: Any) -> bool:
        pair = {a, b}
        return self.tip_geometry in pair and bool(pair & self.surface_geometries)

    def _depth(self) -> float | None:
        """The deepest tip/surface penetration of the current state; None: no contact."""
        query = self.query_port.Eval(self.plant_context)
        depths = [
            float(p.depth)
            for p in query.ComputePointPairPenetration()
            if self._tip_pair(p.id_A, p.id_B)
        ]
        return max(depths) if depths else None

    def _normal_force(self) -> float:
        """The normal force of the step just taken (Drake reports a discrete step's contact
        results at the state it ends in)."""
        results = self.contact_port.Eval(self.plant_context)
        total = 0.0
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            pair = info.point_pair()
            if self._tip_pair(pair.id_A, pair.id_B):
                total += abs(float(np.dot(info.contact_force(), pair.nhat_BA_W)))
        return total
