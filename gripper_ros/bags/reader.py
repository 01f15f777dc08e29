"""Read rosbag2 (MCAP) bags of the gripper graph robustly, without rclpy.

Why a reader of our own: a recorder killed mid-run leaves an ``.mcap`` without summary and
footer (and no ``metadata.yaml``). The seeking readers of ``mcap`` and ``rosbags`` refuse such
a file; here the file is read record by record with the ``mcap`` stream reader, so every
complete message up to the damage is recovered and the bag is flagged ``truncated``.

Decoding uses the ``rosbags`` Jazzy typestore plus the types registered from the schemas
stored IN the bag, so a bag is self-describing: no interface package needs to be installed.

Every failure is a :class:`BagError` subclass whose ``str()`` is one line, fit for a CLI.
"""
from __future__ import annotations

import importlib
import json
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np
import yaml

from gripper_ros.wire import (FINGER_JOINT, GRAPH_TOPICS, TOPIC_CLOCK, TOPIC_FORCE_SENSOR,  # noqa: F401,E501
                              TOPIC_JOINT_STATES, TOPIC_MOTOR_COMMAND, TOPIC_MOTOR_STATE,
                              TOPIC_STATUS, Outcome, Phase, SwitchCriterion, enum_name)
from gripper_ros.wire import Controller  # noqa: F401

REQUIRED_GRASP_TOPICS = (TOPIC_JOINT_STATES, TOPIC_FORCE_SENSOR, TOPIC_STATUS)
"""Without these a bag cannot be analysed as a grasp."""

GRASP_TOPICS = GRAPH_TOPICS
"""Topic -> type of everything a grasp run publishes (what the recorder records by default)."""

SCHEMA_SEPARATOR = '=' * 80
EXIT_ERROR = 1
"""CLI exit code: bad input, nothing done."""
EXIT_TRUNCATED = 3
"""CLI exit code: done, but the bag was damaged (only the complete messages were used)."""

CUSTOM_DATA_RECORD = 'gripper_ros/custom_data'
"""MCAP metadata record the recorder writes as soon as custom data is set (survives a kill)."""


# --- errors -----------------------------------------------------------------------------------

class BagError(Exception):
    """Any problem with a bag; the message is one line."""


class BagNotFoundError(BagError):
    """The path does not exist."""


class NotABagError(BagError):
    """A folder (or file) that is not a rosbag2 MCAP bag."""


class EmptyBagError(BagError):
    """A bag without any message."""


class MissingTopicsError(BagError):
    """A bag without the topics the caller needs."""


class UnreadableBagError(BagError):
    """A file that cannot be read or decoded."""


def _one_line(text: object) -> str:
    return ' '.join(str(text).split())


# --- message definitions from the installed share dirs (used by the recorder) -----------------

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


# --- raw bag reading --------------------------------------------------------------------------

@dataclass(frozen=True)
class RawMessage:
    """One message as stored: CDR bytes plus its times (ns)."""

    topic: str
    msgtype: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int = 0


@dataclass
class TopicInfo:
    """What ``ros2 bag info`` lists per topic, plus rate and size."""

    name: str
    msgtype: str
    count: int = 0
    serialization_format: str = 'cdr'
    offered_qos_profiles: list = field(default_factory=list)
    type_hash: str = ''
    first_ns: int | None = None
    last_ns: int | None = None
    size_bytes: int = 0

    @property
    def rate_hz(self) -> float:
        """Mean message rate over the topic's own span (0 for fewer than two messages)."""
        if self.count < 2 or self.first_ns is None or self.last_ns in (None, self.first_ns):
            return 0.0
        return (self.count - 1) / ((self.last_ns - self.first_ns) * 1e-9)


@dataclass
class Bag:
    """A whole bag in memory (grasp runs are small: thousands of messages)."""

    path: Path
    files: list[Path]
    size_bytes: int
    storage_identifier: str
    ros_distro: str
    topics: dict[str, TopicInfo]
    schemas: dict[str, str]
    messages: list[RawMessage]
    custom_data: dict[str, str]
    metadata: dict
    truncated: bool = False
    damage: str = ''
    profile: str = ''
    _typestore: Any = field(default=None, repr=False)

    @property
    def message_count(self) -> int:
        return len(self.messages)

    @property
    def start_ns(self) -> int:
        return min((m.log_time_ns for m in self.messages), default=0)

    @property
    def end_ns(self) -> int:
        return max((m.log_time_ns for m in self.messages), default=0)

    @property
    def duration_ns(self) -> int:
        return self.end_ns - self.start_ns

    def counts(self) -> dict[str, int]:
        """Messages per topic."""
        return {name: info.count for name, info in self.topics.items()}

    def custom_data_parsed(self) -> dict[str, Any]:
        """custom_data with JSON values decoded (the recorder stores dicts as JSON)."""
        return {k: _maybe_json(v) for k, v in self.custom_data.items()}

    def require_topics(self, topics: Iterable[str]) -> None:
        """Raise MissingTopicsError unless every topic has at least one message."""
        missing = [t for t in topics if self.topics.get(t) is None or self.topics[t].count == 0]
        if missing:
            have = ', '.join(sorted(t for t, i in self.topics.items() if i.count)) or 'none'
            raise MissingTopicsError(f'{self.path}: missing topics {", ".join(missing)} '
                                     f'(has: {have})')

    def truncation_note(self) -> str:
        """One line for damaged bags ('' when intact)."""
        if not self.truncated:
            return ''
        return (f'{self.path}: truncated: {self.message_count} complete messages recovered '
                f'({self.damage})')

    @property
    def typestore(self):
        """rosbags Jazzy typestore plus every type defined by the bag's own schemas."""
        if self._typestore is None:
            self._typestore = make_typestore(self.schemas)
        return self._typestore

    def decode(self, msg: RawMessage) -> Any:
        """Deserialize one message (rosbags dataclass)."""
        try:
            return self.typestore.deserialize_cdr(msg.data, msg.msgtype)
        except Exception as exc:  # noqa: BLE001 - any decoder failure is an unreadable bag
            raise UnreadableBagError(f'{self.path}: cannot decode {msg.msgtype} on {msg.topic}: '
                                     f'{_one_line(exc)}') from None

    def iter_decoded(self, topic: str) -> Iterator[tuple[RawMessage, Any]]:
        """(raw, decoded) for every message of one topic, in recorded order."""
        for msg in self.messages:
            if msg.topic == topic:
                yield msg, self.decode(msg)


def _maybe_json(value: str) -> Any:
    if isinstance(value, str) and value[:1] in '{[':
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def make_typestore(schemas: dict[str, str]):
    """Jazzy typestore with the given ``ros2msg`` schema texts registered (new types only)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in schemas.items():
        if name in store.fielddefs:
            continue
        try:
            types = get_types_from_msg(text, name)
        except Exception as exc:  # noqa: BLE001
            raise UnreadableBagError(f'schema of {name} does not parse: {_one_line(exc)}') from None
        store.register({k: v for k, v in types.items() if k not in store.fielddefs})
    return store


_MCAP_MAGIC = b'\x89MCAP0\r\n'


class _StrictFile:
    """File wrapper whose short reads raise, so a cut record is never parsed as complete."""

    def __init__(self, fobj):
        self._f = fobj

    def read(self, size: int = -1) -> bytes:
        data = self._f.read(size)
        if size is not None and size > 0 and len(data) < size:
            raise _Truncated(self._f.tell())
        return data


class _Truncated(Exception):
    pass


@dataclass
class _McapFile:
    profile: str = ''
    schemas: dict = field(default_factory=dict)      # id -> (name, encoding, text)
    channels: dict = field(default_factory=dict)     # id -> (topic, encoding, schema_id, meta)
    messages: list = field(default_factory=list)     # mcap Message records
    metadata: dict = field(default_factory=dict)     # name -> dict (last wins)
    truncated: bool = False
    damage: str = ''


def _read_mcap(path: Path) -> _McapFile:
    """Every complete record of one .mcap, stopping (flagged) at the first damage."""
    from mcap.exceptions import InvalidMagic, RecordLengthLimitExceeded
    from mcap.records import Channel, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    out = _McapFile()
    try:
        size = path.stat().st_size
        fobj = open(path, 'rb')  # noqa: SIM115 - closed below
    except OSError as exc:
        raise UnreadableBagError(f'{path}: cannot open: {exc.strerror or exc}') from None
    if size == 0:
        fobj.close()
        out.truncated, out.damage = True, 'file is empty'
        return out
    with fobj:
        head = fobj.read(len(_MCAP_MAGIC))
        fobj.seek(0)
        if head != _MCAP_MAGIC[:len(head)]:
            raise UnreadableBagError(f'{path}: not an MCAP file (bad magic)')
        reader = StreamReader(_StrictFile(fobj), validate_crcs=True, record_size_limit=size)
        try:
            for record in reader.records:
                if isinstance(record, Message):
                    out.messages.append(record)
                elif isinstance(record, Channel):
                    out.channels[record.id] = (record.topic, record.message_encoding,
                                               record.schema_id, dict(record.metadata))
                elif isinstance(record, Schema):
                    out.schemas[record.id] = (record.name, record.encoding,
                                              bytes(record.data).decode('utf-8', 'replace'))
                elif isinstance(record, Metadata):
                    out.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Header):
                    out.profile = record.profile
        except InvalidMagic:
            if not out.profile:
                raise UnreadableBagError(f'{path}: not an MCAP file (bad magic)') from None
            out.truncated, out.damage = True, 'bad closing magic'
        except _Truncated as exc:
            where = exc.args[0]
            out.truncated = True
            out.damage = ('file ends inside the MCAP magic' if where < 8 else
                          'file ends before the first record' if not out.profile else
                          f'file ends inside a record at byte {where}')
        except RecordLengthLimitExceeded:
            out.truncated, out.damage = True, 'file ends inside a record (length beyond the end)'
        except Exception as exc:  # noqa: BLE001 - zstd/lz4/struct/CRC errors in a damaged chunk
            out.truncated, out.damage = True, f'damaged record: {_one_line(exc)}'
    return out


def _load_metadata_yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise UnreadableBagError(f'{path}: unreadable metadata.yaml: {_one_line(exc)}') from None
    if not isinstance(data, dict) or not isinstance(data.get('rosbag2_bagfile_information'), dict):
        raise NotABagError(f'{path}: not rosbag2 metadata (no rosbag2_bagfile_information)')
    return data['rosbag2_bagfile_information']


def _bag_files(path: Path) -> tuple[list[Path], dict]:
    """The .mcap files of a bag directory (or the file itself) and its metadata.yaml content."""
    if not path.exists():
        raise BagNotFoundError(f'{path}: no such file or directory')
    if path.is_file():
        if path.name == 'metadata.yaml':
            return _bag_files(path.parent)
        if path.suffix != '.mcap':
            raise NotABagError(f'{path}: not a bag (expected a bag folder or an .mcap file)')
        meta_path = path.parent / 'metadata.yaml'
        info = {}
        if meta_path.is_file():
            try:
                info = _load_metadata_yaml(meta_path)
            except BagError:
                info = {}
            if path.name not in [Path(p).name for p in info.get('relative_file_paths', [])]:
                info = {}                            # metadata of another bag: ignore
        return [path], info
    meta_path = path / 'metadata.yaml'
    info = _load_metadata_yaml(meta_path) if meta_path.is_file() else {}
    storage = str(info.get('storage_identifier', 'mcap') or 'mcap')
    if storage != 'mcap':
        raise NotABagError(f'{path}: storage {storage!r} is not supported (only mcap)')
    files = [path / rel for rel in info.get('relative_file_paths', []) or []]
    files = [f for f in files if f.is_file()]
    if not files:
        files = sorted(path.glob('*.mcap'))
    if not files:
        if info:
            raise NotABagError(f'{path}: metadata.yaml lists no existing .mcap file')
        raise NotABagError(f'{path}: not a rosbag2 bag (no metadata.yaml and no .mcap file)')
    return files, info


def _parse_qos(text: str) -> list:
    if not text:
        return []
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return []
    return value if isinstance(value, list) else []


def read_bag(path: str | os.PathLike, *, allow_empty: bool = False) -> Bag:
    """Open a bag directory (or one .mcap) and read every complete message.

    A damaged/truncated file yields all messages before the damage with ``truncated=True``.
    Raises a :class:`BagError` subclass for a missing path, a folder that is not a bag, an
    unreadable file and (unless ``allow_empty``) a bag without messages.
    """
    path = Path(path)
    files, info = _bag_files(path)
    topics: dict[str, TopicInfo] = {}
    schemas: dict[str, str] = {}
    messages: list[RawMessage] = []
    custom_data: dict[str, str] = {}
    truncated, damages, profile = False, [], ''
    record_meta: dict = {}
    for fpath in files:
        content = _read_mcap(fpath)
        profile = profile or content.profile
        if content.truncated:
            truncated = True
            damages.append(f'{fpath.name}: {content.damage}')
        schema_names = {}
        for sid, (name, encoding, text) in content.schemas.items():
            schema_names[sid] = name
            if encoding == 'ros2msg' and name not in schemas:
                schemas[name] = text
        channels = {}
        for cid, (topic, encoding, sid, meta) in content.channels.items():
            msgtype = schema_names.get(sid, '')
            channels[cid] = (topic, msgtype)
            if topic not in topics:
                topics[topic] = TopicInfo(
                    name=topic, msgtype=msgtype, serialization_format=encoding,
                    offered_qos_profiles=_parse_qos(meta.get('offered_qos_profiles', '')),
                    type_hash=meta.get('topic_type_hash', ''))
        for rec in content.messages:
            topic, msgtype = channels.get(rec.channel_id, ('', ''))
            if not topic:
                continue
            data = bytes(rec.data)
            messages.append(RawMessage(topic, msgtype, rec.log_time, rec.publish_time, data,
                                       rec.sequence))
            tinfo = topics[topic]
            tinfo.count += 1
            tinfo.size_bytes += len(data)
            tinfo.first_ns = rec.log_time if tinfo.first_ns is None else min(tinfo.first_ns,
                                                                              rec.log_time)
            tinfo.last_ns = rec.log_time if tinfo.last_ns is None else max(tinfo.last_ns,
                                                                            rec.log_time)
        if CUSTOM_DATA_RECORD in content.metadata:
            custom_data.update(content.metadata[CUSTOM_DATA_RECORD])
        if 'rosbag2' in content.metadata:
            record_meta = content.metadata['rosbag2']
    # metadata precedence: metadata.yaml, then the rosbag2 record inside the file
    if not info and record_meta.get('serialized_metadata'):
        try:
            parsed = yaml.safe_load(record_meta['serialized_metadata'])
            if isinstance(parsed, dict):
                info = parsed.get('rosbag2_bagfile_information', parsed)
        except yaml.YAMLError:
            info = {}
    if isinstance(info.get('custom_data'), dict):
        custom_data.update({str(k): str(v) for k, v in info['custom_data'].items()})
    # topics with no message still known from metadata.yaml
    for entry in info.get('topics_with_message_count', []) or []:
        meta = entry.get('topic_metadata', {}) if isinstance(entry, dict) else {}
        name = meta.get('name')
        if name and name not in topics:
            qos = meta.get('offered_qos_profiles', [])
            topics[name] = TopicInfo(name=name, msgtype=meta.get('type', ''),
                                     serialization_format=meta.get('serialization_format', 'cdr'),
                                     offered_qos_profiles=qos if isinstance(qos, list)
                                     else _parse_qos(qos),
                                     type_hash=meta.get('type_description_hash', ''))
    messages.sort(key=lambda m: m.log_time_ns)        # stable: keeps in-tick publish order
    bag = Bag(path=path, files=files, size_bytes=sum(f.stat().st_size for f in files),
              storage_identifier='mcap', ros_distro=str(info.get('ros_distro', '') or ''),
              topics=topics, schemas=schemas, messages=messages, custom_data=custom_data,
              metadata=info, truncated=truncated, damage='; '.join(damages), profile=profile)
    if not messages and not allow_empty:
        how = f' (truncated: {bag.damage})' if truncated else ''
        raise EmptyBagError(f'{path}: bag holds no messages{how}')
    return bag


def open_bag(bag: Bag | str | os.PathLike, **kwargs) -> Bag:
    """Accept an already read :class:`Bag` or a path."""
    return bag if isinstance(bag, Bag) else read_bag(bag, **kwargs)


# --- grasp series -----------------------------------------------------------------------------

def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


@dataclass
class JointSeries:
    """/gripper/joint_states: finger travel from fully open, its speed, contact force."""

    t_s: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    contact_force_n: np.ndarray


@dataclass
class SensorSeries:
    """/gripper/force_sensor."""

    t_s: np.ndarray
    force_n: np.ndarray
    voltage_v: np.ndarray
    peak_force_n: np.ndarray      # largest force since the previous sample (NaN in older bags)


@dataclass
class MotorSeries:
    """/gripper/motor_state: voltage applied over the interval ending at t_s."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    speed_rad_s: np.ndarray


@dataclass
class StatusSeries:
    """/gripper/supervisor/status, one row per tick."""

    t_s: np.ndarray
    phase: np.ndarray
    active_controller: np.ndarray
    switch_criterion: np.ndarray
    grasp_id: np.ndarray
    outcome: np.ndarray
    position_setpoint_m: np.ndarray
    force_setpoint_n: np.ndarray
    position_m: np.ndarray
    force_n: np.ndarray
    contact: np.ndarray
    seed_voltage_v: np.ndarray


@dataclass
class CommandSeries:
    """/gripper/motor_command, one row per controller answer."""

    t_s: np.ndarray
    voltage_v: np.ndarray
    source: np.ndarray
    grasp_id: np.ndarray
    hold_s: np.ndarray
    inner_setpoint: np.ndarray


@dataclass
class GraspSeries:
    """Numpy series of one grasp bag; ``t_s`` everywhere = simulated time of header stamps."""

    path: Path
    joint: JointSeries
    sensor: SensorSeries
    motor: MotorSeries
    status: StatusSeries
    command: CommandSeries
    custom_data: dict[str, Any]
    counts: dict[str, int]
    start_ns: int
    end_ns: int
    size_bytes: int
    truncated: bool
    damage: str = ''

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9


def _columns(rows: list[tuple], n: int, dtypes: tuple) -> list[np.ndarray]:
    if not rows:
        return [np.zeros(0, dtype=d) for d in dtypes]
    cols = list(zip(*rows))
    return [np.asarray(cols[i], dtype=dtypes[i]) for i in range(n)]


def _joint_value(values, index: int) -> float:
    return float(values[index]) if len(values) > index else float('nan')


def load_grasp_series(bag: Bag | str | os.PathLike,
                      required: Iterable[str] = REQUIRED_GRASP_TOPICS) -> GraspSeries:
    """Series of every graph topic of a grasp bag (missing optional topics give empty arrays)."""
    bag = open_bag(bag)
    bag.require_topics(required)
    joint, sensor, motor, status, command = [], [], [], [], []
    for raw in bag.messages:
        if raw.topic == TOPIC_JOINT_STATES:
            m = bag.decode(raw)
            names = list(m.name)
            idx = names.index(FINGER_JOINT) if FINGER_JOINT in names else 0
            joint.append((_stamp_ns(m) * 1e-9, _joint_value(m.position, idx),
                          _joint_value(m.velocity, idx), _joint_value(m.effort, idx)))
        elif raw.topic == TOPIC_FORCE_SENSOR:
            m = bag.decode(raw)
            sensor.append((_stamp_ns(m) * 1e-9, m.force_n, m.voltage_v,
                           getattr(m, 'peak_force_n', float('nan'))))
        elif raw.topic == TOPIC_MOTOR_STATE:
            m = bag.decode(raw)
            motor.append((_stamp_ns(m) * 1e-9, m.voltage_v, m.current_a, m.speed_rad_s))
        elif raw.topic == TOPIC_STATUS:
            m = bag.decode(raw)
            status.append((_stamp_ns(m) * 1e-9, m.phase, m.active_controller, m.switch_criterion,
                           m.grasp_id, m.outcome, m.position_setpoint_m, m.force_setpoint_n,
                           m.position_m, m.force_n, bool(m.contact), m.seed_voltage_v))
        elif raw.topic == TOPIC_MOTOR_COMMAND:
            m = bag.decode(raw)
            command.append((_stamp_ns(m) * 1e-9, m.voltage_v, m.source, m.grasp_id, m.hold_s,
                            m.inner_setpoint))
    f, i = float, int
    return GraspSeries(
        path=bag.path,
        joint=JointSeries(*_columns(joint, 4, (f, f, f, f))),
        sensor=SensorSeries(*_columns(sensor, 4, (f, f, f, f))),
        motor=MotorSeries(*_columns(motor, 4, (f, f, f, f))),
        status=StatusSeries(*_columns(status, 12, (f, i, i, i, i, i, f, f, f, f, bool, f))),
        command=CommandSeries(*_columns(command, 6, (f, f, i, i, f, f))),
        custom_data=bag.custom_data_parsed(), counts=bag.counts(), start_ns=bag.start_ns,
        end_ns=bag.end_ns, size_bytes=bag.size_bytes, truncated=bag.truncated,
        damage=bag.damage)
