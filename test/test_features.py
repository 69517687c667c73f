"""Model only what a scene requires: surfaces, laws, friction, gravity, integral
states decide what the generated module contains, and the kernel keeps every piece of contact,
friction and integral code behind the compile-time constants that remove it."""

import ast
import inspect
import os
import re

import pytest

from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.kernel import template_source
from impact_arm.physics.model import ArmModel

from scenes import scene_from

HERTZ_FLOOR = [{'height': -1.0, 'law': 'hertz', 'mu': 0.0, 'material': 'steel'}]


def shape(scene):
    eq = ArmModel(scene).eq
    return eq.N, eq.HAS_CONTACT, eq.HAS_FRICTION, eq.NI


@pytest.mark.parametrize(
    'name, scene, expected',
    [
        ('article', lambda: scene_from(), (2, True, True, 0)),
        (
            'no surface',
            lambda: scene_from({('controller', 'law'): 'none'}, surfaces=[]),
            (2, False, False, 0),
        ),
        (
            'surface with law none',
            lambda: scene_from(
                {('controller', 'law'): 'none'},
                surfaces=[{'height': -1.0, 'law': 'none', 'mu': 0.5, 'material': 'steel'}],
            ),
            (2, False, False, 0),
        ),
        (
            'frictionless Hertz',
            lambda: scene_from({('controller', 'law'): 'none'}, gravity=0.0, surfaces=HERTZ_FLOOR),
            (2, True, False, 0),
        ),
        (
            'continuous PID',
            lambda: scene_from({('controller', 'law'): 'pid'}, surfaces=[]),
            (2, False, False, 2),
        ),
        (
            'sampled PID',
            lambda: scene_from(
                {('controller', 'law'): 'pid', ('controller', 'rate'): 1e3}, surfaces=[]
            ),
            (2, False, False, 0),
        ),
        (
            'PD',
            lambda: scene_from({('controller', 'law'): 'pd'}, surfaces=[]),
            (2, False, False, 0),
        ),
    ],
)
def test_generated_module_holds_only_what_the_scene_uses(name, scene, expected):
    assert shape(scene()) == expected, name


def test_state_has_integral_states_only_with_a_continuous_pid():
    assert ArmModel(scene_from({('controller', 'law'): 'pid'}, surfaces=[])).size == 6
    assert ArmModel(scene_from({('controller', 'law'): 'pd'}, surfaces=[])).size == 4


def test_gravity_off_removes_gravity_from_the_equations():
    def body(scene):
        source = inspect.getsource(
            ArmModel(scene).eq.accel.py_func
            if hasattr(ArmModel(scene).eq.accel, 'py_func')
            else ArmModel(scene).eq.accel
        )
        return source.split(':', 1)[1]  # after the signature, which names g

    free = {('controller', 'law'): 'none'}
    with_g = body(scene_from(free, surfaces=[]))
    without = body(scene_from(free, surfaces=[], gravity=0.0))
    assert re.search(r'\bg\b', with_g.split('\n', 1)[1])
    assert not re.search(r'\bg\b', without.split('\n', 1)[1])


GUARDED = {
    'contact_forces': 'HAS_CONTACT',
    'tip_jacobian': 'HAS_CONTACT',
    'record_point': 'HAS_CONTACT',
    'friction_force': 'HAS_FRICTION',
}


def test_contact_friction_and_integral_code_sits_behind_compile_time_constants():
    """numba prunes `if HAS_CONTACT:` etc. when the constant is False, so the hot functions
    (rhs, the free-flight part of the step loop) of a scene without surfaces contain no contact
    test, without friction no friction term, without PID no integral states."""
    source = template_source()
    tree = ast.parse(source)
    functions = {f.name: f for f in tree.body if isinstance(f, ast.FunctionDef)}

    def guarded_calls(func):
        found = []

        def visit(node, guards):
            if isinstance(node, ast.If):
                names = {n.id for n in ast.walk(node.test) if isinstance(n, ast.Name)}
                for child in node.body:
                    visit(child, guards | names)
                for child in node.orelse:
                    visit(child, guards)
                return
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                found.append((node.func.id, guards))
            for child in ast.iter_child_nodes(node):
                visit(child, guards)

        visit(func, frozenset())
        return found

    checked = 0
    for fname in ('rhs', 'contact_forces', 'control_torque'):
        for callee, guards in guarded_calls(functions[fname]):
            if callee in GUARDED and fname != 'contact_forces':
                assert GUARDED[callee] in guards, (fname, callee)
                checked += 1
            if callee == 'friction_force':
                assert 'HAS_FRICTION' in guards
                checked += 1
    # the step loop: per-step contact bookkeeping only under HAS_CONTACT
    loop_calls = [
        (c, g) for c, g in guarded_calls(functions['stepping_loop']) if c == 'record_point'
    ]
    assert any('HAS_CONTACT' in g for c, g in loop_calls)
    assert checked >= 3
    rhs_src = ast.get_source_segment(source, functions['rhs'])
    assert 'if NI > 0' in rhs_src


def test_several_surfaces_each_with_its_own_law():
    """A Hertz shelf at -0.8 m above the article's floor: the arm strikes the shelf (elastic,
    no dent), never the floor below it; a `none` surface is not there at all."""
    scene = scene_from(
        cycles=2,
        surfaces=[
            {'height': -0.5, 'law': 'none', 'material': 'steel'},
            {'height': -0.8, 'law': 'hertz', 'mu': 0.2, 'material': 'steel'},
            {'height': -1.0, 'law': 'elastoplastic', 'mu': 0.2, 'material': 'steel'},
        ],
    )
    model = ArmModel(scene)
    assert [s.height for s in model.surfaces] == [-0.8, -1.0]
    integ = PhaseIntegrator(model)
    kinds, surfaces = [], set()
    while kinds.count('switch') < 2:
        for event in integ.advance(scene.t_max, stop_at_event=True):
            kinds.append(event.kind)
            if event.kind == 'contact':
                surfaces.add(event.surface)
            if event.kind == 'max_compression':
                assert event.info['delta_r'] == 0.0  # Hertz: elastic, no dent
    assert surfaces == {0}
    assert 'yield' not in kinds and kinds.count('separation') >= 2


def test_kernel_parts_name_only_what_their_imports_declare():
    """Each template part, imported on its own, resolves every global it uses (from layout,
    the ``injected`` stub or a sibling part): the stub and the parts' linter imports keep up
    with the generator."""
    import builtins
    import importlib
    import symtable

    from impact_arm.physics.kernel import MARKER, PARTS

    missing = []
    for name in PARTS:
        module = importlib.import_module(f'impact_arm.physics.kernel.{name}')
        source = open(module.__file__, encoding='utf-8').read()
        assert MARKER in source
        for func in symtable.symtable(source, module.__file__, 'exec').get_children():
            missing += [
                f'{name}.{func.get_name()}: {s.get_name()}'
                for s in func.get_symbols()
                if s.is_global()
                and s.is_referenced()
                and not hasattr(module, s.get_name())
                and not hasattr(builtins, s.get_name())
            ]
    assert missing == []
