"""The hot path's messages as CDR bytes, for nodes that publish and take at kilohertz rates.

rclpy converts every message between its Python class and C on each publish and take, and
after a sleep (a realtime period) that costs more than the physics: publishing a joint state
and a wrench took ~65 us, taking one Float64MultiArray ~60 us (2-vCPU VM, 2026-11-23). rclpy
also publishes ``bytes`` as an already serialized message and takes raw bytes from a
subscription created with ``raw=True``; both are public API. So:

* ``PatchedMessage`` serializes a pre-built message once and, each period, writes the header
  stamp and the float64 fields that change into those bytes in place (the sizes of the other
  fields, joint names for instance, never change during a run);
* ``float64_array_data``, ``joint_state_fields`` and ``wrench_stamped_fields`` read what a
  driver or a controller needs straight out of the raw bytes.

Subscribers see ordinary messages; the bytes are exactly what ``msgdefs.serialize_cdr`` (and
DDS) produce, which the tests check against rclpy's own deserializer.

The readers take bytes straight from the network, so any peer can hand them garbage: every
malformation (short, bad header, absurd sequence length, non-UTF-8 name) ends as one
``MalformedMessage`` (a ValueError) with a one-line reason, which a node counts and drops.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar, cast

import functools
import struct

from .msgdefs import serialize_cdr


class MalformedMessage(ValueError):
    """Bytes that are not a well-formed message of the expected type."""


class CdrReader:
    """A cursor over CDR bytes (encapsulation header read, alignment relative to the
    payload)."""

    __slots__ = ('data', 'pos', 'endian')

    def __init__(self, data):
        self.data = memoryview(data)
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise ValueError('not a CDR message (bad encapsulation header)')
        self.endian = '<' if data[1] == 1 else '>'
        self.pos = 4

    def align(self, n: int) -> None:
        self.pos += -(self.pos - 4) % n

    def unpack(self, fmt: str, size: int, count: int = 1) -> tuple:
        end = self.pos + size * count
        if end > len(self.data):
            raise ValueError('CDR message too short for its type')
        values = struct.unpack_from(f'{self.endian}{count}{fmt}', self.data, self.pos)
        self.pos = end
        return values


_Reader = TypeVar('_Reader', bound=Callable[..., Any])


def _reader(function: _Reader) -> _Reader:
    """Any failure while reading hostile bytes becomes one ``MalformedMessage`` (the reader
    keeps its signature: its callers are checked against its own types)."""

    @functools.wraps(function)
    def read(raw: bytes, *args: Any) -> Any:
        try:
            return function(raw, *args)
        except MalformedMessage:
            raise
        except (ValueError, struct.error, IndexError, OverflowError, MemoryError) as exc:
            reason = (
                'a name is not UTF-8'
                if isinstance(exc, UnicodeDecodeError)
                else str(exc)[:120] or type(exc).__name__
            )
            raise MalformedMessage(f'{len(raw)}-byte payload: {reason}') from None

    return cast(_Reader, read)


# values nobody publishes, to find where a field's bytes lie in the serialized template
_SENTINEL_SEC, _SENTINEL_NANOSEC = 0x5A1E7A3C, 0x3B9AC9FF - 0x2A5
_SENTINEL_BASE = -1.2345678901234567e299
_STAMP = struct.Struct('<iI')  # builtin_interfaces/Time: sec, nanosec


class PatchedMessage:
    """``msg`` serialized once; ``fill(values, stamp)`` writes the float64 slots named in
    ``float_fields`` (attribute paths: ``'wrench.force.x'``, or a sequence field such as
    ``'position'``, whose current length is kept) and the ``builtin_interfaces/Time`` at
    ``stamp`` (``'header.stamp'``, ``'clock'`` for /clock, None for none) as ``(sec, nanosec)``,
    and returns the bytes to publish.

    ``values`` is flat, in the order of ``float_fields`` (a sequence gives all its elements)."""

    def __init__(self, msg, float_fields, stamp='header.stamp'):
        # (object, attribute, index or None) in fill order
        slots: list[tuple[Any, str, int | None]] = []
        for path in float_fields:
            parent, _, last = path.rpartition('.')
            owner = _resolve(msg, parent)
            value = getattr(owner, last)
            if isinstance(value, float):
                slots.append((owner, last, None))
            else:
                slots.extend((owner, last, i) for i in range(len(value)))
        self.size = len(slots)
        # stamp the template with sentinels, serialize, and find each sentinel's bytes
        stamped = stamp is not None
        if stamped:
            time_of = _resolve(msg, stamp)
            time_of.sec, time_of.nanosec = _SENTINEL_SEC, _SENTINEL_NANOSEC
        sentinels = [_SENTINEL_BASE * (1.0 + k * 2.0**-20) for k in range(self.size)]
        for (owner, name, index), sentinel in zip(slots, sentinels):
            if index is None:
                setattr(owner, name, sentinel)
            else:
                values = list(getattr(owner, name))
                values[index] = sentinel
                setattr(owner, name, values)
        template = serialize_cdr(msg)
        if template[:2] != b'\x00\x01':
            raise ValueError('expected little-endian CDR')
        self._stamp_at = (
            _find(template, _STAMP.pack(_SENTINEL_SEC, _SENTINEL_NANOSEC)) if stamped else None
        )
        offsets = [_find(template, struct.pack('<d', s)) for s in sentinels]
        # consecutive slots (a sequence's elements, a vector's x y z) are written in one go
        self._runs = []
        start = 0
        for k in range(1, self.size + 1):
            if k == self.size or offsets[k] != offsets[k - 1] + 8:
                self._runs.append((offsets[start], start, k, struct.Struct(f'<{k - start}d')))
                start = k
        self._buffer = bytearray(template)
        self.fill([0.0] * self.size, (0, 0) if stamped else None)

    def fill(self, values: Sequence[float], stamp: tuple[int, int] | None = None) -> bytes:
        """The message with these float64 values and this stamp (sec, nanosec), serialized."""
        buf = self._buffer
        if stamp is not None:
            _STAMP.pack_into(buf, self._stamp_at, *stamp)  # type: ignore[arg-type]  # stamped
        for offset, start, end, packer in self._runs:
            packer.pack_into(buf, offset, *values[start:end])
        self.data = bytes(buf)
        return self.data


def _resolve(msg, path: str):
    """The sub-message at a dotted attribute path ('' for the message itself)."""
    for name in filter(None, path.split('.')):
        msg = getattr(msg, name)
    return msg


def _find(data: bytes, needle: bytes) -> int:
    at = data.find(needle)
    if at < 0 or data.find(needle, at + 1) >= 0:
        raise ValueError('template field not found exactly once in the serialized message')
    return at


# encapsulation header, layout.dim count, layout.data_offset, data count (little-endian CDR)
_PLAIN_ARRAY = struct.Struct('<4xIII')


@_reader
def float64_array_data(raw: bytes) -> list:
    """The ``data`` of a serialized ``std_msgs/Float64MultiArray`` (layout skipped)."""
    if raw[:2] == b'\x00\x01' and len(raw) >= 16:
        # a command without layout dimensions (the usual one): the doubles start at byte 20
        dims, _, n = _PLAIN_ARRAY.unpack_from(raw)
        if dims == 0:
            _ends_at(raw, 20 + 8 * n if n else 16)
            return list(struct.unpack_from(f'<{n}d', raw, 20)) if n else []
    r = CdrReader(raw)
    (dims,) = r.unpack('I', 4)
    for _ in range(dims):  # MultiArrayDimension: label, size, stride
        r.align(4)
        _skip(r, r.unpack('I', 4)[0])
        r.align(4)
        r.unpack('I', 4, 2)
    r.align(4)
    r.unpack('I', 4)  # data_offset
    values = _doubles_at(r)[0]
    _ends_at(raw, r.pos)
    return values


def _ends_at(raw, end: int):
    """A command must be exactly its encoding: serializers and transports pad a payload to
    a multiple of 4 bytes (Fast CDR up to 8, not always with zeros), and any other length
    means bytes were cut or added on the way. (A command cut short by 1-3 bytes comes
    zero-padded back to its length: the driver refuses its subnormal last value.)"""
    if len(raw) < end:
        raise ValueError('CDR message too short for its type')
    extra = len(raw) - end
    if extra > 7 or (extra and len(raw) % 4):
        raise ValueError(f'{extra} bytes after the end of the message')


@_reader
def header_stamp_ns(raw: bytes) -> int:
    """The header stamp [ns] of a stamped message (std_msgs/Header first), read from its
    first bytes without parsing the rest."""
    r = CdrReader(raw)
    sec, nanosec = r.unpack('i', 4)[0], r.unpack('I', 4)[0]
    return sec * 1_000_000_000 + nanosec


def _header(r: CdrReader):
    sec, nanosec = r.unpack('i', 4)[0], r.unpack('I', 4)[0]
    _skip(r, r.unpack('I', 4)[0])  # frame_id
    return sec, nanosec


def _skip(r: CdrReader, length: int):
    """Step over ``length`` bytes that must lie inside the message."""
    if length > len(r.data) - r.pos:
        raise MalformedMessage(
            f'{len(r.data)}-byte payload: a string or sequence of {length} bytes runs past its end'
        )
    r.pos += length


def _strings(r: CdrReader) -> list:
    r.align(4)
    (n,) = r.unpack('I', 4)
    if 4 * n > len(r.data) - r.pos:  # each string takes at least its 4-byte length
        raise MalformedMessage(f'{len(r.data)}-byte payload: {n} strings cannot fit')
    out = []
    for _ in range(n):
        r.align(4)
        (length,) = r.unpack('I', 4)
        start = r.pos
        _skip(r, length)
        out.append(bytes(r.data[start : start + length - 1]).decode() if length else '')
    return out


class _JointStateLayout:
    """Where one publisher's joint states keep their numbers. A driver sends the same frame,
    names and sequence lengths every period, so after the first message only the stamp and
    the doubles need reading: the bytes from the frame up to the first position (the layout)
    and the velocity count are compared instead of parsed (15 us -> 1 us)."""

    __slots__ = ('prefix', 'names', 'position', 'velocity_count_at', 'velocity_count', 'velocity')

    def __init__(self, raw, names, position_at, n_position, velocity_at, n_velocity):
        self.prefix = raw[12:position_at]
        self.names = names
        self.position = (position_at, struct.Struct(f'<{n_position}d'))
        self.velocity_count_at = position_at + 8 * n_position
        self.velocity_count = raw[self.velocity_count_at : self.velocity_count_at + 4]
        self.velocity = (velocity_at, struct.Struct(f'<{n_velocity}d'))

    def matches(self, raw: bytes) -> bool:
        """For a message of the size this layout is kept under."""
        at = self.velocity_count_at
        return raw[12 : self.position[0]] == self.prefix and raw[at : at + 4] == self.velocity_count


_joint_state_layouts: dict[
    int, _JointStateLayout
] = {}  # message size -> _JointStateLayout (a few at most)


@_reader
def joint_state_fields(raw: bytes) -> tuple[int, int, list[str], list[float], list[float]]:
    """``(sec, nanosec, names, position, velocity)`` of a serialized ``sensor_msgs/JointState``."""
    layout = _joint_state_layouts.get(len(raw))
    if layout is not None and raw[:2] == b'\x00\x01' and layout.matches(raw):
        (p_at, p_struct), (v_at, v_struct) = layout.position, layout.velocity
        return (
            *_STAMP.unpack_from(raw, 4),
            list(layout.names),
            list(p_struct.unpack_from(raw, p_at)),
            list(v_struct.unpack_from(raw, v_at)),
        )
    r = CdrReader(raw)
    sec, nanosec = _header(r)
    names = _strings(r)
    position, position_at = _doubles_at(r)
    velocity, velocity_at = _doubles_at(r)
    if r.endian == '<' and position and velocity and len(_joint_state_layouts) < 8:
        _joint_state_layouts[len(raw)] = _JointStateLayout(
            bytes(raw), names, position_at, len(position), velocity_at, len(velocity)
        )
    return sec, nanosec, names, position, velocity


_COUNT = struct.Struct('<I')


@_reader
def joint_state_effort(raw: bytes) -> list[float]:
    """The ``effort`` of a serialized ``sensor_msgs/JointState`` (in the order of its names):
    the torques a driver says act now, read only by a controller that measures its command
    latency from them."""
    layout = _joint_state_layouts.get(len(raw))
    if layout is not None and raw[:2] == b'\x00\x01' and layout.matches(raw):
        # effort is the message's last field: its count right after the velocities, its
        # doubles after the count, aligned to 8 bytes from the CDR origin (byte 4)
        v_at, v_struct = layout.velocity
        count_at = v_at + v_struct.size
        (n,) = _COUNT.unpack_from(raw, count_at)
        at = count_at + 4
        at += (8 - (at - 4) % 8) % 8
        if not n and count_at + 4 == len(raw):
            return []
        if at + 8 * n == len(raw):
            return list(struct.unpack_from(f'<{n}d', raw, at))
    r = CdrReader(raw)
    _header(r)
    _strings(r)
    _doubles_at(r)
    _doubles_at(r)
    return _doubles_at(r)[0]


def _doubles_at(r: CdrReader):
    """A float64 sequence and the offset of its first element."""
    r.align(4)
    (n,) = r.unpack('I', 4)
    if not n:
        return [], r.pos
    r.align(8)
    at = r.pos
    return list(r.unpack('d', 8, n)), at


# little-endian header: sec, nanosec, frame_id's length; then the force's three doubles
_WRENCH_HEADER = struct.Struct('<iII')
_VECTOR = struct.Struct('<3d')


@_reader
def wrench_stamped_fields(raw: bytes) -> tuple[int, int, tuple[float, ...]]:
    """``(sec, nanosec, (fx, fy, fz))`` of a serialized ``geometry_msgs/WrenchStamped``."""
    if raw[:2] == b'\x00\x01' and len(raw) >= 16:
        # the usual message, read at fixed offsets (a third of the cursor's time); anything
        # the offsets do not fit is left to the cursor, which says what is wrong
        sec, nanosec, length = _WRENCH_HEADER.unpack_from(raw, 4)
        at = 16 + length
        at += -(at - 4) % 8
        if length <= len(raw) - 16 and at + 24 <= len(raw):
            return sec, nanosec, _VECTOR.unpack_from(raw, at)
    r = CdrReader(raw)
    sec, nanosec = _header(r)
    r.align(8)
    return sec, nanosec, r.unpack('d', 8, 3)


@_reader
def joint_state_command(raw: bytes, joints: Sequence[str]) -> list[float]:
    """The efforts of a serialized ``sensor_msgs/JointState`` command, in the order of
    ``joints`` (matched by name; position and velocity ignored), as topic_based_ros2_control
    sends them. ValueError names what is wrong: an unknown or repeated joint, a joint left
    out, or efforts that do not match the names one to one."""
    r = CdrReader(raw)
    _header(r)
    names = _strings(r)
    _doubles_at(r)  # position
    _doubles_at(r)  # velocity
    efforts = _doubles_at(r)[0]
    _ends_at(raw, r.pos)
    unknown = [n for n in names if n not in joints]
    if unknown:
        raise ValueError(f'unknown joint name(s) {unknown}: expected {list(joints)}')
    if len(set(names)) != len(names) or len(names) != len(joints):
        raise ValueError(f'joint names {names}: must name each of {list(joints)} once')
    if len(efforts) != len(names):
        raise ValueError(
            f'{len(efforts)} efforts for {len(names)} joints {names}: '
            f'one effort per joint name is required'
        )
    by_name = dict(zip(names, efforts))
    return [by_name[j] for j in joints]
