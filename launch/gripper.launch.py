"""The gripper's node graph for a system ROS 2: one process per node.

    ros2 launch gripper_ros gripper.launch.py
    ros2 launch gripper_ros gripper.launch.py namespace:=left time_mode:=fast

Launch arguments: ``namespace`` (default ``gripper``: ``/gripper/grasp``, ``/gripper/move``,
``/gripper/gripper_cmd``, ...), ``config_file`` (default: the installed
``share/gripper_ros/config/gripper.yaml``; each node reads it once at start-up),
``time_mode`` (``realtime``, the default, paced to the wall clock; ``fast``: as fast as the
loop goes, paused between requests),
``real_time_factor`` (realtime: simulated seconds per wall second), ``publish_clock``
(``/clock``, one simulator per ROS graph) and ``prefix`` (the xacro's: ``left_`` names the
joint ``left_finger_joint`` in joint_states and joint_commands, and the URDF's links).
The nodes: plant_simulator, position_controller, force_controller, supervisor,
grasp_action_server, move_action_server (which also serves control_msgs
ParallelGripperCommand on ``gripper_cmd`` where control_msgs is installed) and the one
publisher of ``robot_description`` and ``/tf``: robot_state_publisher with the URDF of the
config (``gripper_urdf --config``) where the ament index has it, else description_publisher.
"""
from gripper_ros.nodes import launched_executables, robot_state_publisher_installed
from gripper_ros.wire import (DEFAULT_NAMESPACE, NODE_DESCRIPTION, NODE_MOVE_ACTION, NODE_PLANT,
                              NODE_SUPERVISOR,
                              ROBOT_STATE_PUBLISHER, TIME_MODE_CHOICES, TimeMode)
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import Command, LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackagePrefix, FindPackageShare

PACKAGE = 'gripper_ros'
JOINT_NAMED = (NODE_PLANT, NODE_SUPERVISOR, NODE_MOVE_ACTION, NODE_DESCRIPTION)
"""The nodes that take the ``prefix`` parameter: the joint's name and the URDF's."""
ARGUMENTS = (
    ('namespace', DEFAULT_NAMESPACE, 'namespace of every node, topic, service and action'),
    ('config_file', PathJoinSubstitution([FindPackageShare(PACKAGE), 'config', 'gripper.yaml']),
     'config YAML (every constant and gain)'),
    ('time_mode', TimeMode.REALTIME.parameter,
     f'{" or ".join(TIME_MODE_CHOICES)}: paced to the wall clock, or as fast as the loop goes'),
    ('real_time_factor', '1.0', 'realtime: simulated seconds per wall second'),
    ('publish_clock', 'true', 'publish /clock'),
    ('prefix', '', "before finger_joint and the URDF's names (the xacro's prefix, e.g. left_)"),
)


def generate_launch_description() -> LaunchDescription:
    """Return the launch arguments and one Node action per node of the graph."""
    config = {'config_file': ParameterValue(LaunchConfiguration('config_file'), value_type=str)}
    named = {'prefix': ParameterValue(LaunchConfiguration('prefix'), value_type=str)}
    plant = {
        'time_mode': ParameterValue(LaunchConfiguration('time_mode'), value_type=str),
        'real_time_factor': ParameterValue(LaunchConfiguration('real_time_factor'),
                                           value_type=float),
        'publish_clock': ParameterValue(LaunchConfiguration('publish_clock'), value_type=bool),
    }
    actions = [DeclareLaunchArgument(name, default_value=default, description=description)
               for name, default, description in ARGUMENTS]
    urdf = Command([PathJoinSubstitution([FindPackagePrefix(PACKAGE), 'lib', PACKAGE,
                                          'gripper_urdf']),
                    ' --config ', LaunchConfiguration('config_file'),
                    ' --prefix "', LaunchConfiguration('prefix'), '"'])
    for package, name in launched_executables(robot_state_publisher_installed()):
        if package == ROBOT_STATE_PUBLISHER:
            parameters = [{'robot_description': ParameterValue(urdf, value_type=str)}]
        else:
            parameters = [config, plant] if name == NODE_PLANT else [config]
            if name in JOINT_NAMED:
                parameters.append(named)
        actions.append(Node(package=package, executable=name, name=name,
                            namespace=LaunchConfiguration('namespace'),
                            parameters=parameters, output='screen', emulate_tty=True))
    return LaunchDescription(actions)
