"""Planar arms written as URDF by hand, at random, and scenes that load them."""

import copy
import math

from impact_arm.contract import to_joint_space
from impact_arm.physics.scene import parse_scene
from scenes import paper_dict


def num(value):
    return repr(float(value))


def random_urdf(rng, n, base_height=0.3):
    """A planar arm written by hand, as a user's description might be: a base link fixed to
    the world (with mass: the ground's), links with centres of mass off their axis (also out
    of the plane, which the planar model ignores) and full inertia tensors given in turned
    inertial frames, limits and dynamics on some joints, a sensor frame, and a tool link
    fixed to the last link carrying the contact sphere. Returns (text, lengths, tip)."""
    lengths = rng.uniform(0.3, 1.0, n)
    tip = (rng.uniform(0.6, 1.1) * lengths[-1], rng.uniform(-0.1, 0.1))
    parts = [
        '<robot name="hand_written">',
        '<link name="world"/>',
        '<link name="base"><inertial><mass value="5"/>'
        '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>',
        f'<joint name="base_joint" type="fixed"><parent link="world"/><child link="base"/>'
        f'<origin xyz="0.1 0 {base_height}" rpy="0 0 0"/></joint>',
    ]
    for k in range(n):
        mass = rng.uniform(0.3, 2.0)
        com = (
            rng.uniform(-0.2, 0.9) * lengths[k],
            rng.uniform(-0.05, 0.05),
            rng.uniform(-0.2, 0.2) * lengths[k],
        )
        principal = rng.uniform(0.01, 0.1, 3)
        principal[2] = rng.uniform(
            abs(principal[0] - principal[1]) + 1e-3, principal[0] + principal[1]
        )
        rpy = rng.uniform(-math.pi, math.pi, 3)
        parts.append(
            f'<link name="l{k}"><inertial><origin xyz="{num(com[0])} {num(com[1])} {num(com[2])}" '
            f'rpy="{num(rpy[0])} {num(rpy[1])} {num(rpy[2])}"/><mass value="{num(mass)}"/>'
            f'<inertia ixx="{num(principal[0])}" ixy="0" ixz="0" iyy="{num(principal[1])}" iyz="0" '
            f'izz="{num(principal[2])}"/></inertial></link>'
        )
        parent = 'base' if k == 0 else f'l{k - 1}'
        x = 0.0 if k == 0 else lengths[k - 1]
        kind = 'revolute' if k % 2 else 'continuous'
        limit = '<limit lower="-2.5" upper="2.0" effort="40" velocity="6"/>' if k % 2 else ''
        dynamics = f'<dynamics damping="{num(0.1 * k)}" friction="{num(0.05 * k)}"/>' if k else ''
        parts.append(
            f'<joint name="j{k}" type="{kind}"><parent link="{parent}"/><child link="l{k}"/>'
            f'<origin xyz="{num(x)} 0 0" rpy="0 0 0"/><axis xyz="0 -1 0"/>{limit}{dynamics}</joint>'
        )
    last = f'l{n - 1}'
    parts += [
        '<link name="camera"/>',
        '<joint name="camera_joint" type="fixed"><parent link="l0"/><child link="camera"/>'
        '<origin xyz="0.1 0.05 0.02" rpy="0.3 -1.0 0.2"/></joint>',
        '<link name="tool"><collision><origin xyz="0 0 0"/><geometry><sphere radius="0.006"/>'
        '</geometry></collision></link>',
        f'<joint name="tool_joint" type="fixed"><parent link="{last}"/><child link="tool"/>'
        f'<origin xyz="{num(tip[0])} 0 {num(tip[1])}" rpy="0 0 0"/></joint>',
        '</robot>',
    ]
    return '\n'.join(parts), lengths, tip


def scene_data(urdf_path, n, **contact):
    data = copy.deepcopy(paper_dict())
    del data['links'], data['tip_radius']
    data['arm'] = {'urdf': str(urdf_path), 'contact': {'link': 'tool', **contact}}
    controller = data['controller']
    for key in ('kp', 'kd', 'ki', 'down_target_deg', 'up_target_deg'):
        controller[key] = (controller[key] * n)[:n]
    # a URDF arm's angles are the robot's joint angles: relative ones for this convention
    for key in ('down_target_deg', 'up_target_deg'):
        controller[key] = to_joint_space(controller[key])
    data['initial'] = {'q_deg': to_joint_space([60.0 - 10 * k for k in range(n)])}
    data['surfaces'] = [{'height': -0.25, 'material': 'steel'}]
    return data


def load(tmp_path, text, n, **contact):
    path = tmp_path / 'arm.urdf'
    path.write_text(text)
    return parse_scene(scene_data(path, n, **contact), origin='test', path=str(tmp_path / 's.yaml'))
