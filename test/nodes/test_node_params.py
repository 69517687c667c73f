"""The nodes' parameter tables, without DDS: one joint check for every node, joint names and
their number from the scene, and the shipped parameter files valid for any arm."""

import dataclasses
import os

import pytest
import yaml

from impact_arm.nodes import controller_params, param_types, simulator_params
from impact_arm.nodes.params import ParameterError, check_joints, scene_joint_names
from impact_arm.physics.scene import parse_scene
from ros_helpers import ROOT
from scenes import arm_dict, scene_from

SCENES = {2: scene_from(), 3: parse_scene(arm_dict(3)), 4: parse_scene(arm_dict(4))}
SCENE_TABLES = {
    'simulator': simulator_params.parameter_table,
    'controller': controller_params.parameter_table,
}
SCENE_CLASSES = {
    'simulator': param_types.SimulatorParameters,
    'controller': param_types.ControllerParameters,
}


def test_check_joints_takes_any_order_of_the_scenes_joints():
    names = ['joint1', 'joint2', 'joint3']
    assert check_joints(names, names) == [0, 1, 2]
    assert check_joints(['joint3', 'joint1', 'joint2'], names) == [2, 0, 1]


@pytest.mark.parametrize(
    'given',
    [
        ['joint1', 'joint2'],  # the article's two joints on a three-link arm
        ['joint1', 'joint2', 'joint2'],
        ['joint1', 'joint2', 'joint3', 'joint4'],
        ['joint1', 'joint2', 'jointX'],
        [],
    ],
)
def test_check_joints_refuses_in_one_line_naming_parameter_value_and_joints(given):
    with pytest.raises(ParameterError) as refused:
        check_joints(given, ['joint1', 'joint2', 'joint3'], 'joints')
    message = str(refused.value)
    assert message.startswith(f'parameter joints = {given}')
    assert "['joint1', 'joint2', 'joint3']" in message and '\n' not in message


def test_joint_order_beyond_nine_joints_is_checked_by_name_not_by_sort_order():
    names = [f'joint{i + 1}' for i in range(12)]
    assert check_joints(names, names) == list(range(12))
    assert check_joints(names[::-1], names) == list(range(12))[::-1]


@pytest.mark.parametrize('n', sorted(SCENES))
@pytest.mark.parametrize('node', sorted(SCENE_TABLES))
def test_joint_parameters_default_to_the_scenes_joints(node, n):
    scene = SCENES[n]
    table = {p.name: p for p in SCENE_TABLES[node](scene)}
    assert (
        table['joints'].default == scene_joint_names(scene) == [f'joint{i + 1}' for i in range(n)]
    )
    assert table['joints'].size == n
    for p in table.values():  # no other parameter sized for another arm
        if p.kind in ('floats', 'strs') and p.size is not None:
            assert p.size == n, p.name


@pytest.mark.parametrize('n', sorted(SCENES))
@pytest.mark.parametrize('node', sorted(SCENE_TABLES))
def test_shipped_parameter_files_fit_an_arm_of_any_number_of_links(node, n):
    """The launch file passes config/NODE.yaml whatever the scene: nothing in it may be
    sized for the article's two links."""
    with open(os.path.join(ROOT, 'config', f'{node}.yaml'), encoding='utf-8') as f:
        given = yaml.safe_load(f)[node]['ros__parameters']
    table = {p.name: p for p in SCENE_TABLES[node](SCENES[n])}
    for name, value in given.items():
        table[name].check(value)


def test_docs_parameter_tables_are_generated_from_the_nodes_tables():
    """docs/nodes.md and docs/topics.md show each node's table as the node declares it
    (regenerate with python -m impact_arm.nodes.param_docs)."""
    from impact_arm.nodes import param_docs

    assert param_docs.main(['--check']) == 0


def test_parameter_classes_are_generated_from_the_nodes_tables():
    """param_types.py is what the generator makes of the tables as they are now (regenerate
    with python -m impact_arm.nodes.param_docs)."""
    from impact_arm.nodes import param_docs

    with open(param_docs.TYPES_MODULE, encoding='utf-8') as f:
        assert f.read() == param_docs.types_module()


@pytest.mark.parametrize('n', sorted(SCENES))
@pytest.mark.parametrize('node', sorted(SCENE_TABLES))
def test_parameter_classes_fit_the_table_of_any_scene(node, n):
    """The classes are static: a scene-dependent table has their fields, in their order, for
    an arm of any number of links, and its defaults fill them."""
    table = SCENE_TABLES[node](SCENES[n])
    cls = SCENE_CLASSES[node]
    assert [p.name for p in table] == [f.name for f in dataclasses.fields(cls)]
    values = cls(**{p.name: p.check(p.default) for p in table})
    reordered = values.replace(joints=values.joints[::-1])
    assert check_joints(reordered.joints, values.joints) == list(range(n))[::-1]
    assert dataclasses.replace(reordered, joints=values.joints) == values


def test_every_node_declares_its_parameters_through_one_table():
    from impact_arm.nodes import param_docs

    for node, (_, table) in param_docs.tables().items():
        names = [p.name for p in table]
        assert len(names) == len(set(names)), node
        for p in table:  # each default passes its own check
            p.check(list(p.default) if isinstance(p.default, tuple) else p.default)
