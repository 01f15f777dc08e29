"""An optional interface that cannot load costs those interfaces only, with one line.

control_msgs installed but its C type support not loadable: the overlay's ``control_msgs/lib``
left off ``LD_LIBRARY_PATH`` (what made ``grasp_demo`` die with ``UnsupportedTypeSupport``), or,
where control_msgs is not installed, a control_msgs package whose type support is missing, as
rosidl_generator_py's ``import_type_support`` meets it. Known answer: the graph grasps (HOLDING),
exits 0, and says once that control_msgs' three actions are not served, with no traceback.
On the wheels without the ROS 2 command line, neither control_msgs nor trajectory_msgs (its
dependency) is there: the graph grasps and says nothing of them.
"""
from __future__ import annotations

import os
import subprocess
import sys

from gripper_ros.wire import CONTROL_ACTIONS

NO_TYPE_SUPPORT = """\
class Metaclass_NoTypeSupport(type):
    _TYPE_SUPPORT = None

    @classmethod
    def __import_type_support__(cls):
        from rosidl_generator_py import import_type_support
        import_type_support('control_msgs')


class ParallelGripperCommand(metaclass=Metaclass_NoTypeSupport):
    pass


class GripperCommand(metaclass=Metaclass_NoTypeSupport):
    pass


class FollowJointTrajectory(metaclass=Metaclass_NoTypeSupport):
    pass
"""


def _control_msgs_installed() -> bool:
    import importlib.util
    return importlib.util.find_spec('control_msgs') is not None


def _environment(tmp_path) -> dict:
    env = os.environ.copy()
    if _control_msgs_installed():
        env['LD_LIBRARY_PATH'] = ':'.join(
            p for p in env.get('LD_LIBRARY_PATH', '').split(':')
            if os.sep + 'control_msgs' + os.sep not in p + os.sep)
    else:
        package = tmp_path / 'control_msgs'
        (package / 'action').mkdir(parents=True)
        (package / '__init__.py').write_text('')
        (package / 'action' / '__init__.py').write_text(NO_TYPE_SUPPORT)
        env['PYTHONPATH'] = os.pathsep.join(p for p in (str(tmp_path), env.get('PYTHONPATH'))
                                            if p)
    return env


def test_control_msgs_without_type_support_costs_its_actions_only(tmp_path):
    result = subprocess.run(
        [sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--namespace', 'optional_interface',
         '--width', '0.05', '--mass', '1.69', '--no-record', '--no-plot'],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
        env=_environment(tmp_path))
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert 'Traceback' not in output
    said = [line for line in output.splitlines() if 'control_msgs' in line]
    assert len(said) == 1, output
    listed = ', '.join(f'{name} (control_msgs/action/{kind})'
                       for name, kind in CONTROL_ACTIONS.items())
    assert f'{listed} not served' in said[0]
    assert "Could not import 'rosidl_typesupport_c' for package 'control_msgs'" in said[0]
    assert 'HOLDING' in result.stdout


def test_without_control_msgs_and_trajectory_msgs_the_graph_grasps_and_says_nothing(tmp_path):
    """The README's machine before ``setup.sh --ros2-cli``: both packages absent from Python.

    ``sys.modules[name] = None`` makes every import of them fail as an absent package's does
    (ModuleNotFoundError naming it).
    """
    hide = ("import runpy, sys; sys.modules['control_msgs'] = None; "
            "sys.modules['trajectory_msgs'] = None; sys.argv[0] = 'grasp_demo'; "
            "runpy.run_module('gripper_ros.apps.grasp_demo', run_name='__main__')")
    result = subprocess.run(
        [sys.executable, '-c', hide, '--namespace', 'no_command_line', '--width', '0.05',
         '--mass', '1.69', '--no-record', '--no-plot'],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL, cwd=tmp_path)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert 'Traceback' not in output
    assert not [line for line in output.splitlines() if '_msgs' in line], output
    assert 'HOLDING' in result.stdout
