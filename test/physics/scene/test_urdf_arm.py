"""The arm from its URDF (scene key ``arm``): read into the scene, checked against Pinocchio
(which reads the same file itself), written back by ``robot_description`` and read again,
and refused, naming the joint and why, when it is not a planar chain the model can be."""

import copy
import xml.etree.ElementTree as ET
import math
import os
import re
import tempfile
import time

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.contract import to_joint_space
from impact_arm.io.urdf import robot_description
from impact_arm.physics.errors import SceneError
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import parse_scene
from scenes import paper_dict
from urdf_arms import load, random_urdf, scene_data
from repo_paths import EXAMPLES


@pytest.mark.parametrize('n', [2, 3, 4, 6])
def test_mass_matrix_and_bias_match_pinocchio_on_the_same_urdf(tmp_path, n):
    """Pinocchio builds the arm from the same file (its own parser and algorithms, gravity
    -9.81 along the world's -z): CRBA's mass matrix and RNEA at zero acceleration (velocity
    terms and gravity) in relative joint angles θ against the generated equations in
    absolute angles q = T θ: M_θ = Tᵀ M_q T and RNEA = −Tᵀ (Q_g − b)."""
    pin = pytest.importorskip('pinocchio')
    rng = np.random.default_rng(40 + n)
    text, lengths, tip = random_urdf(rng, n)
    scene = load(tmp_path, text, n)
    assert scene.general_links and scene.n_links == n
    assert scene.lengths[:-1] == pytest.approx(lengths[:-1], rel=1e-15)
    assert scene.contact_point == pytest.approx(tip, rel=1e-15)
    arm = ArmModel(scene)
    model = pin.buildModelFromXML(text)
    data = model.createData()
    T = np.tril(np.ones((n, n)))
    for _ in range(10):
        q, qd = rng.uniform(-math.pi, math.pi, n), rng.uniform(-3, 3, n)
        theta, theta_d = np.linalg.solve(T, q), np.linalg.solve(T, qd)
        # continuous joints are (cos, sin) pairs in Pinocchio's configuration
        config = np.concatenate(
            [[a] if k % 2 else [math.cos(a), math.sin(a)] for k, a in enumerate(theta)]
        )
        M = pin.crba(model, data, config)
        M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper half
        want = T.T @ arm.mass_matrix(q) @ T
        assert np.max(np.abs(M - want)) <= 1e-12 * np.max(np.abs(want))
        bias = pin.rnea(model, data, config, theta_d, np.zeros(n))
        want = -T.T @ arm.free_forces(q, qd)
        assert np.max(np.abs(bias - want)) <= 1e-12 * np.max(np.abs(want))
        # the contact point: Pinocchio's frame 'tool' in the world's x-z plane
        pin.framesForwardKinematics(model, data, config)
        tool = data.oMf[model.getFrameId('tool')].translation
        x, y = arm.tip(q, qd)[:2]
        base = data.oMf[model.getFrameId('base')].translation  # the model's origin O
        assert tool - base == pytest.approx([x, 0.0, y], abs=1e-12)


def test_joints_keep_limits_and_dynamics_and_the_urdf_names(tmp_path):
    text, _, _ = random_urdf(np.random.default_rng(1), 3)
    scene = load(tmp_path, text, 3)
    assert [j.name for j in scene.joints] == ['j0', 'j1', 'j2']
    assert scene.link_names == ('l0', 'l1', 'l2')
    assert scene.joints[0].lower is None and scene.joints[0].upper is None  # continuous
    assert (scene.joints[1].lower, scene.joints[1].upper) == (-2.5, 2.0)
    assert (scene.joints[1].effort, scene.joints[1].velocity) == (40.0, 6.0)
    assert [j.damping for j in scene.joints] == [0.0, 0.1, 0.2]
    assert [j.friction for j in scene.joints] == [0.0, 0.05, 0.1]
    assert scene.tip_radius == 0.006  # the tool's collision sphere


def general_yaml_scene(n, rng):
    data = copy.deepcopy(paper_dict())
    data['links'] = [
        {
            'length': float(L),
            'mass': float(rng.uniform(0.3, 2.0)),
            'com_x': float(rng.uniform(0.1, 0.9) * L),
            'com_y': float(rng.uniform(-0.1, 0.1) * L),
            'inertia': float(rng.uniform(0.01, 0.2)),
        }
        for L in rng.uniform(0.3, 1.0, n)
    ]
    controller = data['controller']
    for key in ('kp', 'kd', 'ki', 'down_target_deg', 'up_target_deg'):
        controller[key] = (controller[key] * n)[:n]
    data['initial'] = {'q_deg': [60.0 - 10 * k for k in range(n)]}
    data['surfaces'] = [
        {'height': -0.25, 'material': 'steel'},
        {'height': 0.2, 'law': 'none', 'material': 'steel'},
    ]
    return data


@pytest.mark.parametrize('n', [2, 3, 5])
@pytest.mark.parametrize('kind', ['rods', 'general'])
def test_scene_to_urdf_to_scene_round_trips(tmp_path, n, kind):
    """Scene → ``impact-arm urdf``'s text → a scene taking its arm from that file: the same
    arm, to the last bit (the URDF holds each number's repr)."""
    rng = np.random.default_rng(n)
    data = general_yaml_scene(n, rng)
    if kind == 'rods':
        for link in data['links']:
            del link['com_x'], link['com_y'], link['inertia']
    original = parse_scene(data, origin='yaml')
    assert original.general_links == (kind == 'general')
    path = tmp_path / 'arm.urdf'
    path.write_text(robot_description(original))
    again_data = copy.deepcopy(data)
    del again_data['links'], again_data['tip_radius']
    again_data['arm'] = {'urdf': str(path), 'contact': {'link': 'tip'}}
    # the URDF arm's angles are its joint angles: the rods' absolute ones, relative
    again_data['initial']['q_deg'] = to_joint_space(data['initial']['q_deg'])
    for key in ('down_target_deg', 'up_target_deg'):
        again_data['controller'][key] = to_joint_space(data['controller'][key])
    again = parse_scene(again_data, origin='urdf')
    assert again.q0 == pytest.approx(original.q0, abs=1e-12)
    for key in ('lengths', 'masses', 'link_com', 'link_inertias', 'contact_point', 'tip_radius'):
        assert getattr(again, key) == getattr(original, key), key
    assert again.general_links == original.general_links  # rods stay the rods' equations
    assert [j.name for j in again.joints] == [j.name for j in original.joints]
    assert again.surfaces == original.surfaces
    # written again (now the whole robot, read as it ships) and read back: the same text,
    # nothing drifts
    path.write_text(robot_description(again))
    third = parse_scene(again_data, origin='urdf')
    assert robot_description(third) == robot_description(again)
    for key in ('lengths', 'masses', 'link_com', 'link_inertias', 'contact_point', 'tip_radius'):
        assert getattr(third, key) == getattr(original, key), key


def test_limits_and_dynamics_round_trip_through_the_written_urdf(tmp_path):
    text, _, _ = random_urdf(np.random.default_rng(2), 4)
    scene = load(tmp_path, text, 4)
    path = tmp_path / 'written.urdf'
    path.write_text(robot_description(scene))
    data = scene_data(path, 4)
    data['arm']['contact'] = {'link': 'tip'}
    again = parse_scene(data, origin='again')
    for key in ('lengths', 'masses', 'link_com', 'link_inertias', 'contact_point', 'tip_radius'):
        assert getattr(again, key) == getattr(scene, key), key  # repr: every bit
    for a, b in zip(again.joints, scene.joints):
        assert (a.lower, a.upper, a.effort, a.velocity, a.damping, a.friction) == (
            b.lower,
            b.upper,
            b.effort,
            b.velocity,
            b.damping,
            b.friction,
        )


ROD = (
    '<inertial><origin xyz="0.5 0 0"/><mass value="1"/>'
    '<inertia ixx="0" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.08"/></inertial>'
)
GOOD = (
    '<robot name="r"><link name="world"/>\n'
    f'<link name="a">{ROD}</link>\n'
    f'<link name="b">{ROD}\n'
    '<collision><origin xyz="1.0 0 0"/><geometry><sphere radius="0.005"/></geometry>'
    '</collision></link>\n'
    '<joint name="ja" type="continuous"><parent link="world"/><child link="a"/>'
    '<axis xyz="0 -1 0"/></joint>\n'
    '<joint name="jb" type="continuous"><parent link="a"/><child link="b"/>'
    '<origin xyz="1 0 0"/><axis xyz="0 -1 0"/></joint>\n'
    '</robot>'
)
EXTRA_LINK = (
    '<link name="c"><inertial><mass value="1"/>'
    '<inertia ixx="0" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.08"/></inertial></link>'
)


@pytest.mark.parametrize(
    'change, message',
    [
        (
            ('type="continuous"><parent link="a"', 'type="prismatic"><parent link="a"'),
            'has 1 moving joint (ja): an arm needs at least 2 links',
        ),
        (
            ('type="continuous"><parent link="a"', 'type="floating"><parent link="a"'),
            "joint 'jb' is of type 'floating'",
        ),
        (
            (
                '<origin xyz="1 0 0"/><axis xyz="0 -1 0"/>',
                '<origin xyz="1 0 0"/><axis xyz="0 0 1"/>',
            ),
            "joint 'jb' axis is 90 deg from joint 'ja''s at the locked posture: the moving "
            "joints' axes must be parallel",
        ),
        (
            (
                '<origin xyz="1 0 0"/><axis xyz="0 -1 0"/>',
                '<origin xyz="1 0 0"/><axis xyz="0.01 -1 0"/>',
            ),
            "joint 'jb' axis is 0.5729 deg from joint 'ja''s",
        ),
        (
            ('<origin xyz="1 0 0"/>', '<origin xyz="0 0.4 0"/>'),
            "joints 'ja' and 'jb' lie on one line along their axes: the link between them has "
            'no length in the plane',
        ),
        (
            (
                '</robot>',
                EXTRA_LINK + '<joint name="jc" type="revolute"><parent link="a"/>'
                '<child link="c"/><axis xyz="0 -1 0"/></joint></robot>',
            ),
            "joints 'jc' and 'jb' lie on different branches: the model is one serial chain",
        ),
        (('<child link="b"/>', '<child link="a"/>'), "link 'a' is already the child of joint 'ja'"),
        ((f'{ROD}\n<collision>', '<collision>'), "link 'b' has no <inertial> mass"),
        (
            (
                '<mass value="1"/><inertia ixx="0" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.08"/>'
                '</inertial>\n<collision>',
                '<mass value="nan"/></inertial>\n<collision>',
            ),
            "link 'b' mass = 'nan' is not finite",
        ),
        (
            ('<sphere radius="0.005"/>', '<box size="1 1 1"/>'),
            "arm.contact.radius is missing and link 'b' has no collision sphere",
        ),
        (('<robot name="r">', '<robot name="r"'), 'not valid XML'),
        (
            ('<robot name="r">', '<robot name="r"><xacro:property name="l" value="1"/>'),
            'not valid XML: unbound prefix: line 1, column 16 (a xacro file? give it as arm.xacro',
        ),
        (
            (
                '<origin xyz="1 0 0"/><axis xyz="0 -1 0"/>',
                '<axis xyz="0 -1 0"/><mimic joint="ja"/>',
            ),
            "joint 'jb' mimics another joint",
        ),
    ],
)
def test_what_is_not_a_planar_chain_is_refused_naming_the_joint_and_why(tmp_path, change, message):
    old, new = change
    assert old in GOOD
    path = tmp_path / 'bad.urdf'
    path.write_text(GOOD.replace(old, new, 1))
    data = scene_data(path, 2)
    del data['arm']['contact']
    with pytest.raises(SceneError) as refused:
        parse_scene(data, origin='s.yaml')
    text = str(refused.value)
    assert message in text and '\n' not in text
    assert text.startswith(f"scene 's.yaml': arm.urdf '{path}'") or 'arm.urdf' in text
    path.write_text(GOOD)
    assert parse_scene(data, origin='s.yaml').n_links == 2  # the unchanged file loads


def test_the_scene_gives_its_arm_once_and_the_contact_on_the_last_link(tmp_path):
    path = tmp_path / 'arm.urdf'
    path.write_text(GOOD)
    data = scene_data(path, 2)
    both = dict(data, links=paper_dict()['links'])
    with pytest.raises(SceneError, match='links is given with arm.urdf'):
        parse_scene(both, origin='s')
    with pytest.raises(SceneError, match='tip_radius is given with arm.urdf'):
        parse_scene(dict(data, tip_radius=0.005), origin='s')
    neither = dict(data)
    del neither['arm']
    with pytest.raises(SceneError, match=r'links is missing \(required unless arm.urdf'):
        parse_scene(neither, origin='s')
    data['arm']['contact'] = {'link': 'a'}
    with pytest.raises(SceneError, match="joint 'jb' moves beyond the contact link 'a'"):
        parse_scene(data, origin='s')
    data['arm']['contact'] = {'link': 'b', 'point': [0.7, 0.0, 0.1], 'radius': 0.004}
    scene = parse_scene(data, origin='s')
    assert scene.contact_point == (0.7, 0.1) and scene.tip_radius == 0.004
    data['arm']['contact'] = {'link': 'b', 'point': [0.7, 0.1]}
    with pytest.raises(SceneError, match=r'arm.contact.point has 2 entries'):
        parse_scene(data, origin='s')
    # a point off the plane, along the axis, is taken at its projection
    data['arm']['contact'] = {'link': 'b', 'point': [0.7, 0.1, 0.0]}
    assert parse_scene(data, origin='s').contact_point == (0.7, 0.0)
    data['arm'] = {'urdf': str(tmp_path / 'missing.urdf')}
    with pytest.raises(SceneError, match="arm.urdf = '.*missing.urdf': cannot be read"):
        parse_scene(data, origin='s')


def test_a_relative_urdf_path_is_relative_to_the_scene_file(tmp_path):
    (tmp_path / 'arms').mkdir()
    (tmp_path / 'arms' / 'two.urdf').write_text(GOOD)
    data = scene_data('arms/two.urdf', 2)
    del data['arm']['contact']
    scene = parse_scene(data, origin='s', path=str(tmp_path / 'scene.yaml'))
    assert scene.lengths == (1.0, 1.0)


# ------------------------------------------------------------------------ hostile input
BOUNDED = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck)
)
WILD = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=8),
    st.integers(min_value=-(2**80), max_value=2**1100),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([5e-324, -0.0, 1e308, 1e-300, 2.0**64, 0.0, 1e-12]),
)


def general_numbers(scene):
    return [
        *scene.lengths,
        *scene.masses,
        *(c for centre in scene.link_com for c in centre),
        *scene.link_inertias,
        *scene.contact_point,
        scene.tip_radius,
    ]


@BOUNDED
@given(st.data())
def test_mutated_general_links_are_finite_or_refused_in_one_line(data):
    """The new link keys (com_x, com_y, inertia) under the scene fuzzing's mutations: a scene
    loads with finite numbers and a positive definite mass matrix, or is refused in one line."""
    scene = general_yaml_scene(data.draw(st.integers(2, 4)), np.random.default_rng(0))
    for _ in range(data.draw(st.integers(1, 3))):
        k = data.draw(st.integers(0, len(scene['links']) - 1))
        key = data.draw(st.sampled_from(['com_x', 'com_y', 'inertia', 'length', 'mass']))
        if data.draw(st.booleans()):
            scene['links'][k].pop(key, None)
        else:
            scene['links'][k][key] = data.draw(WILD)
    try:
        result = parse_scene(scene, origin='fuzz')
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    assert all(math.isfinite(x) for x in general_numbers(result))
    M = ArmModel(result).mass_matrix(result.q0)
    assert np.all(np.isfinite(M)) and np.all(np.linalg.eigvalsh(M) > 0)


URDF_NUMBERS = re.compile(r'(?<==")-?[0-9][0-9.e+-]*(?: -?[0-9][0-9.e+-]*)*(?=")')


@BOUNDED
@given(st.data())
def test_mutated_urdf_numbers_are_finite_or_refused_in_one_line(data):
    """A description's numbers (origins, axes, masses, inertias, radii, limits) replaced by
    wild values, or its elements cut: the scene loads with finite numbers, or is refused in
    one line naming the description."""
    text, _, _ = random_urdf(np.random.default_rng(3), 3)
    spans = [m.span() for m in URDF_NUMBERS.finditer(text)]
    for _ in range(data.draw(st.integers(1, 3))):
        start, end = data.draw(st.sampled_from(spans))
        value = data.draw(WILD)
        replacement = str(value) if not isinstance(value, float) else repr(value)
        text = text[:start] + replacement[:40] + text[end:]
        spans = [m.span() for m in URDF_NUMBERS.finditer(text)] or [(0, 0)]
    if data.draw(st.booleans()):
        cut = data.draw(st.integers(0, len(text)))
        text = text[:cut]
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, 'arm.urdf')
        with open(path, 'w', encoding='utf-8') as f:
            f.write(text)
        try:
            result = parse_scene(scene_data(path, 3), origin='fuzz')
        except SceneError as exc:
            assert '\n' not in str(exc) and len(str(exc)) < 1000
            assert 'arm.urdf' in str(exc)
            return
    assert all(math.isfinite(x) for x in general_numbers(result))


@pytest.mark.parametrize(
    'link, message',
    [
        ({'com_x': 11.0}, r'links\[1\].com_x = \(11, 0.*must lie within 10 link lengths'),
        (
            {'com_x': 0.0, 'com_y': 0.0, 'inertia': 1e-9},
            r'links\[1\].inertia = 1e-09 .*must be >= 1e-06 m L\^2',
        ),
        ({'inertia': 0.0}, r'links\[1\].inertia = 0 is out of range: must be >= 1e-12'),
        ({'com_y': math.nan}, r'links\[1\].com_y = nan is not finite'),
        ({'com_z': 0.1}, r'links\[1\].com_z is not a known key'),
    ],
)
def test_general_link_keys_are_refused_out_of_range(link, message):
    data = copy.deepcopy(paper_dict())
    data['links'][1].update(link)
    with pytest.raises(SceneError, match=message):
        parse_scene(data, origin='s')


def test_rod_keys_given_explicitly_are_the_rods():
    """A link whose keys say what the shorthand means is the same scene, rod equations and
    all; a link that differs in a key is a general link."""
    data = copy.deepcopy(paper_dict())
    plain = parse_scene(data, origin='s')
    data['links'][1].update({'com_x': 0.5, 'com_y': 0.0, 'inertia': 1.0 / 12})
    explicit = parse_scene(data, origin='s')
    assert not plain.general_links and not explicit.general_links
    assert explicit.link_com == plain.link_com and explicit.link_inertias == plain.link_inertias
    data['links'][1]['com_y'] = 0.01
    assert parse_scene(data, origin='s').general_links


def test_fit_and_sweep_keys_address_link_masses_centres_and_inertias():
    """``--param links[1].mass`` as before; the new keys also when the scene leaves them to
    the rod's defaults (the fit starts from the default), and as overrides of a study."""
    from impact_arm.calibration.fit import FitError, parameter_specs
    from impact_arm.calibration.study import Study

    study = Study('paper')
    specs = parameter_specs(
        study,
        {
            'links[1].mass': (0.5, 2.0),
            'links[1].com_x': (0.3, 0.7),
            'links[0].com_y': (-0.1, 0.1),
            'links[1].inertia': (0.01, 0.2),
        },
    )
    assert [s.start for s in specs] == [1.0, 0.5, 0.0, 1.0 / 12]
    assert [s.log for s in specs] == [True, True, False, True]
    with pytest.raises(FitError, match=r'links\[1\].com_x=0.6:0.7: the bounds exclude .* 0.5'):
        parameter_specs(study, {'links[1].com_x': (0.6, 0.7)})
    with pytest.raises(FitError, match=r"no 'com_z' in links\[1\]"):
        parameter_specs(study, {'links[1].com_z': (0.0, 1.0)})
    with pytest.raises(FitError, match='has no 5 in links'):
        parameter_specs(study, {'links[5].com_x': (0.0, 1.0)})
    scene = study.scene({'links[1].com_y': 0.05, 'links[1].inertia': 0.2, 'links[0].mass': 1.1})
    assert scene.link_com[1] == (0.5, 0.05) and scene.link_inertias == (1.1 / 12, 0.2)
    assert scene.general_links


EXAMPLE = os.path.join(EXAMPLES, 'three_link.yaml')


def example_data():
    from impact_arm.physics.scene import read_scene_file, scene_data as yaml_data

    text, path = read_scene_file(EXAMPLE)
    return yaml_data(text, path), path


def test_the_example_arm_is_read_from_its_urdf_beside_the_scene():
    from impact_arm.physics.scene import load_scene

    scene = load_scene(EXAMPLE)
    assert scene.lengths == (0.7, 0.7, 0.6) and scene.masses == (2.0, 1.5, 0.8)
    assert scene.link_com == ((0.32, 0.01), (0.30, -0.005), (0.25, 0.0))
    assert scene.link_inertias == (0.09, 0.065, 0.03) and scene.tip_radius == 0.005
    assert [j.name for j in scene.joints] == ['shoulder', 'elbow', 'wrist']
    assert scene.general_links and scene.urdf_path == 'three_link.urdf'


def test_a_general_arm_conserves_energy_in_the_kernel(tmp_path):
    """The example's arm swinging freely (no control, no surface) through the compiled
    kernel: T + V constant to the reference preset's error, with T and V from the generated
    functions on the Python side; wrong geometry or masses in the kernel's parameter block
    (P_L holds NL values for general links) would break the balance."""
    from impact_arm.physics.simulate import run

    data, path = example_data()
    data.update(surfaces=[], cycles=0, t_max=3.0, publish_rate=100.0)
    data['controller']['law'] = 'none'
    # the URDF's <dynamics> act as joint friction: off here, so that T + V is conserved
    data['joints'] = [{'damping': 0.0, 'friction': 0.0} for _ in range(3)]
    scene = parse_scene(data, origin='free', path=path)
    result = run(scene, preset='reference')
    model = ArmModel(scene)
    energy = [
        sum(model.link_energies(s.q, s.qd)) + model.potential_energy(s.q) for s in result.samples
    ]
    scale = max(abs(model.potential_energy(s.q)) for s in result.samples)
    assert result.samples[-1].t == pytest.approx(3.0)
    assert max(abs(e - energy[0]) for e in energy) / scale < 1e-8
    assert max(sum(model.link_energies(s.q, s.qd)) for s in result.samples) > 5.0


def test_impact_arm_urdf_writes_the_general_arm(tmp_path, capsys):
    from impact_arm.tools.cli import main

    assert main(['urdf', '--scene', EXAMPLE]) == 0
    text = capsys.readouterr().out
    path = tmp_path / 'written.urdf'
    path.write_text(text)
    data, scene_path = example_data()
    data['arm'] = {'urdf': str(path), 'contact': {'link': 'tip'}}
    again = parse_scene(data, origin='again')
    original = parse_scene(example_data()[0], origin='example', path=scene_path)
    for key in ('lengths', 'masses', 'link_com', 'link_inertias', 'contact_point', 'tip_radius'):
        assert getattr(again, key) == getattr(original, key), key
    assert [j.damping for j in again.joints] == [0.05, 0.05, 0.02]
    assert [(j.lower, j.upper) for j in again.joints] == [(None, None), (-2.6, 2.6), (-2.6, 2.6)]


def test_a_recording_carries_the_arms_urdf_in_its_scene(tmp_path):
    """What a recording stores (``self_contained_text``): the scene with the URDF's text as
    ``arm.description``, which loads to the same arm with the file gone; a scene without a
    URDF is stored as it was written."""
    from impact_arm.physics.scene import load_scene, scene_from_text, self_contained_text

    urdf = tmp_path / 'arm.urdf'
    urdf.write_text(open(os.path.join(os.path.dirname(EXAMPLE), 'three_link.urdf')).read())
    scene_file = tmp_path / 'three.yaml'
    scene_file.write_text(open(EXAMPLE).read().replace('three_link.urdf', 'arm.urdf'))
    scene = load_scene(str(scene_file))
    text = self_contained_text(scene)
    urdf.unlink()
    again = scene_from_text(text, origin='stored')
    for key in ('lengths', 'masses', 'link_com', 'link_inertias', 'contact_point', 'joints'):
        assert getattr(again, key) == getattr(scene, key), key
    assert again.controller == scene.controller and again.surfaces == scene.surfaces
    assert self_contained_text(again) == text  # an inline description stays as it is
    paper = load_scene('paper')
    assert self_contained_text(paper) == paper.source_text
    data = scene_data(tmp_path / 'x.urdf', 2)
    data['arm']['description'] = GOOD
    with pytest.raises(SceneError, match='arm gives both urdf and description'):
        parse_scene(data, origin='s')
    del data['arm']['urdf'], data['arm']['description']
    with pytest.raises(
        SceneError, match=r'arm needs urdf \(a URDF file\), xacro \(a xacro file\) or description'
    ):
        parse_scene(data, origin='s')


def test_an_offline_recording_of_a_urdf_arm_reads_back_without_the_file(tmp_path, capsys):
    """``impact-arm simulate --mcap`` of a scene whose URDF is then gone: the recording's own
    scene (read with rosbags, as analyze and fit read it) is the arm."""
    from impact_arm.tools.analysis import load as load_recording
    from impact_arm.tools.cli import main

    for name in ('three_link.yaml', 'three_link.urdf'):
        text = open(os.path.join(os.path.dirname(EXAMPLE), name)).read()
        text = text.replace('cycles: 5', 'cycles: 2')  # and the tip 2 cm off the axis:
        (tmp_path / name).write_text(text.replace('xyz="0.6 0 0"', 'xyz="0.6 0 0.02"'))
    mcap = tmp_path / 'run.mcap'
    assert (
        main(['simulate', '--scene', str(tmp_path / 'three_link.yaml'), '--mcap', str(mcap)]) == 0
    )
    (tmp_path / 'three_link.urdf').unlink()
    (tmp_path / 'three_link.yaml').unlink()
    run = load_recording(str(mcap))
    assert run.scene is not None and run.scene.general_links
    assert run.scene.link_com == ((0.32, 0.01), (0.30, -0.005), (0.25, 0.0))
    assert run.scene.contact_point == (0.6, 0.02)
    assert len(run.impacts) == 2
    # the analysis's tip velocity is the contact point's (off the last link's end here)
    from impact_arm.tools.analysis import tip_velocity

    model, v = ArmModel(run.scene), tip_velocity(run)
    for i in range(0, len(run.t), max(1, len(run.t) // 20)):
        assert v[i] == pytest.approx(model.tip(run.q[i], run.qd[i])[2:], rel=1e-12, abs=1e-12)


def test_fit_recovers_a_contact_parameter_of_a_urdf_arm():
    """A recording of the example's URDF arm with friction 0.3 (sampled as a driver reports):
    the fit, starting from the scene's 0.2, finds 0.3 within its interval."""
    from impact_arm.calibration.fit import fit
    from impact_arm.io.synthetic import synthetic_recording

    rec = synthetic_recording(
        EXAMPLE, {'surfaces[0].mu': 0.3}, cycles=3, seed=5, control_rate=1000.0
    )
    result = fit(rec, EXAMPLE, {'surfaces[0].mu': (0.05, 1.0)})
    mu = result.parameters['surfaces[0].mu']
    assert mu.ci95[0] <= 0.3 <= mu.ci95[1] and mu.identifiable
    assert abs(mu.value - 0.3) < 0.01


def test_a_urdf_arms_link_values_are_scene_keys_for_fit_and_sweep():
    """``arm.links[i].mass`` (com_x, com_y, inertia) states a value instead of the file's: a
    fit finds a link 5 % heavier than the URDF says, starting from the URDF's mass."""
    from impact_arm.calibration.fit import fit, parameter_specs
    from impact_arm.calibration.study import Study, load_scene_data
    from impact_arm.io.synthetic import synthetic_recording

    data, _ = load_scene_data(EXAMPLE)
    data['arm']['urdf'] = os.path.join(os.path.dirname(EXAMPLE), 'three_link.urdf')
    truth = copy.deepcopy(data)
    truth['arm']['links'] = [{}, {'mass': 1.5 * 1.05}, {'com_y': 0.0}]
    scene = parse_scene(truth, origin='truth')
    assert scene.masses == (2.0, 1.5 * 1.05, 0.8) and scene.link_com[2] == (0.25, 0.0)
    study = Study(EXAMPLE)
    specs = parameter_specs(
        study, {'arm.links[1].mass': (1.0, 2.5), 'arm.links[0].com_x': (0.2, 0.5)}
    )
    assert [s.start for s in specs] == [1.5, 0.32]
    rec = synthetic_recording(truth, None, cycles=4, seed=5, control_rate=1000.0)
    mass = fit(rec, EXAMPLE, {'arm.links[1].mass': (1.0, 2.5)}).parameters['arm.links[1].mass']
    assert mass.ci95[0] <= 1.575 <= mass.ci95[1]
    truth['arm']['links'] = [{}, {}]
    with pytest.raises(SceneError, match=r'arm.links has 2 entries: must have one per moving link'):
        parse_scene(truth, origin='s')
    truth['arm']['links'] = [{}, {'mass': -1.0}, {}]
    with pytest.raises(SceneError, match=r'arm.links\[1\].mass = -1 is out of range'):
        parse_scene(truth, origin='s')


@BOUNDED
@given(st.data())
def test_mutated_arm_link_values_are_finite_or_refused_in_one_line(data):
    path = os.path.join(os.path.dirname(EXAMPLE), 'three_link.urdf')
    scene = scene_data(path, 3)
    scene['arm']['contact'] = {'link': 'tool'}
    links = [{} for _ in range(data.draw(st.integers(2, 4)))]
    for _ in range(data.draw(st.integers(1, 4))):
        entry = data.draw(st.sampled_from(links))
        entry[data.draw(st.sampled_from(['mass', 'com_x', 'com_y', 'inertia', 'length']))] = (
            data.draw(WILD)
        )
    scene['arm']['links'] = links
    try:
        result = parse_scene(scene, origin='fuzz')
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    assert all(math.isfinite(x) for x in general_numbers(result))
    M = ArmModel(result).mass_matrix(result.q0)
    assert np.all(np.isfinite(M)) and np.all(np.linalg.eigvalsh(M) > 0)


def test_the_recorder_node_stores_a_urdf_arms_description(ros_env, tmp_path):
    """The recorder (a real node in its own process) given a scene whose arm comes from a
    URDF file: the file's scene metadata loads the arm with the files gone."""
    from mcap.reader import make_reader
    from ros_helpers import node_args, start_process, wait_for

    for name in ('three_link.yaml', 'three_link.urdf'):
        (tmp_path / name).write_text(open(os.path.join(os.path.dirname(EXAMPLE), name)).read())
    out = tmp_path / 'rec.mcap'
    args = node_args(
        'impact_arm.nodes.recorder',
        f'output:={out}',
        f'scene:={tmp_path / "three_link.yaml"}',
        'flush_interval:=0.2',
        'param_nodes:=[""]',
    )
    with start_process(args, ros_env, tmp_path, 'recorder') as rec:
        assert wait_for(lambda: out.exists() and out.stat().st_size > 0, 30), rec.stderr
        time.sleep(1.0)  # a flush or two
    (tmp_path / 'three_link.urdf').unlink()
    (tmp_path / 'three_link.yaml').unlink()
    with open(out, 'rb') as f:
        stored = {m.name: m.metadata for m in make_reader(f).iter_metadata()}['scene']['yaml']
    assert 'description:' in stored and 'urdf:' not in stored
    scene = parse_scene(yaml.safe_load(stored), origin='stored')
    assert scene.link_com == ((0.32, 0.01), (0.30, -0.005), (0.25, 0.0))


@pytest.mark.slow
def test_impact_arm_run_of_a_urdf_arm_completes_and_puts_its_tip_on_the_surface(ros_env, tmp_path):
    """The example's URDF arm, its tip 2 cm off the last link's axis, through ``impact-arm
    run`` (simulator, controller and recorder over DDS, lockstep): complete, and at each
    impact's first contact the recorded TF puts frame 'tip' on the surface, where Pinocchio
    puts the contact sphere of the same URDF for the reported contact angles."""
    pin = pytest.importorskip('pinocchio')
    from cli_runs import impact_arm_run, read_back
    from tf_frames import compose, stamp_ns

    from impact_arm.physics.impact import impact_from_json

    urdf = open(os.path.join(os.path.dirname(EXAMPLE), 'three_link.urdf')).read()
    urdf = urdf.replace('xyz="0.6 0 0"', 'xyz="0.6 0 0.02"')
    (tmp_path / 'three_link.urdf').write_text(urdf)
    (tmp_path / 'three.yaml').write_text(open(EXAMPLE).read().replace('cycles: 5', 'cycles: 2'))
    code, out = impact_arm_run(
        ['--scene', 'three.yaml', '--mode', 'lockstep', '--name', 'arm', '--out', 'runs'],
        ros_env,
        tmp_path,
    )
    assert code == 0 and ': complete' in out, out
    by_topic = read_back(tmp_path / 'runs' / 'arm.mcap')
    reports = [impact_from_json(m.data) for m in by_topic['/impact_report']]
    assert len(reports) >= 2
    (static,) = by_topic['/tf_static']

    def tip_in_world(msg):
        """Frame 'tip' in 'world': the whole robot's tree, its fixed and moving joints."""
        by_child = {t.child_frame_id: t for t in [*static.transforms, *msg.transforms]}
        chain, frame = [], 'tip'
        while frame != 'world':
            chain.insert(0, by_child[frame])
            frame = by_child[frame].header.frame_id
        return compose(chain)

    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    for report in reports:
        t0 = round(report.t_contact * 1e9)
        first = next(m for m in by_topic['/tf'] if stamp_ns(m.transforms[0].header) >= t0 - 1)
        at_contact = tip_in_world(first)
        assert at_contact[2] == pytest.approx(-1.2, abs=1e-6)  # the surface's height
        q = np.radians(report.q_contact_deg)
        theta = np.concatenate([[q[0]], np.diff(q)])  # joint values: relative angles
        config = np.array([math.cos(theta[0]), math.sin(theta[0]), theta[1], theta[2]])
        pin.framesForwardKinematics(model, data, config)
        assert at_contact == pytest.approx(data.oMf[model.getFrameId('tool')].translation, abs=1e-9)


def test_the_description_names_a_urdf_arms_links_and_joints_as_its_urdf_does(tmp_path):
    from impact_arm.io.urdf import VisualSettingError, robot_description

    text, _, _ = random_urdf(np.random.default_rng(1), 3)
    scene = load(tmp_path, text, 3)
    assert scene.joint_names == ('j0', 'j1', 'j2')
    robot = ET.fromstring(robot_description(scene))
    moving = [j for j in robot.findall('joint') if j.get('type') != 'fixed']
    assert [j.get('name') for j in moving] == ['j0', 'j1', 'j2']
    assert [j.find('child').get('link') for j in moving] == ['l0', 'l1', 'l2']
    # a link named as a frame the description adds would make two links of one name
    clash = load(tmp_path, text.replace('"l1"', '"tip"'), 3)
    with pytest.raises(VisualSettingError, match="arm.urdf link 'tip'"):
        robot_description(clash)
