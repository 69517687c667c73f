"""Parameter values never make a new kernel: gravity 0, a scene without surfaces, a surface
of law none and μ = 0 run on the compiled module of their arm's shape, and the physics those
values switch off is still off (no gravity torque, no friction force)."""

import numpy as np
import pytest

from impact_arm.physics import layout
from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel

from scenes import scene_from

HERTZ_FLOOR = [{'height': -1.0, 'law': 'hertz', 'mu': 0.0, 'material': 'steel'}]
UNCONTROLLED = {('controller', 'law'): 'none'}


@pytest.mark.parametrize(
    'name, scene',
    [
        ('no surface', lambda: scene_from(UNCONTROLLED, surfaces=[])),
        (
            'surface with law none',
            lambda: scene_from(
                UNCONTROLLED,
                surfaces=[{'height': -1.0, 'law': 'none', 'mu': 0.5, 'material': 'steel'}],
            ),
        ),
        ('frictionless Hertz', lambda: scene_from(UNCONTROLLED, surfaces=HERTZ_FLOOR)),
        ('gravity 0', lambda: scene_from(UNCONTROLLED, gravity=0.0)),
        ('gravity 0, μ 0, no surface', lambda: scene_from(UNCONTROLLED, gravity=0.0, surfaces=[])),
        (
            'sampled PID',
            lambda: scene_from(
                {('controller', 'law'): 'pid', ('controller', 'rate'): 1e3}, surfaces=[]
            ),
        ),
        ('PD', lambda: scene_from({('controller', 'law'): 'pd'}, surfaces=[])),
        ('continuous PID (integral states)', lambda: scene_from({('controller', 'law'): 'pid'})),
    ],
)
def test_parameter_values_share_the_kernel_of_their_arm_shape(name, scene):
    assert ArmModel(scene()).eq is ArmModel(scene_from()).eq, name


def test_state_has_integral_states_only_with_a_continuous_pid():
    assert ArmModel(scene_from({('controller', 'law'): 'pid'}, surfaces=[])).size == 6
    assert ArmModel(scene_from({('controller', 'law'): 'pd'}, surfaces=[])).size == 4


def test_gravity_0_gives_no_gravity_torque():
    q = np.array([0.3, -1.1])
    weightless = ArmModel(scene_from(UNCONTROLLED, gravity=0.0))
    assert np.all(np.asarray(weightless.gravity_forces(q)) == 0.0)
    assert np.all(weightless.free_forces(q, np.zeros(2)) == 0.0)  # at rest: no force at all
    assert weightless.potential_energy(q) == 0.0
    heavy = ArmModel(scene_from(UNCONTROLLED))
    assert np.all(np.abs(heavy.gravity_forces(q)) > 1.0)  # the same kernel, g = 9.81


def test_weightless_arm_at_rest_stays_at_rest():
    scene = scene_from(
        UNCONTROLLED, gravity=0.0, surfaces=[], initial={'q_deg': [40, -20], 'qd': [0.0, 0.0]}
    )
    model = ArmModel(scene)
    integ = PhaseIntegrator(model)
    q0 = integ.state.y[:2].copy()
    list(integ.advance(1.0))
    assert integ.state.t == pytest.approx(1.0)
    np.testing.assert_array_equal(integ.state.y[:2], q0)
    np.testing.assert_array_equal(integ.state.y[2:4], 0.0)


@pytest.mark.parametrize('mu, has_friction', [(0.0, False), (0.3, True)])
def test_mu_0_gives_no_friction_force(mu, has_friction):
    """The tip pressed 1 µm into a Hertz floor while sliding along it: a normal force, and a
    tangential one exactly when μ > 0."""
    floor = [{'height': -1.0, 'law': 'hertz', 'mu': mu, 'material': 'steel'}]
    model = ArmModel(scene_from(UNCONTROLLED, surfaces=floor))
    state = model.initial_state()
    q = np.array([-1.2, -1.9])
    tip_y = model.tip(q, np.zeros(2))[1]
    state.y[:2] = q
    state.y[2:4] = (1.0, 1.0)  # sliding
    state.levels[:] = tip_y + 1e-6
    state.c[layout.C_PHASE], state.c[layout.C_SURF] = layout.ELASTIC, 0
    P = model.parameters(1e-9, 1e-12, 1e-3)
    delta, fn, ff, _, _ = model.eq.contact_forces(
        state.y, P, model.surface_table, state.c, state.levels
    )
    assert delta == pytest.approx(1e-6, rel=1e-6) and fn > 0.0
    assert (ff != 0.0) == has_friction
    if has_friction:
        assert abs(ff) <= mu * fn * (1 + 1e-12)


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
