"""The launch file and the node parameter files: what a ROS 2 user starts with
`ros2 launch impact_arm arm.launch.py` must name real executables and valid parameters."""

import ast
import contextlib
import os
import signal
import subprocess
import sys
import time
import types

import pytest
import yaml

from ros_helpers import PYTHON, ROOT, controller, start_process, wait_for

NODES = ('simulator', 'controller', 'recorder')


def console_scripts():
    tree = ast.parse(open(os.path.join(ROOT, 'setup.py')).read())
    scripts = [
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and ' = impact_arm.' in n.value
    ]
    return {s.split(' = ')[0] for s in scripts}


def load_launch_with_stubs(share):
    """Evaluate launch/arm.launch.py against minimal stand-ins of launch/launch_ros."""
    created = []

    class Action:
        def __init__(self, *args, **kwargs):
            self.args, self.kwargs = args, kwargs
            created.append(self)

    stubs = {
        'ament_index_python': types.ModuleType('ament_index_python'),
        'ament_index_python.packages': types.ModuleType('ament_index_python.packages'),
        'launch': types.ModuleType('launch'),
        'launch.actions': types.ModuleType('launch.actions'),
        'launch.substitutions': types.ModuleType('launch.substitutions'),
        'launch_ros': types.ModuleType('launch_ros'),
        'launch_ros.actions': types.ModuleType('launch_ros.actions'),
        'launch.conditions': types.ModuleType('launch.conditions'),
        'launch_ros.parameter_descriptions': types.ModuleType('launch_ros.parameter_descriptions'),
    }
    stubs['ament_index_python.packages'].get_package_share_directory = lambda pkg: share
    stubs['launch'].LaunchDescription = lambda actions: actions
    stubs['launch.actions'].DeclareLaunchArgument = type('DeclareLaunchArgument', (Action,), {})
    stubs['launch.substitutions'].LaunchConfiguration = type('LaunchConfiguration', (Action,), {})
    stubs['launch.substitutions'].PythonExpression = type('PythonExpression', (Action,), {})
    stubs['launch_ros.actions'].Node = type('Node', (Action,), {})
    stubs['launch.conditions'].IfCondition = type('IfCondition', (Action,), {})
    stubs['launch.substitutions'].Command = type('Command', (Action,), {})
    stubs['launch_ros.parameter_descriptions'].ParameterValue = type(
        'ParameterValue', (Action,), {}
    )
    saved = {k: sys.modules.get(k) for k in stubs}
    sys.modules.update(stubs)
    try:
        namespace = {}
        path = os.path.join(ROOT, 'launch', 'arm.launch.py')
        exec(compile(open(path).read(), path, 'exec'), namespace)
        return namespace['generate_launch_description']()
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v


def test_launch_file_starts_the_three_nodes_with_their_parameter_files():
    actions = load_launch_with_stubs(ROOT)
    nodes = [
        a for a in actions if type(a).__name__ == 'Node' and a.kwargs['package'] == 'impact_arm'
    ]
    arguments = {a.args[0] for a in actions if type(a).__name__ == 'DeclareLaunchArgument'}
    assert {'scene', 'law', 'rate', 'mode', 'tf', 'rviz', 'cycles'} <= arguments
    controller = next(n for n in nodes if n.kwargs['executable'] == 'controller')
    cycles = controller.kwargs['parameters'][1]['cycles']
    assert cycles.args[0].args == ('cycles',) and cycles.kwargs == {'value_type': int}
    assert sorted(n.kwargs['executable'] for n in nodes) == sorted(NODES)
    assert {n.kwargs['executable'] for n in nodes} <= console_scripts()
    for n in nodes:
        files = [p for p in n.kwargs['parameters'] if isinstance(p, str)]
        assert files == [os.path.join(ROOT, 'config', n.kwargs['executable'] + '.yaml')]
        assert os.path.exists(files[0])


def test_tf_rsp_starts_robot_state_publisher_with_the_urdf_and_rviz_its_shipped_config():
    """tf:=rsp: robot_state_publisher gets the output of `impact-arm urdf` for the launched
    scene and the simulator stops publishing TF; rviz:=true opens config/impact_arm.rviz."""
    actions = load_launch_with_stubs(ROOT)
    by_package = {a.kwargs['package']: a for a in actions if type(a).__name__ == 'Node'}
    rsp, rviz, sim = (
        by_package['robot_state_publisher'],
        by_package['rviz2'],
        [
            a
            for a in actions
            if type(a).__name__ == 'Node' and a.kwargs.get('executable') == 'simulator'
        ][0],
    )

    def text(sub):  # a stub substitution tree flattened to the text it would evaluate
        if isinstance(sub, str):
            return sub
        if isinstance(sub, (list, tuple)):
            return ''.join(text(s) for s in sub)
        return type(sub).__name__ + '(' + ''.join(text(a) for a in sub.args) + ')'

    rsp_condition = text(rsp.kwargs['condition'])
    assert "' == 'rsp'" in rsp_condition and 'LaunchConfiguration(tf)' in rsp_condition
    command = rsp.kwargs['parameters'][0]['robot_description'].args[0]
    assert text(command) == (
        'Command(python3 -m impact_arm.tools.cli urdf --scene LaunchConfiguration(scene))'
    )
    assert text(rsp.kwargs['condition'].args[0]) in text(sim.kwargs['parameters'][1]['publish_tf'])
    assert text(rviz.kwargs['condition']) == 'IfCondition(LaunchConfiguration(rviz))'
    config = rviz.kwargs['arguments'][1]
    assert config == os.path.join(ROOT, 'config', 'impact_arm.rviz')
    rviz_config = yaml.safe_load(open(config))
    displays = {d['Class']: d for d in rviz_config['Visualization Manager']['Displays']}
    assert (
        displays['rviz_default_plugins/RobotModel']['Description Topic']['Value']
        == '/robot_description'
    )
    assert displays['rviz_default_plugins/MarkerArray']['Topic']['Value'] == '/impact_markers'
    assert rviz_config['Visualization Manager']['Global Options']['Fixed Frame'] == 'world'


def test_rviz_view_looks_along_y_onto_the_arms_x_z_plane():
    """REP 103: z up, the arm moves in x-z. RViz's orbit camera sits at focal + distance *
    (cos yaw cos pitch, sin yaw cos pitch, sin pitch): here on -y, level, so it looks along
    +y with x to the right and z up."""
    import math

    config = yaml.safe_load(open(os.path.join(ROOT, 'config', 'impact_arm.rviz')))
    view = config['Visualization Manager']['Views']['Current']
    assert view['Class'] == 'rviz_default_plugins/Orbit'
    yaw, pitch = view['Yaw'], view['Pitch']
    direction = (math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch))
    assert direction == pytest.approx((0, -1, 0), abs=1e-6)
    grid = next(
        d
        for d in config['Visualization Manager']['Displays']
        if d['Class'] == 'rviz_default_plugins/Grid'
    )
    assert grid['Plane'] == 'XZ'


def test_foxglove_layout_shows_the_arm_plots_and_impact_table(tmp_path):
    """config/impact_arm.foxglove.json: every panel in the layout tree is configured, the 3D
    camera looks along +y onto the x-z plane, and every topic a panel reads is in a
    recording."""
    import json
    import math
    import re

    from impact_arm.physics.simulate import run
    from impact_arm.io.offline_mcap import OfflineRecorder
    from scenes import scene_from

    layout = json.load(open(os.path.join(ROOT, 'config', 'impact_arm.foxglove.json')))

    def panels(node):
        if isinstance(node, str):  # a tab panel holds the layouts of its tabs
            tabs = layout['configById'][node].get('tabs', [])
            return [node] + [p for tab in tabs for p in panels(tab['layout'])]
        return panels(node['first']) + panels(node['second'])

    shown = panels(layout['layout'])
    assert sorted(shown) == sorted(layout['configById'])
    kinds = {panel.split('!')[0] for panel in shown}
    assert kinds == {'3D', 'Plot', 'Table', 'Tab'}
    three_d = layout['configById']['3D!arm']
    camera = three_d['cameraState']
    # the 3D panel's camera: spherical (distance, phi from +z, theta = -thetaOffset)
    phi, theta = math.radians(camera['phi']), -math.radians(camera['thetaOffset'])
    position = (math.sin(phi) * math.sin(theta), -math.sin(phi) * math.cos(theta), math.cos(phi))
    assert position == pytest.approx((0, -1, 0), abs=1e-9) and camera['perspective']
    # the display frame is the TF tree's root (world): named, the panel logged that it was
    # not found at every load, before the first TF message
    assert 'followTf' not in three_d and 'frameId' not in three_d['layers']['grid']
    assert three_d['topics']['/robot_description']['visible']
    assert three_d['topics']['/impact_markers']['visible']
    # the full /tf history read ahead, so that seeking shows the arm where it was
    assert three_d['scene']['transforms']['enablePreloading'] is True
    # every panel's title shows in Foxglove and in Lichtblick (each reads its own key)
    for config in layout['configById'].values():
        title = config['foxglovePanelTitle']
        assert title and config['lichtblickPanelTitle'] == title
    # the force plot: each period's peak beside its average
    forces = [e['value'] for e in layout['configById']['Plot!force']['paths']]
    assert '/contact_force_peak.wrench.force.y' in forces
    assert '/contact_wrench.wrench.force.y' in forces
    # the topics the panels and the table's script read are in a recording
    path = tmp_path / 'run.mcap'
    scene = scene_from(cycles=1)
    rec = OfflineRecorder(path, scene)
    rec.close(run(scene, observer=rec))
    from rosbags.highlevel import AnyReader
    from pathlib import Path

    with AnyReader([Path(path)]) as reader:
        recorded = {c.topic: c.msgtype for c in reader.connections}
    (script,) = layout['userNodes'].values()
    inputs = re.search(r'inputs = \[([^]]*)\]', script['sourceCode']).group(1)
    output = re.search(r'output = "([^"]+)"', script['sourceCode']).group(1)
    assert [t.strip().strip('"') for t in inputs.split(',')] == ['/impact_table']
    used = set()
    for config in layout['configById'].values():
        for entry in config.get('paths', []):
            used.add(entry['value'].split('.')[0])
        if 'topicPath' in config:
            assert config['topicPath'].startswith(output + '.')
    used |= set(three_d['topics'])
    assert used <= set(recorded), used - set(recorded)
    assert recorded['/joint_states'] == 'sensor_msgs/msg/JointState'


def test_urdf_command_prints_the_robot_description(tmp_path):
    out = subprocess.run(
        [PYTHON, '-m', 'impact_arm.tools.cli', 'urdf', '--scene', 'paper'],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith('<?xml') and '<robot name="impact_arm">' in out.stdout


@pytest.mark.parametrize('node', ['simulator', 'controller'])
def test_parameter_files_are_accepted_by_the_nodes(ros_env, tmp_path, node):
    """Start the node with its parameter file; a bad key or value would stop it at once."""
    params = os.path.join(ROOT, 'config', f'{node}.yaml')
    assert yaml.safe_load(open(params))[node]['ros__parameters']
    args = [PYTHON, '-m', f'impact_arm.nodes.{node}', '--ros-args', '--params-file', params]
    with start_process(args, ros_env, tmp_path, node) as proc:
        # its constructor, which checks the file, has logged (no fixed wait: a start-up on a
        # busy machine may take longer, and a signal during the imports is a traceback)
        assert wait_for(lambda: f'[{node}]:' in proc.stderr or not proc.alive(), 60)
        time.sleep(1.0)  # past the constructor: a bad value may stop it a little later
        assert proc.alive(), f'{node} exited with {proc.popen.returncode}:\n{proc.stderr}'
        proc.signal(signal.SIGINT)
        code = proc.wait(10)
    out = proc.stdout + proc.stderr
    assert code == 0, out
    assert 'Traceback' not in out and 'ERROR' not in out, out


def test_nodes_keep_discovery_on_this_machine_unless_told_otherwise(ros_env):
    """Started without ROS_AUTOMATIC_DISCOVERY_RANGE, a node process limits DDS discovery to
    localhost before rclpy starts; an explicit choice is kept."""
    probe = (
        'import os, rclpy\n'
        'from rclpy.node import Node\n'
        'from impact_arm.nodes._runner import run\n'
        'class Once(Node):\n'
        '    done = True\n'
        '    def __init__(self):\n'
        '        super().__init__("once")\n'
        '        print("RANGE=" + os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"])\n'
        '    def finish(self, executor):\n'
        '        return 0\n'
        'raise SystemExit(run(Once))\n'
    )
    for given, expected in ((None, 'LOCALHOST'), ('OFF', 'OFF')):
        env = {k: v for k, v in ros_env.items() if k != 'ROS_AUTOMATIC_DISCOVERY_RANGE'}
        if given:
            env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = given
        out = subprocess.run(
            [PYTHON, '-c', probe], env=env, capture_output=True, text=True, timeout=60
        )
        assert out.returncode == 0, out.stderr
        assert f'RANGE={expected}' in out.stdout


def _fifo_allowed():
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except (AttributeError, OSError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def _scheduling(pid):
    """{thread name: {(policy, priority)}} of a running process."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        try:
            with open(f'/proc/{pid}/task/{tid}/comm', encoding='utf-8') as f:
                name = f.read().strip()
            policy = os.sched_getscheduler(int(tid))
            priority = os.sched_getparam(int(tid)).sched_priority
        except OSError:  # the thread ended meanwhile
            continue
        out.setdefault(name, set()).add((policy, priority))
    return out


@pytest.mark.skipif(not _fifo_allowed(), reason='this system refuses SCHED_FIFO')
@pytest.mark.parametrize('priority', [31, 0])
def test_controller_middleware_threads_share_its_realtime_priority(ros_env, tmp_path, priority):
    """The middleware threads that deliver the joint states run at the control thread's
    SCHED_FIFO priority (under load they held samples back for 100 ms and more at normal
    priority); thread_priority 0 leaves every thread to the normal scheduler."""
    with start_process(
        controller(f'thread_priority:={priority}'), ros_env, tmp_path, 'controller'
    ) as proc:
        deadline = time.monotonic() + 60
        while 'scheduling' not in proc.stderr and proc.alive() and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(0.5)  # the runner raises them right after the constructor
        threads = _scheduling(proc.pid)
    middleware = {k: v for k, v in threads.items() if k.startswith('dds.')}
    assert middleware, threads  # Fast DDS names its threads dds.*
    expected = {(os.SCHED_FIFO, priority)} if priority else {(os.SCHED_OTHER, 0)}
    assert all(v == expected for v in middleware.values()), middleware


@pytest.mark.dds
def test_launched_nodes_each_appear_once_in_the_graph(probe, ros_env, tmp_path):
    """Started as the launch file starts them (``-r __node:=NAME`` and the parameter file),
    the nodes and their helper nodes (the simulator's command reader, the recorder's reader)
    have distinct names: launch's global ``__node`` remap used to rename the helpers too, so
    ``ros2 node list`` showed /simulator and /recorder twice and rcl warned "Publisher
    already registered for node name"."""
    actions = load_launch_with_stubs(ROOT)
    nodes = [
        a.kwargs
        for a in actions
        if type(a).__name__ == 'Node' and a.kwargs['package'] == 'impact_arm'
    ]
    names = sorted(n['name'] for n in nodes)
    assert len(set(names)) == len(names)
    procs = []
    with contextlib.ExitStack() as stack:
        for n in nodes:
            args = [
                PYTHON,
                '-m',
                f'impact_arm.nodes.{n["executable"]}',
                '--ros-args',
                '-r',
                f'__node:={n["name"]}',
                '--params-file',
                os.path.join(ROOT, 'config', n['executable'] + '.yaml'),
            ]
            if n['executable'] == 'recorder':
                args += ['-p', f'output:={tmp_path / "run.mcap"}']
            procs.append(stack.enter_context(start_process(args, ros_env, tmp_path, n['name'])))

        def graph():
            return [
                f'{ns.rstrip("/")}/{name}'
                for name, ns in probe.node.get_node_names_and_namespaces()
            ]

        helpers = ['/_simulator_command_reader', '/_recorder_reader']
        assert wait_for(
            lambda: (
                set(f'/{n}' for n in names) | set(helpers) <= set(graph())
                or not all(p.alive() for p in procs)
            ),
            timeout=60,
        ), (graph(), [p.stderr[-2000:] for p in procs])
        time.sleep(1.0)  # anything duplicated would be discovered by now
        seen = [n for n in graph() if n != '/test_probe']
        assert sorted(seen) == sorted(set(seen)), seen
        for p in procs:
            assert p.alive(), p.stderr
            assert 'already registered' not in p.stderr + p.stdout, p.stderr
