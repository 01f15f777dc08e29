"""The wire codes and the numeric core: one home for codes, and a core without rclpy."""
import ast
import importlib
from pathlib import Path
import subprocess
import sys

from gripper_ros import wire
import pytest

PACKAGE = Path(wire.__file__).resolve().parent
WITHOUT_ROS = sorted(p for folder in ('core', 'studies', 'identify')
                     for p in (PACKAGE / folder).rglob('*.py')) + [PACKAGE / 'wire.py']
"""The core (every layer of it), the studies, the identification and the wire codes."""
WITHOUT_ROS_MODULES = sorted('.'.join(p.relative_to(PACKAGE.parent).with_suffix('').parts)
                             .removesuffix('.__init__') for p in WITHOUT_ROS)


def _generated_constants(module: str, cls_path: str, prefix: str) -> dict[str, int]:
    cls = importlib.import_module(module)
    for part in cls_path.split('.'):
        cls = getattr(cls, part)
    return {name[len(prefix):]: getattr(cls, name) for name in dir(cls)
            if name.startswith(prefix) and name.isupper()}


@pytest.mark.parametrize('enum_cls, module, cls_path, prefix', wire.WIRE_CODES,
                         ids=[f'{c[2]}.{c[3]}' for c in wire.WIRE_CODES])
def test_every_code_equals_the_generated_constant(enum_cls, module, cls_path, prefix):
    generated = _generated_constants(module, cls_path, prefix)
    assert generated, f'no {prefix}* constants in {module}.{cls_path}'
    assert {m.name: m.value for m in enum_cls} == generated


def test_enum_name_of_an_unknown_code_is_the_number():
    assert wire.enum_name(wire.Outcome, 1) == 'HOLDING'
    assert wire.enum_name(wire.Outcome, 250) == '250'


def _imports(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            yield node.module


@pytest.mark.parametrize('path', WITHOUT_ROS, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_core_module_names_no_ros_client_library(path):
    """Not even lazily inside a function: the core runs where no ROS is installed.

    Which package modules each may import is test_structure's (the layers).
    """
    names = set(_imports(ast.parse(path.read_text(), str(path))))
    ros = sorted(n for n in names
                 if n.split('.')[0] in ('rclpy', 'rosidl_runtime_py', 'gripper_interfaces'))
    assert not ros, f'{path.name} imports {ros}'


def test_importing_the_whole_core_loads_no_rclpy():
    code = ('import sys\n' + ''.join(f'import {m}\n' for m in WITHOUT_ROS_MODULES) +
            'bad = sorted(m for m in sys.modules if m.split(".")[0] in ("rclpy", '
            '"gripper_interfaces"))\n'
            'assert not bad, bad\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


# --- the byte layouts of the lockstep messages -------------------------------------------------

def _message_class(msgtype: str):
    pkg, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{pkg}.{kind}'), name)


def _random_values(cls, rng):
    types = cls.get_fields_and_field_types()
    out = []
    for name, kind in types.items():
        if kind == 'double':
            out.append(float(rng.choice([rng.normal() * 10.0 ** rng.integers(-9, 9), 0.0, -0.0,
                                         float('inf'), float('nan')])))
        elif kind == 'boolean':
            out.append(int(rng.integers(0, 2)))
        elif kind == 'int64':
            out.append(int(rng.integers(-2 ** 62, 2 ** 62)))
        elif kind == 'uint32':
            out.append(int(rng.integers(0, 2 ** 32)))
        elif kind == 'uint8':
            out.append(int(rng.integers(0, 256)))
        else:
            raise AssertionError(f'{name}: {kind} has no fixed layout')
    return out


@pytest.mark.parametrize('layout', wire.LOOP_LAYOUTS.values(), ids=lambda lay: lay.msgtype)
def test_loop_layout_is_rclpys_own_serialisation(layout):
    """Both ways, for random values, field by field, so that every offset agrees.

    rclpy reads what the nodes pack, and the nodes read what rclpy writes (NaN and infinities
    included).
    """
    import numpy as np
    from rclpy.serialization import deserialize_message, serialize_message
    cls = _message_class(layout.msgtype)
    assert tuple(cls.get_fields_and_field_types()) == layout.fields
    rng = np.random.default_rng(7)
    for _ in range(200):
        values = _random_values(cls, rng)
        msg = cls(**{n: (bool(v) if cls.get_fields_and_field_types()[n] == 'boolean' else v)
                     for n, v in zip(layout.fields, values)})
        data = serialize_message(msg)
        assert len(layout.pack(*values)) == len(data)   # (alignment padding is not zeroed)
        unpacked = layout.unpack(data)
        assert len(unpacked) == len(values)
        for got, want in zip(unpacked, values):
            assert got == want or (got != got and want != want)
        back = deserialize_message(layout.pack(*values), cls)
        for name, want in zip(layout.fields, values):
            got = getattr(back, name)
            assert got == want or (got != got and want != want), name


def test_a_big_endian_message_is_left_to_the_general_decoder():
    layout = wire.TICK_LAYOUT
    data = bytearray(layout.pack(*([0] + [0.0] * 8 + [0, 0] + [0.0] * 4)))
    data[1] = 0x00                                  # CDR_BE encapsulation
    assert layout.unpack(bytes(data)) is None


def test_qualified_names_and_namespaces():
    assert wire.qualified('gripper', wire.TOPIC_TICK) == '/gripper/loop/tick'
    assert wire.qualified('/left/', 'grasp') == '/left/grasp'
    assert wire.qualified('left', wire.TOPIC_CLOCK) == '/clock'
    assert wire.qualified('', 'grasp') == '/grasp'
    assert wire.check_namespace('/robot/left/') == 'robot/left'
    for bad in ('left gripper', '1left', 'a//b', 'le-ft'):
        with pytest.raises(ValueError, match='not a ROS name'):
            wire.check_namespace(bad)


def test_the_name_prefix_of_a_namespace():
    """None in the default namespace and the root; else the namespace's parts and ``_``."""
    assert wire.namespace_prefix(wire.DEFAULT_NAMESPACE) == ''
    assert wire.namespace_prefix('/gripper/') == wire.namespace_prefix('') == ''
    assert wire.namespace_prefix('/left') == 'left_'
    assert wire.namespace_prefix('robot/left/') == 'robot_left_'
    assert wire.namespace_prefix('right') != wire.namespace_prefix('left')
    assert set(wire.namespace_prefix('robot_2/left')) <= wire.NAME_CHARACTERS


def test_the_longest_namespace_leaves_room_for_every_action_name_under_it():
    """Fit every action's names under the longest namespace: rcl's limit is 255 - 8.

    rcl/src/rcl/node_resolve_name.c refuses a longer topic or service name; an action's
    longest is its ``_action/cancel_goal``.
    """
    actions = (wire.ACTION_GRASP, wire.ACTION_MOVE, *wire.CONTROL_ACTIONS)
    longest = max(len(f'{action}/_action/{part}') for action in actions
                  for part in ('send_goal', 'cancel_goal', 'get_result', 'feedback', 'status'))
    assert wire.MAX_NAMESPACE_LENGTH == 255 - 8 - len('//') - longest
