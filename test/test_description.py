"""The robot description, from the config and through xacro, and who publishes it in a launch.

The shipped URDF is the config's, its joint is joint_states' joint with the plant's limits, the
xacro expands to the same links with a ros2_control block (or prefixed, on a parent link), and
the launch file runs robot_state_publisher only where it is installed.
"""
from __future__ import annotations

from pathlib import Path
import subprocess
import xml.etree.ElementTree as ET

from gripper_ros.core.config import ConfigError, load_config, parse_config
from gripper_ros.core.description import (finger_frames, FIXED_FINGER_JOINT, MOUNT_JOINT,
                                          urdf_text, xacro_macro_text)
from gripper_ros.nodes import launched_executables, robot_state_publisher_installed
from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER,
                              LAUNCHED_NODES, NODE_DESCRIPTION, ROBOT_STATE_PUBLISHER)
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / 'config' / 'gripper.yaml'
CONFIG = load_config(SHIPPED)


def _joints(root) -> dict:
    return {j.get('name'): j for j in root.iter('joint')}


def test_the_shipped_urdf_is_what_gripper_urdf_writes_from_the_config():
    assert (ROOT / 'urdf' / 'gripper.urdf').read_text(encoding='utf-8') == urdf_text(CONFIG)
    assert (ROOT / 'urdf' / 'gripper.macro.xacro').read_text(encoding='utf-8') == \
        xacro_macro_text(CONFIG)


def test_each_link_weighs_its_stated_mass_as_a_solid_box():
    root = ET.fromstring(urdf_text(CONFIG))
    links = {link.get('name'): link for link in root.iter('link')}
    masses = {name: float(link.find('inertial/mass').get('value')) for name, link in links.items()}
    assert masses == {FRAME_BASE: 0.4, FRAME_FIXED_FINGER: 0.03, FRAME_MOVING_FINGER: 0.03}
    # the finger: 0.01 x 0.02 x 0.06 m, 0.03 kg: ixx = m (y^2 + z^2) / 12 = 1e-5 kg m^2
    inertia = links[FRAME_MOVING_FINGER].find('inertial/inertia').attrib
    assert float(inertia['ixx']) == pytest.approx(1.0e-5)
    assert float(inertia['izz']) == pytest.approx(0.03 * (0.01**2 + 0.02**2) / 12)


def test_finger_joint_has_the_plant_s_travel_force_and_speed():
    root = ET.fromstring(urdf_text(CONFIG))
    assert {link.get('name') for link in root.iter('link')} == {
        FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER}
    joint = _joints(root)[FINGER_JOINT]
    assert joint.get('type') == 'prismatic'
    limit = {k: float(v) for k, v in joint.find('limit').attrib.items()}
    assert limit == pytest.approx({'lower': 0.0, 'upper': 0.150, 'effort': 33.3855799373,
                                   'velocity': 0.068816036302})


@pytest.mark.parametrize('position_m, width_m', [(0.0, 0.150), (0.1, 0.05), (0.150, 0.0)])
def test_the_pad_faces_are_the_width_apart(position_m, width_m):
    frames = finger_frames(CONFIG)
    gap = frames.fixed_finger_xyz[0] - frames.moving_finger_xyz(position_m)[0]
    assert gap == pytest.approx(width_m)


def test_a_geometry_value_out_of_bounds_is_refused_by_name():
    data = yaml.safe_load(SHIPPED.read_text(encoding='utf-8'))
    data['geometry']['finger_length_m'] = -0.01
    with pytest.raises(ConfigError, match='geometry.finger_length_m'):
        parse_config(data)


def _canonical(element) -> tuple:
    """Return an element as tag, attributes and children (whitespace, attribute order aside)."""
    return (element.tag, sorted(element.attrib.items()), [_canonical(c) for c in element])


def _xacro(**args) -> ET.Element:
    xacro = pytest.importorskip('xacro')
    doc = xacro.process_file(str(ROOT / 'urdf' / 'gripper.urdf.xacro'), mappings=args)
    return ET.fromstring(doc.toxml())


@pytest.mark.parametrize('hardware, plugin', [
    ('mock', 'mock_components/GenericSystem'),
    ('topic', 'joint_state_topic_hardware_interface/JointStateTopicSystem')])
def test_the_xacro_is_the_urdf_with_a_ros2_control_block(hardware, plugin):
    root = _xacro(hardware=hardware, namespace='/left')
    plain = ET.fromstring(urdf_text(CONFIG))
    assert [_canonical(e) for e in root if e.tag in ('link', 'joint')] == \
        [_canonical(e) for e in plain if e.tag in ('link', 'joint')]
    (control,) = root.iter('ros2_control')
    assert control.find('hardware/plugin').text == plugin
    params = {p.get('name'): p.text for p in control.findall('hardware/param')}
    assert params == ({} if hardware == 'mock' else {
        'joint_commands_topic': '/left/joint_commands',
        'joint_states_topic': '/left/joint_states'})
    (joint,) = control.findall('joint')
    assert joint.get('name') == FINGER_JOINT
    assert [c.get('name') for c in joint.findall('command_interface')] == [
        'position', 'velocity', 'effort']


def test_the_xacro_with_a_prefix_hangs_the_gripper_on_the_parent_link():
    root = _xacro(prefix='left_', parent='tool0', xyz='0 0 0.01', hardware='topic')
    joints = {j.get('name'): j for j in root.findall('joint')}   # the URDF's, not ros2_control's
    assert set(joints) == {f'left_{j}' for j in (MOUNT_JOINT, FIXED_FINGER_JOINT, FINGER_JOINT)}
    mount = joints[f'left_{MOUNT_JOINT}']
    assert (mount.find('parent').get('link'), mount.find('child').get('link')) == \
        ('tool0', f'left_{FRAME_BASE}')
    assert mount.find('origin').get('xyz') == '0 0 0.01'
    assert {link.get('name') for link in root.iter('link')} == {
        f'left_{n}' for n in (FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER)}
    assert joints[f'left_{FINGER_JOINT}'].find('limit').attrib == \
        _joints(ET.fromstring(urdf_text(CONFIG)))[FINGER_JOINT].find('limit').attrib
    (control,) = root.iter('ros2_control')
    assert [j.get('name') for j in control.findall('joint')] == [f'left_{FINGER_JOINT}']


def test_the_xacro_refuses_an_unknown_hardware():
    xacro = pytest.importorskip('xacro')
    with pytest.raises(xacro.XacroException, match='hardware must be mock or topic'):
        _xacro(hardware='gazebo')


@pytest.mark.parametrize('installed', [False, True])
def test_the_launch_runs_robot_state_publisher_where_the_ament_index_has_it(
        tmp_path, monkeypatch, installed):
    index = tmp_path / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    if installed:
        (index / ROBOT_STATE_PUBLISHER).write_text('', encoding='utf-8')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    assert robot_state_publisher_installed() is installed
    launched = launched_executables(installed)
    publishers = [e for e in launched if e in (
        (ROBOT_STATE_PUBLISHER, ROBOT_STATE_PUBLISHER), ('gripper_ros', NODE_DESCRIPTION))]
    assert publishers == [(ROBOT_STATE_PUBLISHER, ROBOT_STATE_PUBLISHER) if installed
                          else ('gripper_ros', NODE_DESCRIPTION)]     # one /tf publisher
    assert len(launched) == len(LAUNCHED_NODES)


def test_gripper_urdf_prints_the_urdf_robot_state_publisher_gets_in_a_launch():
    """As the launch file's Command runs it: ``gripper_urdf --config FILE --prefix P``."""
    from ament_index_python.packages import get_package_prefix
    exe = Path(get_package_prefix('gripper_ros')) / 'lib' / 'gripper_ros' / 'gripper_urdf'
    for prefix in ('', 'left_'):
        out = subprocess.run([str(exe), '--config', str(SHIPPED), '--prefix', prefix],
                             capture_output=True, text=True, timeout=60, check=True).stdout
        assert out == urdf_text(CONFIG, prefix)
    bad = subprocess.run([str(exe), '--prefix', 'left-'], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and bad.stderr.count('\n') == 1 and '--prefix' in bad.stderr
