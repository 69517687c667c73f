"""ROS 2 message types by introspection: classes by name, ``ros2msg`` definitions, CDR bytes.

Everything works from the installed Python message classes (rosidl_generator_py), so any
standard or custom type works and no rclpy context is needed.

``serialize_cdr`` exists because ``rclpy.serialization.serialize_message`` (rmw_fastrtps,
Kilted) returns the *estimated* buffer size with uninitialised trailing and padding bytes;
``rosbags`` rejects such data ("CDR message size mismatch"), and files would not be byte-for-byte
reproducible. This writer emits exactly what a DDS publisher sends (XCDR1 little endian,
8-byte alignment relative to the payload) with zeroed padding.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import struct
import sys
from typing import Any, Optional


def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type`` (also accepts ``pkg/Type``), imported lazily;
    for a type of ``STAND_INS`` whose package is not installed, the stand-in class."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'message type {type_name!r} is not of the form pkg/msg/Type')
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError) as e:
        stand_in = STAND_INS.get('/'.join(parts))
        if stand_in is not None:
            return stand_in()
        raise ValueError(f'message type {type_name!r} is not installed: {e}') from None


def has_type_support(cls) -> bool:
    """Whether rclpy can publish or subscribe ``cls`` (a stand-in class cannot)."""
    return not getattr(cls, 'STAND_IN', False)


_STAND_IN_CLASSES: dict = {}


def _tf_message():
    """tf2_msgs/msg/TFMessage (``geometry_msgs/TransformStamped[] transforms``) for machines
    without tf2_msgs: there is no PyPI wheel of it, yet every recording must store /tf with
    its full definition. Its only field's type comes from the installed geometry_msgs, so
    ``message_definition`` and ``serialize_cdr`` treat it like an installed class; rclpy
    cannot (no type support), which ``has_type_support`` tells."""
    cls = _STAND_IN_CLASSES.get('tf2_msgs/msg/TFMessage')
    if cls is None:
        from rosidl_parser import definition as d

        class TFMessage:
            STAND_IN = True
            __slots__ = ('transforms',)
            SLOT_TYPES = (
                d.UnboundedSequence(d.NamespacedType(['geometry_msgs', 'msg'], 'TransformStamped')),
            )

            @classmethod
            def get_fields_and_field_types(cls) -> dict[str, str]:
                return {'transforms': 'sequence<geometry_msgs/TransformStamped>'}

            def __init__(self, transforms=()):
                self.transforms = list(transforms)

            def __eq__(self, other):
                return type(other) is type(self) and other.transforms == self.transforms

        TFMessage.__module__ = 'tf2_msgs.msg'
        cls = _STAND_IN_CLASSES.setdefault('tf2_msgs/msg/TFMessage', TFMessage)
    return cls


# types every recording needs whose Python package may be missing (builders of stand-ins)
STAND_INS = {'tf2_msgs/msg/TFMessage': _tf_message}


def typestore() -> Any:
    """rosbags' Kilted type store: its CDR (de)serialization, where speed does not matter
    (offline writing, reading files back); the live hot path uses io/wire.py."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_KILTED)
    return _TYPESTORE


_TYPESTORE: Any = None


def type_name_of(msg_or_class: Any) -> str:
    """``pkg/msg/Type`` of a message instance or class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    pkg, sub = cls.__module__.split('.')[:2]
    return f'{pkg}/{sub}/{cls.__name__}'


def _fields(cls) -> list:
    """[(field name, rosidl_parser type)] in wire order (cached on the class)."""
    fields = cls.__dict__.get('_impact_arm_fields')
    if fields is None:
        fields = list(zip(cls.get_fields_and_field_types(), cls.SLOT_TYPES))
        cls._impact_arm_fields = fields
    return fields


# ------------------------------------------------------------------------- definitions
_IDL_TO_MSG = {
    'boolean': 'bool',
    'octet': 'byte',
    'float': 'float32',
    'double': 'float64',
    'long double': 'float64',
    'short': 'int16',
    'unsigned short': 'uint16',
    'long': 'int32',
    'unsigned long': 'uint32',
    'long long': 'int64',
    'unsigned long long': 'uint64',
}


def _msg_type(t, deps: list) -> str:
    """.msg spelling of a rosidl_parser type; nested message types are appended to deps."""
    from rosidl_parser import definition as d

    if isinstance(t, d.Array):
        return f'{_msg_type(t.value_type, deps)}[{t.size}]'
    if isinstance(t, d.BoundedSequence):
        return f'{_msg_type(t.value_type, deps)}[<={t.maximum_size}]'
    if isinstance(t, d.UnboundedSequence):
        return f'{_msg_type(t.value_type, deps)}[]'
    if isinstance(t, (d.BoundedString, d.BoundedWString)):
        return ('wstring' if isinstance(t, d.BoundedWString) else 'string') + f'<={t.maximum_size}'
    if isinstance(t, d.UnboundedString):
        return 'string'
    if isinstance(t, d.UnboundedWString):
        return 'wstring'
    if isinstance(t, d.NamespacedType):
        # ignored: rosidl_parser declares namespaces an Iterable; it is a list
        deps.append('/'.join(t.namespaces + [t.name]))  # type: ignore[operator]
        return f'{t.namespaces[0]}/{t.name}'  # type: ignore[index]
    return _IDL_TO_MSG.get(t.typename, t.typename)


def _literal(v, in_list=False) -> str:
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, bytes):
        return str(v[0]) if len(v) == 1 else str(list(v))
    if isinstance(v, str):
        return json.dumps(v) if in_list or not v or v != v.strip() or '#' in v else v
    if isinstance(v, (list, tuple)) or hasattr(v, 'tolist'):
        return '[' + ', '.join(_literal(x, True) for x in list(v)) + ']'
    return repr(v)


def share_file(type_name: str, ext: str) -> Optional[str]:
    """The installed interface file (``.msg``, ``.json``) of a type, if a prefix has one."""
    pkg, sub, name = type_name.split('/')
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    for prefix in prefixes + [sys.prefix]:
        path = os.path.join(prefix, 'share', pkg, sub, name + ext)
        if os.path.isfile(path):
            return path
    return None


def _constant_type(value, declared: Optional[str]) -> str:
    if declared:
        return declared
    # Introspection keeps constant values, not their types: infer one that holds the value.
    if isinstance(value, bool):
        return 'bool'
    if isinstance(value, bytes):
        return 'byte'
    if isinstance(value, str):
        return 'string'
    if isinstance(value, float):
        return 'float64'
    return 'int32' if -(2**31) <= value < 2**31 else ('int64' if value < 2**63 else 'uint64')


def _own_definition(type_name: str) -> tuple:
    """(text of the type's own constants and fields, names of the nested types it uses)."""
    cls = message_class(type_name)
    meta = type(cls)
    constants = getattr(meta, f'_{meta.__name__}__constants', {})
    declared = {}
    msg_file = share_file(type_name, '.msg') if constants else None
    if msg_file:  # the installed .msg, when there is one, knows each constant's declared type
        with open(msg_file, encoding='utf-8') as f:
            declared = {
                m.group(2): m.group(1)
                for m in re.finditer(r'^\s*([\w/<=\[\]]+)\s+([A-Za-z]\w*)\s*=', f.read(), re.M)
            }
    lines = [
        f'{_constant_type(v, declared.get(k))} {k}={_literal(v)}' for k, v in constants.items()
    ]
    deps: list[str] = []
    for field, slot in _fields(cls):
        line = f'{_msg_type(slot, deps)} {field}'
        default = getattr(cls, field.upper() + '__DEFAULT', None)
        if default is not None:
            line += ' ' + _literal(default)
        lines.append(line)
    return '\n'.join(lines) + ('\n' if lines else ''), deps


_DEFINITIONS: dict = {}


def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` text: the type's own definition, then each nested type once, each after
    a line of 80 ``=`` and ``MSG: pkg/Type`` (the layout rosbag2 writes)."""
    type_name = type_name_of(message_class(type_name))
    if type_name not in _DEFINITIONS:
        text, deps = _own_definition(type_name)
        seen = {type_name}
        stack = list(reversed(deps))
        while stack:  # depth first, like rosbag2, so a reader meets each type near its user
            dep = stack.pop()
            if dep in seen:
                continue
            seen.add(dep)
            dep_text, dep_deps = _own_definition(dep)
            pkg, _, name = dep.split('/')
            text += '=' * 80 + f'\nMSG: {pkg}/{name}\n' + dep_text
            stack.extend(reversed(dep_deps))
        _DEFINITIONS[type_name] = text
    return _DEFINITIONS[type_name]


def type_hash(type_name: str) -> str:
    """RIHS01 type hash from the installed type description (.json); for a stand-in type
    (``STAND_INS``, no .json installed) the hash of its full definition as stored; '' if
    neither is available."""
    path = share_file(type_name, '.json')
    try:
        with open(path, encoding='utf-8') as f:  # type: ignore[arg-type]  # None: TypeError below
            hashes = json.load(f)['type_hashes']
        return next(h['hash_string'] for h in hashes if h['type_name'] == type_name)
    except (TypeError, OSError, ValueError, KeyError, StopIteration):
        pass
    if type_name in STAND_INS:
        return definition_hash(type_name)
    return ''


def definition_hash(type_name: str) -> str:
    """RIHS01 hash of ``message_definition(type_name)``, computed by rosbags as ROS does
    (SHA-256 of the type description, nested types included)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(message_definition(type_name), type_name))
    return store.hash_rihs01(type_name)


# --------------------------------------------------------------------------------- CDR
_FORMATS = {
    'boolean': '?',
    'octet': 'B',
    'char': 'B',
    'uint8': 'B',
    'int8': 'b',
    'int16': 'h',
    'uint16': 'H',
    'int32': 'i',
    'uint32': 'I',
    'int64': 'q',
    'uint64': 'Q',
    'float': 'f',
    'double': 'd',
    'short': 'h',
    'unsigned short': 'H',
    'long': 'i',
    'unsigned long': 'I',
    'long long': 'q',
    'unsigned long long': 'Q',
}
_SIZES = {k: struct.calcsize(v) for k, v in _FORMATS.items()}


def _align(buf: bytearray, n: int):
    pad = -(len(buf) - 4) % n  # alignment counts from the end of the 4-byte encapsulation
    if pad:
        buf += bytes(pad)


def _octets(values, typename) -> list:
    if typename == 'octet':
        return list(b''.join(values)) if values and isinstance(values[0], bytes) else values
    if typename == 'char':
        return [ord(x) if isinstance(x, str) else x for x in values]
    return values


def _write(buf: bytearray, v, t):
    from rosidl_parser import definition as d

    if isinstance(t, d.BasicType):
        name = t.typename
        if name not in _FORMATS:
            raise NotImplementedError(f'CDR of {name}')
        _align(buf, _SIZES[name])
        buf += struct.pack('<' + _FORMATS[name], *_octets([v], name))
    elif isinstance(t, (d.UnboundedString, d.BoundedString)):
        b = v.encode()
        _align(buf, 4)
        buf += struct.pack('<I', len(b) + 1) + b + b'\0'
    elif isinstance(t, d.NamespacedType):
        _write_message(buf, v)
    elif isinstance(t, d.AbstractNestedType):
        n = len(v)
        if isinstance(t, d.AbstractSequence):
            _align(buf, 4)
            buf += struct.pack('<I', n)
        et = t.value_type
        if isinstance(et, d.BasicType) and et.typename in _FORMATS:
            if n:  # an empty sequence adds no alignment (as Fast CDR does)
                _align(buf, _SIZES[et.typename])
                buf += struct.pack(f'<{n}{_FORMATS[et.typename]}', *_octets(v, et.typename))
        else:
            for x in v:
                _write(buf, x, et)
    else:
        raise NotImplementedError(f'CDR of {type(t).__name__}')


def _write_message(buf: bytearray, msg):
    fields = _fields(type(msg))
    if not fields:
        _align(buf, 1)
        buf += b'\0'  # rosidl gives empty messages one uint8 member
    for name, t in fields:
        _write(buf, getattr(msg, name), t)


def serialize_cdr(msg: Any) -> bytes:
    """CDR bytes of a message exactly as DDS carries them (see the module docstring)."""
    buf = bytearray(b'\x00\x01\x00\x00')
    try:
        _write_message(buf, msg)
    except NotImplementedError:  # wide characters: let the middleware do it
        from rclpy.serialization import serialize_message

        return serialize_message(msg)
    return bytes(buf)


def sequence_cdr_prefix(items: list, count: int) -> bytes:
    """The start of the CDR of a message whose only field is a sequence of ``count``
    messages: encapsulation, ``count`` and the first ``items``. ``append_cdr`` adds the
    others; the result is exactly ``serialize_cdr`` of the whole message (alignment counts
    from the payload, so a prefix that does not change can be kept as bytes)."""
    buf = bytearray(b'\x00\x01\x00\x00') + struct.pack('<I', count)
    for item in items:
        _write_message(buf, item)
    return bytes(buf)


def append_cdr(prefix: bytes, msg: Any) -> bytes:
    """``prefix`` (CDR so far, encapsulation included) followed by ``msg``'s CDR."""
    buf = bytearray(prefix)
    _write_message(buf, msg)
    return bytes(buf)
