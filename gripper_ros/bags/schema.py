"""Message definitions and types from the installed interface packages (no rclpy).

The recorder stores, per type, the full ``ros2msg`` schema text exactly as rosbag2 writes it
into MCAP (the ``.msg`` and each nested dependency, named as its field writes it) and the type
hash; the nodes import generated classes by name.
"""
from __future__ import annotations

import importlib
import json
import os
from pathlib import Path
import re
import sys
from typing import Iterator

from gripper_ros.text import one_line

SCHEMA_SEPARATOR = '=' * 80

# How rosbag2 (rosbag2_cpp LocalMessageDefinitionSource, Jazzy) finds a .msg's dependencies:
# the first word of every line that is not a comment, with any array suffix dropped, unless it
# is one of its primitive names. A word without '/' gets the enclosing package as prefix
# ('Header' in std_msgs -> 'std_msgs/Header'); any other word is kept exactly as written, so a
# field 'std_msgs/Header' yields 'MSG: std_msgs/Header' and 'pkg/msg/Type' yields
# 'MSG: pkg/msg/Type'. Foxglove resolves a qualified field type only by an exact 'MSG:' name.
_MSG_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_TYPE_NAME = re.compile(r'^([a-zA-Z0-9_]+)/(?:msg/|srv/)?([a-zA-Z0-9_]+)$')
# rosbag2's list plus 'wstring' (rosbag2 would look for a message 'pkg/wstring', miss it and
# store the whole type as IDL instead).
_PRIMITIVES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring',
})
_MAX_DEPTH = 50
"""rosbag2's ROSBAG2_CPP_LOCAL_MESSAGE_DEFINITION_SOURCE_MAX_RECURSION_DEPTH."""


def msg_dependencies(text: str, package: str) -> list[str]:
    """Names of the message types a .msg text uses, as rosbag2 writes them in 'MSG:' lines.

    Sorted and unique (rosbag2 keeps them in a ``std::set``); ``package`` is the package of the
    type whose text this is.
    """
    deps = set()
    for match in _MSG_FIELD_TYPE.finditer(text):
        word = match.group(1)
        if word in _PRIMITIVES:
            continue
        deps.add(word if '/' in word else f'{package}/{word}')
    return sorted(deps)


def _share_dirs(pkg: str) -> Iterator[Path]:
    """Candidate ``share/<pkg>`` folders: ament index first, then this interpreter's prefix."""
    try:
        from ament_index_python.packages import get_package_share_directory
        yield Path(get_package_share_directory(pkg))
    except Exception:  # noqa: BLE001 - no index (unsourced shell) or unknown package
        pass
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            yield Path(prefix) / 'share' / pkg
    yield Path(sys.prefix) / 'share' / pkg
    try:                                             # e.g. install/<pkg>/lib/python3.11/...
        spec = importlib.util.find_spec(pkg)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.origin:
        for parent in Path(spec.origin).resolve().parents:
            yield parent / 'share' / pkg


def find_interface_file(msgtype: str, suffix: str = '.msg') -> Path:
    """Find the installed ``<share>/pkg/msg/Type.msg`` (or ``.json`` with ``suffix``) of a type."""
    pkg, kind, name = split_type(msgtype)
    for share in _share_dirs(pkg):
        candidate = share / kind / f'{name}{suffix}'
        if candidate.is_file():
            return candidate
    raise LookupError(f'no {kind}/{name}{suffix} found for {msgtype}: is {pkg} installed '
                      f'(source install/setup.bash)?')


def split_type(msgtype: str) -> tuple[str, str, str]:
    """'pkg/msg/Type' (or 'pkg/Type') -> ('pkg', 'msg', 'Type')."""
    parts = msgtype.split('/')
    if len(parts) == 3 and all(parts):
        return parts[0], parts[1], parts[2]
    if len(parts) == 2 and all(parts):
        return parts[0], 'msg', parts[1]
    raise ValueError(f'not a ROS type name: {msgtype!r} (expected pkg/msg/Type)')


def message_definition(msgtype: str) -> str:
    """Full ``ros2msg`` schema text of ``msgtype``, written as rosbag2 writes it into MCAP.

    The installed .msg text as is; after it, each dependency not written yet, depth first in
    the order of :func:`msg_dependencies`, as a newline, 80 '=', 'MSG: <name as the field
    writes it>' and that type's .msg text. Readers (Foxglove, mcap_ros2, rosbags) need every
    nested type present and named so.
    """
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise LookupError(f'{msgtype}: nested deeper than {_MAX_DEPTH} types')
        match = _TYPE_NAME.match(name)
        if match is None:
            raise ValueError(f'not a ROS message type name: {name!r} (in {msgtype})')
        package = match.group(1)
        # bytes as stored: no newline translation
        text = find_interface_file(f'{package}/msg/{match.group(2)}').read_bytes().decode(
            'utf-8')
        for dep in msg_dependencies(text, package):
            if dep not in seen:
                seen.add(dep)
                text += f'\n{SCHEMA_SEPARATOR}\nMSG: {dep}\n' + append(dep, depth - 1)
        return text

    return append(msgtype, _MAX_DEPTH)


def type_hash_from_share(msgtype: str) -> str:
    """RIHS01 type hash from the installed ``Type.json``; '' when unknown."""
    try:
        data = json.loads(find_interface_file(msgtype, '.json').read_text(encoding='utf-8'))
    except (LookupError, OSError, ValueError):
        return ''
    for entry in data.get('type_hashes', []):
        if entry.get('type_name') == msgtype:
            return str(entry.get('hash_string', ''))
    return ''


def import_message_class(msgtype: str) -> type:
    """Import the generated class of 'pkg/msg/Type' (importlib only, no rosidl_runtime_py)."""
    pkg, kind, name = split_type(msgtype)
    try:
        module = importlib.import_module(f'{pkg}.{kind}')
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise LookupError(f'cannot import {msgtype} ({one_line(exc)}): is {pkg} installed '
                          f'and install/setup.bash sourced?') from None
