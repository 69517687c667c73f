"""The free planar body (physics/bodies/): closed forms, conservation and symmetry of its
contacts, the same phase machine as the sphere drop's independent integration, and its scene
section's refusals (fuzzed)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.physics.bodies import kernel as K
from impact_arm.physics.bodies.model import build_model, energy, simulate_body
from impact_arm.physics.bodies.scene import BodyState, parse_body_scene
from impact_arm.physics.contact import contact_constants
from impact_arm.physics.errors import SceneError, SimulationError
from impact_arm.physics.kinds import EventKind
from impact_arm.physics.layout import ELASTIC, FREE, RESTITUTION
from impact_arm.physics.scene import Material
from impact_arm.physics.sphere_drop import drop

from impact_arm_bench.generators import key_paths
from repo_paths import REPO_ROOT

SIDE = 0.06
RADIUS = 0.002
HALF = SIDE / 2 - RADIUS  # corner sphere centres: the rounded square's outline stays SIDE wide
MASS = 0.05
INERTIA = MASS * SIDE**2 / 6


def square(**surface) -> dict:
    """A rounded aluminium square over a steel floor, as scene data (no gravity unless set)."""
    floor = {'point': [0.0, 0.0], 'normal': [0.0, 1.0], 'law': 'hertz', 'mu': 0.0}
    floor.update(surface)
    return {
        'name': 'square',
        'gravity': 0.0,
        'materials': {
            'body': {'E': 70e9, 'nu': 0.33, 'S_y': 0.27e9},
            'surface': {'E': 210e9, 'nu': 0.29, 'S_y': 1.12e9},
        },
        'body': {
            'mass': MASS,
            'inertia': INERTIA,
            'corner_radius': RADIUS,
            'corners': [[HALF, HALF], [-HALF, HALF], [-HALF, -HALF], [HALF, -HALF]],
        },
        'initial': {'z': 0.1},
        'surfaces': [floor],
        't_max': 1.0,
        'integrator': {'rtol': 1e-10, 'atol': 1e-14},
    }


def model_of(data: dict):
    return build_model(parse_body_scene(data, 'test'))


def lowest_corner_state(theta: float, clearance: float, vx: float, vz: float, w: float):
    """The square at angle theta with its lowest corner sphere ``clearance`` above z = 0."""
    low = min(
        math.sin(theta) * bx + math.cos(theta) * bz
        for bx, bz in ((HALF, HALF), (-HALF, HALF), (-HALF, -HALF), (HALF, -HALF))
    )
    return BodyState(0.0, RADIUS + clearance - low, theta, vx, vz, w)


def test_free_flight_follows_the_parabola_and_keeps_its_spin():
    data = square()
    data['gravity'] = 9.81
    data['surfaces'] = []
    start = BodyState(0.1, 0.5, 0.3, 0.7, 2.0, -13.0)
    run = simulate_body(model_of(data), start, 0.4)
    t = run.t
    assert t == 0.4 and not run.events
    end = run.state
    assert end.vx == pytest.approx(0.7, abs=1e-12)
    assert end.omega == pytest.approx(-13.0, abs=1e-12)
    assert end.vz == pytest.approx(2.0 - 9.81 * t, abs=1e-10)
    assert end.x == pytest.approx(0.1 + 0.7 * t, abs=1e-10)
    assert end.z == pytest.approx(0.5 + 2.0 * t - 9.81 * t * t / 2, abs=1e-10)
    assert end.theta == pytest.approx(0.3 - 13.0 * t, abs=1e-10)


def impulse_law(state: BodyState, e: float) -> tuple[float, float, float]:
    """Frictionless rigid-body impact of the lowest corner on z = 0 with Newton restitution e:
    the normal impulse P = -(1 + e) v_n / (1/m + r_x²/I) with r the contact point from the
    centre of mass (Routh; e.g. Stronge, Impact Mechanics, ch. 5)."""
    c, s = math.cos(state.theta), math.sin(state.theta)
    corners = [(c * bx - s * bz, s * bx + c * bz) for bx, bz in ((HALF, HALF), (-HALF, HALF))]
    corners += [(-rx, -rz) for rx, rz in corners]
    rx, rz = min(corners, key=lambda r: r[1])
    rz -= RADIUS
    v_n = state.vz + state.omega * rx
    impulse = -(1 + e) * v_n / (1 / MASS + rx * rx / INERTIA)
    return state.vx, state.vz + impulse / MASS, state.omega + rx * impulse / INERTIA


@pytest.mark.parametrize(
    'theta_deg, vx, w', [(20.0, 0.0, 0.0), (35.0, -0.5, 8.0), (5.0, 0.3, -4.0)]
)
def test_a_frictionless_elastic_corner_impact_follows_the_rigid_body_impulse_law(theta_deg, vx, w):
    """With a stiff Hertz contact the body turns little during the 30 us contact, so the
    velocities after it approach the e = 1 impulse law (to the rotation during contact)."""
    start = lowest_corner_state(math.radians(theta_deg), 1e-6, vx, -2.0, w)
    run = simulate_body(model_of(square()), start, 0.05, settle=1e-3)
    assert run.settled
    kinds = [e.kind for e in run.events]
    assert kinds == [EventKind.CONTACT, EventKind.MAX_COMPRESSION, EventKind.SEPARATION]
    expected = impulse_law(start, 1.0)
    got = (run.state.vx, run.state.vz, run.state.omega)
    assert got[0] == pytest.approx(expected[0], abs=1e-12)  # no friction: no tangential force
    assert got[1] == pytest.approx(expected[1], abs=2e-3 * 2.0)
    assert got[2] == pytest.approx(expected[2], abs=2e-3 * 2.0 / SIDE)


def test_energy_is_conserved_through_elastic_frictionless_bounces():
    data = square()
    data['gravity'] = 9.81
    model = model_of(data)
    start = lowest_corner_state(math.radians(25.0), 0.05, 0.2, -1.0, 6.0)
    run = simulate_body(model, start, 1.0)
    separations = [e for e in run.events if e.kind == EventKind.SEPARATION]
    assert len(separations) >= 3  # several impacts, of more than one corner
    assert len({e.corner for e in separations}) >= 2
    assert energy(model, run.state) == pytest.approx(energy(model, start), rel=1e-7)


@pytest.mark.parametrize('mu', [0.0, 0.3])
def test_a_square_landing_flat_strikes_with_two_corners_at_once_and_stays_level(mu):
    data = square(law='elastoplastic', mu=mu)
    data['gravity'] = 9.81
    start = lowest_corner_state(0.0, 1e-4, 0.0, -2.0, 0.0)
    run = simulate_body(model_of(data), start, 0.05, settle=1e-3)
    contacts = [e for e in run.events if e.kind == EventKind.CONTACT]
    assert sorted(e.corner for e in contacts) == [2, 3]
    assert contacts[0].t == contacts[1].t
    kinds = [e.kind for e in run.events]
    # both in contact at once: both reach maximum compression before either separates
    assert kinds.index(EventKind.SEPARATION) > max(
        i for i, k in enumerate(kinds) if k == EventKind.MAX_COMPRESSION
    )
    assert EventKind.YIELD in kinds  # 2 m/s on aluminium yields
    end = run.state
    assert end.vz > 0
    assert abs(end.omega) < 1e-9 and abs(end.theta) < 1e-12 and abs(end.vx) < 1e-12


def test_one_corner_dropped_normally_matches_the_independent_sphere_drop():
    """A body whose only corner sits at its centre is a sphere: its normal rebound through
    the three phases equals the sphere drop's (scipy DOP853 and terminal events)."""
    data = square(law='elastoplastic')
    data['body']['corners'] = [[0.0, 0.0]]
    model = model_of(data)
    run = simulate_body(
        model, BodyState(0.0, RADIUS + 1e-7, 0.0, 0.0, -3.0, 0.0), 0.01, settle=1e-4
    )
    body, floor = Material(70e9, 0.33, 0.27e9), Material(210e9, 0.29, 1.12e9)
    reference = drop(contact_constants(body, floor, RADIUS), MASS, 3.0)
    assert reference.yielded
    assert run.state.vz == pytest.approx(reference.rebound, rel=1e-6)
    maximum = next(e for e in run.events if e.kind == EventKind.MAX_COMPRESSION)
    assert maximum.values[0] == pytest.approx(reference.delta_m, rel=1e-6)
    assert maximum.values[2] == pytest.approx(reference.delta_r, rel=1e-6)


def test_a_dent_is_forgotten_once_the_corner_rises_above_the_surface():
    """Each bounce of an elasto-plastic sphere starts where the surface was (as the arm's
    impacts do): the dent of the first does not lower the second's contact."""
    data = square(law='elastoplastic')
    data['gravity'] = 9.81
    data['body']['corners'] = [[0.0, 0.0]]
    model = model_of(data)
    run = simulate_body(
        model, BodyState(0.0, RADIUS + 1e-4, 0.0, 0.0, -2.0, 0.0), 0.2, trace=50_000
    )
    contacts = [e.t for e in run.events if e.kind == EventKind.CONTACT]
    separations = [e for e in run.events if e.kind == EventKind.SEPARATION]
    assert len(contacts) >= 2 and separations[0].values[2] > 0  # a dent was left
    at = {row[0]: row for row in run.trace}
    for t in contacts:
        assert at[t][2] - RADIUS == pytest.approx(0.0, abs=1e-12)


def test_the_constant_cor_law_rebounds_with_its_coefficient():
    data = square(law='constant_cor', cor=0.65)
    data['body']['corners'] = [[0.0, 0.0]]
    run = simulate_body(
        model_of(data), BodyState(0.0, RADIUS + 1e-7, 0.0, 0.0, -2.5, 0.0), 0.01, settle=1e-4
    )
    assert run.state.vz == pytest.approx(0.65 * 2.5, rel=1e-7)


@pytest.mark.parametrize('kind', [K.EV_CONTACT, K.EV_MAX, K.EV_SEPARATION])
def test_the_event_rates_newton_locates_with_are_the_event_functions_time_derivatives(kind):
    """The rate each event's Newton step uses (``event_rate``) is dg/dt along the motion:
    the central difference of g over y ± ε ẏ, on a spinning, tilted square in contact (the
    maximum compression's rate needs the corner's acceleration, spin included)."""
    data = square(law='elastoplastic', mu=0.3)
    data['gravity'] = 9.81
    model = model_of(data)
    state = lowest_corner_state(0.4, -2e-7, 0.7, -1.3, 25.0)  # the lowest corner 0.2 um in
    y = np.array([state.x, state.z, state.theta, state.vx, state.vz, state.omega])
    CS = np.zeros((model.n_pairs, K.CS_COLUMNS))
    phase = {K.EV_CONTACT: FREE, K.EV_MAX: ELASTIC, K.EV_SEPARATION: RESTITUTION}[kind]
    CS[:, K.CS_PHASE] = phase
    CS[:, K.CS_RR] = RADIUS
    f = np.zeros(6)
    K.rhs(0.0, y, f, model.P, model.corners, model.pairs, CS, np.zeros(4))
    g = np.zeros((2, K.EVENTS_PER_PAIR * model.n_pairs))
    step = 1e-7
    K.event_values(y + step * f, model.corners, model.pairs, CS, g[0])
    K.event_values(y - step * f, model.corners, model.pairs, CS, g[1])
    for k in range(model.n_pairs):
        slot = K.EVENTS_PER_PAIR * k + kind
        rate = K.event_rate(y, f, slot, model.corners, model.pairs)
        assert rate == pytest.approx((g[0, slot] - g[1, slot]) / (2 * step), rel=1e-6, abs=1e-9)


def _rotate(x: float, z: float, a: float) -> tuple[float, float]:
    return (math.cos(a) * x - math.sin(a) * z, math.sin(a) * x + math.cos(a) * z)


@pytest.mark.parametrize('angle_deg', [30.0, -115.0])
def test_a_tilted_surface_gives_the_rotated_impact(angle_deg):
    """Without gravity, turning surface and body together by an angle turns the outcome."""
    a = math.radians(angle_deg)
    start = lowest_corner_state(math.radians(20.0), 1e-6, -0.4, -2.0, 9.0)
    level = simulate_body(model_of(square(law='elastoplastic', mu=0.2)), start, 0.01, settle=1e-3)
    data = square(law='elastoplastic', mu=0.2, point=[0.3, -0.2])
    data['surfaces'][0]['normal'] = list(_rotate(0.0, 2.0, a))  # not of unit length
    x, z = _rotate(start.x, start.z, a)
    vx, vz = _rotate(start.vx, start.vz, a)
    turned = BodyState(x + 0.3, z - 0.2, start.theta + a, vx, vz, start.omega)
    data['initial'] = {'x': turned.x, 'z': turned.z, 'theta_deg': math.degrees(turned.theta)}
    tilted = simulate_body(model_of(data), turned, 0.01, settle=1e-3)
    assert [e.kind for e in tilted.events] == [e.kind for e in level.events]
    expected = _rotate(level.state.vx, level.state.vz, a)
    assert tilted.state.vx == pytest.approx(expected[0], abs=1e-7)
    assert tilted.state.vz == pytest.approx(expected[1], abs=1e-7)
    assert tilted.state.omega == pytest.approx(level.state.omega, abs=1e-5)


# ------------------------------------------------------------------------------ the scene
@pytest.mark.parametrize(
    'change, words',
    [
        (lambda d: d['body'].update(mass=-1), 'body.mass = -1 is out of range'),
        (lambda d: d['body'].update(corners=[]), 'body.corners'),
        (lambda d: d['body'].update(corners=[[0.1, 0.2, 0.3]]), 'body.corners[0]'),
        (lambda d: d['surfaces'][0].update(normal=[0, 0]), 'surfaces[0].normal'),
        (lambda d: d['surfaces'][0].update(law='constant_cor'), 'surfaces[0].cor is missing'),
        (lambda d: d['surfaces'][0].update(cor=0.5), 'only used by law constant_cor'),
        (lambda d: d['surfaces'][0].update(mu=float('nan')), 'surfaces[0].mu = nan'),
        (lambda d: d['initial'].update(z=0.0), 'inside surfaces[0]'),
        (lambda d: d['body'].update(materal='x'), 'body.materal is not a known key'),
        (lambda d: d['surfaces'][0].update(material='glass'), "'glass' names no entry"),
    ],
)
def test_body_scene_refusals_name_the_key_in_one_line(change, words):
    data = square()
    change(data)
    with pytest.raises(SceneError) as err:
        parse_body_scene(data, 'test')
    assert words in str(err.value) and '\n' not in str(err.value)


@pytest.mark.parametrize(
    'corner, message',
    [
        (
            [0.1, 2000],
            'body.corners[0][1] = 2000 is out of range: must be >= -1000 and <= 1000 (m)',
        ),
        ([0.1, 'x'], "body.corners[0][1] = 'x' is not a number; must be >= -1000 and <= 1000 (m)"),
        (
            [float('inf'), 0],
            'body.corners[0][0] = inf is not finite; must be >= -1000 and <= 1000 (m)',
        ),
    ],
)
def test_a_corner_coordinate_is_refused_by_the_scene_checker_number_check(corner, message):
    """A body scene's points go through the arm scene's number check: the same words."""
    data = square()
    data['body']['corners'] = [corner]
    with pytest.raises(SceneError) as err:
        parse_body_scene(data, 'test')
    assert str(err.value) == f"scene 'test': {message}"


LEAVES = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=8),
    st.integers(min_value=-(2**80), max_value=2**1100),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([5e-324, -0.0, 1e308, 1e-300, 2.0**64]),
    st.lists(st.floats(), max_size=3),
    st.lists(st.lists(st.floats(-1, 1), min_size=2, max_size=2), max_size=3),
)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
@given(st.data())
def test_mutated_body_scenes_are_accepted_finite_or_refused_in_one_line(data):
    scene = copy.deepcopy(square())
    paths = list(key_paths(scene))
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(paths))
        parent = scene
        try:
            for key in path[:-1]:
                parent = parent[key]
            if data.draw(st.booleans()) and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = data.draw(LEAVES)
        except (KeyError, IndexError, TypeError):
            continue
    try:
        result = parse_body_scene(scene, 'fuzz')
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    numbers = [result.body.mass, result.body.inertia, *result.initial.as_tuple()]
    numbers += [v for s in result.surfaces for v in (*s.normal, *s.point, s.mu, s.v_d)]
    assert all(math.isfinite(v) for v in numbers)
    # an accepted scene runs to a finite state, or stops by name
    try:
        run = simulate_body(build_model(result), t_end=min(result.t_max, 0.05))
    except SimulationError as exc:
        assert '\n' not in str(exc)
        return
    assert all(math.isfinite(v) for v in run.state.as_tuple())


def test_the_shipped_square_drop_scene_loads_and_strikes():
    import os

    from impact_arm.physics.bodies.scene import load_body_scene

    root = REPO_ROOT
    scene = load_body_scene(os.path.join(root, 'config', 'square_drop.yaml'))
    run = simulate_body(build_model(scene), t_end=0.13)
    kinds = [e.kind for e in run.events]
    assert kinds[:4] == [
        EventKind.CONTACT,
        EventKind.YIELD,
        EventKind.MAX_COMPRESSION,
        EventKind.SEPARATION,
    ]


@pytest.mark.parametrize('half_angle_deg', [30.0, 60.0])
def test_a_sphere_dropped_into_a_v_groove_strikes_both_walls_at_once_and_bounces_straight_back(
    half_angle_deg,
):
    """Two surfaces: a frictionless elastic sphere falling into a symmetric groove touches
    both walls together; their forces' horizontal parts cancel, so it leaves straight up at
    its impact speed."""
    a = math.radians(half_angle_deg)
    data = square()
    data['body']['corners'] = [[0.0, 0.0]]
    walls = [
        {'point': [0.0, 0.0], 'normal': [-math.cos(a), math.sin(a)], 'law': 'hertz'},
        {'point': [0.0, 0.0], 'normal': [math.cos(a), math.sin(a)], 'law': 'hertz'},
    ]
    data['surfaces'] = walls
    height = RADIUS / math.sin(a)  # the centre's height where the sphere touches both walls
    data['initial'] = {'z': height + 1e-6}
    run = simulate_body(
        model_of(data), BodyState(0.0, height + 1e-6, 0.0, 0.0, -1.5, 0.0), 0.05, settle=1e-3
    )
    contacts = [e for e in run.events if e.kind == EventKind.CONTACT]
    assert sorted(e.surface for e in contacts) == [0, 1]
    assert contacts[0].t == contacts[1].t
    assert run.state.vz == pytest.approx(1.5, rel=1e-7)
    assert abs(run.state.vx) < 1e-12


def _oblique(angle_deg: float, speed: float = 3.9) -> tuple[float, float, float, float]:
    """The shipped sphere-on-flat scene at an incidence angle: (tangential CoR, normal CoR,
    spin after, the sphere's radius)."""
    import os

    from impact_arm.physics.bodies.scene import load_body_scene

    root = REPO_ROOT
    scene = load_body_scene(os.path.join(root, 'config', 'oblique_sphere.yaml'))
    r = scene.body.corner_radius
    a = math.radians(angle_deg)
    vx, vz = speed * math.sin(a), -speed * math.cos(a)
    run = simulate_body(build_model(scene), BodyState(0.0, r + 1e-9, 0.0, vx, vz, 0.0), settle=1e-5)
    return run.state.vx / vx, -run.state.vz / vz, run.state.omega, r


@pytest.mark.parametrize('angle_deg', [45.0, 60.0])
def test_an_oblique_sphere_that_slides_throughout_follows_rigid_coulomb(angle_deg):
    """Sliding all through the contact: the tangential impulse is μ times the normal one,
    e_t = 1 - μ (1 + e) / tan α, and the spin 5 μ (1 + e) v_n / (2 R)."""
    mu, e = 0.092, 0.98
    et, en, omega, r = _oblique(angle_deg)
    a = math.radians(angle_deg)
    assert en == pytest.approx(e, rel=1e-6)
    assert et == pytest.approx(1 - mu * (1 + e) / math.tan(a), rel=1e-4)
    assert -omega == pytest.approx(5 * mu * (1 + e) * 3.9 * math.cos(a) / (2 * r), rel=1e-4)


@pytest.mark.parametrize('angle_deg', [5.0, 20.0])
def test_an_oblique_sphere_that_stops_sliding_leaves_rolling(angle_deg):
    """Below tan α = 7/2 μ (1 + e) the slip stops: a solid sphere leaves rolling, at 5/7 of
    its tangential speed (no tangential compliance, so no reversal of the slip)."""
    et, _, omega, r = _oblique(angle_deg)
    assert et == pytest.approx(5 / 7, rel=2e-3)
    vx = 3.9 * math.sin(math.radians(angle_deg)) * et
    assert -omega * r == pytest.approx(vx, rel=5e-3)


def test_impact_arm_body_prints_the_events_and_writes_them(tmp_path):
    import json
    import subprocess
    import sys

    root = REPO_ROOT
    out = tmp_path / 'body.json'
    args = ['body', '--scene', 'square_drop', '--t-end', '0.13', '--json', str(out)]
    result = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', *args],
        capture_output=True,
        text=True,
        cwd=root,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert 'max_compression' in result.stdout and 'theta' in result.stdout
    data = json.loads(out.read_text())
    assert [e['kind'] for e in data['events']][:2] == ['contact', 'yield']
    refused = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'body', '--scene', 'paper'],
        capture_output=True,
        text=True,
        cwd=root,
        timeout=300,
    )
    assert refused.returncode == 2
    assert 'is not a known key' in refused.stderr and '\n' not in refused.stderr.strip()
