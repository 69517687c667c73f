"""A xacro description expanded without ROS (impact_arm/physics/scene/xacro.py): ``$(find pkg)``
through the scene's package_paths (then the ament index), the scene's args over the file's
defaults, and every failure a one-line SceneError starting with the scene key that gave it."""

import math
import os
import threading
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from impact_arm.physics.errors import SceneError
from impact_arm.physics.scene.xacro import (
    PackageIndex,
    expand_xacro,
    find_package,
    resolve_package_uri,
)
from repo_paths import TEST_DATA

DATA = TEST_DATA
RRBOT = os.path.join(DATA, 'rrbot', 'urdf', 'rrbot.urdf.xacro')
ORIGIN = "scene 'x': arm.xacro 'robot.urdf.xacro'"
PKG = 'my_robot_description'

PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>test</description>
  <maintainer email="a@example.com">a</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <exec_depend>xacro</exec_depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""

PARTS = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="width" value="0.05"/>
  <xacro:macro name="rod" params="name length mass">
    <link name="${name}">
      <inertial>
        <origin xyz="${length / 2} 0 0"/>
        <mass value="${mass}"/>
        <inertia ixx="0" ixy="0" ixz="0" iyy="${mass * length**2 / 12}" iyz="0" izz="0"/>
      </inertial>
      <visual>
        <geometry><mesh filename="package://my_robot_description/meshes/x.stl"/></geometry>
      </visual>
    </link>
  </xacro:macro>
</robot>
"""

ROBOT = """<?xml version="1.0"?>
<robot name="two" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:arg name="prefix" default=""/>
  <xacro:arg name="length" default="0.5"/>
  <xacro:arg name="with_tool" default="false"/>
  <xacro:property name="mass" value="2.0"/>
  <xacro:property name="L" value="$(arg length)"/>
  <xacro:include filename="$(find my_robot_description)/urdf/parts.xacro"/>
  <link name="$(arg prefix)base"/>
  <joint name="$(arg prefix)joint1" type="revolute">
    <parent link="$(arg prefix)base"/>
    <child link="$(arg prefix)link1"/>
    <axis xyz="0 -1 0"/>
    <limit lower="-3" upper="3" effort="50" velocity="5"/>
  </joint>
  <xacro:rod name="$(arg prefix)link1" length="${L}" mass="${mass}"/>
  <joint name="$(arg prefix)joint2" type="continuous">
    <parent link="$(arg prefix)link1"/>
    <child link="$(arg prefix)link2"/>
    <origin xyz="${L} 0 0"/>
    <axis xyz="0 -1 0"/>
  </joint>
  <xacro:rod name="$(arg prefix)link2" length="${L}" mass="${mass / 2}"/>
  <xacro:if value="$(arg with_tool)">
    <link name="$(arg prefix)tool">
      <collision><geometry><sphere radius="${width}"/></geometry></collision>
    </link>
  </xacro:if>
</robot>
"""


def write_package(root, name=PKG, robot=ROBOT, parts=PARTS):
    """A ROS 2 description package at ``root/name`` (package.xml, urdf/, meshes/)."""
    package = root / name
    (package / 'urdf').mkdir(parents=True)
    (package / 'meshes').mkdir()
    (package / 'package.xml').write_text(PACKAGE_XML.format(name=name))
    (package / 'urdf' / 'robot.urdf.xacro').write_text(robot)
    (package / 'urdf' / 'parts.xacro').write_text(parts)
    (package / 'meshes' / 'x.stl').write_text('solid x\nendsolid x\n')
    return package


@pytest.fixture
def workspace(tmp_path):
    """A colcon-like workspace ws/src/<package>; the package's directory is returned."""
    return write_package(tmp_path / 'ws' / 'src')


@pytest.fixture(autouse=True)
def no_ament_index(monkeypatch):
    """No ament index unless a test makes one: each test's packages come from its paths."""
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)


def refusal(*args, **kwargs):
    with pytest.raises(SceneError) as info:
        expand_xacro(*args, **kwargs)
    message = str(info.value)
    assert '\n' not in message, message
    assert message.startswith(ORIGIN + ': '), message
    return message


def robot_file(package):
    return str(package / 'urdf' / 'robot.urdf.xacro')


def by_name(root, tag):
    return {e.get('name'): e for e in root.findall(tag)}  # the robot's, not ros2_control's


@pytest.mark.parametrize('where', ['package', 'src', 'ws'])
def test_find_resolves_through_the_package_or_a_directory_holding_it(workspace, where):
    path = {'package': workspace, 'src': workspace.parent, 'ws': workspace.parent.parent}[where]
    text = expand_xacro(robot_file(workspace), None, [str(path)], ORIGIN)
    root = ET.fromstring(text.split('?>', 1)[1])
    assert root.tag == 'robot' and root.get('name') == 'two'
    assert set(by_name(root, 'link')) == {'base', 'link1', 'link2'}  # no tool by default
    joints = by_name(root, 'joint')
    assert [joints[j].get('type') for j in ('joint1', 'joint2')] == ['revolute', 'continuous']
    assert joints['joint2'].find('origin').get('xyz') == '0.5 0 0'  # the arg's default
    links = by_name(root, 'link')
    assert float(links['link1'].find('inertial/mass').get('value')) == 2.0  # the property
    assert float(links['link2'].find('inertial/mass').get('value')) == 1.0
    iyy = float(links['link1'].find('inertial/inertia').get('iyy'))
    assert iyy == pytest.approx(2.0 * 0.5**2 / 12, rel=1e-12)
    # mesh URIs stay as they are: the text is the same on every machine
    assert links['link1'].find('visual/geometry/mesh').get('filename') == (
        'package://my_robot_description/meshes/x.stl'
    )
    assert str(workspace) not in text and '$(' not in text and '${' not in text


def test_args_override_the_files_defaults(workspace):
    text = expand_xacro(
        robot_file(workspace),
        {'prefix': 'left_', 'length': 0.8, 'with_tool': True},
        [str(workspace)],
        ORIGIN,
    )
    root = ET.fromstring(text.split('?>', 1)[1])
    assert set(by_name(root, 'link')) == {'left_base', 'left_link1', 'left_link2', 'left_tool'}
    joints = by_name(root, 'joint')
    assert joints['left_joint2'].find('origin').get('xyz') == '0.8 0 0'
    iyy = float(by_name(root, 'link')['left_link1'].find('inertial/inertia').get('iyy'))
    assert iyy == pytest.approx(2.0 * 0.8**2 / 12, rel=1e-12)
    radius = by_name(root, 'link')['left_tool'].find('collision/geometry/sphere').get('radius')
    assert float(radius) == 0.05  # a property of the included file
    # an int, a string and a float that prints with an exponent are all numbers to xacro
    for value, expected in ((2, 2.0), ('0.25', 0.25), (1e-5, 1e-5)):
        text = expand_xacro(robot_file(workspace), {'length': value}, [str(workspace)], ORIGIN)
        origin = by_name(ET.fromstring(text.split('?>', 1)[1]), 'joint')['joint2'].find('origin')
        assert float(origin.get('xyz').split()[0]) == pytest.approx(expected, rel=1e-12)
    # the text says where it came from and with which args, and nothing of this machine
    first = text.splitlines()[1]
    assert 'robot.urdf.xacro' in first and "length='1.0e-05'" in first
    assert "with_tool='false'" in first


def test_relative_paths_are_relative_to_the_scene_directory(workspace, tmp_path):
    scene_dir = tmp_path / 'scenes'
    scene_dir.mkdir()
    relative = os.path.relpath(workspace, scene_dir)
    text = expand_xacro(
        os.path.join(relative, 'urdf', 'robot.urdf.xacro'),
        {},
        [os.path.join('..', 'ws')],
        ORIGIN,
        base_dir=str(scene_dir),
    )
    assert '<link name="link2">' in text


def test_the_first_package_path_holding_a_package_wins(workspace, tmp_path):
    other = write_package(tmp_path / 'other', parts=PARTS.replace('0.05', '0.07'))
    for paths, radius in (([other.parent, workspace], 0.07), ([workspace, other.parent], 0.05)):
        text = expand_xacro(
            robot_file(workspace), {'with_tool': 'true'}, [str(p) for p in paths], ORIGIN
        )
        assert f'<sphere radius="{radius}"/>' in text


def test_an_unknown_package_names_it_and_where_it_was_looked_for(workspace, tmp_path):
    empty = tmp_path / 'empty'
    empty.mkdir()
    message = refusal(robot_file(workspace), None, [str(empty)], ORIGIN)
    assert f"package '{PKG}' not found" in message
    assert str(empty) in message and 'arm.package_paths' in message
    assert 'AMENT_PREFIX_PATH is not set' in message
    # with none given too
    message = refusal(robot_file(workspace), None, [], ORIGIN)
    assert f"package '{PKG}' not found" in message and 'none given' in message


def test_a_package_path_that_is_no_directory_is_refused(workspace, tmp_path):
    message = refusal(robot_file(workspace), None, [str(tmp_path / 'nowhere')], ORIGIN)
    assert 'arm.package_paths' in message and 'nowhere' in message
    message = refusal(robot_file(workspace), None, str(workspace), ORIGIN)
    assert 'must be a list' in message


def test_a_missing_file_is_refused(tmp_path):
    message = refusal(str(tmp_path / 'robot.urdf.xacro'), None, [], ORIGIN)
    assert 'no such file' in message and str(tmp_path) in message


def test_an_unclosed_tag_is_refused_naming_the_included_file(workspace):
    (workspace / 'urdf' / 'parts.xacro').write_text(PARTS.replace('</link>', '', 1))
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert 'not well-formed XML' in message and 'mismatched tag' in message
    assert 'parts.xacro' in message
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(ROBOT.replace('</robot>', ''))
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert 'not well-formed XML' in message


def test_an_undefined_property_is_refused_naming_it(workspace):
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(
        ROBOT.replace('mass="${mass / 2}"', 'mass="${masss / 2}"')
    )
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert 'masss' in message and 'undefined' in message


def test_a_missing_include_is_refused_naming_it(workspace):
    (workspace / 'urdf' / 'parts.xacro').unlink()
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert 'parts.xacro' in message and 'No such file' in message


def test_an_arg_without_value_is_refused_naming_it(workspace):
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(
        ROBOT.replace('<xacro:arg name="length" default="0.5"/>', '')
    )
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert "xacro arg 'length' has no value" in message and 'arm.args' in message
    # given, it expands
    assert 'link2' in expand_xacro(robot_file(workspace), {'length': 1}, [str(workspace)], ORIGIN)


def test_an_arg_the_file_does_not_read_is_refused_as_a_typo(workspace):
    message = refusal(robot_file(workspace), {'lenght': 0.8}, [str(workspace)], ORIGIN)
    assert "'lenght'" in message and 'length' in message and 'prefix' in message


@pytest.mark.parametrize('value', [[1, 2], None, math.inf, {'a': 1}])
def test_an_arg_value_xacro_cannot_take_is_refused(workspace, value):
    message = refusal(robot_file(workspace), {'length': value}, [str(workspace)], ORIGIN)
    assert "arm.args 'length'" in message


def test_a_document_that_is_not_a_robot_is_refused(workspace):
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text('<sdf version="1.9"/>')
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert 'not a URDF <robot>' in message


def test_a_broken_package_manifest_is_refused_naming_it(workspace):
    (workspace / 'package.xml').write_text('<package><name></name></package>')
    message = refusal(robot_file(workspace), None, [str(workspace.parent)], ORIGIN)
    assert 'package.xml' in message and '<name>' in message


def test_package_uris_resolve_through_the_same_paths(workspace):
    uri = f'package://{PKG}/meshes/x.stl'
    path = resolve_package_uri(uri, [str(workspace.parent)])
    assert path == str(workspace / 'meshes' / 'x.stl') and os.path.isfile(path)
    assert find_package(PKG, [str(workspace.parent)], ORIGIN) == str(workspace)
    assert resolve_package_uri('file:///a/b.stl', []) == '/a/b.stl'
    with pytest.raises(SceneError) as info:
        resolve_package_uri('package://nobody/x.stl', [str(workspace.parent)], origin=ORIGIN)
    assert str(info.value).startswith(ORIGIN + ": package 'nobody' not found")
    # ignored and hidden directories are not searched
    (workspace.parent / 'COLCON_IGNORE').write_text('')
    with pytest.raises(SceneError):
        PackageIndex([str(workspace.parent.parent)], ORIGIN).find(PKG)


def test_the_ament_index_is_the_fallback(workspace, tmp_path, monkeypatch):
    """A package the paths do not hold comes from the ament index, where there is one."""
    pytest.importorskip('ament_index_python')
    prefix = tmp_path / 'install'
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PKG).write_text('')
    os.symlink(workspace, prefix / 'share' / PKG)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    text = expand_xacro(robot_file(workspace), None, [], ORIGIN)
    assert '<link name="link2">' in text
    # an unknown package names the index it looked in
    message = refusal(
        robot_file(workspace).replace('robot.urdf', 'other.urdf'), None, [], ORIGIN, base_dir=''
    )
    assert 'no such file' in message
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(ROBOT.replace('$(find ', '$(find x'))
    message = refusal(robot_file(workspace), None, [], ORIGIN)
    assert f"'x{PKG}' not found" in message and f'AMENT_PREFIX_PATH={prefix}' in message


def test_xacro_is_left_as_it_was_found(workspace):
    """The find function is substituted only while expanding, failure or not."""
    from xacro import substitution_args

    before = (substitution_args._eval_find, substitution_args._eval_dict['find'])
    expand_xacro(robot_file(workspace), None, [str(workspace)], ORIGIN)
    refusal(robot_file(workspace), None, [], ORIGIN)
    assert (substitution_args._eval_find, substitution_args._eval_dict['find']) == before


def test_expansions_in_threads_do_not_mix(tmp_path):
    """xacro's module state is shared: expansions at once each get their own packages."""
    packages = [
        write_package(tmp_path / f'ws{k}', parts=PARTS.replace('0.05', f'0.0{k + 1}'))
        for k in range(4)
    ]
    barrier = threading.Barrier(4)

    def expand(k):
        barrier.wait()
        return [
            expand_xacro(robot_file(packages[k]), {'with_tool': True}, [str(packages[k])], ORIGIN)
            for _ in range(3)
        ]

    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(expand, range(4)))
    for k, texts in enumerate(results):
        assert all(f'<sphere radius="0.0{k + 1}"/>' in t for t in texts)


def test_the_rrbot_description_expands_and_pinocchio_loads_it():
    text = expand_xacro(RRBOT, None, [DATA], "scene 'rrbot': arm.xacro 'rrbot.urdf.xacro'")
    root = ET.fromstring(text.split('?>', 1)[1])
    joints, links = by_name(root, 'joint'), by_name(root, 'link')
    assert set(links) == {'world', 'base_link', 'link1', 'link2', 'tool_link'}
    assert joints['base_joint'].get('type') == 'fixed'
    assert joints['base_joint'].find('origin').get('xyz') == '0 0 1.95'
    for name, xyz in (('joint1', '0 0.1 0'), ('joint2', '0 0.1 1.0')):
        joint = joints[name]
        assert joint.get('type') == 'revolute' and joint.find('axis').get('xyz') == '0 1 0'
        assert joint.find('origin').get('xyz') == xyz
        limit = joint.find('limit')
        assert float(limit.get('effort')) == 100.0 and float(limit.get('velocity')) == 10.0
        assert float(limit.get('upper')) == -float(limit.get('lower')) == math.pi
    for name in ('link1', 'link2'):
        inertial = links[name].find('inertial')
        assert float(inertial.find('mass').get('value')) == 1.0
        assert inertial.find('origin').get('xyz') == '0 0 0.5'
        inertia = inertial.find('inertia')
        assert float(inertia.get('iyy')) == pytest.approx((0.1**2 + 1.0**2) / 12, rel=1e-12)
        assert float(inertia.get('izz')) == pytest.approx((0.1**2 + 0.1**2) / 12, rel=1e-12)
    assert joints['tool_joint'].find('origin').get('xyz') == '0 0 1.0'
    assert links['tool_link'].find('inertial') is None
    assert float(links['tool_link'].find('collision/geometry/sphere').get('radius')) == 0.05
    (control,) = root.iter('ros2_control')
    assert [j.get('name') for j in control.iter('joint')] == ['joint1', 'joint2']
    assert [c.get('name') for c in control.iter('command_interface')] == ['effort', 'effort']

    pin = pytest.importorskip('pinocchio')
    model = pin.buildModelFromXML(text)
    assert (model.nq, model.nv) == (2, 2)
    assert list(model.names)[1:] == ['joint1', 'joint2']
    assert list(model.effortLimit) == [100.0, 100.0]
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(2))
    pin.updateFramePlacements(model, data)
    tool = data.oMf[model.getFrameId('tool_link')].translation
    assert list(tool) == pytest.approx([0.0, 0.2, 1.95 + 2.0], abs=1e-12)


def test_the_rrbot_takes_its_args():
    pin = pytest.importorskip('pinocchio')
    text = expand_xacro(
        RRBOT, {'prefix': 'r_', 'link_length': 0.8}, [os.path.join(DATA, 'rrbot')], ORIGIN
    )
    model = pin.buildModelFromXML(text)
    assert list(model.names)[1:] == ['r_joint1', 'r_joint2']
    data = model.createData()
    pin.forwardKinematics(model, data, np.array([0.0, math.pi / 2]))
    pin.updateFramePlacements(model, data)
    tool = data.oMf[model.getFrameId('r_tool_link')].translation
    # joint2 turns link 2 about +y: its +z end swings to +x
    assert list(tool) == pytest.approx([0.8, 0.2, 1.95 + 0.8], abs=1e-12)
    link2 = model.inertias[model.getJointId('r_joint2')]
    assert link2.mass == 1.0 and list(link2.lever) == pytest.approx([0, 0, 0.4])


def test_a_substitution_error_is_told_once(workspace):
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(
        ROBOT.replace('"$(arg prefix)base"/>', '"$(env IMPACT_ARM_NO_SUCH_VARIABLE)base"/>')
    )
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert message.count('IMPACT_ARM_NO_SUCH_VARIABLE') == 1 and '<class' not in message
    (workspace / 'urdf' / 'robot.urdf.xacro').write_text(
        ROBOT.replace('"$(arg prefix)base"/>', '"$(eval 1 +)base"/>')
    )
    message = refusal(robot_file(workspace), None, [str(workspace)], ORIGIN)
    assert message.count('invalid syntax') == 1 and '<class' not in message
