"""The robot description, from the config and through xacro.

The shipped URDF is the config's, its joint is joint_states' joint with the plant's limits, and
the xacro expands to the same links with a ros2_control block.
"""
from __future__ import annotations

from pathlib import Path
import xml.etree.ElementTree as ET

from gripper_ros.core.config import ConfigError, load_config, parse_config
from gripper_ros.core.description import finger_frames, urdf_text
from gripper_ros.wire import FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / 'config' / 'gripper.yaml'
CONFIG = load_config(SHIPPED)


def _joints(root) -> dict:
    return {j.get('name'): j for j in root.iter('joint')}


def test_the_shipped_urdf_is_what_gripper_urdf_writes_from_the_config():
    assert (ROOT / 'urdf' / 'gripper.urdf').read_text(encoding='utf-8') == urdf_text(CONFIG)


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


def test_the_xacro_refuses_an_unknown_hardware():
    xacro = pytest.importorskip('xacro')
    with pytest.raises(xacro.XacroException, match='hardware must be mock or topic'):
        _xacro(hardware='gazebo')
