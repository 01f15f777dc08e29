"""Message definitions and types from the installed interface packages (no rclpy).

The recorder stores, per type, the full ``ros2msg`` schema text that rosbag2 writes into MCAP
(the ``.msg`` and each nested dependency) and the type hash; the nodes import generated
classes by name.
"""
from __future__ import annotations

import importlib
import json
import os
import re
import sys
from pathlib import Path
from typing import Iterator

SCHEMA_SEPARATOR = '=' * 80


def _one_line(text: object) -> str:
    return ' '.join(str(text).split())

_PRIMITIVES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring',
})


def _normalize_type(name: str, own_pkg: str) -> str | None:
    """'pkg/Type' or 'Type' or 'pkg/msg/Type' -> 'pkg/msg/Type'; None for primitives."""
    base = re.sub(r'\[.*\]$', '', name)          # arrays: T[], T[3], T[<=3]
    base = re.sub(r'<=\d+$', '', base)            # bounded strings: string<=10
    if base in _PRIMITIVES:
        return None
    parts = base.split('/')
    if len(parts) == 1:
        return f'{own_pkg}/msg/{parts[0]}'
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    return base


def _msg_dependencies(text: str, msgtype: str) -> list[str]:
    """Field types of a .msg text that are messages themselves, in order of appearance."""
    own_pkg = msgtype.split('/')[0]
    deps: list[str] = []
    for raw_line in text.splitlines():
        line = raw_line.split('#', 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2:
            continue
        type_token, name_token = tokens[0], tokens[1]
        if '=' in name_token or (len(tokens) > 2 and tokens[2].startswith('=')):
            continue                                   # constant
        dep = _normalize_type(type_token, own_pkg)
        if dep and dep not in deps:
            deps.append(dep)
    return deps


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
    """The installed ``<share>/pkg/msg/Type.msg`` (or ``.json`` with ``suffix``) of a type."""
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
    """Full ``ros2msg`` schema text: the .msg, then each dependency after 80 '=' and 'MSG:'.

    This is the format rosbag2 stores in MCAP schemas; readers (Foxglove, mcap_ros2, rosbags)
    need every nested type present.
    """
    root = find_interface_file(msgtype).read_text(encoding='utf-8')
    parts = [root.rstrip('\n')]
    seen = {msgtype}
    queue = list(_msg_dependencies(root, msgtype))
    while queue:
        dep = queue.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        text = find_interface_file(dep).read_text(encoding='utf-8')
        parts.append(f'{SCHEMA_SEPARATOR}\nMSG: {dep}\n{text.rstrip(chr(10))}')
        queue.extend(d for d in _msg_dependencies(text, dep) if d not in seen)
    return '\n'.join(parts) + '\n'


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
    """The generated Python class of 'pkg/msg/Type' (importlib only, no rosidl_runtime_py)."""
    pkg, kind, name = split_type(msgtype)
    try:
        module = importlib.import_module(f'{pkg}.{kind}')
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise LookupError(f'cannot import {msgtype} ({_one_line(exc)}): is {pkg} installed '
                          f'and install/setup.bash sourced?') from None
