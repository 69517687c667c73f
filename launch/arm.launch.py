"""Simulator, controller and recorder with the parameter files in config/ (ROS 2 installs).

    ros2 launch impact_arm arm.launch.py [scene:=FILE] [law:=q|pid|pd] [rate:=1000.0]
        [mode:=realtime|lockstep] [output:=runs/arm.mcap] [tf:=sim|rsp] [rviz:=false|true]

tf:=sim (default): the simulator publishes /tf and /tf_static itself (needs tf2_msgs);
tf:=rsp: robot_state_publisher does, from /joint_states and the scene's URDF
(``impact-arm urdf``). rviz:=true starts RViz with config/impact_arm.rviz.

Without ros2 launch (PyPI rclpy only), `impact-arm run` starts the same three nodes.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import Command, LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from impact_arm import contract


def generate_launch_description():
    config = os.path.join(get_package_share_directory('impact_arm'), 'config')
    scene, law = LaunchConfiguration('scene'), LaunchConfiguration('law')
    rate, mode = LaunchConfiguration('rate'), LaunchConfiguration('mode')
    lockstep = PythonExpression(["'", mode, "' == 'lockstep'"])
    tf = LaunchConfiguration('tf')
    cycles = LaunchConfiguration('cycles')
    rsp = PythonExpression(["'", tf, "' == 'rsp'"])
    # the URDF of the launched scene, as `impact-arm urdf` prints it (the scripts of an
    # ament_python package are not on PATH, the module is importable)
    urdf = ParameterValue(
        Command(['python3 -m impact_arm.tools.cli urdf --scene ', scene]), value_type=str
    )
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                'scene', default_value='paper', description='scene file or installed scene name'
            ),
            DeclareLaunchArgument('law', default_value='q', description='q, pid or pd'),
            DeclareLaunchArgument(
                'rate', default_value='1000.0', description='publish and control rate [Hz]'
            ),
            DeclareLaunchArgument(
                'mode', default_value='realtime', description='realtime or lockstep'
            ),
            DeclareLaunchArgument(
                'cycles',
                default_value='0',
                description='down/up cycles after which the controller stops commanding (0: never)',
            ),
            DeclareLaunchArgument(
                'output', default_value='runs/arm.mcap', description='MCAP file the recorder writes'
            ),
            DeclareLaunchArgument(
                'tf',
                default_value='sim',
                choices=['sim', 'rsp'],
                description='who publishes /tf: the simulator or robot_state_publisher',
            ),
            DeclareLaunchArgument(
                'rviz', default_value='false', description='start RViz with config/impact_arm.rviz'
            ),
            Node(
                package='impact_arm',
                executable='simulator',
                name='simulator',
                output='screen',
                parameters=[
                    os.path.join(config, 'simulator.yaml'),
                    {
                        'scene': scene,
                        'publish_rate': rate,
                        'mode': mode,
                        'rate_factor': PythonExpression(['0.0 if ', lockstep, ' else 1.0']),
                        'publish_tf': PythonExpression(['not ', rsp]),
                        # lockstep: wait for the recorder, so the recording is complete
                        'recorder_window': PythonExpression(
                            [f'{contract.RECORDER_WINDOW} if ', lockstep, ' else 0']
                        ),
                    },
                ],
            ),
            Node(
                package='impact_arm',
                executable='controller',
                name='controller',
                output='screen',
                parameters=[
                    os.path.join(config, 'controller.yaml'),
                    {
                        'scene': scene,
                        'law': law,
                        'rate': rate,
                        'cycles': ParameterValue(cycles, value_type=int),
                        'command_readers': 2,  # simulator and recorder hear the start
                        # lockstep: history to resend what a starved recorder missed
                        'command_history': PythonExpression(
                            [
                                f'{contract.WRITER_REPAIR_DEPTH} if ',
                                lockstep,
                                f' else {contract.qos(contract.COMMANDS).depth}',
                            ]
                        ),
                        # realtime: the arm moves once DDS discovery has settled
                        'startup_hold': PythonExpression(
                            ['0.0 if ', lockstep, f' else {contract.STARTUP_HOLD}']
                        ),
                    },
                ],
            ),
            Node(
                package='impact_arm',
                executable='recorder',
                name='recorder',
                output='screen',
                parameters=[
                    os.path.join(config, 'recorder.yaml'),
                    {'scene': scene, 'output': LaunchConfiguration('output')},
                ],
            ),
            Node(
                package='robot_state_publisher',
                executable='robot_state_publisher',
                name='robot_state_publisher',
                output='screen',
                condition=IfCondition(rsp),
                parameters=[{'robot_description': urdf}],
            ),
            Node(
                package='rviz2',
                executable='rviz2',
                name='rviz2',
                output='screen',
                condition=IfCondition(LaunchConfiguration('rviz')),
                arguments=['-d', os.path.join(config, 'impact_arm.rviz')],
            ),
        ]
    )
