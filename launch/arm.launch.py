"""Simulator, controller and recorder with the parameter files in config/ (ROS 2 installs).

    ros2 launch impact_arm arm.launch.py [scene:=FILE] [law:=q|pid|pd] [rate:=1000.0]
        [mode:=realtime|lockstep] [output:=runs/arm.mcap]

Without ros2 launch (PyPI rclpy only), `impact-arm run` starts the same three nodes.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description():
    config = os.path.join(get_package_share_directory('impact_arm'), 'config')
    scene, law = LaunchConfiguration('scene'), LaunchConfiguration('law')
    rate, mode = LaunchConfiguration('rate'), LaunchConfiguration('mode')
    lockstep = PythonExpression(["'", mode, "' == 'lockstep'"])
    return LaunchDescription([
        DeclareLaunchArgument('scene', default_value='paper',
                              description='scene file or installed scene name'),
        DeclareLaunchArgument('law', default_value='q', description='q, pid or pd'),
        DeclareLaunchArgument('rate', default_value='1000.0',
                              description='publish and control rate [Hz]'),
        DeclareLaunchArgument('mode', default_value='realtime',
                              description='realtime or lockstep'),
        DeclareLaunchArgument('output', default_value='runs/arm.mcap',
                              description='MCAP file the recorder writes'),
        Node(package='impact_arm', executable='simulator', name='simulator', output='screen',
             parameters=[os.path.join(config, 'simulator.yaml'),
                         {'scene': scene, 'publish_rate': rate, 'mode': mode,
                          'rate_factor': PythonExpression(['0.0 if ', lockstep,
                                                           ' else 1.0'])}]),
        Node(package='impact_arm', executable='controller', name='controller', output='screen',
             parameters=[os.path.join(config, 'controller.yaml'),
                         {'scene': scene, 'law': law, 'rate': rate,
                          'command_readers': 2}]),   # simulator and recorder hear the start
        Node(package='impact_arm', executable='recorder', name='recorder', output='screen',
             parameters=[os.path.join(config, 'recorder.yaml'),
                         {'scene': scene, 'output': LaunchConfiguration('output')}]),
    ])
