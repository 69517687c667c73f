"""A strike run in Drake: the exported SDF in a discrete MultibodyPlant with point contact
(Hunt-Crossley, Drake's 'lagged' approximation), the arm set at contact in the robot's
joint coordinates, stepped with no actuation until the tip leaves the surface; at each phase
of the time step (``phases``), the outcome their mean."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .arm import PlanarArm
from .phases import PHASES, over_phases
from .sdf import DrakeContact, drake_sdf
from .strike import Outcome, Strike

MAX_CONTACT_TIME = 0.05  # [s] a strike still in contact after this is reported unseparated
APPROXIMATION = 'lagged'  # Drake's default discrete approximation with Hunt-Crossley


def plant_config(timestep: float) -> Any:
    from pydrake.multibody.plant import MultibodyPlantConfig

    return MultibodyPlantConfig(
        time_step=timestep, contact_model='point', discrete_contact_approximation=APPROXIMATION
    )


class _NoDeformableNotice:
    """Drops Drake's notice that a half-space takes no part in deformable contact (there
    is no deformable body here); every other message passes."""

    def filter(self, record: Any) -> bool:
        return 'deformable contact' not in record.getMessage()


def quiet_drake() -> None:
    import logging

    drake_log = logging.getLogger('drake')
    if not any(isinstance(f, _NoDeformableNotice) for f in drake_log.filters):
        drake_log.addFilter(_NoDeformableNotice())


class DrakeStriker:
    """One diagram; a candidate contact replaces the geometries' proximity properties in
    the diagram's context (``set_contact``: 0.4 ms where building a diagram takes 0.2 s)."""

    def __init__(self, arm: PlanarArm, contact: DrakeContact | None, timestep: float):
        from pydrake.multibody.parsing import Parser
        from pydrake.multibody.plant import AddMultibodyPlant
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(plant_config(timestep), builder)
        quiet_drake()
        Parser(plant).AddModelsFromString(drake_sdf(arm, contact), 'sdf')
        plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -arm.gravity])
        plant.Finalize()
        self.diagram = builder.Build()
        self.plant = plant
        self.timestep = timestep
        self.simulator = Simulator(self.diagram)
        self.tip = plant.GetFrameByName('tip')
        self.joints = [plant.GetJointByName(name) for name in arm.joint_names]
        self.scene_graph = scene_graph
        self.contact = contact

    def set_contact(self, contact: DrakeContact) -> None:
        """The contact's stiffness, dissipation and friction on every geometry of the pair,
        set in the context as the SDF sets them in the model (the striker must have been
        built with a contact: one built with Drake's defaults has no properties to set)."""
        from pydrake.geometry import ProximityProperties, Role, RoleAssign
        from pydrake.multibody.plant import CoulombFriction

        if self.contact is None:
            raise ValueError('a Drake striker built with the defaults takes no contact')
        graph = self.scene_graph
        context = graph.GetMyMutableContextFromRoot(self.simulator.get_mutable_context())
        inspector = graph.model_inspector()
        for geometry in inspector.GetAllGeometryIds(Role.kProximity):
            properties = ProximityProperties(inspector.GetProximityProperties(geometry))
            properties.UpdateProperty('material', 'point_contact_stiffness', contact.stiffness)
            properties.UpdateProperty('material', 'hunt_crossley_dissipation', contact.dissipation)
            properties.UpdateProperty(
                'material', 'coulomb_friction', CoulombFriction(contact.mu, contact.mu)
            )
            graph.AssignRole(
                context, self.plant.get_source_id(), geometry, properties, RoleAssign.kReplace
            )
        self.contact = contact

    def outcome(self, strike: Strike, phases: int = PHASES) -> Outcome:
        """The mean of the strike over ``phases`` phases of the time step."""
        return over_phases(self.one_phase, strike, self.timestep, phases)

    def one_phase(self, strike: Strike) -> Outcome:
        """The strike from its joint state at time 0 (the phase its start gives)."""
        plant, sim = self.plant, self.simulator
        context = sim.get_mutable_context()
        context.SetTime(0.0)
        pc = plant.GetMyMutableContextFromRoot(context)
        for joint, angle, rate in zip(self.joints, strike.joints, strike.joint_rates):
            joint.set_angle(pc, angle)
            joint.set_angular_rate(pc, rate)
        sim.Initialize()
        port = plant.get_contact_results_output_port()
        dt = self.timestep
        steps = int(MAX_CONTACT_TIME / dt)
        first = last = -1
        peak = 0.0
        for k in range(steps):
            sim.AdvanceTo((k + 1) * dt)
            results = port.Eval(pc)
            force = 0.0
            for i in range(results.num_point_pair_contacts()):
                info = results.point_pair_contact_info(i)
                force += abs(float(np.dot(info.contact_force(), info.point_pair().nhat_BA_W)))
            if force > 0.0:
                first = k if first < 0 else first
                last, peak = k, max(peak, force)
            elif first >= 0:
                break
        v = self.tip.CalcSpatialVelocityInWorld(pc).translational()
        separated = first >= 0 and last < steps - 1
        duration = (last - first + 1) * dt if first >= 0 else 0.0
        return Outcome(-float(v[2]) / strike.v_before[1], duration, peak, float(v[0]), separated)


def drake_outcomes(
    arm: PlanarArm, contact: DrakeContact | None, timestep: float, strikes: Sequence[Strike]
) -> list[Outcome]:
    striker = DrakeStriker(arm, contact, timestep)
    return [striker.outcome(s) for s in strikes]


def drake_problem(arm: PlanarArm, timestep: float, stiffness: float, mu: float) -> Any:
    """The Drake search: each geometry's point-contact stiffness (from ``stiffness``, a
    linear spring of our contact's duration), Hunt-Crossley dissipation and friction."""
    from .tuning import Parameter, PeerProblem

    start = math.log10(stiffness)
    striker = DrakeStriker(arm, DrakeContact(stiffness, 0.1, mu, timestep), timestep)
    parameters = (
        Parameter('stiffness', start, start - 3.0, start + 3.0, log=True),
        Parameter('dissipation', 0.1, 0.0, 5.0),
        Parameter('mu', mu, 0.0, 2.0),
    )

    def contact(v: dict[str, float]) -> DrakeContact:
        return DrakeContact(timestep=timestep, **v)

    def outcomes(c: DrakeContact, strikes: Sequence[Strike]) -> list[Outcome]:
        striker.set_contact(c)
        return [striker.outcome(s) for s in strikes]

    return PeerProblem(parameters, contact, outcomes)
