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

from dataclasses import dataclass, field
import functools
import json
import os
from pathlib import Path
import signal
import sys
from typing import Any, Callable, Iterable, Iterator

from gripper_ros.text import one_line
import yaml

EXIT_ERROR = 1
"""CLI exit code: bad input, nothing done."""
EXIT_TRUNCATED = 3
"""CLI exit code: done, but the bag was damaged (only the complete messages were used)."""
EXIT_UNDELIVERED = 4
"""CLI exit code: published, but not every message was acknowledged by every reliable reader."""
EXIT_CLOSED_PIPE = 128 + signal.SIGPIPE
"""CLI exit code: the reader of the output stopped early (``| head``), as a shell reports it."""


def quiet_on_closed_pipe(main: Callable[..., int]) -> Callable[..., int]:
    """Wrap a CLI ``main``: output into a pipe whose reader stopped (``| head``) ends it quietly.

    Without this, the print into the closed pipe is a BrokenPipeError traceback.
    """
    @functools.wraps(main)
    def wrapper(*args, **kwargs) -> int:
        try:
            code = main(*args, **kwargs)
            sys.stdout.flush()
            return code
        except BrokenPipeError:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())      # the interpreter's last flush goes nowhere
            return EXIT_CLOSED_PIPE
    return wrapper


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
        """Return the rosbags Jazzy typestore plus every type the bag's own schemas define."""
        if self._typestore is None:
            self._typestore = make_typestore(self.schemas)
        return self._typestore

    def decode(self, msg: RawMessage) -> Any:
        """Deserialize one message (rosbags dataclass)."""
        try:
            return self.typestore.deserialize_cdr(msg.data, msg.msgtype)
        except Exception as exc:  # noqa: BLE001 - any decoder failure is an unreadable bag
            raise UnreadableBagError(f'{self.path}: cannot decode {msg.msgtype} on {msg.topic}: '
                                     f'{one_line(exc)}') from None

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
            raise UnreadableBagError(
                f'schema of {name} does not parse: {one_line(exc)}') from None
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
            out.truncated, out.damage = True, f'damaged record: {one_line(exc)}'
    return out


def _load_metadata_yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise UnreadableBagError(f'{path}: unreadable metadata.yaml: {one_line(exc)}') from None
    if not isinstance(data, dict) or not isinstance(data.get('rosbag2_bagfile_information'), dict):
        raise NotABagError(f'{path}: not rosbag2 metadata (no rosbag2_bagfile_information)')
    return data['rosbag2_bagfile_information']


def _bag_files(path: Path) -> tuple[list[Path], dict]:
    """Return the .mcap files of a bag directory (or the file itself) and its metadata.yaml."""
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
    files = [path / str(rel) for rel in info.get('relative_file_paths', []) or []]
    inside = path.resolve()
    for f in files:
        if not f.resolve().is_relative_to(inside):
            raise NotABagError(f'{path}: metadata.yaml lists {f.relative_to(path)}, which lies '
                               'outside the bag folder; refusing to read it')
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
            tinfo.first_ns = (rec.log_time if tinfo.first_ns is None
                              else min(tinfo.first_ns, rec.log_time))
            tinfo.last_ns = (rec.log_time if tinfo.last_ns is None
                             else max(tinfo.last_ns, rec.log_time))
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
