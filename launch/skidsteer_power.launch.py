"""Launch the on-board suite on a robot with a full ROS 2 install (``ros2 launch skidsteer_power
skidsteer_power.launch.py``). Without ROS launch, use ``skidsteer-power run`` (same nodes).

Arguments: vehicle, terrain (estimator parameters), left_port, right_port (DES 70/10 amplifiers),
monitor (true: also open energy_monitor in view mode in this terminal).
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('skidsteer_power')
    estimator_defaults = os.path.join(share, 'config', 'estimator.yaml')
    vehicle = LaunchConfiguration('vehicle')
    return LaunchDescription(
        [
            DeclareLaunchArgument('vehicle', default_value='test_robot_track'),
            DeclareLaunchArgument('terrain', default_value='dry_sand'),
            DeclareLaunchArgument('left_port', default_value='/dev/ttyUSB0'),
            DeclareLaunchArgument('right_port', default_value='/dev/ttyUSB1'),
            DeclareLaunchArgument('monitor', default_value='false'),
            Node(
                package='skidsteer_power',
                executable='power_estimator',
                name='power_estimator',
                parameters=[
                    estimator_defaults,
                    {'vehicle': vehicle, 'terrain': LaunchConfiguration('terrain')},
                ],
                output='screen',
            ),
            Node(
                package='skidsteer_power',
                executable='des_driver',
                name='des_driver',
                parameters=[
                    {
                        'left_port': LaunchConfiguration('left_port'),
                        'right_port': LaunchConfiguration('right_port'),
                    }
                ],
                output='screen',
            ),
            Node(
                package='skidsteer_power',
                executable='energy_monitor',
                name='energy_monitor',
                arguments=['--mode', 'view'],
                output='screen',
                emulate_tty=True,
                condition=IfCondition(LaunchConfiguration('monitor')),
            ),
        ]
    )
