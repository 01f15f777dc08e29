"""An MCAP file written a chunk at a time: the encoding half of the bag recorder.

Why not ``mcap.writer.Writer``: it takes one message a call and spends some microseconds of
Python on each (a record object, statistics, the chunk builder's index), and the recorder runs
in the executor's thread (or shares the GIL with it), so every microsecond of it is one the
simulation waits for. Here a whole chunk of messages is encoded in one loop of ``struct``
packs and joined once; compression, the CRCs and the file write are C code. Every record
other than a message is ``mcap.records``' own, and the layout (chunks, their message indexes,
a summary with schemas, channels, statistics, chunk and metadata indexes, summary offsets,
CRCs) is what ``mcap.writer.Writer`` writes, so every MCAP reader reads it.
"""
from __future__ import annotations

from collections import defaultdict
from itertools import chain
import struct
from typing import BinaryIO, Mapping
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata,
                          MetadataIndex, Schema, Statistics, SummaryOffset)
from mcap.writer import CompressionType

MAGIC = b'\x89MCAP0\r\n'
_MESSAGE = struct.Struct('<BQHIQQ')     # opcode, record length, channel, sequence, log, publish
_MESSAGE_FIELDS_SIZE = _MESSAGE.size - 9  # what the record length counts before the data
_INDEX_HEAD = struct.Struct('<BQHI')     # opcode, record length, channel, entries' byte length
_INDEX_FIELDS_SIZE = _INDEX_HEAD.size - 9
_INDEX_ENTRY = struct.Struct('<QQ')      # log ns, offset
_FOOTER_FIELDS = struct.Struct('<BQQQ')
_FOOTER_LENGTH = 8 + 8 + 4
_SEQUENCE_MASK = 0xFFFFFFFF


def _compressor(compression: CompressionType):
    """Return (the name a Chunk record gives, a bytes -> bytes function)."""
    if compression == CompressionType.ZSTD:
        import zstandard
        return 'zstd', zstandard.ZstdCompressor().compress
    if compression == CompressionType.LZ4:
        import lz4.frame
        return 'lz4', lz4.frame.compress
    return '', bytes


def _message_index(channel: int, entries: list[tuple[int, int]]) -> bytes:
    """Return a MessageIndex record (``mcap.records.MessageIndex``'s bytes) in one pack.

    ``entries``: (log ns, offset in the chunk's records) of each message of ``channel``.
    """
    size = _INDEX_ENTRY.size * len(entries)
    head = _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, _INDEX_FIELDS_SIZE + size, channel, size)
    return head + struct.pack(f'<{2 * len(entries)}Q', *chain.from_iterable(entries))


class McapFile:
    """Write an MCAP file to ``stream``: schemas, channels, chunks of messages, metadata.

    Not thread-safe: the recorder calls it under its lock.
    """

    def __init__(self, stream: BinaryIO, profile: str, library: str,
                 compression: CompressionType = CompressionType.ZSTD):
        self._stream = stream
        self._compression, self._compress = _compressor(compression)
        self._offset = 0
        self._crc = 0                           # of the data section
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._channel_counts: dict[int, int] = defaultdict(int)
        self._message_count = 0
        self._start_ns: int | None = None
        self._end_ns = 0
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=library))

    # ------------------------------------------------------------------ records
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._write_record(schema)
        return schema.id

    def add_channel(self, topic: str, message_encoding: str, schema_id: int,
                    metadata: Mapping[str, str]) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, schema_id=schema_id,
                          message_encoding=message_encoding, metadata=dict(metadata))
        self._channels.append(channel)
        self._write_record(channel)
        return channel.id

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        record = Metadata(name=name, metadata=dict(data))
        offset = self._offset
        length = self._write_record(record)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    @property
    def message_times_ns(self) -> tuple[int | None, int]:
        """The earliest and latest log time of the messages written (None, 0: none yet)."""
        return self._start_ns, self._end_ns

    def add_chunk(self, messages: list[tuple[int, int, int, int, bytes]]) -> int:
        """Write one chunk of ``(channel, sequence, log ns, publish ns, data)`` and its indexes.

        Returns the number of messages written (none: no chunk).
        """
        if not messages:
            return 0
        pack = _MESSAGE.pack
        op = Opcode.MESSAGE
        fields = _MESSAGE_FIELDS_SIZE
        head = _MESSAGE.size
        parts: list[bytes] = []
        append = parts.append
        indexes: dict[int, list] = defaultdict(list)
        offset = 0
        for channel, sequence, log_ns, publish_ns, data in messages:
            size = len(data)
            append(pack(op, fields + size, channel, sequence & _SEQUENCE_MASK, log_ns,
                        publish_ns))
            append(data)
            indexes[channel].append((log_ns, offset))
            offset += head + size
        counts = self._channel_counts
        for channel, entries in indexes.items():
            counts[channel] += len(entries)
        start = min(m[2] for m in messages)
        end = max(m[2] for m in messages)
        n = sum(len(v) for v in indexes.values())
        self._message_count += n
        self._start_ns = start if self._start_ns is None else min(self._start_ns, start)
        self._end_ns = max(self._end_ns, end)
        raw = b''.join(parts)
        data = self._compress(raw)
        chunk_start = self._offset
        chunk_length = self._write_record(Chunk(
            compression=self._compression, data=data, message_start_time=start,
            message_end_time=end, uncompressed_crc=zlib.crc32(raw), uncompressed_size=len(raw)))
        index_offsets = {}
        index_parts = []
        index_length = 0
        for channel, entries in sorted(indexes.items()):
            index_offsets[channel] = self._offset + index_length
            part = _message_index(channel, entries)
            index_parts.append(part)
            index_length += len(part)
        self._write(b''.join(index_parts))
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_start,
            chunk_length=chunk_length, message_index_offsets=index_offsets,
            message_index_length=index_length, compression=self._compression,
            compressed_size=len(data), uncompressed_size=len(raw)))
        return n

    def flush(self) -> None:
        """Hand what was written to the OS (no fsync)."""
        self._stream.flush()

    def finish(self) -> None:
        """Write the data end, the summary and the footer; the stream stays open."""
        self._write_record(DataEnd(data_section_crc=self._crc))
        summary_start = self._offset
        builder = RecordBuilder()
        offsets = []
        groups = ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [self._statistics()]),
                  (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, []),
                  (Opcode.METADATA_INDEX, self._metadata_indexes))
        for opcode, records in groups:
            group_start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(SummaryOffset(group_opcode=opcode,
                                         group_start=summary_start + group_start,
                                         group_length=builder.count - group_start))
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(_FOOTER_FIELDS.pack(Opcode.FOOTER, _FOOTER_LENGTH, summary_start,
                                             summary_offset_start), zlib.crc32(summary))
        self._stream.write(summary)
        footer = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
               summary_crc=crc).write(footer)
        self._stream.write(footer.end())
        self._stream.write(MAGIC)
        self._stream.flush()

    # ------------------------------------------------------------------ internals
    def _statistics(self) -> Statistics:
        return Statistics(
            message_count=self._message_count, schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=0,
            metadata_count=len(self._metadata_indexes), chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_ns or 0, message_end_time=self._end_ns,
            channel_message_counts=dict(self._channel_counts))

    def _write_record(self, record) -> int:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._write(data)
        return len(data)

    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._offset += len(data)
