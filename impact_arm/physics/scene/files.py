"""Scene files: find, read and parse YAML into plain data as YAML 1.1 and 1.2 agree on it,
and the self-contained text a recording stores."""

from __future__ import annotations

import os
import re
from typing import Any, NoReturn

import yaml

from ..errors import SceneError
from .parse import parse_scene
from .types import Scene

MAX_FILE_BYTES = 1 << 20  # a scene is a few hundred bytes; /dev/zero must not be read whole
MAX_YAML_NODES = 100_000  # after alias expansion: an alias bomb is refused, not expanded


def read_scene_file(name: str | os.PathLike) -> tuple[str, str]:
    """(text, path) of a scene file given by path or installed name; at most
    ``MAX_FILE_BYTES`` are read (``--scene /dev/zero`` is refused at once)."""
    path = str(resolve_scene_path(name))
    try:
        with open(path, 'rb') as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        hint = ''
        if isinstance(exc, FileNotFoundError) and not os.path.dirname(path):
            names = installed_scenes()
            hint = (
                f'; installed scenes: {", ".join(names)} (or give a path to a scene file)'
                if names
                else ''
            )
        raise SceneError(f"scene '{path}': cannot be read: {exc.strerror}{hint}") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"scene '{path}': larger than {MAX_FILE_BYTES} bytes: not a scene file")
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise SceneError(f"scene '{path}': not UTF-8 text (byte {exc.start})") from None
    return text, path


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a scene file; raises ``SceneError`` with a user-facing message."""
    text, path = read_scene_file(path)
    return scene_from_text(text, origin=path, path=path)


class _SceneLoader(yaml.SafeLoader):
    """SafeLoader that reads numbers as YAML 1.2 does, refuses what YAML 1.1 and 1.2 read
    differently, and refuses duplicate keys.

    PyYAML implements YAML 1.1: ``210e9`` would be a string, ``1:30`` the number 90
    (sexagesimal), ``017`` the number 15 (octal), ``on``/``no`` booleans. A scene means one
    thing under either reading or is refused, naming the value."""

    yaml_implicit_resolvers = {
        first: [
            (tag, regexp)
            for tag, regexp in resolvers
            if tag
            not in ('tag:yaml.org,2002:int', 'tag:yaml.org,2002:float', 'tag:yaml.org,2002:bool')
        ]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else None
            if key is not None and key in seen:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f'duplicate key {key[:60]!r} (the file would mean only its last value)',
                    key_node.start_mark,
                )
            seen.add(key)
        return super().construct_mapping(node, deep)

    def construct_ambiguous(self, node: yaml.ScalarNode) -> NoReturn:
        raise yaml.constructor.ConstructorError(
            None,
            None,
            f'{node.value[:60]!r} reads differently in YAML 1.1 and 1.2 '
            f'(sexagesimal, octal, yes/no/on/off, digit separators): write a plain decimal '
            f'number, true/false, or quote it as a string',
            node.start_mark,
        )


_AMBIGUOUS = 'tag:impact_arm,2026:ambiguous'
_SceneLoader.add_constructor(_AMBIGUOUS, _SceneLoader.construct_ambiguous)
for _tag, _pattern, _first in (
    (
        _AMBIGUOUS,
        r'^(?:[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?'
        r'|[-+]?0[0-9_]+|[-+]?0b[01_]+|[-+]?[0-9][0-9_]*_[0-9_]*(?:\.[0-9_]*)?'
        r'|yes|Yes|YES|no|No|NO|on|On|ON|off|Off|OFF|y|Y|n|N)$',
        list('-+0123456789yYnNoO'),
    ),
    ('tag:yaml.org,2002:bool', r'^(?:true|True|TRUE|false|False|FALSE)$', list('tTfF')),
    (
        'tag:yaml.org,2002:int',
        r'^(?:[-+]?(?:0|[1-9][0-9]*)|0x[0-9a-fA-F]+|0o[0-7]+)$',
        list('-+0123456789'),
    ),
    (
        'tag:yaml.org,2002:float',
        r'^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?'
        r'|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$',
        list('-+0123456789.'),
    ),
):
    _SceneLoader.add_implicit_resolver(_tag, re.compile(_pattern), _first)


def _construct_int(loader, node):
    """YAML 1.2 integers: decimal, 0x hex, 0o octal (PyYAML's reader would take 0o as text)."""
    value = node.value
    if value.startswith('0x'):
        return int(value[2:], 16)
    if value.startswith('0o'):
        return int(value[2:], 8)
    return int(value)


_SceneLoader.add_constructor('tag:yaml.org,2002:int', _construct_int)


def _expanded_size(node, sizes) -> int:
    """Nodes the document becomes once aliases are expanded (shared nodes counted each time)."""
    key = id(node)
    if key not in sizes:
        sizes[key] = 0  # a recursive alias counts as one node here; it is refused later
        if isinstance(node, yaml.SequenceNode):
            total = 1 + sum(_expanded_size(child, sizes) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            total = 1 + sum(
                _expanded_size(k, sizes) + _expanded_size(v, sizes) for k, v in node.value
            )
        else:
            total = 1
        sizes[key] = min(total, MAX_YAML_NODES + 1)
    return sizes[key]


def _near_key(text: str, line: int) -> str:
    """The key being written at (or just before) a 0-based line, for the one-line message."""
    lines = text.splitlines()
    for k in range(min(line, len(lines) - 1), -1, -1):
        m = re.match(r'\s*(?:-\s*)?\{?\s*([A-Za-z_][\w]*)\s*:', lines[k])
        if m:
            return f", near key '{m.group(1)}'"
    return ''


def scene_data(text: str, origin: str = '<scene>', what: str = 'scene') -> Any:
    """The scene's YAML as plain data, not yet validated (studies change values in it), or
    ``SceneError`` in one line with line, column and key. Also reads sweep specs (``what``)."""
    loader = None
    try:
        # the reader checks the characters as it is built: a NUL byte fails here already
        loader = _SceneLoader(text)
        node = loader.get_single_node()
        if node is not None and _expanded_size(node, {}) > MAX_YAML_NODES:
            raise SceneError(
                f"{what} '{origin}': more than {MAX_YAML_NODES} YAML nodes once "
                f'aliases are expanded: not a scene file'
            )
        return loader.construct_document(node) if node is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = (
            (f' at line {mark.line + 1}, column {mark.column + 1}{_near_key(text, mark.line)}')
            if mark
            else ''
        )
        problem = ' '.join(str(exc.problem or exc.context or 'unreadable').split())
        raise SceneError(f"{what} '{origin}': not valid YAML{where}: {problem[:200]}") from None
    except (yaml.YAMLError, RecursionError, ValueError) as exc:
        problem = ' '.join(str(exc).split()) or type(exc).__name__
        raise SceneError(f"{what} '{origin}': not valid YAML: {problem[:200]}") from None
    finally:
        if loader is not None:
            loader.dispose()


def scene_from_text(text: str, origin: str = '<scene>', path: str = '') -> Scene:
    return parse_scene(scene_data(text, origin), origin=origin, text=text, path=path)


def resolve_scene_path(name: str | os.PathLike) -> str:
    """Accept a path, or a bare scene name ('paper') found in the installed config directory."""
    name = os.fspath(name)
    if os.path.exists(name):
        return name
    for directory in config_dirs():
        for candidate in (name, name + '.yaml'):
            full = os.path.join(directory, candidate)
            if os.path.exists(full):
                return full
    return name  # load_scene reports it as unreadable


def installed_scenes() -> list[str]:
    """Names of the scene files in the installed config directories (the node parameter
    files there are not scenes: a scene has a top-level ``links:`` or ``arm:``)."""
    names = set()
    for directory in config_dirs():
        for entry in os.listdir(directory):
            if not entry.endswith('.yaml'):
                continue
            try:
                with open(os.path.join(directory, entry), encoding='utf-8') as f:
                    if any(line.startswith(('links:', 'arm:')) for line in f):
                        names.add(entry[: -len('.yaml')])
            except (OSError, UnicodeDecodeError):
                continue
    return sorted(names)


def config_dirs() -> list[str]:
    """Where scene files live: the source tree, the install prefix, the ament share dir."""
    import sys

    here = os.path.dirname(os.path.abspath(__file__))
    dirs = [
        os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(here))), 'config'),
        os.path.join(sys.prefix, 'share', 'impact_arm', 'config'),
    ]
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(os.path.join(get_package_share_directory('impact_arm'), 'config'))
    except Exception:  # no ament index (plain venv): the other places suffice
        pass
    return [d for d in dirs if os.path.isdir(d)]


def self_contained_text(scene: Scene) -> str:
    """The scene's YAML text as a recording stores it: unchanged, but for an arm read from
    a URDF file, whose text it carries as ``arm.description`` instead of the file's path, so
    that the recording's scene loads wherever the file is not."""
    if not scene.urdf_path or not scene.source_text:
        return scene.source_text
    data = scene_data(scene.source_text, scene.source_path or scene.name)
    arm = {
        k: v for k, v in data['arm'].items() if k not in ('urdf', 'xacro', 'args', 'package_paths')
    }
    arm['description'] = scene.urdf_text
    data['arm'] = arm
    header = (
        f'# {scene.name}: the arm of {scene.urdf_path} inlined as arm.description (docs/scene.md)\n'
    )
    return header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
