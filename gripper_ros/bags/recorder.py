"""Record graph topics into a rosbag2 bag (MCAP storage) from inside an rclpy process.

Why not rosbag2: it is not installable here (no ``ros2 bag``); why not ``rosbags``' Writer: it
aborts without summary or metadata.yaml when an exception leaves its ``with`` block, and it
cannot flush. This recorder writes the rosbag2 MCAP layout itself (:mod:`mcap_file`, from
``mcap``'s records): ``ros2`` profile, ``ros2msg`` schemas with their dependencies, ``cdr``
channels with ``offered_qos_profiles``/``topic_type_hash``, a ``rosbag2`` metadata record,
``metadata.yaml`` version 9; so ``ros2 bag info/play``, Foxglove, ``rosbags`` and ``mcap`` all
read it.

A message handed to the recorder is appended to the chunk being filled (its channel, sequence,
times and bytes); once the chunk is full it is encoded in one pass, compressed and written. Per
message, the executor thread that hands it over pays for an append and a share of that pass,
not for the ``mcap`` writer's per-message Python. The pass stays in the caller's thread on
purpose: a writer thread measured slower, since it shares the GIL with the executor and takes
it in the middle of ticks (docs/BENCHMARKS.md, "Recording"). A timer thread writes what waits
longer than ``flush_every_s``.
"""
from __future__ import annotations

import atexit
import enum
import functools
import json
import os
from pathlib import Path
import shutil
import threading
import time
from typing import Any, Callable, Mapping

from gripper_ros.bags.mcap_file import McapFile
from gripper_ros.bags.reader import BagError, CUSTOM_DATA_RECORD, read_bag
from gripper_ros.bags.schema import import_message_class, message_definition, type_hash_from_share
from gripper_ros.bags.series import GRASP_TOPICS
from mcap.writer import CompressionType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
import yaml

ROS_DISTRO = 'jazzy'
CHUNK_MESSAGES = 1000
"""Messages a chunk holds before it is written: about 110 kB of lockstep messages, a tenth of a
second of a held object. Fewer cost the executor more (each chunk is a compression, index
records and a write); a killed process loses at most these and ``flush_every_s`` of them."""
BAG_VERSION = 9
_NS_PER_S = 1_000_000_000
_INFINITE_NS = 0x7FFFFFFFFFFFFFFF  # RMW_DURATION_INFINITE
WRITER_PERIOD_S = 0.02
"""How often the timer thread looks for messages waiting longer than ``flush_every_s``."""


_YAML_DUMPER = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)
"""libyaml's emitter where PyYAML has it: a bag's metadata (the whole config) in a few ms, not
the 50 ms of the pure-Python one that the closing of a bag would hold the executor for."""


def _yaml_text(data) -> str:
    """Return ``data`` as YAML, keys in their order (as ``yaml.safe_dump(sort_keys=False)``)."""
    return yaml.dump(data, Dumper=_YAML_DUMPER, sort_keys=False)


class PublishTime(enum.Enum):
    """What goes into an MCAP message's publish_time."""

    RECEIVE = 'receive'   # same as log_time: the simulated receive time (one time base)
    SOURCE = 'source'     # the publisher's DDS source timestamp (wall time)


class BagRecorderError(Exception):
    """Recorder set-up failure; the message is one line."""


def _duration_dict(duration) -> dict:
    ns = int(getattr(duration, 'nanoseconds', 0))
    if ns >= _INFINITE_NS or ns < 0:
        return {'sec': 9223372036, 'nsec': 854775807}
    return {'sec': ns // _NS_PER_S, 'nsec': ns % _NS_PER_S}


def _policy_name(policy) -> str:
    return str(getattr(policy, 'name', policy)).lower()


def qos_to_dict(qos: QoSProfile) -> dict:
    """One rclpy QoS profile as a rosbag2 version-9 ``offered_qos_profiles`` entry."""
    return {
        'history': _policy_name(qos.history),
        'depth': int(qos.depth),
        'reliability': _policy_name(qos.reliability),
        'durability': _policy_name(qos.durability),
        'deadline': _duration_dict(qos.deadline),
        'lifespan': _duration_dict(qos.lifespan),
        'liveliness': _policy_name(qos.liveliness),
        'liveliness_lease_duration': _duration_dict(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


def _custom_value(value: Any) -> str:
    """rosbag2 custom_data is str -> str; structured values are stored as JSON."""
    return value if isinstance(value, str) else json.dumps(value, sort_keys=True)


def _prepare_dir(bag_dir: Path, overwrite: bool) -> None:
    if bag_dir.exists() and not bag_dir.is_dir():
        raise BagRecorderError(f'{bag_dir} exists and is not a folder')
    if bag_dir.is_dir() and any(bag_dir.iterdir()):
        if not overwrite:
            raise BagRecorderError(f'{bag_dir} exists and is not empty (pass overwrite=True to '
                                   f'replace a previous bag)')
        foreign = [p.name for p in bag_dir.iterdir()
                   if not (p.is_file() and (p.suffix == '.mcap' or p.name == 'metadata.yaml'))]
        if foreign:
            raise BagRecorderError(f'{bag_dir} holds more than a bag ({", ".join(foreign[:3])}); '
                                   f'refusing to delete it')
        shutil.rmtree(bag_dir)
    bag_dir.mkdir(parents=True, exist_ok=True)


class BagRecorder:
    """Subscribe (raw CDR) to topics on a caller's node and write a rosbag2 MCAP bag.

    Times: ``log_time`` is the receive time from ``time_source`` (ns; default the node's clock,
    i.e. simulated time under ``use_sim_time`` -- which is 0 until the first /clock). A caller
    that knows the tick better passes its own ``time_source``. ``publish_time`` is the same
    (``PublishTime.RECEIVE``) or the DDS source timestamp (``PublishTime.SOURCE``, wall time).

    Batches: a received message goes into the chunk being filled (bytes and times, nothing
    else); every ``flush_every_messages`` messages the chunk is encoded, compressed and written
    by the call that filled it. :attr:`counts` are the messages taken, in the chunk or
    written. A write that fails (a full disk) stops the recorder and is raised; one that fails
    in the timer thread is raised by the next :meth:`write`. Either way the caller learns of it
    and the messages taken but not readable are counted (:attr:`accepted_count` against what a
    reader gets back), never dropped without a trace.

    Loss bound on SIGKILL: a chunk is closed and written to the OS every
    ``flush_every_messages`` messages and, by the timer thread, when messages have waited
    ``flush_every_s`` seconds of wall time. A killed process therefore loses at most the last
    ``flush_every_messages - 1`` messages and at most those of the last ``flush_every_s``
    seconds; everything before reads back with ``gripper_ros.bags.reader.read_bag`` (flagged
    truncated). No fsync: a power cut can lose more. ``close()`` (also on context-manager exit,
    even after an exception, and at interpreter exit) writes the queue, the summary, the
    ``rosbag2`` record and ``metadata.yaml``.
    """

    def __init__(self, node: Node, bag_dir: str | os.PathLike,
                 topics: Mapping[str, str] | None = None, *,
                 time_source: Callable[[], int] | None = None,
                 flush_every_messages: int = CHUNK_MESSAGES, flush_every_s: float = 0.5,
                 custom_data: Mapping[str, Any] | None = None, overwrite: bool = False,
                 publish_time: PublishTime = PublishTime.RECEIVE,
                 compression: CompressionType = CompressionType.ZSTD,
                 subscribe: bool = True):
        if flush_every_messages < 1:
            raise BagRecorderError('flush_every_messages must be >= 1')
        if not flush_every_s > 0:
            raise BagRecorderError('flush_every_s must be > 0')
        self._node = node
        self._bag_dir = Path(bag_dir)
        self._topics = dict(GRASP_TOPICS if topics is None else topics)
        if not self._topics:
            raise BagRecorderError('no topics to record')
        self._time_source = time_source or (lambda: node.get_clock().now().nanoseconds)
        self._flush_every_messages = int(flush_every_messages)
        self._flush_every_s = float(flush_every_s)
        self._publish_time = publish_time
        self._lock = threading.RLock()          # the MCAP writer and everything it counts
        self._closed = False
        self._custom_data: dict[str, str] = {}

        classes, definitions = {}, {}
        for topic, msgtype in self._topics.items():
            try:
                classes[topic] = import_message_class(msgtype)
                if msgtype not in definitions:
                    definitions[msgtype] = message_definition(msgtype)
            except (LookupError, ValueError, OSError) as exc:
                raise BagRecorderError(f'cannot record {topic}: {exc}') from None

        _prepare_dir(self._bag_dir, overwrite)
        self._mcap_path = self._bag_dir / f'{self._bag_dir.name}_0.mcap'
        self._file = open(self._mcap_path, 'wb')  # noqa: SIM115 - closed in close()
        self._writer = McapFile(self._file, profile='ros2',
                                library='gripper_ros.bags.recorder (mcap python)',
                                compression=compression)
        self._schema_ids = {t: self._writer.add_schema(t, 'ros2msg', d.encode('utf-8'))
                            for t, d in definitions.items()}
        self._channel_ids: dict[str, int] = {}
        self._topic_meta: dict[str, dict] = {}
        self._counts = dict.fromkeys(self._topics, 0)    # messages taken
        self._sequence = dict.fromkeys(self._topics, 0)  # the next sequence number
        self._chunk: list[tuple] = []           # the chunk being filled, as McapFile takes it
        self._total = 0                         # messages handed to the writer
        self._readable = 0                      # of those, in chunks written to the file
        self._last_flush = time.monotonic()
        self._lost = 0                          # received after the writer failed
        self._failure: BaseException | None = None
        self._stop = threading.Event()
        if custom_data:
            self.set_custom_data(custom_data)

        # keep_all: a message the executor has not taken yet waits in the subscription's history
        # (acknowledged there) however long the executor is starved; keep_last would drop the
        # oldest, acknowledged, which no publisher could tell. rosbag2's recorder keeps 10.
        qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        # subscribe=False: the caller owns long-lived subscriptions and calls write(). A volatile
        # reader created just before a grasp can drop the first sample an idle writer sends it:
        # a caller publishing into a new recorder first waits for the match
        # (Publisher.get_subscription_count()), as with ros2 bag record.
        self._subscriptions = [
            node.create_subscription(classes[topic], topic,
                                     functools.partial(self._on_message, topic), qos, raw=True)
            for topic in self._topics] if subscribe else []
        self._thread = threading.Thread(target=self._run, name=f'bag_timer {self._bag_dir.name}',
                                        daemon=True)
        self._thread.start()
        atexit.register(self.close)

    # --- public API ---------------------------------------------------------------------------

    @property
    def bag_dir(self) -> Path:
        return self._bag_dir

    @property
    def counts(self) -> dict[str, int]:
        """Messages taken per topic so far (written, or in the chunk being filled)."""
        return dict(self._counts)

    @property
    def message_count(self) -> int:
        """Messages taken so far (written, or in the chunk being filled)."""
        return sum(self._counts.values())

    @property
    def accepted_count(self) -> int:
        """Messages handed to the recorder, whether written yet or still buffered."""
        return sum(self._counts.values()) + self._lost

    @property
    def readable_count(self) -> int:
        """Messages in chunks already written to the file.

        What a reader gets after a crash or a full disk (the rest was still buffered).
        """
        with self._lock:
            return self._readable

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def failure(self) -> BaseException | None:
        """The error that stopped the writer, if one did."""
        return self._failure

    def set_custom_data(self, data: Mapping[str, Any]) -> None:
        """Merge key/values into custom_data (e.g. grasp request and outcome).

        Non-string values are stored as JSON. They are also written at once as an MCAP metadata
        record and flushed, after every message queued before, so even a killed recording keeps
        them.
        """
        with self._lock:
            if self._closed:
                raise BagRecorderError('recorder is closed')
            self._custom_data.update({str(k): _custom_value(v) for k, v in data.items()})
            self._raise_failure()
            self._guarded(self._flush_locked)
            self._guarded(lambda: self._writer.add_metadata(CUSTOM_DATA_RECORD,
                                                            dict(self._custom_data)))
            self._guarded(self._writer.flush)

    def write(self, topic: str, data: bytes, t_ns: int | None = None) -> None:
        """Record one serialized message received on ``topic`` (for subscribe=False).

        ``t_ns`` is its log time (default: now, by the time source). Raises the writer's error
        once it has failed (an ``OSError`` for a full disk).
        """
        if self._failure is not None:
            raise self._failure
        if t_ns is None:
            t_ns = int(self._time_source())
        self._take(topic, data, t_ns, t_ns)

    def _take(self, topic: str, data: bytes, log_ns: int, publish_ns: int) -> None:
        """Add a message to the chunk being filled; write the chunk once it is full."""
        with self._lock:
            if self._closed:
                return
            channel = self._channel_ids.get(topic)
            if channel is None:
                channel = self._guarded(lambda: self._channel_locked(topic))
            sequence = self._sequence[topic]
            self._sequence[topic] = sequence + 1
            self._counts[topic] += 1
            chunk = self._chunk
            chunk.append((channel, sequence, log_ns, publish_ns, data))
            if len(chunk) >= self._flush_every_messages:
                self._guarded(self._flush_locked)

    def flush(self) -> None:
        """Write everything received so far to the file (ends the current chunk)."""
        with self._lock:
            if not self._closed and self._failure is None:
                self._guarded(self._flush_locked)

    def close(self) -> None:
        """Stop recording, write the queue, finish the MCAP and write metadata.yaml.

        The MCAP ends with its summary and the ``rosbag2`` record. Idempotent; safe after the
        node or rclpy context is gone.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        atexit.unregister(self.close)
        self._destroy_subscriptions()
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join()
        with self._lock:
            errors = [] if self._failure is None else [self._failure]
            if not errors:
                try:
                    self._flush_locked()
                except Exception as exc:  # noqa: BLE001
                    errors.append(exc)
            try:
                for topic in self._topics:            # topics that never got a message
                    self._channel_locked(topic)
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
            info = self._metadata_locked()
            try:
                self._writer.add_metadata('rosbag2', {
                    'serialized_metadata': _yaml_text(info).strip()})
                self._writer.finish()
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)
            finally:
                self._file.close()
            meta_path = self._bag_dir / 'metadata.yaml'
            tmp = meta_path.with_suffix('.yaml.tmp')
            tmp.write_text(_yaml_text({'rosbag2_bagfile_information': info}), encoding='utf-8')
            tmp.replace(meta_path)
            if errors:
                raise BagRecorderError(f'bag closed with errors: {errors[0]}') from errors[0]

    def __enter__(self) -> BagRecorder:
        return self

    def __exit__(self, *exc_info) -> bool:
        self.close()
        return False

    # --- internals ----------------------------------------------------------------------------

    def _destroy_subscriptions(self) -> None:
        """Destroy this recorder's subscriptions in the thread that spins its node, if any.

        rclpy's executor (Jazzy, executors.py ``_wait_for_ready_callbacks``) still adds to its
        wait set an event handler whose destruction another thread requested meanwhile, and
        the InvalidHandle that raises ends its spinning thread: every node it spins then goes
        deaf. In the executor's own thread nothing races; a message taken after close() is
        ignored.
        """
        subscriptions, self._subscriptions = self._subscriptions, []
        if not subscriptions:
            return
        node = self._node

        def destroy() -> None:
            for sub in subscriptions:
                try:
                    node.destroy_subscription(sub)
                except Exception:  # noqa: BLE001 - node already destroyed / context shut down
                    pass
        executor = getattr(node, 'executor', None)
        try:
            if executor is not None:
                executor.create_task(destroy)
                return
        except Exception:  # noqa: BLE001 - an executor already shut down: nothing spins
            pass
        destroy()

    def _on_message(self, topic: str, data: bytes, info: Any = None) -> None:
        """Queue a message of one of this recorder's own subscriptions."""
        if self._closed or self._failure is not None:
            if not self._closed:
                self._lost += 1                 # received and lost: counted, never silent
            return
        t_ns = int(self._time_source())
        if self._publish_time is PublishTime.SOURCE and isinstance(info, dict):
            publish_ns = int(info.get('source_timestamp', t_ns))
        else:
            publish_ns = t_ns
        try:
            self._take(topic, data, t_ns, publish_ns)
        except Exception:  # noqa: BLE001 - kept in failure; a callback must not raise
            pass

    def _run(self) -> None:
        """Write what waits longer than ``flush_every_s`` (the timer thread).

        It checks every ``WRITER_PERIOD_S`` and does nothing while messages keep coming, so
        that it seldom takes the GIL from the executor.
        """
        while not self._stop.wait(WRITER_PERIOD_S):
            if time.monotonic() - self._last_flush < self._flush_every_s:
                continue
            with self._lock:
                if self._closed or self._failure is not None:
                    return
                if not self._chunk:
                    continue
                try:
                    self._flush_locked()
                except Exception as exc:  # noqa: BLE001 - kept; the next write() raises it
                    self._failure = exc
                    return

    def _raise_failure(self) -> None:
        if self._failure is not None:
            raise self._failure

    def _guarded(self, action: Callable[[], Any]) -> Any:
        """Run a writer action; an error stops the recorder as one in the timer thread does."""
        try:
            return action()
        except Exception as exc:
            self._failure = exc
            raise

    def _flush_locked(self) -> None:
        """Write the chunk being filled (if any) and hand the file's buffer to the OS."""
        chunk = self._chunk
        if chunk:
            self._total += len(chunk)
            try:
                self._writer.add_chunk(chunk)
            finally:
                chunk.clear()                   # in place: the drain loop appends to it
        self._writer.flush()
        self._readable = self._total
        self._last_flush = time.monotonic()

    def _publisher_qos_and_hash(self, topic: str, msgtype: str) -> tuple[list, str]:
        """Offered QoS profiles of the current publishers and the type hash (rosbag2 does so)."""
        profiles, type_hash = [], ''
        try:
            for endpoint in self._node.get_publishers_info_by_topic(topic):
                profiles.append(qos_to_dict(endpoint.qos_profile))
                text = str(getattr(endpoint, 'topic_type_hash', ''))
                if text.startswith('RIHS') and not type_hash:
                    type_hash = text
        except Exception:  # noqa: BLE001 - graph query after shutdown
            pass
        return profiles, type_hash or type_hash_from_share(msgtype)

    def _channel_locked(self, topic: str) -> int:
        channel_id = self._channel_ids.get(topic)
        if channel_id is None:
            msgtype = self._topics[topic]
            profiles, type_hash = self._publisher_qos_and_hash(topic, msgtype)
            self._topic_meta[topic] = {'qos': profiles, 'type_hash': type_hash}
            channel_id = self._writer.add_channel(
                topic=topic, message_encoding='cdr', schema_id=self._schema_ids[msgtype],
                metadata={'offered_qos_profiles': _yaml_text(profiles)
                          .strip() if profiles else '',
                          'topic_type_hash': type_hash})
            self._channel_ids[topic] = channel_id
        return channel_id

    def _metadata_locked(self) -> dict:
        first, last = self._writer.message_times_ns
        start = first or 0
        duration = (last - first) if first is not None else 0
        count = sum(self._counts.values())
        return {
            'version': BAG_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': topic,
                    'type': msgtype,
                    'serialization_format': 'cdr',
                    'offered_qos_profiles': self._topic_meta.get(topic, {}).get('qos', []),
                    'type_description_hash': self._topic_meta.get(topic, {}).get('type_hash', ''),
                 },
                 'message_count': self._counts[topic]}
                for topic, msgtype in self._topics.items()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self._mcap_path.name],
            'files': [{'path': self._mcap_path.name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': count}],
            'custom_data': dict(self._custom_data),
            'ros_distro': ROS_DISTRO,
        }


BAG_FORMAT = 2
"""custom_data gripper_ros.format: 2 = the lockstep loop topics (loop/tick, references,
loop/motor_command); 1 (absent) = bags with a tick message per topic (joint_states...)."""


class RecordingError(RuntimeError):
    """Recording could not start or stopped early; the message is one line."""


def _readable_messages(sink: BagRecorder) -> int:
    """Count the messages a reader gets back from a bag whose recording failed.

    It is read back: a write that failed may have left a chunk whole without its index.
    """
    try:
        return read_bag(sink.bag_dir, allow_empty=True).message_count
    except BagError:
        return sink.readable_count


def failure_message(sink: BagRecorder, exc: BaseException) -> str:
    """Close a bag whose recording failed and say so in one line.

    The line names the bag, the error, the messages a reader gets back and those lost: every
    message handed to the recorder is either readable or counted as lost.
    """
    count = sink.accepted_count
    try:
        sink.close()
    except Exception:  # noqa: BLE001 - the first error is the one to report
        pass
    readable = _readable_messages(sink)
    if isinstance(exc, BagRecorderError) and exc.__cause__ is not None:
        exc = exc.__cause__                     # what failed, not that closing did
    reason = getattr(exc, 'strerror', None) or str(exc)
    lost = f' ({count - readable} more were still buffered and are lost)' \
        if count > readable else ''
    return (f'recording stopped: {sink.bag_dir}: {reason}; the bag holds {readable} '
            f'messages, readable up to there{lost}')


def unique_bag_dir(parent: Path, stem: str) -> Path:
    """Create a new folder under ``parent`` named after ``stem``, never one that exists.

    The name carries the process id and a counter, and the folder is created atomically.
    """
    parent.mkdir(parents=True, exist_ok=True)
    for n in range(1000):
        candidate = parent / f'{stem}_{os.getpid()}' if n == 0 else \
            parent / f'{stem}_{os.getpid()}_{n}'
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        return candidate
    raise RecordingError(f'no free bag folder name for {stem} under {parent}')
