"""The habits the repository keeps, as tests: lint clean (ruff), the typed modules type-check
(mypy, over every package's modules), every public function of physics/, driver/,
calibration/, export/, io/, nodes/ and api/ annotated, and imports point down the layers
physics -> driver, calibration, export (side by side) -> io -> nodes, api (side by side) ->
tools, with contract.py at the bottom importing nothing of the package. The top-level package
is the API's face (``import impact_arm as ia``): it sits in the api layer, so the core never
imports its names, and it may import nothing but the api package."""

import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, 'impact_arm')
LAYERS = {
    'contract': 0,
    'physics': 1,
    'driver': 2,
    'calibration': 2,
    'export': 2,
    'io': 3,
    'nodes': 4,
    'api': 4,
    'tools': 5,
}
TYPED = ('physics', 'driver', 'calibration', 'export', 'io', 'nodes', 'api')
# the packages mypy checks every module of: the typed ones, and the command line, whose bodies
# are checked though not every function states its types
TYPE_CHECKED = TYPED + ('tools',)


def _tool(module, *args):
    pytest.importorskip(
        module, reason=f'{module} not installed: pip install -r requirements-dev.txt'
    )
    return subprocess.run(
        [sys.executable, '-m', module, *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_ruff_finds_nothing():
    out = _tool('ruff', 'check', 'impact_arm', 'test', 'bench', 'launch')
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_tree_is_formatted():
    out = _tool('ruff', 'format', '--check', 'impact_arm', 'test', 'bench', 'launch')
    assert out.returncode == 0, out.stdout + out.stderr


def test_typed_modules_type_check():
    out = _tool('mypy', '--config-file', 'mypy.ini')
    assert out.returncode == 0, out.stdout + out.stderr


def unannotated(source):
    """Public functions and methods (nested ones too) of ``source`` missing a parameter or
    return annotation, as (line, name)."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith(
            '_'
        ):
            args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
            args += [a for a in (node.args.vararg, node.args.kwarg) if a is not None]
            params = [a for a in args if a.arg not in ('self', 'cls')]
            if node.returns is None or any(a.annotation is None for a in params):
                yield node.lineno, node.name


def _typed_modules(packages=TYPED):
    """The modules of ``packages`` but the numba kernel template (its functions are source
    text compiled per arm shape), as (path relative to the package, path)."""
    for path, parts in _modules():
        rel = os.path.relpath(path, PACKAGE).replace(os.sep, '/')
        if parts[1:2] and parts[1] in packages and not rel.startswith('physics/kernel/'):
            yield rel, path


def test_public_functions_of_typed_packages_are_annotated():
    """Every public function of the typed packages states its parameter and return types, so
    that mypy checks its callers and its body."""
    missing = [
        f'{rel}:{line} {name}'
        for rel, path in _typed_modules()
        for line, name in unannotated(open(path, encoding='utf-8').read())
    ]
    assert not missing, missing


def test_typed_modules_are_type_checked():
    """Each module of the type-checked packages is among mypy.ini's files (a new one too)."""
    config = open(os.path.join(ROOT, 'mypy.ini'), encoding='utf-8').read()
    files = config.split('files =')[1].split('\nignore_missing_imports')[0]
    checked = {f.strip() for f in files.split(',')}
    absent = [
        rel
        for rel, _ in _typed_modules(TYPE_CHECKED)
        if not rel.endswith('__init__.py') and f'impact_arm/{rel}' not in checked
    ]
    assert not absent, f'add to mypy.ini files: {absent}'


def test_the_annotation_check_sees_a_missing_annotation():
    """The check above cannot pass by seeing nothing."""
    source = (
        'def f(x: int) -> int: ...\n'
        'def g(x, y: int) -> int: ...\n'
        'def h(x: int): ...\n'
        'def _private(x): ...\n'
        'class C:\n'
        '    def m(self, *args) -> None: ...\n'
        '    def n(self, **kw: int) -> None:\n'
        '        def inner(y): ...\n'
    )
    assert [name for _, name in unannotated(source)] == ['g', 'h', 'm', 'inner']


def _modules():
    for folder, _, files in os.walk(PACKAGE):
        for name in files:
            if name.endswith('.py'):
                path = os.path.join(folder, name)
                parts = os.path.relpath(path, ROOT)[:-3].split(os.sep)
                yield path, parts[:-1] if parts[-1] == '__init__' else parts


def imported(path, parts):
    """The package modules ``path`` (module ``parts``) imports, anywhere in it, as parts."""
    package = parts if path.endswith('__init__.py') else parts[:-1]
    for node in ast.walk(ast.parse(open(path, encoding='utf-8').read(), path)):
        if isinstance(node, ast.Import):
            names = [alias.name.split('.') for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = (package[: len(package) - node.level + 1] if node.level else []) + (
                node.module.split('.') if node.module else []
            )
            names = [base + [alias.name] for alias in node.names] if not node.module else [base]
        else:
            continue
        yield from (n for n in names if n[0] == 'impact_arm')


def _top_level_names():
    """The names the top-level package offers (its ``__all__``), read from its source."""
    tree = ast.parse(open(os.path.join(PACKAGE, '__init__.py'), encoding='utf-8').read())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == '__all__' for t in node.targets
        ):
            return set(ast.literal_eval(node.value))
    return set()


TOP_LEVEL_NAMES = _top_level_names()


def layer(parts):
    """The layer of a module of the package, or of what an import names in it: the top-level
    package and the API names it offers are the api layer's."""
    if parts == ['impact_arm'] or (len(parts) > 1 and parts[1] in TOP_LEVEL_NAMES):
        return LAYERS['api']
    return LAYERS.get(parts[1]) if len(parts) > 1 else None


def _package(parts):
    """The layer's package a module or an import belongs to ('api' for the top level)."""
    return 'api' if layer(parts) == LAYERS['api'] and parts[1:2] != ['nodes'] else parts[1]


def test_imports_point_down_the_layers_only():
    upward = []
    for path, parts in _modules():
        own = layer(parts)
        for target in imported(path, parts):
            theirs = layer(target)
            side_by_side = theirs == own and _package(target) != _package(parts)
            if own is not None and theirs is not None and (theirs > own or side_by_side):
                upward.append(f'{".".join(parts)} imports {".".join(target)}')
    assert not upward, upward


def test_contract_imports_nothing_of_the_package():
    path = os.path.join(PACKAGE, 'contract.py')
    assert list(imported(path, ['impact_arm', 'contract'])) == []


def test_the_layer_check_sees_an_upward_import(tmp_path):
    """The checks above cannot pass by seeing nothing."""
    module = tmp_path / 'bad.py'
    module.write_text('from ..nodes import simulator\nfrom .. import contract\n')
    found = list(imported(str(module), ['impact_arm', 'physics', 'bad']))
    assert found == [['impact_arm', 'nodes'], ['impact_arm', 'contract']]
    assert layer(found[0]) > layer(['impact_arm', 'physics', 'bad']) > layer(found[1])


def test_the_layer_check_sees_a_sibling_import(tmp_path):
    """driver and calibration sit side by side: neither may import the other."""
    module = tmp_path / 'bad.py'
    module.write_text('from ..calibration import fit\n')
    (target,) = imported(str(module), ['impact_arm', 'driver', 'bad'])
    assert layer(target) == layer(['impact_arm', 'driver', 'bad']) and target[1] != 'driver'


def test_the_top_level_imports_only_the_api():
    """``import impact_arm`` offers the API and nothing else of the package: what it imports
    (lazily, on first use) is the api package."""
    path = os.path.join(PACKAGE, '__init__.py')
    targets = {'.'.join(t[:2]) for t in imported(path, ['impact_arm'])}
    assert targets == {'impact_arm.api'}, targets


def test_the_layer_check_sees_the_core_import_the_api(tmp_path):
    """The core must not import the API (by its package or the names the top level offers),
    nor the API the command line."""
    module = tmp_path / 'bad.py'
    module.write_text('from .. import simulate\nfrom ..api import fit\nimport impact_arm\n')
    found = list(imported(str(module), ['impact_arm', 'physics', 'bad']))
    assert [t[:2] for t in found] == [
        ['impact_arm', 'simulate'],
        ['impact_arm', 'api'],
        ['impact_arm'],
    ]
    assert all(layer(t) > layer(['impact_arm', 'physics', 'bad']) for t in found)
    module.write_text('from ..tools import cli\n')
    (target,) = imported(str(module), ['impact_arm', 'api', 'bad'])
    assert layer(target) > layer(['impact_arm', 'api', 'bad'])


def test_the_api_and_the_nodes_sit_side_by_side(tmp_path):
    """The nodes do not import the API (the API has no ROS), nor the API the nodes."""
    module = tmp_path / 'bad.py'
    module.write_text('from ..nodes import simulator\n')
    (target,) = imported(str(module), ['impact_arm', 'api', 'bad'])
    assert layer(target) == layer(['impact_arm', 'api', 'bad'])
    assert _package(target) != _package(['impact_arm', 'api', 'bad'])


TESTS = os.path.join(ROOT, 'test')
# test folders that mirror no package: whole workflows, shared helpers, test data
NOT_A_PACKAGE = {'integration', 'support', 'data'}


def imports_of_test_modules(folder=TESTS):
    """(importer, imported) for every test module that imports another test module."""
    found = []
    for base, dirs, files in os.walk(folder):
        dirs[:] = [d for d in dirs if d not in ('data', '__pycache__')]
        for name in files:
            if not (name.startswith('test_') and name.endswith('.py')):
                continue
            path = os.path.join(base, name)
            with open(path, encoding='utf-8') as f:
                tree = ast.parse(f.read(), path)
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and (node.module or '').startswith('test_'):
                    found.append((os.path.relpath(path, folder), node.module))
                elif isinstance(node, ast.Import):
                    found += [
                        (os.path.relpath(path, folder), a.name)
                        for a in node.names
                        if a.name.startswith('test_')
                    ]
    return found


def test_no_test_module_imports_another():
    """What two test modules share lives in test/support: a test module imported by another
    is found only when pytest happened to collect its folder first."""
    assert not imports_of_test_modules()


def test_the_import_check_sees_a_test_importing_a_test(tmp_path):
    (tmp_path / 'physics').mkdir()
    (tmp_path / 'physics' / 'test_a.py').write_text('from test_b import helper\n')
    assert imports_of_test_modules(str(tmp_path)) == [
        (os.path.join('physics', 'test_a.py'), 'test_b')
    ]


def test_test_folders_mirror_the_package():
    """Each test folder is named after the package it tests (or is one of NOT_A_PACKAGE), and
    every test module sits in a folder but the repository-wide ones and the contract's."""
    packages = {d for d in os.listdir(PACKAGE) if os.path.isdir(os.path.join(PACKAGE, d))}
    folders = {d for d in os.listdir(TESTS) if os.path.isdir(os.path.join(TESTS, d))}
    folders.discard('__pycache__')
    assert not folders - packages - NOT_A_PACKAGE
    for base, dirs, _ in os.walk(TESTS):
        rel = os.path.relpath(base, TESTS)
        if rel == '.' or rel.split(os.sep)[0] in NOT_A_PACKAGE:
            continue
        dirs[:] = [d for d in dirs if d != '__pycache__']
        assert os.path.isdir(os.path.join(PACKAGE, rel)), f'test/{rel} mirrors no package'
    top = sorted(f for f in os.listdir(TESTS) if f.startswith('test_') and f.endswith('.py'))
    assert top == [
        'test_contract.py',
        'test_dependencies.py',
        'test_import_graph.py',
        'test_license.py',
        'test_lint.py',
    ]
