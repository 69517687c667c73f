"""The controller's state predictor (physics/prediction.py): the model's free motion over the
periods a command is in flight, checked against conservation, a static equilibrium, the
order of its integration and a constant joint torque's work."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.physics import prediction as prediction_module
from impact_arm.physics.control import CycleController
from impact_arm.physics.model import ArmModel
from impact_arm.physics.prediction import ArrayStatePredictor, StatePredictor, solve3, solve_small
from impact_arm.physics.scene import load_scene, parse_scene, resolve_scene_path
from scenes import arm_dict

PERIOD = 1e-3


@pytest.fixture(scope='module')
def model():
    return ArmModel(load_scene(resolve_scene_path('paper')))


def energy(model, q, qd):
    return math.fsum(model.link_energies(q, qd)) + model.potential_energy(q)


def test_free_swing_conserves_energy_and_converges_at_fourth_order(model):
    """Unactuated, the arm swings under gravity alone: its energy is conserved, and the
    drift over 0.2 s shrinks ~16x per halved step (classical Runge-Kutta)."""
    q0, qd0 = [0.3, -0.4], [2.0, -3.0]
    e0 = energy(model, q0, qd0)
    drifts = []
    for substeps in (1, 2):
        q, qd = StatePredictor(model, PERIOD, substeps).ahead(q0, qd0, [[0.0, 0.0]] * 200)
        assert q != q0  # it did move
        drifts.append(abs(energy(model, q, qd) - e0))
    assert drifts[0] < 1e-7 * abs(e0)
    assert 8 < drifts[0] / drifts[1] < 32, drifts


def test_gravity_compensating_torques_hold_the_arm_still(model):
    """Joint torques τ_i = -Σ_{j>=i} Q_jg cancel gravity (article eq. 9 without gains): the
    predicted state stays where it was."""
    q = np.array([0.7, -0.2])
    gravity = np.asarray(model.gravity_forces(q), float)
    tau = [-gravity[0] - gravity[1], -gravity[1]]
    q1, qd1 = StatePredictor(model, PERIOD).ahead(q, [0.0, 0.0], [tau] * 3)
    assert np.allclose(q1, q, atol=1e-12) and np.allclose(qd1, 0.0, atol=1e-12)
    # without them the arm falls: the prediction is not the identity
    q2, _ = StatePredictor(model, PERIOD).ahead(q, [0.0, 0.0], [[0.0, 0.0]] * 3)
    assert not np.allclose(q2, q, atol=1e-9)


def test_a_joint_torque_does_the_work_the_energy_gains(model):
    """A constant torque on joint 1 only, from rest: the energy gained equals τ times the
    angle link 1 turned (joint 1 acts between the ground and link 1)."""
    tau = 40.0
    q0 = [0.5, 0.1]
    q, qd = StatePredictor(model, PERIOD, 4).ahead(q0, [0.0, 0.0], [[tau, 0.0]] * 100)
    gained = energy(model, q, qd) - energy(model, q0, [0.0, 0.0])
    assert gained == pytest.approx(tau * (q[0] - q0[0]), rel=1e-6)
    with pytest.raises(ValueError, match='period'):
        StatePredictor(model, 0.0)


def test_an_implicit_damping_command_is_backward_euler_and_never_overshoots(model):
    """The article's damping (Kd = 100 N m s/rad at 1 kHz) on a rebound's rates: evaluated
    on the state its own command leads to after a period, the torque is backward Euler's,
    (I + Kd T M⁻¹ S) τ = -Kd q̇ (S maps joint torques to generalized forces), to the few
    per mil the period's change of M, gravity and the velocity terms make. Held one period or
    two (a latency that varies by a period), it takes energy out; the explicit torque held
    two periods puts energy in: it reverses the rates."""
    kd = np.diag([100.0, 100.0])

    def damping(q, qd):
        return (-kd @ np.asarray(qd)).tolist()

    q0, qd0 = [-1.2, -0.9], [-2.0, 6.0]
    predictor = StatePredictor(model, PERIOD)
    explicit = damping(q0, qd0)
    implicit = predictor.implicit_command(damping, q0, qd0, explicit)
    mass = model.mass_matrix(q0)
    joint_to_generalized = np.array([[1.0, -1.0], [0.0, 1.0]])
    backward_euler = np.linalg.solve(
        np.eye(2) + kd @ np.linalg.solve(mass, joint_to_generalized) * PERIOD, -kd @ np.asarray(qd0)
    )
    assert implicit == pytest.approx(backward_euler, rel=5e-3)
    assert explicit != pytest.approx(backward_euler, rel=0.1)  # a different torque

    def kinetic(q, qd):
        return math.fsum(model.link_energies(q, qd))

    start = kinetic(q0, qd0)
    for periods in (1, 2):
        assert kinetic(*predictor.ahead(q0, qd0, [implicit] * periods)) < 0.4 * start
    assert kinetic(*predictor.ahead(q0, qd0, [explicit] * 2)) > start
    with pytest.raises(ValueError, match='periods = 0'):
        predictor.implicit_command(damping, q0, qd0, explicit, 0)


angles = st.lists(st.floats(-math.pi, math.pi), min_size=2, max_size=2)
rates = st.lists(st.floats(-30.0, 30.0), min_size=2, max_size=2)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(q=angles, qd=rates, periods=st.integers(1, 3), substeps=st.integers(1, 2))
def test_the_float_predictor_is_the_array_formula(model, q, qd, periods, substeps):
    """``StatePredictor`` runs on Python floats for speed; ``ArrayStatePredictor`` is the
    formula written with numpy arrays. Same operations in the same order: the prediction is
    the same to the last bits, and the implicit command (whose 2x2 solve is done by hand
    instead of LAPACK) to 1e-12 of its size, with the article's law and gains."""
    scene = load_scene(resolve_scene_path('paper'))
    ctrl = CycleController.for_scene(model, scene.controller)
    fast = StatePredictor(model, PERIOD, substeps)
    reference = ArrayStatePredictor(model, PERIOD, substeps)
    tau = ctrl.torque(q, qd)
    held = [tau, [-t for t in tau], [0.5 * t for t in tau]][:periods]
    for got_part, expected_part in zip(fast.ahead(q, qd, held), reference.ahead(q, qd, held)):
        assert got_part == pytest.approx(expected_part, rel=1e-14, abs=0)
    got = fast.implicit_command(ctrl.torque, q, qd, tau, periods)
    expected = reference.implicit_command(ctrl.torque, q, qd, tau, periods)
    size = max(1.0, *map(abs, expected))
    assert got == pytest.approx(expected, rel=0, abs=1e-12 * size)
    assert all(isinstance(t, float) for t in got + fast.ahead(q, qd, held)[1])


def test_the_float_predictor_is_the_array_formula_on_a_four_link_arm():
    """Four links: the mass matrix is solved numerically instead of in closed form (the
    other branch of the acceleration); the fast path is still the array formula."""
    model = ArmModel(parse_scene(arm_dict(4), origin='test'))
    assert not model.eq.HAS_ACCEL

    def damping(q, qd):
        return [-50.0 * v for v in qd]

    q, qd = [0.3, 0.2, -0.1, 0.4], [1.0, -2.0, 3.0, -1.0]
    held = [[1.0, 2.0, 3.0, 4.0], [-4.0, 3.0, -2.0, 1.0]]
    fast, reference = StatePredictor(model, PERIOD), ArrayStatePredictor(model, PERIOD)
    for got_part, expected_part in zip(fast.ahead(q, qd, held), reference.ahead(q, qd, held)):
        assert got_part == pytest.approx(expected_part, rel=1e-14, abs=0)
    expected = reference.implicit_command(damping, q, qd, damping(q, qd), 2)
    got = fast.implicit_command(damping, q, qd, damping(q, qd), 2)
    assert got == pytest.approx(expected, rel=0, abs=1e-12 * max(map(abs, expected)))
    assert got != pytest.approx(damping(q, qd), rel=1e-3)  # the step did something


@pytest.mark.parametrize('n', [2, 3, 4])
def test_a_urdf_arms_prediction_is_pinocchios_forward_dynamics(tmp_path, n):
    """A hand-written URDF arm (centres of mass off the axis, turned inertia tensors): the
    prediction equals classical Runge-Kutta on Pinocchio's forward dynamics (ABA, its own
    parser and algorithm) in joint angles θ with the same joint torques and step; the steps
    commute with q = T θ, so the two agree to rounding. Two and three links take the
    closed-form acceleration, four the numerical solve; a predictor handed the rod lengths
    in place of a general link's geometry fails here."""
    pin = pytest.importorskip('pinocchio')
    from urdf_arms import load, random_urdf

    rng = np.random.default_rng(70 + n)
    text, _, _ = random_urdf(rng, n)
    model = ArmModel(load(tmp_path, text, n))
    assert model.general
    robot = pin.buildModelFromXML(text)
    data = robot.createData()

    def accel(theta, theta_d, tau):
        # continuous joints are (cos, sin) pairs in Pinocchio's configuration
        config = np.concatenate(
            [[a] if k % 2 else [math.cos(a), math.sin(a)] for k, a in enumerate(theta)]
        )
        return np.array(pin.aba(robot, data, config, theta_d, tau))

    T = np.tril(np.ones((n, n)))
    h = PERIOD / 2
    for _ in range(3):
        theta, theta_d = rng.uniform(-2.0, 2.0, n), rng.uniform(-3.0, 3.0, n)
        held = [rng.uniform(-20.0, 20.0, n) for _ in range(3)]
        y, v = theta.copy(), theta_d.copy()
        for tau in held:
            for _ in range(2):
                a1 = accel(y, v, tau)
                v2 = v + h / 2 * a1
                a2 = accel(y + h / 2 * v, v2, tau)
                v3 = v + h / 2 * a2
                a3 = accel(y + h / 2 * v2, v3, tau)
                v4 = v + h * a3
                a4 = accel(y + h * v3, v4, tau)
                y = y + h / 6 * (v + 2 * v2 + 2 * v3 + v4)
                v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        for predictor in (StatePredictor(model, PERIOD, 2), ArrayStatePredictor(model, PERIOD, 2)):
            q, qd = predictor.ahead(T @ theta, T @ theta_d, [t.tolist() for t in held])
            assert np.linalg.solve(T, q) == pytest.approx(y, rel=0, abs=1e-12)
            assert np.linalg.solve(T, qd) == pytest.approx(v, rel=0, abs=1e-9)
        assert not np.allclose(y, theta + 3 * PERIOD * theta_d, atol=1e-6)  # forces acted


def test_the_small_solve_pivots_and_refuses_a_singular_matrix():
    """Against numpy's solve, on a matrix that needs a row exchange; a singular one gives
    None (the implicit law then keeps its explicit torque)."""
    a = [[0.0, 2.0, 0.5], [3.0, -1.0, 2.0], [0.2, 4.0, -3.0]]  # row 0 cannot pivot
    b = [1.0, -2.0, 0.5]
    expected = np.linalg.solve(np.array(a), np.array(b))
    assert solve_small([list(r) for r in a], list(b)) == pytest.approx(expected, rel=1e-13)
    assert solve_small([[1.0, 2.0], [2.0, 4.0]], [1.0, 1.0]) is None


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-10.0, 10.0), min_size=9, max_size=9),
    st.lists(st.floats(-100.0, 100.0), min_size=3, max_size=3),
)
def test_the_three_by_three_solve_is_numpys(entries, rhs):
    """The adjugate solve three-link predictions use, against LAPACK: the residual within
    rounding of the matrix's condition, on any matrix numpy solves; None on a singular one."""
    a, r = np.reshape(entries, (3, 3)), np.array(rhs)
    x = solve3([*entries, *rhs])
    if np.linalg.cond(a) > 1e8:
        return  # ill-conditioned: neither answer means much
    assert x is not None
    assert np.array(x) == pytest.approx(np.linalg.solve(a, r), rel=1e-6, abs=1e-6)
    assert solve3([1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 5.0, 1.0, 1.0, 1.0]) is None


def _bits(values):
    return [float(v).hex() for v in values]


@pytest.mark.parametrize(
    'scene_name', ['paper', 'examples/three_link.yaml', 'examples/real_arm.yaml']
)
def test_the_compiled_prediction_and_implicit_law_are_the_float_steps_to_the_bit(scene_name):
    """``free_periods`` and ``implicit_q_law`` (compiled into the scene's kernel module) do
    the float path's operations in its order: the same bits, for closed-form accelerations
    (two and three rods) and for three general links (the mass matrix solved by its
    adjugate), across the law's two targets and 1-3 periods."""
    from repo_paths import REPO_ROOT

    path = resolve_scene_path(scene_name) if '/' not in scene_name else f'{REPO_ROOT}/{scene_name}'
    scene = load_scene(path)
    model = ArmModel(scene)
    ctrl = CycleController.for_scene(model, scene.controller)
    compiled, floats = StatePredictor(model, PERIOD), StatePredictor(model, PERIOD)
    assert compiled._compiled is not None and compiled._compiled_implicit is not None
    floats._compiled = floats._compiled_implicit = None
    rng = np.random.default_rng(5)
    for k in range(60):
        q = rng.uniform(-math.pi, math.pi, model.n).tolist()
        qd = rng.uniform(-10.0, 10.0, model.n).tolist()
        ctrl.mode = ('down', 'up')[k % 2]
        tau = ctrl.torque(q, qd)
        periods = 1 + k % 3
        held = [[(1.0 - 0.3 * j) * t for t in tau] for j in range(periods)]
        for got, expected in zip(compiled.ahead(q, qd, held), floats.ahead(q, qd, held)):
            assert _bits(got) == _bits(expected)
        got = compiled.implicit_command(ctrl.torque, q, qd, tau, periods, ctrl.q_law_terms())
        expected = floats.implicit_command(ctrl.torque_arrays, q, qd, tau, periods)
        assert _bits(got) == _bits(expected)
        assert all(isinstance(t, float) for t in got)


finite = st.floats(-1e3, 1e3) | st.sampled_from([0.0, -0.0, 1.0, -1.0])


@settings(max_examples=300, deadline=None)
@given(st.lists(finite, min_size=4, max_size=4), st.lists(finite, min_size=2, max_size=2))
def test_the_two_by_two_solve_is_the_elimination_to_the_bit(entries, rhs):
    """Written out for two unknowns, ``solve_small`` is the general elimination: the same
    pivot (the first of equal magnitudes), the same None for a zero pivot, the same bits
    (signed zeros included)."""
    a = [entries[:2], entries[2:]]
    got = prediction_module._solve2([list(r) for r in a], list(rhs))
    expected = prediction_module.eliminate([list(r) for r in a], list(rhs))
    assert (got is None) == (expected is None)
    if got is not None:
        assert _bits(got) == _bits(expected)
    tie = [[2.0, 1.0], [-2.0, 3.0]]  # equal pivots: the first row stays
    assert _bits(solve_small([r[:] for r in tie], [1.0, 1.0])) == _bits(
        prediction_module.eliminate([r[:] for r in tie], [1.0, 1.0])
    )
