"""The parameter tables of docs/nodes.md and docs/topics.md, generated from the nodes' own
tables (the ``Param`` declarations the nodes declare, check and describe with), so the
documentation cannot drift from what the nodes accept.

    python -m impact_arm.nodes.param_docs            # rewrite the tables in docs/
    python -m impact_arm.nodes.param_docs --check    # exit 1 if a table is out of date

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


def tables() -> dict:
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


def _value(value) -> str:
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


def markdown_table(table) -> str:
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


def _begin(node) -> str:
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


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    check = '--check' in argv
    stale = []
    documents: dict = {}
    for node, (document, table) in tables().items():
        path = os.path.join(DOCS, document)
        if path not in documents:
            with open(path, encoding='utf-8') as f:
                documents[path] = (f.read(), None)
        original, current = documents[path]
        documents[path] = (original, rendered(current or original, node, table))
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
