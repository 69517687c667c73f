"""ament_python set-up for impact_arm (also installable with plain pip)."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'impact_arm'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(include=[PACKAGE, PACKAGE + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml') + glob('config/*.rviz')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.py')),
    ],
    # rclpy and the message packages come from the ROS install (package.xml) or, without ROS,
    # from the PyPI wheels the Makefile installs; they are deliberately not listed here.
    # xacro: a scene's arm.xacro is expanded in-process (pure Python, needs only PyYAML)
    install_requires=['setuptools', 'numpy', 'scipy', 'sympy', 'PyYAML', 'mcap', 'matplotlib',
                      'Pillow', 'numba', 'rosbags', 'xacro'],
    # studies (impact-arm sweep): Parquet tables and the Dask scheduler; imported lazily, so
    # the nodes and `simulate` never load them
    extras_require={
        'studies': ['pyarrow', 'dask[distributed]'],
        # impact-arm export runs the peers to tune their contact
        'export': ['mujoco', 'drake'],
    },
    zip_safe=True,
    maintainer='impact_arm developers',
    maintainer_email='impact-arm@example.com',
    description='Planar n-link impacting arm: physics core, ROS 2 nodes, MCAP record/replay.',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'impact-arm = impact_arm.tools.cli:main',
            'simulator = impact_arm.nodes.simulator:main',
            'controller = impact_arm.nodes.controller:main',
            'recorder = impact_arm.nodes.recorder:main',
            'replay = impact_arm.nodes.replay:main',
        ],
    },
)
