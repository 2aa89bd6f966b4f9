"""Launch the on-board suite on a robot with a full ROS 2 install (``ros2 launch skidsteer_power
skidsteer_power.launch.py``). Without ROS launch, use ``skidsteer-power run`` (same nodes).

Arguments: vehicle, terrain (estimator parameters), left_port, right_port (DES 70/10 amplifiers),
monitor (true: also open energy_monitor in view mode in this terminal), namespace (of every node, e.g.
``robot1``: one robot, one energy state file), cmd_vel_topic and joint_states_topic (remaps of the
nodes' ``cmd_vel`` and ``joint_states``, e.g. ``cmd_vel_topic:=/diff_drive_controller/cmd_vel``),
cmd_vel_type (auto, twist or twist_stamped: :mod:`skidsteer_power.nodes.cmd_vel_input`). Every other
parameter comes from the installed ``config/estimator.yaml`` and ``config/des_driver.yaml``.

des_driver is a managed (lifecycle) node: this file configures it once its process is up, activates
it once it is inactive, and on shutdown deactivates it (zero speed, power stages off) and cleans it
up (ports closed). The node zeroes and disables on SIGINT (and on any other signal that would end
it) by itself too, should the launch's SIGINT arrive before the transitions are through. If
power_estimator or des_driver exits, the launch shuts the whole suite down.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler, Shutdown
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessStart, OnShutdown
from launch.events import matches_action
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from launch_ros.event_handlers import OnStateTransition
from launch_ros.events.lifecycle import ChangeState
from lifecycle_msgs.msg import Transition

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('skidsteer_power')
    estimator_defaults = os.path.join(share, 'config', 'estimator.yaml')
    driver_defaults = os.path.join(share, 'config', 'des_driver.yaml')
    vehicle = LaunchConfiguration('vehicle')
    namespace = LaunchConfiguration('namespace')
    cmd_vel_type = LaunchConfiguration('cmd_vel_type')
    remappings = [
        ('cmd_vel', LaunchConfiguration('cmd_vel_topic')),
        ('joint_states', LaunchConfiguration('joint_states_topic')),
    ]
    driver = LifecycleNode(
        package='skidsteer_power',
        executable='des_driver',
        name='des_driver',
        namespace=namespace,
        remappings=remappings,
        parameters=[
            driver_defaults,
            {
                'vehicle': vehicle,
                'left_port': LaunchConfiguration('left_port'),
                'right_port': LaunchConfiguration('right_port'),
                'cmd_vel_type': cmd_vel_type,
            },
        ],
        output='screen',
        on_exit=[Shutdown(reason='des_driver exited')],  # a node that dies stops the suite
    )

    def transition(transition_id: int) -> EmitEvent:
        return EmitEvent(
            event=ChangeState(lifecycle_node_matcher=matches_action(driver), transition_id=transition_id)
        )

    driver_transitions = [
        RegisterEventHandler(
            OnProcessStart(target_action=driver, on_start=[transition(Transition.TRANSITION_CONFIGURE)])
        ),
        RegisterEventHandler(
            OnStateTransition(
                target_lifecycle_node=driver,
                start_state='configuring',
                goal_state='inactive',
                entities=[transition(Transition.TRANSITION_ACTIVATE)],
            )
        ),
        RegisterEventHandler(OnShutdown(on_shutdown=[transition(Transition.TRANSITION_DEACTIVATE)])),
        RegisterEventHandler(
            OnStateTransition(
                target_lifecycle_node=driver,
                start_state='deactivating',
                goal_state='inactive',
                entities=[transition(Transition.TRANSITION_CLEANUP)],
            )
        ),
    ]
    return LaunchDescription(
        [
            DeclareLaunchArgument('vehicle', default_value='test_robot_track'),
            DeclareLaunchArgument('terrain', default_value='dry_sand'),
            DeclareLaunchArgument('left_port', default_value='/dev/ttyUSB0'),
            DeclareLaunchArgument('right_port', default_value='/dev/ttyUSB1'),
            DeclareLaunchArgument('monitor', default_value='false'),
            DeclareLaunchArgument('namespace', default_value=''),
            DeclareLaunchArgument('cmd_vel_topic', default_value='cmd_vel'),
            DeclareLaunchArgument('joint_states_topic', default_value='joint_states'),
            DeclareLaunchArgument('cmd_vel_type', default_value='auto'),
            Node(
                package='skidsteer_power',
                executable='power_estimator',
                name='power_estimator',
                namespace=namespace,
                remappings=remappings,
                parameters=[
                    estimator_defaults,
                    {
                        'vehicle': vehicle,
                        'terrain': LaunchConfiguration('terrain'),
                        'cmd_vel_type': cmd_vel_type,
                    },
                ],
                output='screen',
                on_exit=[Shutdown(reason='power_estimator exited')],
            ),
            driver,
            *driver_transitions,
            Node(
                package='skidsteer_power',
                executable='energy_monitor',
                name='energy_monitor',
                namespace=namespace,
                arguments=['--mode', 'view'],
                output='screen',
                emulate_tty=True,
                condition=IfCondition(LaunchConfiguration('monitor')),
            ),
        ]
    )
