"""control_msgs' actions, served where control_msgs loads, and one line where it cannot.

A system ROS 2 Jazzy (or the overlay of ros2cli and control_msgs) has control_msgs; the
ros-jazzy wheels do not, and then nothing is said. Installed but not loadable (its C type
support, e.g. with its ``lib`` folder missing from ``LD_LIBRARY_PATH``): the actions are not
served, :data:`PROBLEM` says why in one line, and the rest of the graph runs.
"""
from __future__ import annotations

from gripper_ros.text import one_line
from gripper_ros.wire import CONTROL_ACTIONS


def _load() -> tuple[dict, str]:
    """Return {action type name: class} of control_msgs' actions we serve, and why not ('')."""
    try:
        from control_msgs import action as module
    except ModuleNotFoundError as exc:
        if (exc.name or '').split('.')[0] == 'control_msgs':
            return {}, ''
        return {}, one_line(exc)
    except ImportError as exc:  # pragma: no cover - depends on the installation
        return {}, one_line(exc)
    from rclpy.type_support import check_for_type_support
    loaded = {}
    for type_name in CONTROL_ACTIONS.values():
        try:
            action = getattr(module, type_name)
            check_for_type_support(action)
        except Exception as exc:  # noqa: BLE001 - UnsupportedTypeSupport and kin: one line
            cause = exc.__cause__ or exc.__context__
            return {}, one_line(f'{exc} ({cause})' if cause else exc)
        loaded[type_name] = action
    return loaded, ''


_LOADED, PROBLEM = _load()
"""PROBLEM: why control_msgs is installed but its actions are not served; '' otherwise."""
GripperCommand = _LOADED.get('GripperCommand')
ParallelGripperCommand = _LOADED.get('ParallelGripperCommand')
FollowJointTrajectory = _LOADED.get('FollowJointTrajectory')
JointTrajectoryPoint = None
"""trajectory_msgs' point, which FollowJointTrajectory carries: control_msgs depends on it, the
wheels have neither."""
if FollowJointTrajectory is not None:
    from trajectory_msgs import msg as _trajectory_msgs
    JointTrajectoryPoint = _trajectory_msgs.JointTrajectoryPoint


def not_served(names) -> str:
    """Return the line that says the actions ``names`` are not served, and why."""
    listed = ', '.join(f'{name} (control_msgs/action/{CONTROL_ACTIONS[name]})' for name in names)
    return f'{listed} not served: {PROBLEM}; the rest of the graph runs'
