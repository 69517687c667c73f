"""What an export writes for each peer: the model file(s) with the tuned contact, and the
README.md that says how to load them."""

from __future__ import annotations

import os

from .arm import PlanarArm
from .mjcf import MujocoContact, mjcf
from .peers import Peer
from .sdf import DrakeContact, GazeboContact, drake_sdf, gazebo_world

MODEL_FILES = {Peer.MUJOCO: 'arm.xml', Peer.DRAKE: 'arm.sdf', Peer.GAZEBO: 'world.sdf'}


def model_text(arm: PlanarArm, peer: Peer, contact: object) -> str:
    if peer is Peer.MUJOCO and isinstance(contact, MujocoContact):
        return mjcf(arm, contact)
    if peer is Peer.DRAKE and isinstance(contact, DrakeContact):
        return drake_sdf(arm, contact)
    if peer is Peer.GAZEBO and isinstance(contact, GazeboContact):
        return gazebo_world(arm, contact)
    raise TypeError(f'{peer.value}: no model for a contact of type {type(contact).__name__}')


def _ros2_control(arm: PlanarArm) -> str:
    joints = '\n'.join(
        f'    <joint name="{name}">\n'
        '      <command_interface name="effort"/>\n'
        '      <state_interface name="position"/>\n'
        '      <state_interface name="velocity"/>\n'
        '      <state_interface name="effort"/>\n'
        '    </joint>'
        for name in arm.joint_names
    )
    return (
        '```xml\n'
        '<ros2_control name="MujocoSystem" type="system">\n'
        '  <hardware>\n'
        '    <plugin>mujoco_ros2_control/MujocoSystem</plugin>\n'
        '  </hardware>\n'
        f'{joints}\n'
        '</ros2_control>\n'
        '```\n'
    )


def readme(arm: PlanarArm, peer: Peer, contact: object, timestep: float) -> str:
    names = ', '.join(f'`{n}`' for n in arm.joint_names)
    common = (
        f'# {arm.name} for {peer.value}\n\n'
        'Written by `impact-arm export`. The arm moves in the world x-z plane (z up); its '
        f"joints {names} carry the scene's joint names and read the angles of its "
        '/joint_states (same zero, same sign). The tip sphere is `tip`; the struck surfaces '
        "`surface1`, ... sit one tip radius below the scene's heights, because the package "
        "measures indentation at the tip's centre. Mounted surfaces are exported rigid. "
        f'Run at the time step the contact was fitted at: **{timestep:g} s**. '
        "report.md and report.json give the residual against the package's model; "
        'scene.yaml is the exported scene, which `impact-arm export --check DIR` reruns '
        'beside the package in closed loop (MuJoCo).\n\n'
    )
    if peer is Peer.MUJOCO:
        return common + (
            '## Load\n\n'
            '```python\n'
            'import mujoco\n'
            "model = mujoco.MjModel.from_xml_path('arm.xml')  # timestep set in <option>\n"
            'data = mujoco.MjData(model)\n'
            '```\n\n'
            'One `motor` actuator per joint, named as the joint (torque, gear 1, the '
            "scene's effort limits as ctrlrange). The contact is the `<pair>` of `tip` and "
            'each surface (solref, solimp, friction fitted).\n\n'
            '## mujoco_ros2_control\n\n'
            'Add to the robot description given to `mujoco_ros2_control` (plugin name of '
            'the ros-controls package; check it against the version you run), with the '
            'MJCF as its `mujoco_model` parameter:\n\n' + _ros2_control(arm)
        )
    if peer is Peer.DRAKE:
        return common + (
            '## Load\n\n'
            '```python\n'
            'from pydrake.multibody.parsing import Parser\n'
            'from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig\n'
            'from pydrake.systems.framework import DiagramBuilder\n'
            'builder = DiagramBuilder()\n'
            'plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(\n'
            f"    time_step={timestep!r}, contact_model='point',\n"
            "    discrete_contact_approximation='lagged'), builder)\n"
            "Parser(plant).AddModels('arm.sdf')\n"
            f'plant.mutable_gravity_field().set_gravity_vector([0, 0, {-arm.gravity!r}])\n'
            'plant.Finalize()\n'
            '```\n\n'
            'The fitted contact is point contact (Hunt-Crossley): hydroelastic contact, '
            "Drake's default model, ignores it. Each geometry carries the same stiffness, "
            'so the pair has half of it.\n'
        )
    return common + (
        '## Load\n\n'
        '`gz sim world.sdf` (the world holds the ODE engine at the fitted step, the '
        "scene's gravity and the arm). The arm's joints have no actuators here: add the "
        '`gz_ros2_control` plugin and a `<ros2_control>` block for its joints.\n\n'
        "**Not run in Gazebo**: the contact parameters come from a model of ODE's contact "
        '(docs/export.md).\n'
    )


def write(directory: str, name: str, text: str) -> str:
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, name)
    with open(path, 'w', encoding='utf-8') as f:
        f.write(text)
    return path
