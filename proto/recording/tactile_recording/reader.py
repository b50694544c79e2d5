"""Reading a session's recording (proto/RECORDING.md): an MCAP file of Envelopes, closed or cut short.

    recording = open_recording(path)
    recording.complete            # True when the file ends with its summary and footer (the server closed it)
    recording.metadata            # the `tactile` metadata record: scene_name, scene_json, server, started_unix_ns
    for topic, log_time_ns, publish_time_ns, data in recording.messages(["/state"]): ...
    for topic, log_time_ns, envelope in recording.decoded(["/haptic"]): ...   # envelope: EnvelopeT
    recording.problems            # what could not be read, each named with its byte offset

Messages come in file order: each channel's in log-time order, the channels as the server interleaved them.

A file cut short (a server killed with SIGKILL leaves no summary or footer, and maybe half a chunk) is read
record by record up to the first incomplete one, and the cut is a problem, never an exception. A chunk whose
CRC-32 does not match its records, that does not decompress or whose records do not frame, is a problem and
is skipped whole: none of its bytes are returned as messages. The records after it are still read, since the
chunk's own length frames it. RecordingError is raised only for a file that is no recording at all (bad
magic, no Header first) and for a topic no recording has.

Why the records are framed here and not by mcap's readers: in mcap 1.2.2, `StreamReader` and `make_reader`
raise on a file cut short (EndOfFile, struct.error, RecordLengthLimitExceeded or UnicodeDecodeError, by where
the cut falls; `make_reader` reads garbage as a footer), and a chunk CRC mismatch (`validate_crcs=True`)
raises CRCValidationError from inside their generator, which ends the iteration. So this module reads each
record's 9-byte head (opcode u8, length u64, the spec's framing), checks that the whole record is in the
file, and hands it to mcap's record parsers (mcap.records) and each chunk to mcap's decompression and CRC
check (mcap.stream_reader.get_chunk_data_stream).
"""

from __future__ import annotations

import base64
import io
import json
import os
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO, NamedTuple

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
    Statistics,
)
from mcap.stream_reader import CRCValidationError, get_chunk_data_stream

from tactile_proto.codec import ProtocolError, decode
from tactile_proto.generated.Envelope import EnvelopeT

MAGIC = b"\x89MCAP0\r\n"
SCHEMA_NAME = "tactile.proto.Envelope"  # the schema of a channel of whole Envelopes (all of them before 1.7)
MESSAGE_ENCODING = "flatbuffer"
# A channel whose metadata names this carries each Envelope behind a root header of that many bytes, which makes
# the message type the buffer's root (schema "tactile.proto.<Type>"): what Foxglove decodes (RECORDING.md).
ENVELOPE_OFFSET_KEY = "envelope_offset"
# A JSON channel whose metadata names this (/control) holds each Envelope in that field of its object, base64.
ENVELOPE_FIELD_KEY = "envelope_field"
METADATA_NAME = "tactile"
# Topic -> the message type its Envelopes hold (RECORDING.md's table).
TOPICS: dict[str, str] = {
    "/scene": "SceneDescription",
    "/state": "StateFrame",
    "/haptic": "HapticFrame",
    "/input": "DeviceInput",
    "/control": "Control",
    "/error": "Error",
    "/telemetry": "Telemetry",
    "/safety": "SafetyEvent",
    "/device_status": "DeviceStatus",
}
# Topics of JSON objects, not Envelopes (RECORDING.md): topic -> their schema's name.
JSON_TOPICS: dict[str, str] = {"/applied": "tactile.AppliedInput",
                               # Foxglove's views of the session, for its 3D and Log panels (RECORDING.md)
                               "/foxglove/body": "foxglove.SceneUpdate", "/foxglove/surface": "foxglove.SceneUpdate",
                               "/foxglove/log": "foxglove.Log", "/foxglove/transform": "foxglove.FrameTransform"}

_HEAD = struct.Struct("<BQ")  # a record's opcode and body length [bytes]
_COMPRESSIONS = ("", "zstd", "lz4")  # what mcap 1.2.2 decompresses (it reads any other name as "")
_SMALL_RECORD = 64 << 20  # the largest schema, channel, metadata or summary record the scan reads [bytes]
# What mcap's record parsers and decompressors raise on damaged bytes (UnicodeDecodeError is a ValueError;
# lz4.frame raises RuntimeError).
_PARSE_ERRORS = (McapError, struct.error, ValueError)
_CHUNK_ERRORS = (McapError, struct.error, ValueError, RuntimeError, zstandard.ZstdError)
# Records the scan parses whole (the others it steps over: chunks, messages, indexes, attachments).
_SCANNED = {Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.STATISTICS, Opcode.DATA_END,
            Opcode.FOOTER}


class RecordingError(ValueError):
    """A file that is not a recording, or a request no recording can answer; the message names what."""


class RecordedMessage(NamedTuple):
    topic: str
    log_time_ns: int       # the record's log_time: when the server published or received it (RECORDING.md)
    publish_time_ns: int   # the record's publish_time, as RECORDING.md defines it
    data: bytes            # one Envelope


class DecodedMessage(NamedTuple):
    topic: str
    log_time_ns: int
    envelope: EnvelopeT


class _WholeStream(ReadDataStream):
    """mcap's ReadDataStream, refusing a short read (its own returns fewer bytes without a word)."""

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile()
        return data


_PARSERS: dict[int, Callable[[ReadDataStream], McapRecord]] = {
    Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read, Opcode.CHUNK: Chunk.read,
    Opcode.METADATA: Metadata.read, Opcode.STATISTICS: Statistics.read, Opcode.DATA_END: DataEnd.read,
    Opcode.FOOTER: Footer.read,
}


def _parse(opcode: int, body: bytes) -> Any:
    """The record of one whole body, by mcap's parsers; raises one of _PARSE_ERRORS when it does not hold one."""
    stream = _WholeStream(io.BytesIO(body))
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    return _PARSERS[opcode](stream)


def _name(opcode: int) -> str:
    try:
        return Opcode(opcode).name
    except ValueError:
        return f"unknown (opcode 0x{opcode:02x})"


def _split(content: bytes) -> list[tuple[int, bytes]]:
    """A chunk's records as (opcode, body), all of them whole; ValueError when they do not frame."""
    records = []
    pos, n = 0, len(content)
    while pos < n:
        if pos + _HEAD.size > n:
            raise ValueError(f"a record head at byte {pos} of its {n} bytes of records is cut")
        opcode, length = _HEAD.unpack_from(content, pos)
        if pos + _HEAD.size + length > n:
            raise ValueError(f"the {_name(opcode)} record at byte {pos} of its {n} bytes of records claims "
                             f"{length} bytes")
        records.append((opcode, content[pos + _HEAD.size:pos + _HEAD.size + length]))
        pos += _HEAD.size + length
    return records


@dataclass
class _Problem:
    text: str  # the first one seen
    seen: set[Any] = field(default_factory=set)  # where each one of its kind was (offsets): a re-read adds none


class Recording:
    """A recording opened by open_recording: what its first pass found (header, metadata, channels, whether
    it is complete, where it is cut); messages() and decoded() read it again each time they are called."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = os.fspath(path)
        self.size = 0                       # of the file when opened [bytes]
        self.header: Header | None = None
        self.complete = False               # the file ends with a footer and the magic
        self.statistics: Statistics | None = None  # the summary's, when the file is complete
        self._metadata: dict[str, str] | None = None
        self._schemas: dict[int, Schema] = {}     # from the data section and the chunks read so far
        self._channels: dict[int, Channel] = {}   # from the data section and the chunks read so far
        self._summary_channels: dict[int, Channel] = {}
        self._first = len(MAGIC)  # offset of the first record after the header
        self._data_end = len(MAGIC)  # where the records that may hold messages end (DataEnd, a cut, damage)
        self._problems: dict[Any, _Problem] = {}
        with open(self.path, "rb") as f:
            self.size = os.fstat(f.fileno()).st_size
            self._scan(f)

    # ---- what the reads found -----------------------------------------------------------------------------

    @property
    def metadata(self) -> dict[str, str]:
        """The `tactile` metadata record (the last one, if the writer wrote several); {} when none was read."""
        return dict(self._metadata or {})

    @property
    def problems(self) -> list[str]:
        """What could not be read, in the order found: the first pass finds cuts and damaged framing, each
        read adds what its records hold (bad CRCs, undecodable messages). Problems of a kind that recurs are
        counted in one entry."""
        return [p.text if len(p.seen) <= 1 else f"{p.text} (and {len(p.seen) - 1} more like it)"
                for p in self._problems.values()]

    @property
    def topics(self) -> list[str]:
        """The topics of the channels read so far (those defined in chunks are known once a read passed them)."""
        channels = {**self._summary_channels, **self._channels}
        return sorted({c.topic for c in channels.values()})

    @property
    def summary_counts(self) -> dict[str, int] | None:
        """Messages per topic as the writer counted them (the summary's statistics); None without a summary."""
        if self.statistics is None:
            return None
        channels = {**self._summary_channels, **self._channels}
        return {channels[i].topic if i in channels else f"channel {i}": n
                for i, n in self.statistics.channel_message_counts.items()}

    def _note(self, kind: Any, where: Any, text: str) -> None:
        """Records a problem once per place; those of one kind are counted under the first one's text."""
        problem = self._problems.setdefault(kind, _Problem(text))
        problem.seen.add(where)

    # ---- the first pass -----------------------------------------------------------------------------------

    def _scan(self, f: BinaryIO) -> None:
        """Reads the framing from the magic to the footer, stepping over chunks and messages: finds the
        header, metadata, data-section channels, the summary, and where whole records end."""
        magic = f.read(len(MAGIC))
        if magic != MAGIC:
            if not MAGIC.startswith(magic):
                raise RecordingError(f"{self.path}: not an MCAP file: bad magic {magic!r} "
                                     f"(an MCAP file starts with {MAGIC!r})")
            self._note("cut", 0, f"truncated at byte {self.size}: the file ends inside the MCAP magic, before "
                                 "any record (no footer: the recording was not closed)")
            return
        offset = len(MAGIC)
        in_summary = False
        while True:
            head = f.read(_HEAD.size)
            if len(head) < _HEAD.size:
                self._note_cut(offset, None, 0)
                break
            opcode, length = _HEAD.unpack(head)
            if offset == len(MAGIC):
                if opcode != Opcode.HEADER:
                    raise RecordingError(f"{self.path}: not an MCAP recording: its first record is "
                                         f"{_name(opcode)}, not a Header")
                self._first = offset + _HEAD.size + length
            if offset + _HEAD.size + length > self.size:
                self._note_cut(offset, opcode, length)
                break
            if opcode not in _SCANNED:
                f.seek(length, io.SEEK_CUR)
            elif length > _SMALL_RECORD:
                f.seek(length, io.SEEK_CUR)
                self._note(("big", offset), offset, f"the {_name(opcode)} record at byte {offset} claims "
                                                    f"{length} bytes, more than such a record holds: skipped")
            else:
                record = self._parse_at(offset, opcode, f.read(length))
                if isinstance(record, Header):
                    self.header = record
                elif isinstance(record, Schema) and not in_summary:
                    self._schemas[record.id] = record
                elif isinstance(record, Channel):
                    (self._summary_channels if in_summary else self._channels)[record.id] = record
                elif isinstance(record, Metadata) and record.name == METADATA_NAME:
                    self._metadata = record.metadata
                elif isinstance(record, Statistics) and in_summary:
                    self.statistics = record
                elif isinstance(record, DataEnd):
                    in_summary = True
                    self._data_end = offset
                elif isinstance(record, Footer):
                    if not in_summary:
                        self._data_end = offset
                    self._check_close(f, offset, record)
                    break
            offset += _HEAD.size + length
            if not in_summary:
                self._data_end = offset
        if self._metadata is None:
            self._note("no-metadata", 0, f"no `{METADATA_NAME}` metadata record: the scene name, scene JSON and "
                                         "start time are unknown")

    def _parse_at(self, offset: int, opcode: int, body: bytes) -> Any:
        try:
            return _parse(opcode, body)
        except _PARSE_ERRORS as e:
            self._note(("record", offset), offset, f"the {_name(opcode)} record at byte {offset} "
                                                   f"({len(body)} bytes) does not parse "
                                                   f"({type(e).__name__}: {e}): skipped")
            return None

    def _note_cut(self, offset: int, opcode: int | None, length: int) -> None:
        """The first record that is not whole: a cut, or a damaged length in a file that was closed."""
        closed = self._ends_with_footer()
        if opcode is None and self.size - offset == 0:
            text = (f"truncated at byte {offset}: the file ends after a whole record, without the data end, "
                    "summary and footer (the recording was not closed)")
        elif opcode is None:
            text = (f"truncated at byte {offset}: the file ends {self.size - offset} bytes into the 9-byte head of "
                    "a record (the recording was not closed)")
        elif closed:
            text = (f"the {_name(opcode)} record at byte {offset} claims {length} bytes, past the end of the file "
                    f"(byte {self.size}), yet the file ends with a footer: its length is damaged, and the "
                    "records after it are not read")
        else:
            text = (f"truncated at byte {offset}: the {_name(opcode)} record there needs {_HEAD.size + length} "
                    f"bytes, the file ends {self.size - offset} bytes into it (at byte {self.size}); it is lost, "
                    "and the recording was not closed")
        self._note("cut", offset, text)

    def _ends_with_footer(self) -> bool:
        """Whether the file's last bytes are a footer record and the magic (the writer closed it)."""
        tail = _HEAD.size + 20 + len(MAGIC)
        if self.size < len(MAGIC) + tail:
            return False
        with open(self.path, "rb") as f:
            f.seek(self.size - tail)
            end = f.read(tail)
        return end[-len(MAGIC):] == MAGIC and _HEAD.unpack_from(end) == (Opcode.FOOTER, 20)

    def _check_close(self, f: BinaryIO, offset: int, footer: Footer) -> None:
        """After the footer: the magic, and the summary's CRC (a damaged summary's channels are not used)."""
        end = offset + _HEAD.size + 20
        f.seek(end)
        magic = f.read(len(MAGIC))
        self.complete = magic == MAGIC
        if not self.complete and end + len(magic) == self.size and MAGIC.startswith(magic):
            self._note("cut", end, f"truncated at byte {self.size}: the file ends inside the magic after the footer "
                                   "(the records are all there)")
        elif not self.complete:
            self._note("close", offset, f"the footer at byte {offset} is not followed by the MCAP magic")
        elif self.size > end + len(MAGIC):
            self._note("trailing", offset, f"{self.size - end - len(MAGIC)} bytes after the closing magic: ignored")
        if footer.summary_crc != 0 and footer.summary_start != 0:
            f.seek(footer.summary_start)
            crc = zlib.crc32(f.read(max(0, offset - footer.summary_start)))
            crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, footer.summary_start,
                                         footer.summary_offset_start), crc)
            if crc != footer.summary_crc:
                self._note("summary", offset, f"the summary (from byte {footer.summary_start}) does not match its "
                                              "CRC: its channels and statistics are not used")
                self._summary_channels, self.statistics = {}, None

    # ---- reading messages ---------------------------------------------------------------------------------

    def _wanted(self, topics: Iterable[str] | str | None) -> set[str] | None:
        if topics is None:
            return None
        wanted = {topics} if isinstance(topics, str) else set(topics)
        known = set(TOPICS) | set(JSON_TOPICS) | set(self.topics)
        unknown = sorted(wanted - known)
        if unknown:
            raise RecordingError(f"unknown topic{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}: a "
                                 f"recording has {', '.join(TOPICS)}"
                                 + (f" (this one also {', '.join(sorted(known - set(TOPICS)))})"
                                    if known - set(TOPICS) else ""))
        return wanted

    def _channel(self, channel_id: int, where: Any) -> Channel | None:
        channel = self._channels.get(channel_id) or self._summary_channels.get(channel_id)
        if channel is None:
            self._note(("channel", channel_id), where,
                       f"messages on channel id {channel_id}, which no Channel record read defines (it may have "
                       "been in a skipped chunk): skipped")
        return channel

    def _records(self, wanted: set[str] | None) -> Iterator[tuple[Channel, Message]]:
        """Every message on a wanted topic, with its channel, in file order."""
        with open(self.path, "rb") as f:
            f.seek(self._first)
            offset = self._first
            while offset < self._data_end:
                opcode, length = _HEAD.unpack(f.read(_HEAD.size))
                if opcode == Opcode.CHUNK:
                    yield from self._chunk(offset, f.read(length), wanted)
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
                    record = self._parse_at(offset, opcode, f.read(length))
                    yield from self._take([record] if record is not None else [], offset, wanted)
                else:
                    f.seek(length, io.SEEK_CUR)
                offset += _HEAD.size + length

    def _chunk(self, offset: int, body: bytes, wanted: set[str] | None) -> Iterator[tuple[Channel, Message]]:
        """The messages of one chunk, all or none: a chunk that fails its CRC or does not read is skipped."""
        chunk = self._parse_at(offset, Opcode.CHUNK, body)
        if chunk is None:
            return
        what = (f"chunk at byte {offset} ({len(body) + _HEAD.size} bytes, log times {chunk.message_start_time} to "
                f"{chunk.message_end_time} ns)")
        if chunk.compression not in _COMPRESSIONS:
            known = ", ".join(map(repr, _COMPRESSIONS))
            self._note(("chunk", offset), offset, f"the {what} is compressed with {chunk.compression!r}, which "
                                                  f"this reader does not read (only {known}): skipped")
            return
        if chunk.uncompressed_crc == 0:
            self._note("no-crc", offset, f"the {what} has no CRC (0): its records were read unchecked")
        try:
            stream, size = get_chunk_data_stream(chunk, validate_crc=True)
            content = stream.read(size)
            if len(content) != chunk.uncompressed_size:
                raise ValueError(f"its records are {len(content)} bytes, its header says {chunk.uncompressed_size}")
            records = [_parse(opcode, record) for opcode, record in _split(content)
                       if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE)]
        except CRCValidationError as e:
            self._note(("chunk", offset), offset, f"the {what} has a bad CRC (its records hash to "
                                                  f"{e.actual:08x}, its header says {e.expected:08x}): skipped, its "
                                                  "messages are lost")
            return
        except _CHUNK_ERRORS as e:
            self._note(("chunk", offset), offset, f"the {what} does not read ({type(e).__name__}: {e}): skipped, "
                                                  "its messages are lost")
            return
        yield from self._take(records, offset, wanted)

    def _take(self, records: list[Any], offset: int, wanted: set[str] | None) -> Iterator[tuple[Channel, Message]]:
        for i, record in enumerate(records):
            if isinstance(record, Schema):
                self._schemas[record.id] = record
            elif isinstance(record, Channel):
                self._channels[record.id] = record
            elif isinstance(record, Message):
                channel = self._channel(record.channel_id, (offset, i))
                if channel is not None and (wanted is None or channel.topic in wanted):
                    yield channel, record

    def messages(self, topics: Iterable[str] | str | None = None) -> Iterator[RecordedMessage]:
        """Every message read (of `topics`, all when None), in file order: (topic, log_time_ns,
        publish_time_ns, Envelope bytes). Raises RecordingError for a topic no recording has."""
        wanted = self._wanted(topics)
        for channel, message in self._records(wanted):
            yield RecordedMessage(channel.topic, message.log_time, message.publish_time, _envelope(channel, message))

    def applied(self) -> Iterator[dict[str, int]]:
        """The inputs the simulation applied, in order (/applied, JSON): {"loop_step", "device", "sequence"}."""
        for m in self.messages(["/applied"] if "/applied" in self.topics else []):
            yield json.loads(m.data)

    def decoded(self, topics: Iterable[str] | str | None = None) -> Iterator[DecodedMessage]:
        """messages(), decoded: (topic, log_time_ns, EnvelopeT). A message that does not decode, or that is
        not the type its topic holds (TOPICS), is a problem and skipped. The JSON topics (JSON_TOPICS) hold no
        Envelopes: they are left out here (applied() reads /applied)."""
        wanted = self._wanted(topics)
        for channel, message in self._records(wanted):
            if channel.topic in JSON_TOPICS:
                continue
            where = (channel.id, message.log_time, message.sequence, len(message.data))
            schema = self._schemas.get(channel.schema_id)
            rooted = ENVELOPE_OFFSET_KEY in channel.metadata
            in_json = ENVELOPE_FIELD_KEY in channel.metadata
            expected_schema = (f"tactile.proto.{TOPICS.get(channel.topic, '')}" if rooted else
                               f"tactile.{TOPICS.get(channel.topic, '')}" if in_json else SCHEMA_NAME)
            expected_encoding = "json" if in_json else MESSAGE_ENCODING
            if channel.message_encoding != expected_encoding or (schema is not None and schema.name != expected_schema):
                self._note(("encoding", channel.id), where,
                           f"{channel.topic}: message encoding {channel.message_encoding!r}, schema "
                           f"{schema.name if schema is not None else channel.schema_id!r}; not {expected_encoding!r} "
                           f"{expected_schema}: not decoded")
                continue
            try:
                envelope = decode(_envelope(channel, message))
            except ProtocolError as e:
                self._note(("decode", channel.topic), where, f"{channel.topic}: a message at log time "
                                                             f"{message.log_time} ns does not decode ({e}): skipped")
                continue
            expected = TOPICS.get(channel.topic)
            if expected is not None and type(envelope.message).__name__ != f"{expected}T":
                self._note(("type", channel.topic), where, f"{channel.topic}: a {type(envelope.message).__name__[:-1]} "
                                                           f"at log time {message.log_time} ns, where {expected} "
                                                           "belongs: skipped")
                continue
            yield DecodedMessage(channel.topic, message.log_time, envelope)


def _envelope(channel: Channel, message: Message) -> bytes:
    """The Envelope a message holds: its bytes, less the root header where its channel has one, or the base64
    of its JSON object's envelope field (b"" where that is missing: it will not decode)."""
    at = channel.metadata.get(ENVELOPE_OFFSET_KEY)
    if at is not None:
        return message.data[int(at):]
    field = channel.metadata.get(ENVELOPE_FIELD_KEY)
    if field is not None:
        try:
            return base64.b64decode(json.loads(message.data)[field], validate=True)
        except (ValueError, KeyError, TypeError):
            return b""
    return message.data


class Recovered(NamedTuple):
    messages: int           # written to the new file
    topics: dict[str, int]  # of them, per topic
    problems: list[str]     # what the source could not give (its cut, damaged chunks)


def recover(recording: Recording, out: str | os.PathLike[str]) -> Recovered:
    """Writes what `recording` holds (all of it, or for a file cut short everything whole before the cut)
    into `out` as a complete MCAP file: the same header profile, `tactile` metadata, schemas, channels and
    messages in the same order, chunked (zstd) and closed with its summary and indexes, so that the `mcap`
    package's default readers (make_reader, iter_messages) and other tools open it."""
    from mcap.writer import CompressionType, Writer

    if os.path.abspath(os.fspath(out)) == os.path.abspath(recording.path):
        raise RecordingError(f"{out}: recover writes a new file; it would overwrite the recording it reads")
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics: dict[str, int] = {}
    with open(out, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        header = recording.header
        writer.start(profile=header.profile if header else "", library=(header.library if header else "") +
                     " (recovered by tactile-recording)")
        if recording.metadata:
            writer.add_metadata("tactile", recording.metadata)
        count = 0
        for channel, message in recording._records(None):
            if channel.id not in channel_ids:
                schema = recording._schemas.get(channel.schema_id)
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_ids.get(channel.schema_id, 0),
                    dict(channel.metadata))
            writer.add_message(channel_ids[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            count += 1
        writer.finish()
    return Recovered(count, topics, recording.problems)


def open_recording(path: str | os.PathLike[str]) -> Recording:
    """The recording at `path`, after a first pass over its framing (quick: it steps over chunks). Raises
    RecordingError when the file is no MCAP recording, OSError when it cannot be opened."""
    return Recording(path)


__all__ = ["ENVELOPE_FIELD_KEY", "ENVELOPE_OFFSET_KEY", "JSON_TOPICS", "MAGIC", "MESSAGE_ENCODING", "METADATA_NAME",
           "SCHEMA_NAME", "TOPICS", "DecodedMessage", "RecordedMessage", "Recording", "RecordingError",
           "open_recording"]
