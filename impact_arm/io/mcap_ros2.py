"""ROS 2 MCAP files: a crash-safe writer, message definitions from introspection, a reader.

Files follow what rosbag2's MCAP storage writes, so ``ros2 bag play``/``info``, the ``mcap``
library and ``rosbags`` read them: profile ``ros2``; one schema per type named ``pkg/msg/Type``
with encoding ``ros2msg`` (the full definition text, dependencies after a line of 80 ``=`` and
``MSG: pkg/Type``); CDR message data; channel metadata ``offered_qos_profiles`` (rosbag2 QoS
YAML) and ``topic_type_hash``; a ``rosbag2`` metadata record; zstd/lz4 chunks with message and
chunk indexes and statistics so readers can play in log-time order.

Crash safety: the file is a complete MCAP after every flush. A flush writes the new chunk and
then a fresh *tail* (rosbag2 metadata record, DataEnd, summary, footer, magic) in one write at
the end of the committed data; the next flush overwrites that tail. A process killed at any time
(SIGKILL included) leaves everything up to its last flush readable. ``flush_interval`` bounds
how old that is (the writer checks on each write; a recorder also flushes from a timer).

Topics, types and QoS are the contract's (``impact_arm.contract``).
"""

from __future__ import annotations

import os
import re
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Iterator, NamedTuple, Optional

from .. import contract
from ..contract import TopicQos
from ..physics.errors import ImpactArmError
from .msgdefs import message_class, message_definition, serialize_cdr, type_hash, type_name_of

__all__ = [
    'RawMessage',
    'RecordingError',
    'Ros2McapWriter',
    'TopicInfo',
    'iter_raw',
    'message_class',
    'message_definition',
    'qos_yaml',
    'read_attachments',
    'read_metadata',
    'serialize_cdr',
    'topics_info',
    'type_name_of',
]

MAGIC = b'\x89MCAP0\r\n'
ROSBAG2_METADATA_VERSION = 9  # rosbag2 BagMetadata version whose QoS YAML uses policy names


class RecordingError(ImpactArmError, OSError):
    """The MCAP file cannot be written (path, permissions, disk full). Flushed data stays."""


def qos_yaml(profiles: Sequence[TopicQos]) -> str:
    """rosbag2's ``offered_qos_profiles`` string: a YAML sequence, laid out as yaml-cpp does."""
    lines = []
    for p in profiles:
        for i, (k, v) in enumerate(p.as_dict().items()):
            lead = '- ' if i == 0 else '  '
            if isinstance(v, dict):
                lines.append(f'{lead}{k}:')
                lines += [f'    {kk}: {vv}' for kk, vv in v.items()]
            else:
                lines.append(f'{lead}{k}: {str(v).lower() if isinstance(v, bool) else v}')
    return '\n'.join(lines)


def parse_qos_yaml(text: str) -> list:
    import yaml

    return [TopicQos.from_dict(d) for d in (yaml.safe_load(text) or [])]


def ros_distro() -> str:
    if os.environ.get('ROS_DISTRO'):
        return os.environ['ROS_DISTRO']
    try:  # PyPI wheels (no ROS install) are named ros-<distro>-rclpy
        from importlib.metadata import distributions

        for dist in distributions():
            m = re.fullmatch(r'ros-([a-z]+)-rclpy', (dist.metadata['Name'] or '').lower())
            if m:
                return m.group(1)
    except Exception:  # noqa: BLE001 - the distro is informational only
        pass
    return ''


def package_version() -> str:
    try:
        from importlib.metadata import version

        return version('impact_arm')
    except Exception:  # noqa: BLE001 - running from a source tree without metadata
        return '0.1.0'


# --------------------------------------------------------------------------- records
def _s(text: str) -> bytes:
    b = text.encode()
    return struct.pack('<I', len(b)) + b


def _map(d: dict) -> bytes:
    body = b''.join(_s(k) + _s(v) for k, v in d.items())
    return struct.pack('<I', len(body)) + body


def _rec(op: int, body: bytes) -> bytes:
    return struct.pack('<BQ', op, len(body)) + body


_MSG_HEAD = struct.Struct('<BQHIQQ')  # opcode, length, channel, sequence, log, publish time


class _Channel:
    __slots__ = ('id', 'topic', 'type_name', 'qos', 'type_hash', 'seq', 'count')

    def __init__(self, cid, topic, type_name, qos, thash):
        self.id, self.topic, self.type_name = cid, topic, type_name
        self.qos, self.type_hash, self.seq, self.count = qos, thash, 0, 0


class Ros2McapWriter:
    """Writes a ROS 2 MCAP file that stays readable after every flush (see module doc).

    ``compression``: 'zstd', 'lz4' or ''. ``chunk_size``: uncompressed bytes after which a chunk
    is closed (and flushed). ``flush_interval``: seconds between automatic flushes on write
    (None: only on chunk size, ``flush()`` and ``close()``). Thread safe.
    """

    def __init__(
        self,
        path,
        *,
        compression: str = 'zstd',
        chunk_size: int = 1 << 20,
        flush_interval: Optional[float] = 1.0,
        library: str = '',
    ):
        self.path = os.fspath(path)
        self._compress: Callable[[bytes], bytes] | None
        if compression == 'zstd':
            import zstandard

            self._compress = zstandard.ZstdCompressor(level=3).compress
        elif compression == 'lz4':
            import lz4.frame

            self._compress = lz4.frame.compress
        elif compression in ('', 'none', None):
            compression, self._compress = '', None
        else:
            raise ValueError(f"compression must be 'zstd', 'lz4' or '', not {compression!r}")
        self.compression, self.chunk_size, self.flush_interval = (
            compression,
            chunk_size,
            flush_interval,
        )
        self._lock = threading.RLock()
        self._channels: dict = {}  # topic -> _Channel
        self._schema_ids: dict = {}  # type name -> schema id
        self._pending = bytearray()  # data-section records not yet in the file
        self._chunk = bytearray()  # uncompressed records of the open chunk
        self._chunk_index: dict = {}  # channel id -> [(log time, offset in chunk)]
        self._chunk_times: list[Any] = [None, None]  # log times [ns] once a message came
        self._summary_schemas = bytearray()
        self._summary_channels = bytearray()
        self._summary_chunk_indexes = bytearray()
        self._summary_attachment_indexes = bytearray()
        self._summary_metadata_indexes = bytearray()
        self._counts = {'message': 0, 'chunk': 0, 'attachment': 0, 'metadata': 0}
        self._times: list[Any] = [None, None]  # first and last log time of the file
        self._error: Optional[RecordingError] = None
        self._closed = False
        self._fd: Any = None  # the file descriptor once open
        try:
            parent = os.path.dirname(os.path.abspath(self.path))
            os.makedirs(parent, exist_ok=True)
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as e:
            raise self._fail(e, 'cannot create') from None
        lib = library or f'impact_arm {package_version()}'
        head = MAGIC + _rec(0x01, _s('ros2') + _s(lib))
        self._committed = 0  # end of the data that later flushes never rewrite
        self._file_end = 0
        self._tail = b''
        self._pending += head
        self._last_flush = time.monotonic()
        try:
            self.flush()  # an empty but complete file from the start
        except RecordingError:
            os.close(self._fd)
            self._closed = True
            raise

    # ------------------------------------------------------------------ public API
    def add_topic(
        self,
        topic: str,
        type_name: str,
        qos: TopicQos | Sequence[TopicQos] | None = None,
        type_hash_str: str | None = None,
    ) -> int:
        """Register ``topic`` (idempotent); ``qos``: a TopicQos, a list of them, or None for the
        contract's. Returns the channel id."""
        with self._lock:
            if topic in self._channels:
                return self._channels[topic].id
            type_name = type_name_of(message_class(type_name))  # validates, normalises
            qos_list: list[TopicQos] = (
                [contract.qos(topic)]
                if qos is None
                else (list(qos) if isinstance(qos, (list, tuple)) else [qos])  # type: ignore[list-item]
            )
            thash = type_hash(type_name) if type_hash_str is None else type_hash_str
            if type_name not in self._schema_ids:
                sid = len(self._schema_ids) + 1
                rec = _rec(
                    0x03,
                    struct.pack('<H', sid)
                    + _s(type_name)
                    + _s('ros2msg')
                    + _s(message_definition(type_name)),
                )
                self._schema_ids[type_name] = sid
                self._pending += rec
                self._summary_schemas += rec
            ch = _Channel(len(self._channels) + 1, topic, type_name, qos_list, thash)
            rec = _rec(
                0x04,
                struct.pack('<HH', ch.id, self._schema_ids[type_name])
                + _s(topic)
                + _s('cdr')
                + _map({'offered_qos_profiles': qos_yaml(qos_list), 'topic_type_hash': thash}),
            )
            self._pending += rec
            self._summary_channels += rec
            self._channels[topic] = ch
            return ch.id

    def write(
        self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None
    ) -> None:
        """Append one serialized (CDR) message on a registered topic."""
        with self._lock:
            if self._error or self._closed:
                raise self._error or RecordingError(f'{self.path}: writer is closed')
            ch = self._channels[topic]
            log_time_ns = int(log_time_ns)
            pub = log_time_ns if publish_time_ns is None else int(publish_time_ns)
            offset = len(self._chunk)
            self._chunk += _MSG_HEAD.pack(0x05, 22 + len(data), ch.id, ch.seq, log_time_ns, pub)
            self._chunk += data
            ch.seq = (ch.seq + 1) & 0xFFFFFFFF
            ch.count += 1
            self._chunk_index.setdefault(ch.id, []).append((log_time_ns, offset))
            t = self._chunk_times
            if t[0] is None or log_time_ns < t[0]:
                t[0] = log_time_ns
            if t[1] is None or log_time_ns > t[1]:
                t[1] = log_time_ns
            if len(self._chunk) >= self.chunk_size or (
                self.flush_interval is not None
                and time.monotonic() - self._last_flush >= self.flush_interval
            ):
                self._flush()

    def write_message(
        self, topic: str, msg: Any, log_time_ns: int, publish_time_ns: int | None = None
    ) -> None:
        """Serialize a message object (``serialize_cdr``) and write it; registers the topic
        on first use with its contract QoS."""
        if topic not in self._channels:
            self.add_topic(topic, type_name_of(msg))
        self.write(topic, serialize_cdr(msg), log_time_ns, publish_time_ns)

    def add_metadata(self, name: str, data: dict) -> None:
        """Store a named string map (a Metadata record); written at the next flush."""
        if name == 'rosbag2':
            raise ValueError("the 'rosbag2' metadata record is written by the writer itself")
        with self._lock:
            rec = _rec(0x0C, _s(name) + _map({str(k): str(v) for k, v in data.items()}))
            self._summary_metadata_indexes += _rec(
                0x0D, struct.pack('<QQ', self._committed + len(self._pending), len(rec)) + _s(name)
            )
            self._pending += rec
            self._counts['metadata'] += 1

    def add_attachment(
        self,
        name: str,
        data: bytes,
        media_type: str = 'application/octet-stream',
        log_time_ns: int | None = None,
        create_time_ns: int | None = None,
    ) -> None:
        """Store a file (e.g. the scene YAML) as an Attachment record."""
        now = time.time_ns()
        log_time_ns = now if log_time_ns is None else int(log_time_ns)
        create_time_ns = log_time_ns if create_time_ns is None else int(create_time_ns)
        data = data.encode() if isinstance(data, str) else bytes(data)
        with self._lock:
            body = (
                struct.pack('<QQ', log_time_ns, create_time_ns)
                + _s(name)
                + _s(media_type)
                + struct.pack('<Q', len(data))
                + data
            )
            rec = _rec(0x09, body + struct.pack('<I', zlib.crc32(body)))
            self._summary_attachment_indexes += _rec(
                0x0A,
                struct.pack(
                    '<QQQQQ',
                    self._committed + len(self._pending),
                    len(rec),
                    log_time_ns,
                    create_time_ns,
                    len(data),
                )
                + _s(name)
                + _s(media_type),
            )
            self._pending += rec
            self._counts['attachment'] += 1

    def has_topic(self, topic: str) -> bool:
        return topic in self._channels

    @property
    def message_count(self) -> int:
        return self._counts['message'] + sum(len(v) for v in self._chunk_index.values())

    def flush(self) -> None:
        """Write the open chunk and a fresh summary: the file is complete on return."""
        with self._lock:
            if self._error:
                raise self._error
            if not self._closed:
                self._flush()

    def close(self) -> None:
        """Flush and close (idempotent). After a RecordingError it only releases the file."""
        with self._lock:
            if self._closed:
                return
            try:
                if not self._error:
                    self._flush()
                    os.fsync(self._fd)
            except OSError as e:
                self._fail(e, 'cannot write')
            finally:
                self._closed = True
                if self._fd is not None:
                    os.close(self._fd)
            if self._error:
                raise self._error

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        try:
            self.close()
        except RecordingError:
            if exc_type is None:
                raise

    # --------------------------------------------------------------- internals
    def _fail(self, err: OSError, what: str) -> RecordingError:
        self._error = RecordingError(f'{what} MCAP file {self.path}: {err.strerror or err}')
        self._error.errno = err.errno
        return self._error

    def _close_chunk(self, out: bytearray, base: int):
        """Append the open chunk, its message indexes, and record its chunk index."""
        raw = bytes(self._chunk)
        data = self._compress(raw) if self._compress else raw
        start, end = self._chunk_times
        chunk = _rec(
            0x06,
            struct.pack('<QQQI', start, end, len(raw), zlib.crc32(raw))
            + _s(self.compression)
            + struct.pack('<Q', len(data))
            + data,
        )
        chunk_offset = base + len(out)
        out += chunk
        index_offsets = bytearray()
        index_start = len(out)
        for cid in sorted(self._chunk_index):
            entries = sorted(self._chunk_index[cid])
            flat = [x for e in entries for x in e]
            index_offsets += struct.pack('<HQ', cid, base + len(out))
            out += _rec(
                0x07,
                struct.pack('<HI', cid, 16 * len(entries)) + struct.pack(f'<{len(flat)}Q', *flat),
            )
            self._counts['message'] += len(entries)
        self._summary_chunk_indexes += _rec(
            0x08,
            struct.pack('<QQQQ', start, end, chunk_offset, len(chunk))
            + struct.pack('<I', len(index_offsets))
            + index_offsets
            + struct.pack('<Q', len(out) - index_start)
            + _s(self.compression)
            + struct.pack('<QQ', len(data), len(raw)),
        )
        self._counts['chunk'] += 1
        t = self._times
        t[0] = start if t[0] is None else min(t[0], start)
        t[1] = end if t[1] is None else max(t[1], end)
        self._chunk = bytearray()
        self._chunk_index = {}
        self._chunk_times = [None, None]

    def _flush(self):
        self._last_flush = time.monotonic()
        if not self._pending and not self._chunk and self._tail:
            return
        out = bytearray(self._pending)
        if self._chunk:
            self._close_chunk(out, self._committed)
        tail = self._build_tail(self._committed + len(out))
        short = len(self._tail) - len(out) - len(tail)
        if short > 0:
            # Never end the file before the previous tail does: a kill between the write and a
            # truncate would leave the old footer behind. YAML ignores trailing blanks.
            tail = self._build_tail(self._committed + len(out), pad=short)
        buf = bytes(out) + tail
        try:
            # One write replaces the previous tail, so the file is valid before and after it.
            self._pwrite_all(buf, self._committed)
        except OSError as e:
            err = self._fail(e, 'cannot write')
            self._restore_tail()
            raise err from None
        self._pending = bytearray()
        self._committed += len(out)
        self._file_end = self._committed + len(tail)
        self._tail = tail

    def _pwrite_all(self, buf: bytes, offset: int):
        view = memoryview(buf)
        while view:
            n = os.pwrite(self._fd, view, offset)
            view, offset = view[n:], offset + n

    def _restore_tail(self):
        """After a failed write (disk full), put back the last complete tail."""
        try:
            if self._tail:
                self._pwrite_all(self._tail, self._committed)
                os.ftruncate(self._fd, self._committed + len(self._tail))
        except OSError:
            pass  # nothing more can be done; the error already names the cause

    def _bag_metadata(self, pad: int = 0) -> str:
        import yaml

        start, end = self._times
        n = self._counts['message']
        start = start or 0
        duration = (end - start) if n else 0
        name = os.path.basename(self.path)
        topics = [
            {
                'topic_metadata': {
                    'name': ch.topic,
                    'type': ch.type_name,
                    'serialization_format': 'cdr',
                    'offered_qos_profiles': [q.as_dict() for q in ch.qos],
                    'type_description_hash': ch.type_hash,
                },
                'message_count': self._flushed_count(ch),
            }
            for ch in self._channels.values()
        ]
        meta = {
            'version': ROSBAG2_METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': n,
            'topics_with_message_count': topics,
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [name],
            'files': [
                {
                    'path': name,
                    'starting_time': {'nanoseconds_since_epoch': start},
                    'duration': {'nanoseconds': duration},
                    'message_count': n,
                }
            ],
            'custom_data': {'impact_arm_version': package_version()},
            'ros_distro': _distro(),
        }
        # libyaml's dumper when present: this runs at every flush
        dumper = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)
        return yaml.dump(meta, Dumper=dumper, sort_keys=False, default_flow_style=False) + ' ' * pad

    def _flushed_count(self, ch) -> int:
        return ch.count - len(self._chunk_index.get(ch.id, ()))

    def _build_tail(self, base: int, pad: int = 0) -> bytes:
        """rosbag2 metadata record + DataEnd + summary + footer + magic, starting at base."""
        meta = _rec(
            0x0C,
            _s('rosbag2')
            + _map({'serialized_metadata': self._bag_metadata(pad), 'ROS_DISTRO': _distro()}),
        )
        data_tail = meta + _rec(0x0F, struct.pack('<I', 0))  # 0: data CRC not computed
        summary_start = base + len(data_tail)
        counts = {ch.id: self._flushed_count(ch) for ch in self._channels.values()}
        start, end = self._times
        stats = _rec(
            0x0B,
            struct.pack(
                '<QHIIII',
                self._counts['message'],
                len(self._schema_ids),
                len(self._channels),
                self._counts['attachment'],
                self._counts['metadata'] + 1,
                self._counts['chunk'],
            )
            + struct.pack('<QQ', start or 0, end or 0)
            + struct.pack('<I', 10 * len(counts))
            + b''.join(struct.pack('<HQ', k, v) for k, v in counts.items()),
        )
        meta_index = _rec(0x0D, struct.pack('<QQ', base, len(meta)) + _s('rosbag2'))
        groups = [
            (0x03, bytes(self._summary_schemas)),
            (0x04, bytes(self._summary_channels)),
            (0x0B, stats),
            (0x08, bytes(self._summary_chunk_indexes)),
            (0x0A, bytes(self._summary_attachment_indexes)),
            (0x0D, bytes(self._summary_metadata_indexes) + meta_index),
        ]
        summary = bytearray()
        offsets = bytearray()
        for op, body in groups:
            if body:
                offsets += _rec(
                    0x0E, struct.pack('<BQQ', op, summary_start + len(summary), len(body))
                )
                summary += body
        footer = struct.pack('<BQQQ', 0x02, 20, summary_start, summary_start + len(summary))
        crc = zlib.crc32(bytes(summary) + bytes(offsets) + footer)
        return data_tail + bytes(summary) + bytes(offsets) + footer + struct.pack('<I', crc) + MAGIC


_DISTRO: list[str] = []


def _distro() -> str:
    if not _DISTRO:
        _DISTRO.append(ros_distro())
    return _DISTRO[0]


# ----------------------------------------------------------------------------- reading
class RawMessage(NamedTuple):
    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes


def iter_raw(
    path: str | os.PathLike,
    topics: Iterable[str] | None = None,
    start_time_ns: int | None = None,
    log_time_order: bool = True,
) -> Iterator[RawMessage]:
    """Serialized messages in log-time order (chunk indexes let the reader sort), or in the
    order they were written with ``log_time_order=False``."""
    from mcap.reader import make_reader

    with open(path, 'rb') as f:
        reader = make_reader(f)
        kw: dict[str, Any] = {}
        if start_time_ns is not None:  # inclusive; mcap >= 1.2 renamed the argument
            import inspect

            new = 'starting_at' in inspect.signature(reader.iter_messages).parameters
            kw['starting_at' if new else 'start_time'] = int(start_time_ns)
        for schema, channel, message in reader.iter_messages(
            topics=list(topics) if topics else None, log_time_order=log_time_order, **kw
        ):
            yield RawMessage(
                channel.topic,
                schema.name if schema else '',
                message.log_time,
                message.publish_time,
                message.data,
            )


class TopicInfo(NamedTuple):
    type_name: str
    qos: list
    message_count: int


def unreadable_reason(path: str | os.PathLike, exc: BaseException) -> str:
    """What is wrong with an MCAP file a reader failed on, in a few words for a one-line
    message: empty, not MCAP at all, cut off before its footer (a recording stopped
    mid-write and never closed), or the reader's own words."""
    try:
        size = os.path.getsize(path)
        with open(path, 'rb') as f:
            head = f.read(len(MAGIC))
            f.seek(max(size - len(MAGIC), 0))
            tail = f.read(len(MAGIC))
    except OSError as e:
        return f'cannot be read ({e.strerror})'
    if size == 0:
        return 'empty file (0 bytes), not an MCAP recording'
    if head != MAGIC:
        return 'not an MCAP file (it does not start with the MCAP magic bytes)'
    if tail != MAGIC or size < 2 * len(MAGIC):
        return (
            f'truncated MCAP file: {size} bytes ending without the MCAP footer (a recording '
            f'cut off while it was written)'
        )
    words = ' '.join(str(exc).split()) or type(exc).__name__
    return f'unreadable MCAP file ({words})'


def topics_info(path: str | os.PathLike) -> dict[str, TopicInfo]:
    """topic -> TopicInfo(type name, [TopicQos], message count) from the file's summary."""
    from mcap.reader import make_reader

    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    if summary is None:
        return {}
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    out = {}
    for cid, ch in summary.channels.items():
        schema = summary.schemas.get(ch.schema_id)
        text = ch.metadata.get('offered_qos_profiles', '')
        out[ch.topic] = TopicInfo(
            schema.name if schema else '', parse_qos_yaml(text) if text else [], counts.get(cid, 0)
        )
    return out


def read_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """name -> string map of every Metadata record (the last one wins for a repeated name)."""
    from mcap.reader import make_reader

    with open(path, 'rb') as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def read_attachments(path: str | os.PathLike) -> dict[str, bytes]:
    from mcap.reader import make_reader

    with open(path, 'rb') as f:
        return {a.name: bytes(a.data) for a in make_reader(f).iter_attachments()}
