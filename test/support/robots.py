"""Public robot descriptions as they ship: example-robot-data's UR5 and double pendulum (its
installed files), and a RRBot-like xacro written for the tests (test/data/rrbot)."""

import copy
import os

import pytest

from impact_arm.physics.scene import parse_scene
from repo_paths import TEST_DATA
from scenes import paper_dict


def robots_dir():
    """Where example-robot-data's descriptions are installed (its package ships them as
    data files: found through its installed file list)."""
    from importlib import metadata

    try:
        files = metadata.distribution('example-robot-data').files or []
    except metadata.PackageNotFoundError:
        pytest.skip('example-robot-data is not installed (requirements-dev.txt)')
    for f in files:
        if str(f).endswith('ur_description/urdf/ur5_robot.urdf'):
            return str(f.locate().parent.parent.parent)
    pytest.skip('example-robot-data has no ur5_robot.urdf')


UR5_JOINTS = [  # the UR5's six joints, base to flange
    'shoulder_pan_joint',
    'shoulder_lift_joint',
    'elbow_joint',
    'wrist_1_joint',
    'wrist_2_joint',
    'wrist_3_joint',
]


UR5_ARM = {
    'joints': ['shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint'],
    'locked': {'shoulder_pan_joint': 0.3, 'wrist_2_joint': 0.0, 'wrist_3_joint': 0.7},
    'contact': {'link': 'ee_link', 'point': [0.0, 0.0, 0.0], 'radius': 0.02},
}


PENDULUM_ARM = {'contact': {'link': 'link3', 'point': [0.0, 0.0, 0.0], 'radius': 0.01}}


def robot_scene(arm, n, q_deg, kp=1.0, kd=0.1, surfaces=()):
    data = copy.deepcopy(paper_dict())
    del data['links'], data['tip_radius']
    data['arm'] = arm
    c = data['controller']
    c.update(kp=[kp] * n, kd=[kd] * n, down_target_deg=[0.0] * n, up_target_deg=[0.0] * n)
    c.pop('ki', None)
    data['initial'] = {'q_deg': list(q_deg)}
    data['surfaces'] = list(surfaces)
    return parse_scene(data, origin='robot')


def cases():
    root = robots_dir()
    ur5 = os.path.join(root, 'ur_description', 'urdf', 'ur5_robot.urdf')
    pendulum = os.path.join(
        root, 'double_pendulum_description', 'urdf', 'double_pendulum_simple.urdf'
    )
    rrbot = {
        'xacro': os.path.join(TEST_DATA, 'rrbot', 'urdf', 'rrbot.urdf.xacro'),
        'package_paths': [TEST_DATA],
        'contact': {'link': 'tool_link'},
    }
    return {
        'ur5': (ur5, {'urdf': ur5, **UR5_ARM}, 3, 'ee_link'),
        'pendulum': (pendulum, {'urdf': pendulum, **PENDULUM_ARM}, 2, 'link3'),
        'rrbot': (None, rrbot, 2, 'tool_link'),
    }
