"""Bags decode in Foxglove's own ROS 2 readers and in rosbags, message for message.

Schema text: rosbag2 (rosbag2_cpp ``LocalMessageDefinitionSource``) names each appended
dependency as the field writes its type (``MSG: std_msgs/Header`` for a field
``std_msgs/Header header``), and Foxglove's ``@foxglove/rosmsg`` resolves a qualified field type
only by that exact name. The interop tests record one grasp with the real graph and decode
every message with ``@foxglove/rosmsg`` + ``@foxglove/rosmsg2-serialization`` over
``@mcap/core`` (pinned in test/interop/package-lock.json, installed by scripts/setup.sh), and
with rosbags.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
import re
import shutil
import subprocess

from gripper_ros.bags.reader import read_bag
from gripper_ros.bags.schema import find_interface_file, message_definition, SCHEMA_SEPARATOR
from gripper_ros.bags.series import load_grasp_series
from gripper_ros.nodes.recording import recorded_grasp
from gripper_ros.wire import (BAG_TOPICS, DEFAULT_NAMESPACE, DESCRIPTION_TOPICS, GRAPH_TOPICS,
                              qualified, TOPIC_JOINT_STATES, TOPIC_ROBOT_DESCRIPTION, TOPIC_TF,
                              TOPIC_TF_STATIC)
from helpers import copy_mcap, tf_as_robot_state_publisher
import numpy as np
import pytest
import yaml

INTEROP = Path(__file__).resolve().parent / 'interop'
DECODER = INTEROP / 'decode_bag.mjs'
NPM_DIR = Path(__file__).resolve().parents[1] / 'build' / 'interop'
"""Where scripts/setup.sh installs the pinned npm packages: node finds them beside the script."""
RECORDED = {qualified(DEFAULT_NAMESPACE, t): msgtype for t, msgtype in GRAPH_TOPICS.items()}
"""The graph's topics of the default gripper, with their types."""
FRESH = {qualified(DEFAULT_NAMESPACE, t): msgtype for t, msgtype in BAG_TOPICS.items()}
"""The topics of a fresh bag: the graph's and the description's (robot_description, /tf)."""
PLAIN_TYPES = ('gripper_interfaces/msg/PlantTick', 'gripper_interfaces/msg/StageReference',
               'gripper_interfaces/msg/MotorCommand')
"""The lockstep messages: no nested type."""
HEADER_TYPES = sorted(t for t in set(GRAPH_TOPICS.values())
                      if t not in PLAIN_TYPES and t != 'visualization_msgs/msg/Marker')
"""The recorded types whose only nested type is a std_msgs/Header: sensor_msgs/JointState and
our gripper_interfaces messages (the object's Marker has many more)."""
PLAIN_TOPICS = {t for t, msgtype in RECORDED.items() if msgtype in PLAIN_TYPES}
"""The topics whose schema text names no dependency."""
PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
              'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}
FOXGLOVE_HEADER_ERROR = "Expected 1 top level type definition for 'std_msgs/Header' but found 0"


# --- the schema text ------------------------------------------------------------------------

FIXTURE_FILES = {
    'fixture_msgs/msg/Outer.msg': (
        '# Outer: a type of its own package without prefix, one written with msg/.\n'
        '# Inner[] commented_out\n'
        'Inner[] inners                # same package, no prefix\n'
        'fixture_msgs/msg/Leaf leaf\n'
        'uint8 KIND_A=1\n'
        'string<=8 label\n'
        'float64[<=4] gains\n'),
    'fixture_msgs/msg/Inner.msg': (
        'fixture_base_msgs/Stamp stamp\n'
        'float64 value\n'),
    'fixture_msgs/msg/Leaf.msg': (
        'Inner inner\n'
        'fixture_base_msgs/msg/Stamp stamp\n'
        'int32[3] counts\n'),
    'fixture_base_msgs/msg/Stamp.msg': (
        'int32 sec\n'
        'uint32 nanosec\n'),
}

# What rosbag2 writes for fixture_msgs/msg/Outer: the .msg as is; then, depth first and in
# sorted order per type, each dependency not written yet under the name its field writes
# ('Inner' in fixture_msgs -> fixture_msgs/Inner). 'fixture_base_msgs/Stamp' and
# 'fixture_base_msgs/msg/Stamp' are two names, so Stamp is written twice.
OUTER_EXPECTED = (
    '# Outer: a type of its own package without prefix, one written with msg/.\n'
    '# Inner[] commented_out\n'
    'Inner[] inners                # same package, no prefix\n'
    'fixture_msgs/msg/Leaf leaf\n'
    'uint8 KIND_A=1\n'
    'string<=8 label\n'
    'float64[<=4] gains\n'
    '\n'
    '================================================================================\n'
    'MSG: fixture_msgs/Inner\n'
    'fixture_base_msgs/Stamp stamp\n'
    'float64 value\n'
    '\n'
    '================================================================================\n'
    'MSG: fixture_base_msgs/Stamp\n'
    'int32 sec\n'
    'uint32 nanosec\n'
    '\n'
    '================================================================================\n'
    'MSG: fixture_msgs/msg/Leaf\n'
    'Inner inner\n'
    'fixture_base_msgs/msg/Stamp stamp\n'
    'int32[3] counts\n'
    '\n'
    '================================================================================\n'
    'MSG: fixture_base_msgs/msg/Stamp\n'
    'int32 sec\n'
    'uint32 nanosec\n')


def test_schema_text_of_a_nested_type_is_what_rosbag2_writes(tmp_path, monkeypatch):
    for rel, text in FIXTURE_FILES.items():
        path = tmp_path / 'share' / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding='utf-8')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    assert message_definition('fixture_msgs/msg/Outer') == OUTER_EXPECTED


def _sections(text: str) -> list[tuple[str | None, str]]:
    """(MSG name, body) of each part of a schema text; None names the root."""
    root, *rest = text.split(f'\n{SCHEMA_SEPARATOR}\n')
    out: list[tuple[str | None, str]] = [(None, root)]
    for part in rest:
        head, _, body = part.partition('\n')
        assert head.startswith('MSG: '), head
        out.append((head[len('MSG: '):], body))
    return out


def _written_types(body: str, package: str) -> set[str]:
    """Message types the fields of one .msg text use, named as rosbag2 names them."""
    out = set()
    for line in body.splitlines():
        code = line.split('#', 1)[0].split()
        if len(code) < 2 or '=' in code[1] or (len(code) > 2 and code[2].startswith('=')):
            continue
        base = re.sub(r'<=\d+$', '', re.sub(r'\[[^\]]*\]$', '', code[0]))
        if base not in PRIMITIVES:
            out.add(base if '/' in base else f'{package}/{base}')
    return out


@pytest.mark.parametrize('msgtype', sorted(set(BAG_TOPICS.values())))
def test_every_msg_line_names_a_type_as_a_field_writes_it(msgtype):
    sections = _sections(message_definition(msgtype))
    names = [name for name, _ in sections[1:]]
    written = set()
    for name, body in sections:
        written |= _written_types(body, (name or msgtype).split('/')[0])
    assert len(names) == len(set(names))
    assert set(names) == written
    assert sections[0][1] == find_interface_file(msgtype).read_text(encoding='utf-8')
    for name, body in sections[1:]:
        package, type_name = name.split('/')[0], name.split('/')[-1]
        installed = find_interface_file(f'{package}/msg/{type_name}').read_text(encoding='utf-8')
        assert body == installed, name


@pytest.mark.parametrize('msgtype', HEADER_TYPES)
def test_header_types_name_header_and_time_as_written(msgtype):
    """Name Header and Time as their fields write them: std_msgs/Header, builtin_interfaces/Time.

    sensor_msgs/JointState and our messages write 'std_msgs/Header header'; Header writes
    'builtin_interfaces/Time stamp'.
    """
    def installed(name):
        return find_interface_file(name).read_text(encoding='utf-8')
    expected = (f'{installed(msgtype)}\n{SCHEMA_SEPARATOR}\nMSG: std_msgs/Header\n'
                f'{installed("std_msgs/msg/Header")}\n{SCHEMA_SEPARATOR}\n'
                f'MSG: builtin_interfaces/Time\n{installed("builtin_interfaces/msg/Time")}')
    assert message_definition(msgtype) == expected


# --- a fresh bag, decoded ---------------------------------------------------------------------

def _node_skip_reason() -> str:
    node = shutil.which('node')
    if node is None:
        return 'node is not installed (Foxglove interop needs Node.js)'
    wanted = json.loads((INTEROP / 'package.json').read_text(encoding='utf-8'))['dependencies']
    for name, version in wanted.items():
        meta = NPM_DIR / 'node_modules' / name / 'package.json'
        have = json.loads(meta.read_text(encoding='utf-8'))['version'] if meta.is_file() else None
        if have != version:
            return (f'npm package {name}@{version} is not installed in build/interop/node_modules '
                    f'(have {have}): run bash scripts/setup.sh')
    return ''


@pytest.fixture(scope='module')
def node() -> str:
    reason = _node_skip_reason()
    if reason:
        pytest.skip(reason)
    return shutil.which('node')


def foxglove_decode(node: str, mcap_path: Path) -> dict:
    """Run decode_bag.mjs on one .mcap and return its JSON report."""
    decoder = NPM_DIR / DECODER.name
    staged = decoder.with_name(f'.{DECODER.name}.{os.getpid()}')
    shutil.copyfile(DECODER, staged)
    os.replace(staged, decoder)                 # the copy node runs beside node_modules
    done = subprocess.run([node, str(decoder), str(mcap_path)], capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.fixture(scope='module')
def fresh(tmp_path_factory):
    """One short grasp recorded by the real graph: (run, bag dir, counts in metadata.yaml)."""
    from gripper_ros.nodes.graph import GripperGraph
    out = tmp_path_factory.mktemp('interop')
    with GripperGraph.in_own_context() as graph:
        run = recorded_grasp(graph, out / 'fresh', 0.1, 0.75)
    info = yaml.safe_load((run.bag_dir / 'metadata.yaml').read_text(encoding='utf-8'))
    counts = {e['topic_metadata']['name']: e['message_count']
              for e in info['rosbag2_bagfile_information']['topics_with_message_count']}
    assert run.response.success, run.response.message
    assert counts == run.recorded
    assert {t: n for t, n in counts.items() if t in RECORDED} == run.published
    assert set(counts) == set(FRESH)
    assert all(n > 0 for t, n in counts.items() if not t.endswith('/sim/status')), counts
    # the latched description once, at the start; the moving finger at 20 Hz of joint states
    description = qualified(DEFAULT_NAMESPACE, TOPIC_ROBOT_DESCRIPTION)
    assert counts[description] == counts[TOPIC_TF_STATIC] == 1
    tf, expected = tf_as_robot_state_publisher(read_bag(run.bag_dir))
    assert tf == expected and len(tf) >= counts[qualified(DEFAULT_NAMESPACE,
                                                          TOPIC_JOINT_STATES)] // 5
    return run, Path(run.bag_dir), counts


def _plain(value):
    """Turn a rosbags message into the JSON form decode_bag.mjs prints (dicts, lists, numbers)."""
    if dataclasses.is_dataclass(value):              # constants (upper case) are fields here
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if not f.name.startswith('__') and not f.name.isupper()}
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, float) and math.isnan(value):
        return None                                  # JSON.stringify(NaN)
    return value


def _rosbags_decoded(bag) -> dict[str, list]:
    out: dict[str, list] = {}
    for raw in bag.messages:
        out.setdefault(raw.topic, []).append(bag.decode(raw))
    return out


def test_foxglove_decodes_every_message_of_a_fresh_bag(node, fresh):
    run, bag_dir, counts = fresh
    report = foxglove_decode(node, next(bag_dir.glob('*.mcap')))
    assert report['profile'] == 'ros2'
    topics = report['topics']
    assert {t: e['schema'] for t, e in topics.items()} == FRESH
    assert {t: e['error'] for t, e in topics.items()} == dict.fromkeys(FRESH, '')
    assert {t: e['decoded'] for t, e in topics.items()} == counts
    assert {t: e['statistics_count'] for t, e in topics.items()} == counts
    assert all(e['failed'] == 0 and e['trailing_bytes'] == 0 for e in topics.values())
    # the same values as rosbags decodes, first and last message of every topic
    decoded = _rosbags_decoded(read_bag(bag_dir))
    for topic, entry in topics.items():
        if not entry['decoded']:
            continue                                 # sim/status: about one per wall second
        assert entry['first'] == _plain(decoded[topic][0]), topic
        assert entry['last'] == _plain(decoded[topic][-1]), topic
    assert topics['/gripper/joint_states']['last']['name'] == ['finger_joint']
    assert topics['/gripper/robot_description']['first']['data'].startswith('<?xml')
    moving = topics[TOPIC_TF]['last']['transforms'][0]
    assert (moving['header']['frame_id'], moving['child_frame_id']) == ('gripper_base',
                                                                        'moving_finger')
    assert set(DESCRIPTION_TOPICS) <= {t.removeprefix('/gripper/') for t in topics}


def test_rosbags_decodes_every_message_of_a_fresh_bag(fresh):
    """With the repo's reader, and with a typestore holding only the bag's own schemas."""
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores
    run, bag_dir, counts = fresh
    bag = read_bag(bag_dir)
    assert not bag.truncated
    decoded = _rosbags_decoded(bag)
    assert {t: len(v) for t, v in decoded.items()} == counts
    own = get_typestore(Stores.EMPTY)
    for name, text in bag.schemas.items():
        types = get_types_from_msg(text, name)
        assert name in types, sorted(types)
        assert name not in HEADER_TYPES or 'builtin_interfaces/msg/Time' in types, sorted(types)
        own.register({k: v for k, v in types.items() if k not in own.fielddefs})
    own_counts: dict[str, int] = {}
    for raw in bag.messages:
        msg = own.deserialize_cdr(raw.data, raw.msgtype)
        own_counts[raw.topic] = own_counts.get(raw.topic, 0) + 1
    assert own_counts == counts
    assert _plain(msg) == _plain(decoded[bag.messages[-1].topic][-1])


# --- bags with the older schema names ---------------------------------------------------------

def _old_form(text: str) -> str:
    """Rename every dependency of a schema text 'pkg/msg/Type' (as older gripper_ros bags have)."""
    return re.sub(r'^MSG: ([A-Za-z0-9_]+)/([A-Za-z0-9_]+)$', r'MSG: \1/msg/\2', text,
                  flags=re.MULTILINE)


@pytest.fixture(scope='module')
def old_bag(fresh, tmp_path_factory) -> Path:
    """Rewrite the fresh bag record for record, only with old-form schema texts."""
    _, bag_dir, _ = fresh
    src = next(bag_dir.glob('*.mcap'))
    out_dir = tmp_path_factory.mktemp('old') / bag_dir.name
    out_dir.mkdir()
    shutil.copy(bag_dir / 'metadata.yaml', out_dir / 'metadata.yaml')
    copy_mcap(src, out_dir / src.name, schema_text=_old_form)
    return out_dir


def test_old_schema_bags_stay_readable_by_our_tools(fresh, old_bag):
    run, bag_dir, counts = fresh
    old = read_bag(old_bag)
    for msgtype in HEADER_TYPES:
        assert 'MSG: std_msgs/msg/Header\n' in old.schemas[msgtype]
        assert 'MSG: builtin_interfaces/msg/Time\n' in old.schemas[msgtype]
    assert {t: len(v) for t, v in _rosbags_decoded(old).items()} == counts
    new_series, old_series = load_grasp_series(bag_dir), load_grasp_series(old)
    for part in ('ticks', 'references', 'commands', 'statuses', 'objects', 'decisions'):
        a, b = getattr(new_series, part), getattr(old_series, part)
        for name in a.dtype.names:
            assert np.array_equal(a[name], b[name], equal_nan=True), (part, name)
    assert old_series.counts == counts and old_series.custom_data == new_series.custom_data


def test_foxglove_reads_only_the_header_free_topics_of_an_old_schema_bag(node, old_bag):
    """The interop check tells the two forms apart: the old names fail as the issue reports."""
    topics = foxglove_decode(node, next(old_bag.glob('*.mcap')))['topics']
    for topic in PLAIN_TOPICS:                    # no dependencies: nothing to name
        assert topics[topic]['error'] == '' and topics[topic]['decoded'] > 0, topic
    for topic in set(RECORDED) - PLAIN_TOPICS:
        assert topics[topic]['decoded'] == 0
        assert FOXGLOVE_HEADER_ERROR in topics[topic]['error'], topics[topic]['error']
