"""Every module the package imports at run time maps to a dependency package.xml declares, so
that `rosdep install` gives a ROS 2 install everything the nodes need (the recorder once died
at start with `No module named 'rosbags'`). A new third-party import fails here until it is
declared (or listed as optional, with the pip command the README gives for it)."""

import ast
import os
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# top-level module -> the rosdep key that provides it
ROSDEP_KEY = {
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'sympy': 'python3-sympy',
    'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'PIL': 'python3-pil',  # the animation's frames (matplotlib brings Pillow too)
    'numba': 'python3-numba',
    'rosbags': 'python3-rosbags-pip',
    # rosdep has no key for the mcap library: mcap-ros2-support's pip install brings it, and
    # mcap brings its compressors
    'mcap': 'mcap-ros2-support',
    'zstandard': 'mcap-ros2-support',
    'lz4': 'mcap-ros2-support',
}
# ROS packages: the module is the package (rclpy, std_msgs, builtin_interfaces, ...)
ROS_PACKAGES = {
    'rclpy',
    'rcl_interfaces',
    'builtin_interfaces',
    'rosidl_parser',
    'ament_index_python',
    'std_msgs',
    'sensor_msgs',
    'geometry_msgs',
    'rosgraph_msgs',
    'diagnostic_msgs',
    'visualization_msgs',
    'std_srvs',
    'tf2_msgs',
    'launch',
    'launch_ros',
    'simulation_interfaces',
    'xacro',  # a ROS package, and on PyPI under the same name (setup.py)
}
# imported only where a feature asks for it, behind an ImportError with the pip command:
# studies (`pip install .[studies]`), the export to the peer simulators (`pip install
# .[export]`) and the peer comparison of the benchmarks
OPTIONAL = {'pyarrow', 'dask', 'distributed', 'mujoco', 'pydrake', 'simulation_interfaces'}


def declared() -> set:
    root = ET.parse(os.path.join(ROOT, 'package.xml')).getroot()
    return {e.text.strip() for e in root if e.tag in ('depend', 'exec_depend')}


def imported() -> dict:
    """top-level module -> files importing it, over impact_arm/ and launch/."""
    found = {}
    for base in ('impact_arm', 'launch'):
        for folder, _, files in os.walk(os.path.join(ROOT, base)):
            for name in files:
                if not name.endswith('.py'):
                    continue
                path = os.path.join(folder, name)
                with open(path, encoding='utf-8') as f:
                    tree = ast.parse(f.read(), path)
                for node in ast.walk(tree):
                    names = []
                    if isinstance(node, ast.Import):
                        names = [a.name for a in node.names]
                    elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                        names = [node.module]
                    for module in names:
                        found.setdefault(module.split('.')[0], set()).add(
                            os.path.relpath(path, ROOT)
                        )
    return found


def test_every_runtime_import_is_a_declared_dependency():
    keys = declared()
    ours = {'impact_arm', 'impact_arm_bench'}  # the package, and the repository's benchmarks
    third_party = {
        m: files
        for m, files in imported().items()
        if m not in sys.stdlib_module_names and m not in ours
    }
    unknown = {
        m: sorted(f)
        for m, f in third_party.items()
        if m not in ROSDEP_KEY and m not in ROS_PACKAGES and m not in OPTIONAL
    }
    assert not unknown, f'imports with no dependency mapping (declare them): {unknown}'
    missing = {
        m: sorted(f)
        for m, f in third_party.items()
        if m not in OPTIONAL and (ROSDEP_KEY.get(m) or m) not in keys
    }
    assert not missing, f'imported but not in package.xml: {missing}'


def test_the_check_sees_the_imports_that_matter():
    """The scan is not vacuous: the nodes' own imports are found."""
    found = imported()
    assert {'rclpy', 'rosbags', 'mcap', 'numpy', 'builtin_interfaces'} <= set(found)
    assert 'impact_arm/nodes/recorder.py' in found['rosbags']
