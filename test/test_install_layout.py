"""The colcon install is complete: ament index, console scripts, config, generated interfaces.

Needs the environment of scripts/env.sh (bash scripts/test.sh sets it up); no rclpy graph.
"""
import ast
import importlib
import os
from pathlib import Path
import re

from ament_index_python.packages import (get_package_prefix, get_package_share_directory,
                                         get_packages_with_prefixes, PackageNotFoundError)
from ament_index_python.resources import has_resource
from helpers import console_scripts, REPO
import pytest

INTERFACES = {
    'msg': ['ForceSensor', 'MotorCommand', 'ObjectState', 'PlantTick', 'ServoSetpoint',
            'SimStatus', 'StageReference', 'SupervisorStatus'],
    'srv': ['Grasp', 'Move', 'SetObject', 'SimStep'],
    'action': ['Grasp', 'Move'],
}


@pytest.fixture(scope='module')
def prefix():
    try:
        return Path(get_package_prefix('gripper_ros'))
    except PackageNotFoundError:  # pragma: no cover - message for a wrongly set-up shell
        pytest.fail('gripper_ros is not in the ament index: run `bash scripts/setup.sh` and '
                    '`source scripts/env.sh` (or use `bash scripts/test.sh`)')


def test_both_packages_in_ament_index():
    packages = get_packages_with_prefixes()
    assert 'gripper_ros' in packages
    assert 'gripper_interfaces' in packages
    assert has_resource('packages', 'gripper_ros')
    assert has_resource('rosidl_interfaces', 'gripper_interfaces')


def test_share_directory_has_package_xml_and_config():
    share = Path(get_package_share_directory('gripper_ros'))
    assert (share / 'package.xml').is_file()
    assert '<name>gripper_ros</name>' in (share / 'package.xml').read_text()
    assert (share / 'config' / 'gripper.yaml').is_file(), \
        'config/gripper.yaml is not installed (missing in the repo, or setup.sh not re-run)'


def test_launch_file_is_installed_where_ros2_launch_looks():
    installed = Path(get_package_share_directory('gripper_ros')) / 'launch' / 'gripper.launch.py'
    assert installed.is_file(), \
        f'{installed} missing (setup.py data_files, or setup.sh not re-run)'
    source = REPO / 'launch' / 'gripper.launch.py'
    if source.is_file():
        assert installed.read_text() == source.read_text()


def test_every_console_script_names_a_main_that_exists():
    """Each entry point's module is in the package and defines its function (no dead entry)."""
    for exe, target in console_scripts().items():
        module, function = target.split(':')
        path = REPO.joinpath(*module.split('.')).with_suffix('.py')
        assert path.is_file(), f'{exe}: {path} missing'
        defined = {n.name for n in ast.parse(path.read_text()).body
                   if isinstance(n, ast.FunctionDef)}
        assert function in defined, f'{exe}: {module} defines no {function}()'


@pytest.mark.parametrize('exe', sorted(console_scripts()))
def test_executable_installed_where_ros2_run_looks(prefix, exe):
    path = prefix / 'lib' / 'gripper_ros' / exe
    assert path.is_file(), f'{path} missing (setup.cfg install_scripts / colcon build)'
    assert os.access(path, os.X_OK), f'{path} is not executable'
    first_line = path.read_text().splitlines()[0]
    assert first_line.startswith('#!') and 'python' in first_line


# ------------------------------------------------------------------ generated interfaces
_PRIMITIVES = {
    'bool': 'boolean', 'byte': 'octet', 'char': 'uint8',
    'float32': 'float', 'float64': 'double',
    'int8': 'int8', 'uint8': 'uint8', 'int16': 'int16', 'uint16': 'uint16',
    'int32': 'int32', 'uint32': 'uint32', 'int64': 'int64', 'uint64': 'uint64',
    'string': 'string', 'wstring': 'wstring',
}


def _idl_type(ros_type):
    """Translate a .msg field type to the string get_fields_and_field_types() reports."""
    m = re.fullmatch(r'([\w/]+)(?:<=(\d+))?(\[(<=)?(\d*)\])?', ros_type)
    assert m, ros_type
    base, str_bound, array, bounded, size = m.groups()
    if base in _PRIMITIVES:
        t = _PRIMITIVES[base]
        if str_bound:
            t = f'{t}<{str_bound}>'
    else:
        t = base if '/' in base else f'gripper_interfaces/{base}'
        if t == 'Header':
            t = 'std_msgs/Header'
    if array is None:
        return t
    if not size:
        return f'sequence<{t}>'
    if bounded:
        return f'sequence<{t}, {size}>'
    return f'{t}[{size}]'


def _parse(text):
    """Fields (ordered name -> type) and constants (name -> python value) of one .msg section."""
    fields, constants = {}, {}
    for raw in text.splitlines():
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        m = re.fullmatch(r'(\S+)\s+(\w+)\s*=\s*(.+)', line)
        if m:
            typ, name, value = m.groups()
            if typ in ('string', 'wstring'):
                constants[name] = value.strip().strip('"\'')
            elif typ == 'bool':
                constants[name] = value.strip().lower() in ('true', '1')
            elif typ.startswith('float'):
                constants[name] = float(value)
            else:
                constants[name] = int(value, 0)
            continue
        typ, name = line.split()[:2]
        fields[name] = _idl_type(typ)
    return fields, constants


def _definition(kind, name):
    src = REPO / 'gripper_interfaces' / kind / f'{name}.{kind}'
    if not src.is_file():  # installed copy, e.g. when the tests run from another checkout
        src = Path(get_package_share_directory('gripper_interfaces')) / kind / f'{name}.{kind}'
    return src.read_text()


def _check(cls, text):
    fields, constants = _parse(text)
    assert cls.get_fields_and_field_types() == fields, cls.__name__
    for cname, value in constants.items():
        assert getattr(cls, cname) == value, f'{cls.__name__}.{cname}'
    instance = cls()  # default construction works
    for fname in fields:
        assert hasattr(instance, fname)


@pytest.mark.parametrize('name', INTERFACES['msg'])
def test_generated_message_matches_msg_file(name):
    module = importlib.import_module('gripper_interfaces.msg')
    _check(getattr(module, name), _definition('msg', name))


@pytest.mark.parametrize('name', INTERFACES['srv'])
def test_generated_service_matches_srv_file(name):
    module = importlib.import_module('gripper_interfaces.srv')
    srv = getattr(module, name)
    request_text, response_text = re.split(r'^---\s*$', _definition('srv', name), maxsplit=1,
                                           flags=re.M)
    _check(srv.Request, request_text)
    _check(srv.Response, response_text)


@pytest.mark.parametrize('name', INTERFACES['action'])
def test_generated_action_matches_action_file(name):
    module = importlib.import_module('gripper_interfaces.action')
    action = getattr(module, name)
    goal, result, feedback = re.split(r'^---\s*$', _definition('action', name), maxsplit=2,
                                      flags=re.M)
    _check(action.Goal, goal)
    _check(action.Result, result)
    _check(action.Feedback, feedback)


def test_named_types_go_over_the_wire_in_the_layout_the_nodes_read():
    """A generated message, serialised by rclpy, is the bytes the lockstep layout packs."""
    from gripper_interfaces.msg import MotorCommand
    from gripper_interfaces.srv import Grasp
    from gripper_ros.wire import CDR_LITTLE_ENDIAN, COMMAND_LAYOUT
    from rclpy.serialization import deserialize_message, serialize_message

    cmd = MotorCommand(stamp_ns=123_456_789, grasp_id=7, source=MotorCommand.SOURCE_FORCE,
                       voltage_v=1.5, hold_s=0.01, finite=True)
    data = serialize_message(cmd)
    fields = dict(zip(COMMAND_LAYOUT.fields, COMMAND_LAYOUT.unpack(data)))
    assert data[:len(CDR_LITTLE_ENDIAN)] == CDR_LITTLE_ENDIAN
    assert (fields['stamp_ns'], fields['grasp_id'], fields['source'], fields['voltage_v'],
            fields['hold_s'], fields['finite']) == (123_456_789, 7, 2, 1.5, 0.01, True)
    request = Grasp.Request(width_m=0.02, mass_kg=0.1)
    assert deserialize_message(serialize_message(request), Grasp.Request) == request


def test_every_interface_file_is_covered():
    on_disk = {kind: sorted(p.stem for p in (REPO / 'gripper_interfaces' / kind).glob(f'*.{kind}'))
               for kind in INTERFACES}
    if not any(on_disk.values()):
        pytest.skip('not running from the source tree')
    assert on_disk == {k: sorted(v) for k, v in INTERFACES.items()}
