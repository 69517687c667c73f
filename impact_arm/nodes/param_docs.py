"""The parameter tables of docs/nodes.md and docs/topics.md and the typed parameter classes
of param_types.py, generated from the nodes' own tables (the ``Param`` declarations the nodes
declare, check and describe with), so neither the documentation nor the types the nodes read
can drift from what the nodes accept.

    python -m impact_arm.nodes.param_docs            # rewrite the tables and param_types.py
    python -m impact_arm.nodes.param_docs --check    # exit 1 if either is out of date

Each table sits between a ``<!-- parameters: NODE ... -->`` line and ``<!-- end of
parameters -->`` in its document; the rest of the document is left as it is.
"""

from __future__ import annotations

import math
import os
import re
import sys

from . import controller_params, recorder_params, replay_params, simulator_params
from .params import Param

END = '<!-- end of parameters -->'
DOCS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(__file__))), 'docs')
TYPES_MODULE = os.path.join(os.path.dirname(__file__), 'param_types.py')
# node -> the class of param_types.py that ``params.declare`` fills for it
CLASS_NAMES = {
    'simulator': 'SimulatorParameters',
    'controller': 'ControllerParameters',
    'recorder': 'RecorderParameters',
    'replay': 'ReplayParameters',
}
# each kind's field type: what ``Param.check`` returns for it (a 'str' with an enum: the enum)
FIELD_TYPES = {
    'float': 'float',
    'int': 'int',
    'str': 'str',
    'bool': 'bool',
    'floats': 'list[float]',
    'strs': 'list[str]',
}


def tables() -> dict[str, tuple[str, tuple[Param, ...]]]:
    """node -> (document, its parameter table); the scene-dependent tables as the article's
    scene makes them (their scene-set defaults are shown in words)."""
    from ..physics.scene import load_scene, resolve_scene_path

    paper = load_scene(resolve_scene_path('paper'))
    return {
        'simulator': ('nodes.md', simulator_params.parameter_table(paper)),
        'controller': ('nodes.md', controller_params.parameter_table(paper)),
        'recorder': ('topics.md', recorder_params.PARAMS),
        'replay': ('topics.md', replay_params.PARAMS),
    }


def _value(value: object) -> str:
    if isinstance(value, bool):
        return '`true`' if value else '`false`'
    if isinstance(value, str):
        return f'`{value}`' if value else '`""`'
    if isinstance(value, float):
        if math.isinf(value):
            return '∞' if value > 0 else '−∞'
        text = f'{value:g}'
        return text if any(c in text for c in '.e') else text + '.0'
    if isinstance(value, (list, tuple)):
        return '`[' + ', '.join(str(v) for v in value) + ']`'
    return str(value)


def markdown_table(table: tuple[Param, ...]) -> str:
    """One row per parameter: name, default, allowed values (and whether ``ros2 param set``
    may change it while the node runs), meaning."""
    rows = ['| parameter | default | allowed | meaning |', '|---|---|---|---|']
    for p in table:
        allowed = p.allowed() + ('; start-up only' if p.read_only else '; settable')
        rows.append(
            f'| `{p.name}` | {p.shown_default or _value(p.default)} | {allowed} | '
            f'{p.description}{p.doc} |'
        )
    return '\n'.join(rows) + '\n'


def _begin(node: str) -> str:
    return (
        f'<!-- parameters: {node} (generated from its table: '
        f'python -m impact_arm.nodes.param_docs) -->'
    )


def rendered(text: str, node: str, table: tuple[Param, ...]) -> str:
    """``text`` with ``node``'s table between its markers replaced by the generated one."""
    begin = _begin(node)
    pattern = re.compile(re.escape(begin) + r'\n.*?' + re.escape(END), re.S)
    if not pattern.search(text):
        raise ValueError(f'no "{begin}" ... "{END}" block for {node}')
    return pattern.sub(lambda _: f'{begin}\n{markdown_table(table)}{END}', text, count=1)


def _field_type(p: Param) -> str:
    return p.enum.__name__ if p.enum is not None else FIELD_TYPES[p.kind]


def _enum_imports(tables: list[tuple[Param, ...]]) -> list[str]:
    """The import lines of the enums the fields are typed with, relative to this package."""
    by_module: dict[str, set[str]] = {}
    for table in tables:
        for p in table:
            if p.enum is not None:
                package, _, module = p.enum.__module__.partition('.')
                if package != 'impact_arm':
                    raise ValueError(f"{p.name}: enum {p.enum!r} is not impact_arm's")
                by_module.setdefault(module, set()).add(p.enum.__name__)
    return [
        f'from ..{module} import {", ".join(sorted(names))}'
        for module, names in sorted(by_module.items())
    ]


TYPES_HEADER = '''\
"""The nodes' parameters as static types: one frozen dataclass per node, a field per
parameter of its table (simulator_params.py, controller_params.py, recorder_params.py,
replay_params.py) typed as ``Param.check`` returns it, which ``params.declare`` fills and the
node reads as ``self.p.publish_rate``; a ``ros2 param set`` makes a new one with ``replace``.
The scene-dependent tables have the same names whatever the scene, so the classes are fixed.

Generated from the tables by ``python -m impact_arm.nodes.param_docs``: edit the tables and
run it again (a test fails while this file differs from its output).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any
'''


def types_module(nodes: dict[str, tuple[str, tuple[Param, ...]]] | None = None) -> str:
    """The text of param_types.py: one frozen dataclass per node's table (``nodes``, else
    ``tables()``), fields in the table's order (the scene-dependent tables as the article's
    scene makes them: the same names for any scene)."""
    nodes = tables() if nodes is None else nodes
    imports = _enum_imports([table for _, table in nodes.values()])
    parts = [TYPES_HEADER, '\n', '\n'.join(imports) + '\n']
    for node, (_, table) in nodes.items():
        name = CLASS_NAMES[node]
        fields = ''.join(f'    {p.name}: {_field_type(p)}\n' for p in table)
        parts.append(
            f'\n\n@dataclass(frozen=True)\nclass {name}:\n'
            f'    """The {node} node\'s parameters, checked."""\n\n{fields}\n'
            f'    def replace(self, **changes: Any) -> {name}:\n'
            f'        """A copy with ``changes`` (checked values by parameter name)."""\n'
            f'        return dataclasses.replace(self, **changes)\n'
        )
    return ''.join(parts)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    check = '--check' in argv
    stale = []
    documents: dict[str, tuple[str, str]] = {}  # path -> (its text, the text generated)
    nodes = tables()
    for node, (document, table) in nodes.items():
        path = os.path.join(DOCS, document)
        if path not in documents:
            with open(path, encoding='utf-8') as f:
                text = f.read()
            documents[path] = (text, text)
        original, current = documents[path]
        documents[path] = (original, rendered(current, node, table))
    try:
        with open(TYPES_MODULE, encoding='utf-8') as f:
            original = f.read()
    except FileNotFoundError:
        original = ''
    documents[TYPES_MODULE] = (original, types_module(nodes))
    for path, (original, new) in documents.items():
        if new != original:
            stale.append(path)
            if not check:
                with open(path, 'w', encoding='utf-8') as f:
                    f.write(new)
                print(f'wrote {path}')
    if check and stale:
        print(f'out of date: {", ".join(stale)} (python -m impact_arm.nodes.param_docs)')
        return 1
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
