"""The shipped Foxglove layout and RViz config: generated, installed, served and recorded.

Each is what viewer_layouts writes, is installed, and every topic it names is served by the live
view and recorded in a grasp's bag.

Known answers: the topics and types of ``wire.LIVE_TOPICS`` and ``wire.BAG_TOPICS``, the
generated message classes' fields, the latched QoS of the description's publisher, and a bag the
real graph records (test_foxglove_interop's ``fresh``).
"""
from __future__ import annotations

import importlib
import json
from pathlib import Path
import re

from ament_index_python.packages import get_package_share_directory
from gripper_ros.apps.viewer_layouts import (FOXGLOVE_LAYOUT, foxglove_layout, RVIZ_CONFIG,
                                             rviz_config)
from gripper_ros.nodes.qos import LATCHED_QOS
from gripper_ros.wire import (BAG_TOPICS, DEFAULT_NAMESPACE, LIVE_TOPICS, qualified,
                              TOPIC_OBJECT_MARKER, TOPIC_ROBOT_DESCRIPTION)
from helpers import REPO
import pytest
from rclpy.qos import DurabilityPolicy
from test_foxglove_interop import fresh  # noqa: F401 - the recorded grasp, a fixture
import yaml

VIEWERS = REPO / 'viewers'
SERVED = {qualified(DEFAULT_NAMESPACE, t): msgtype for t, msgtype in LIVE_TOPICS.items()}
RECORDED = {qualified(DEFAULT_NAMESPACE, t): msgtype for t, msgtype in BAG_TOPICS.items()}
PATH = re.compile(r'^(/[^.]+)((?:\.[A-Za-z_]\w*(?:\[\d+\])?)*)$')
"""A Foxglove message path: the topic, then fields (an index into an array at most)."""


def _message_class(msgtype: str):
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def _layout_paths(node) -> list[str]:
    """Return every topic and message path a layout's panels name."""
    out: list[str] = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key == 'topics' and isinstance(value, dict):
                out += list(value)
            elif key in ('value', 'topicPath') and isinstance(value, str):
                out.append(value)
            else:
                out += _layout_paths(value)
    elif isinstance(node, list):
        for value in node:
            out += _layout_paths(value)
    return out


def _field_type(msgtype: str, fields: str) -> str:
    """Return the type of the field path ``.a.b[0]`` in ``msgtype`` (AssertionError if none)."""
    cls = _message_class(msgtype)
    slot = msgtype
    for part in filter(None, fields.split('.')):
        name = part.split('[')[0]
        types = cls.get_fields_and_field_types()
        assert name in types, f'{msgtype} has no field {name} (path {fields})'
        slot = types[name]
        if '[' in part:
            assert slot.startswith('sequence<'), f'{name} of {msgtype} is not an array'
            slot = slot[len('sequence<'):-1]
        if '/' in slot:
            package, name = slot.split('/')
            cls = _message_class(f'{package}/msg/{name}')
    return slot


def test_shipped_files_are_what_viewer_layouts_writes():
    assert (VIEWERS / FOXGLOVE_LAYOUT).read_text(encoding='utf-8') == foxglove_layout()
    assert (VIEWERS / RVIZ_CONFIG).read_text(encoding='utf-8') == rviz_config()


def test_both_files_are_installed():
    share = Path(get_package_share_directory('gripper_ros')) / 'viewers'
    for name in (FOXGLOVE_LAYOUT, RVIZ_CONFIG):
        assert (share / name).read_text(encoding='utf-8') == \
            (VIEWERS / name).read_text(encoding='utf-8'), name


def test_every_path_of_the_foxglove_layout_is_a_served_and_recorded_field():
    layout = json.loads((VIEWERS / FOXGLOVE_LAYOUT).read_text(encoding='utf-8'))
    paths = _layout_paths(layout)
    topics = set()
    for path in paths:
        match = PATH.match(path)
        assert match, path
        topic, fields = match.groups()
        assert topic in SERVED and topic in RECORDED, topic
        slot = _field_type(SERVED[topic], fields)
        if fields:                           # a plotted value: a number
            assert slot in ('double', 'float'), (path, slot)
        topics.add(topic)
    namespaced = {qualified(DEFAULT_NAMESPACE, t)
                  for t in (TOPIC_ROBOT_DESCRIPTION, TOPIC_OBJECT_MARKER)}
    assert namespaced <= topics                 # the URDF and the object in the 3D panel
    assert len([p for p in paths if '.' in p]) == 5     # position, force: each with a setpoint


def test_the_rviz_config_draws_the_urdf_the_fingers_and_the_object():
    config = yaml.safe_load((VIEWERS / RVIZ_CONFIG).read_text(encoding='utf-8'))
    manager = config['Visualization Manager']
    displays = {d['Class']: d for d in manager['Displays']}
    assert {'rviz_default_plugins/RobotModel', 'rviz_default_plugins/TF',
            'rviz_default_plugins/Marker'} <= set(displays)
    assert manager['Global Options']['Fixed Frame'] == 'gripper_base'
    model = displays['rviz_default_plugins/RobotModel']
    assert model['Description Source'] == 'Topic'
    description = model['Description Topic']
    assert description['Value'] == qualified(DEFAULT_NAMESPACE, TOPIC_ROBOT_DESCRIPTION)
    latched = LATCHED_QOS.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert latched and description['Durability Policy'] == 'Transient Local'
    marker = displays['rviz_default_plugins/Marker']['Topic']['Value']
    assert marker == qualified(DEFAULT_NAMESPACE, TOPIC_OBJECT_MARKER)
    assert {description['Value'], marker} <= set(SERVED) & set(RECORDED)


def test_a_recorded_grasp_holds_every_topic_the_viewers_name(fresh):  # noqa: F811
    _, _, counts = fresh
    layout = json.loads((VIEWERS / FOXGLOVE_LAYOUT).read_text(encoding='utf-8'))
    topics = {PATH.match(p).group(1) for p in _layout_paths(layout)} | {'/tf', '/tf_static'}
    assert {t: counts.get(t, 0) > 0 for t in topics} == dict.fromkeys(topics, True)


@pytest.mark.parametrize('namespace,frame', [('left', 'left_gripper_base')])
def test_another_namespace_gets_its_own_topics_and_frames(namespace, frame):
    layout = foxglove_layout(namespace)
    assert '"/gripper/' not in layout and f'"/{namespace}/sim/object_marker"' in layout
    assert f'"followTf": "{frame}"' in layout
    rviz = yaml.safe_load(rviz_config(namespace))
    assert rviz['Visualization Manager']['Global Options']['Fixed Frame'] == frame
