"""The rclpy nodes and what they share: names, QoS, executors, the in-process graph."""

from gripper_ros.wire import (LAUNCHED_NODES, NODE_DESCRIPTION, NODE_EXCITATION,
                              NODE_FORCE_CONTROLLER, NODE_GRASP_ACTION, NODE_MOVE_ACTION,
                              NODE_PLANT, NODE_POSITION_CONTROLLER, NODE_SUPERVISOR,
                              NODE_TRAJECTORY_ACTION, ROBOT_STATE_PUBLISHER)

NODE_MODULES = {NODE_PLANT: 'plant_simulator_node',
                NODE_POSITION_CONTROLLER: 'position_controller_node',
                NODE_FORCE_CONTROLLER: 'force_controller_node',
                NODE_SUPERVISOR: 'supervisor_node',
                NODE_GRASP_ACTION: 'grasp_action_node',
                NODE_MOVE_ACTION: 'move_action_node',
                NODE_TRAJECTORY_ACTION: 'trajectory_action_node',
                NODE_EXCITATION: 'excitation_node',
                NODE_DESCRIPTION: 'description_node'}
"""The module of each node executable: ``python -m gripper_ros.nodes.MODULE`` runs it."""

LAUNCHED_MODULES = {node: NODE_MODULES[node] for node in LAUNCHED_NODES}
"""The modules of the nodes the launch file starts, one process each, in its order."""


def robot_state_publisher_installed() -> bool:
    """Return whether the ament index (AMENT_PREFIX_PATH) has robot_state_publisher."""
    from ament_index_python.packages import get_package_prefix, PackageNotFoundError
    try:
        get_package_prefix(ROBOT_STATE_PUBLISHER)
    except (PackageNotFoundError, ValueError):
        return False
    return True


def launched_executables(state_publisher: bool) -> list[tuple[str, str]]:
    """Return (package, executable) of each process the launch file starts, in its order.

    ``state_publisher``: robot_state_publisher takes description_publisher's place, so that
    one node publishes robot_description and /tf.
    """
    return [(ROBOT_STATE_PUBLISHER, ROBOT_STATE_PUBLISHER)
            if name == NODE_DESCRIPTION and state_publisher else ('gripper_ros', name)
            for name in LAUNCHED_NODES]
