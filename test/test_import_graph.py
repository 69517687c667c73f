"""No import circles, anywhere: the modules of impact_arm/ and of the benchmarks
(bench/impact_arm_bench/) import one another along a graph without cycles. Every import
counts, at module level or inside a function (an import moved into a function to get past a
circle at load time is still two modules that need each other). A package's ``__init__`` is a
module of its own: ``from .scene.types import Scene`` depends on ``scene.types``, not on what
the package's ``__init__`` gathers."""

import ast
import os

ROOT = os.path.join(os.path.dirname(__file__), '..')
TREES = {'impact_arm': 'impact_arm', 'impact_arm_bench': os.path.join('bench', 'impact_arm_bench')}


def modules() -> dict:
    """Dotted module name -> file, over the trees."""
    found = {}
    for package, folder in TREES.items():
        base = os.path.join(ROOT, folder)
        for here, _, files in os.walk(base):
            for name in files:
                if not name.endswith('.py'):
                    continue
                path = os.path.join(here, name)
                parts = [package, *os.path.relpath(path, base)[:-3].split(os.sep)]
                if parts[-1] == '__init__':
                    parts.pop()
                found['.'.join(parts)] = path
    return found


def _imported(module: str, node: ast.ImportFrom, is_package: bool) -> str:
    if not node.level:
        return node.module or ''
    parts = module.split('.')
    base = parts if is_package else parts[:-1]
    base = base[: len(base) - (node.level - 1)]
    return '.'.join(base + ([node.module] if node.module else []))


def graph(found: dict) -> dict:
    """Module -> the modules of the trees it imports."""
    edges = {}
    for module, path in found.items():
        with open(path, encoding='utf-8') as f:
            tree = ast.parse(f.read(), path)
        is_package = path.endswith('__init__.py')
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                source = _imported(module, node, is_package)
                for alias in node.names:
                    # a submodule imported by name is the dependency; a name is its module's
                    submodule = f'{source}.{alias.name}'
                    targets.add(submodule if submodule in found else source)
        edges[module] = {t for t in targets if t in found and t != module}
    return edges


def circles(edges: dict) -> list:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_no_module_sits_in_an_import_circle():
    edges = graph(modules())
    found = circles(edges)
    described = [
        '; '.join(f'{v} -> {", ".join(sorted(edges[v] & set(c)))}' for v in c) for c in found
    ]
    assert not found, 'import circles:\n' + '\n'.join(described)


def test_the_graph_sees_imports_and_the_check_sees_circles():
    """Not vacuous: local imports, relative imports and submodules by name are edges, and a
    circle is found."""
    edges = graph(modules())
    assert 'impact_arm.physics.scene.types' in edges['impact_arm.physics.model']
    assert 'impact_arm.contract' in edges['impact_arm.io.mcap_ros2']  # from .. import contract
    assert 'impact_arm.tools.run_data' in edges['impact_arm.tools.animation']  # in a function
    assert 'impact_arm_bench.common' in edges['impact_arm_bench.stress']
    assert circles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
    assert circles({'a': {'b'}, 'b': set()}) == []
