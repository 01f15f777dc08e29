"""The gripper's node graph for a system ROS 2: in one process, or one process per node.

    ros2 launch gripper_ros gripper.launch.py
    ros2 launch gripper_ros gripper.launch.py namespace:=left time_mode:=fast
    ros2 launch gripper_ros gripper.launch.py per_node:=true

Launch arguments: ``namespace`` (default ``gripper``: ``/gripper/grasp``, ``/gripper/move``,
``/gripper/gripper_cmd``, ...), ``config_file`` (default: the installed
``share/gripper_ros/config/gripper.yaml``; each node reads it once at start-up),
``time_mode`` (``realtime``, the default, paced to the wall clock; ``fast``: as fast as the
loop goes, paused between requests),
``real_time_factor`` (realtime: simulated seconds per wall second), ``publish_clock``
(``/clock``, one simulator per ROS graph), ``use_sim_time`` (every node on the ``/clock`` of a
world simulator such as Gazebo or MuJoCo, the simulation in step with it; the gripper then
publishes no ``/clock``), ``prefix`` (the xacro's: ``left_`` names the
joint ``left_finger_joint`` in joint_states and joint_commands, and the URDF's links, so every
TF frame; by default from the namespace: none in ``gripper``, ``left_`` in ``left``, so grippers
launched side by side share no frame and no joint), ``per_node`` (default ``false``), and
``foxglove`` (default ``false``; ``true`` serves the graph live to Foxglove over its WebSocket
protocol, on ``foxglove_port`` (8765) at ``foxglove_address`` (this machine only: 127.0.0.1);
only with the graph in one process).
A namespace that is no ROS name is refused in one line before any node starts.
The nodes: plant_simulator, position_controller, force_controller, supervisor,
grasp_action_server, move_action_server (which also serves control_msgs
ParallelGripperCommand on ``gripper_cmd`` and GripperCommand on
``gripper_action_controller/gripper_cmd`` where control_msgs is installed),
trajectory_action_server (FollowJointTrajectory on
``joint_trajectory_controller/follow_joint_trajectory``, there too) and the one
publisher of ``robot_description`` and ``/tf``.

What each layout costs:

- ``per_node:=false`` (the default): one process, ``gripper_graph``, the nodes under one
  executor with the loop topics handed over inside the process (no serialisation, no DDS
  between them), as ``grasp_demo --serve`` runs them: real time while holding an object
  (0.1 ms ticks), joint_states at 100 Hz, for about 0.4 of a core (``bench_realtime
  --launch``). It also serves ``excitation_server``, and shows
  ``gripper_graph_client`` (its service client) in ``ros2 node list``; the description
  publisher is description_publisher. One Node action without a ``name``: launch_ros names a
  node with a global ``-r __node:=`` remap, which would give all of them one name. A crash
  of the process takes every node down at once.
- ``per_node:=true``: one process per node, each its own Python interpreter and DDS
  participant, the loop topics over DDS; robot_state_publisher with the URDF of the config
  (``gripper_urdf --config``) where the ament index has it, else description_publisher.
  Each can be restarted, profiled or replaced alone, but on 2 cores it holds an object at a
  third of real time or less (joint_states at 30 Hz; ``bench_realtime --launch --per-node``).

On Ctrl-C the terminal sends SIGINT to every process of the group; launch then waits
``sigterm_timeout`` (5 s) before SIGTERM and 5 s more before SIGKILL. Every executable here ends
within its own stop bound first (docs/USING.md, "Stopping").
"""
from gripper_ros.nodes import launched_executables, robot_state_publisher_installed
from gripper_ros.nodes.live_view import DEFAULT_ADDRESS, DEFAULT_PORT
from gripper_ros.wire import (check_namespace, DEFAULT_NAMESPACE, namespace_prefix,
                              NODE_DESCRIPTION, NODE_MOVE_ACTION, NODE_PLANT, NODE_SUPERVISOR,
                              NODE_TRAJECTORY_ACTION,
                              ROBOT_STATE_PUBLISHER, TIME_MODE_CHOICES, TimeMode)
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition, UnlessCondition
from launch.substitution import Substitution
from launch.substitutions import Command, LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackagePrefix, FindPackageShare

PACKAGE = 'gripper_ros'


class NamespacePrefix(Substitution):
    """The ``prefix`` the ``namespace`` launch argument gives (``wire.namespace_prefix``)."""

    def describe(self) -> str:
        """Return what ``--show-args`` prints as the default."""
        return "from the namespace: '' in gripper, left_ in left"

    def perform(self, context) -> str:
        """Return the prefix of the namespace launched in."""
        return namespace_prefix(context.launch_configurations.get('namespace',
                                                                  DEFAULT_NAMESPACE))


def check_namespace_argument(context) -> list:
    """Refuse a ``namespace`` that is no ROS name, in one line, before any node starts.

    launch_ros would say it for each Node action over several lines, naming the argument
    ``<LaunchConfiguration object at 0x...>``. Raised here, launch prints one line
    (``Caught exception in launch ...: namespace 'a-b' is not a ROS name: ...``) and exits 1.
    """
    check_namespace(context.launch_configurations['namespace'])
    return []


JOINT_NAMED = (NODE_PLANT, NODE_SUPERVISOR, NODE_MOVE_ACTION, NODE_TRAJECTORY_ACTION,
               NODE_DESCRIPTION)
"""The nodes that take the ``prefix`` parameter: the joint's name and the URDF's."""
ARGUMENTS = (
    ('namespace', DEFAULT_NAMESPACE, 'namespace of every node, topic, service and action'),
    ('config_file', PathJoinSubstitution([FindPackageShare(PACKAGE), 'config', 'gripper.yaml']),
     'config YAML (every constant and gain)'),
    ('time_mode', TimeMode.REALTIME.parameter,
     f'{" or ".join(TIME_MODE_CHOICES)}: paced to the wall clock, or as fast as the loop goes'),
    ('real_time_factor', '1.0', 'realtime: simulated seconds per wall second'),
    ('publish_clock', 'true', 'publish /clock'),
    ('use_sim_time', 'false', "true: every node on a world simulator's /clock, the simulation "
     'in step with it (the gripper publishes none)'),
    ('prefix', NamespacePrefix(),
     "before finger_joint and the URDF's names, so every TF frame (the xacro's prefix)"),
    ('per_node', 'false', 'true: one process per node; false: the whole graph in one process '
     '(real time while holding)'),
    ('foxglove', 'false', 'true: serve the graph live to Foxglove (its WebSocket protocol; '
     'the graph in one process)'),
    ('foxglove_port', str(DEFAULT_PORT), "the live view's port"),
    ('foxglove_address', DEFAULT_ADDRESS, 'where the live view listens (0.0.0.0: every '
     'interface)'),
)
TRUE = ('true', '1', 'yes', 'on')
"""What launch's conditions take as true."""
GRAPH_EXECUTABLE = 'gripper_graph'
"""The one process of the default layout: every node of the graph under one executor."""


def _live_view_needs_one_process(context) -> list:
    """Refuse ``foxglove:=true`` with ``per_node:=true``: the live view taps the one process."""
    def true(name: str) -> bool:
        return context.launch_configurations.get(name, 'false').strip().lower() in TRUE
    if true('foxglove') and true('per_node'):
        raise RuntimeError('foxglove:=true serves the graph from its one process: it does not '
                           'go with per_node:=true')
    return []


def generate_launch_description() -> LaunchDescription:
    """Return the launch arguments, the one-process graph and one Node action per node.

    ``per_node`` chooses which of the two runs. The one process takes every parameter
    dictionary (each a ``/**`` parameters file, reaching every node in it) and no ``name``.
    """
    config = {'config_file': ParameterValue(LaunchConfiguration('config_file'), value_type=str),
              'use_sim_time': ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)}
    named = {'prefix': ParameterValue(LaunchConfiguration('prefix'), value_type=str)}
    plant = {
        'time_mode': ParameterValue(LaunchConfiguration('time_mode'), value_type=str),
        'real_time_factor': ParameterValue(LaunchConfiguration('real_time_factor'),
                                           value_type=float),
        'publish_clock': ParameterValue(LaunchConfiguration('publish_clock'), value_type=bool),
    }
    live = {
        'foxglove': ParameterValue(LaunchConfiguration('foxglove'), value_type=bool),
        'foxglove_port': ParameterValue(LaunchConfiguration('foxglove_port'), value_type=int),
        'foxglove_address': ParameterValue(LaunchConfiguration('foxglove_address'),
                                           value_type=str),
    }
    per_node = LaunchConfiguration('per_node')
    actions = [DeclareLaunchArgument(name, default_value=default, description=description)
               for name, default, description in ARGUMENTS]
    actions.append(OpaqueFunction(function=check_namespace_argument))
    actions.append(OpaqueFunction(function=_live_view_needs_one_process))
    actions.append(Node(package=PACKAGE, executable=GRAPH_EXECUTABLE,
                        namespace=LaunchConfiguration('namespace'),
                        parameters=[config, plant, named, live], output='screen',
                        emulate_tty=True, condition=UnlessCondition(per_node)))
    urdf = Command([PathJoinSubstitution([FindPackagePrefix(PACKAGE), 'lib', PACKAGE,
                                          'gripper_urdf']),
                    ' --config ', LaunchConfiguration('config_file'),
                    ' --prefix "', LaunchConfiguration('prefix'), '"'])
    for package, name in launched_executables(robot_state_publisher_installed()):
        if package == ROBOT_STATE_PUBLISHER:
            parameters = [{'robot_description': ParameterValue(urdf, value_type=str),
                           'use_sim_time': config['use_sim_time']}]
        else:
            parameters = [config, plant] if name == NODE_PLANT else [config]
            if name in JOINT_NAMED:
                parameters.append(named)
        actions.append(Node(package=package, executable=name, name=name,
                            namespace=LaunchConfiguration('namespace'),
                            parameters=parameters, output='screen', emulate_tty=True,
                            condition=IfCondition(per_node)))
    return LaunchDescription(actions)
