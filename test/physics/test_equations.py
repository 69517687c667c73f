"""The chain's closed-form equations (used past ``SYMBOLIC_LINKS`` links) against the symbolic
derivation for 2-4 links, and against mechanics itself (kinetic energy = ½ q̇ᵀ M q̇, energy
conserved along an undamped motion) for a long chain the symbolic path cannot reach cheaply."""

import math

import numpy as np
import pytest

from impact_arm.physics import equations

FUNCTIONS = (
    'mass_and_rhs',
    'tip',
    'tip_acceleration',
    'tip_jacobian',
    'gravity_forces',
    'link_energies',
    'potential',
)


def functions(source):
    """The generated functions as plain Python (no compilation)."""
    namespace = {
        'jit_leaf': lambda f: f,
        'sin': math.sin,
        'cos': math.cos,
        'sqrt': math.sqrt,
        'math': math,
    }
    exec(source, namespace)
    return namespace


def arguments(rng, n):
    q, qd, qdd, Qx = (rng.uniform(-3, 3, n) for _ in range(4))
    L, m = rng.uniform(0.2, 1.5, n), rng.uniform(0.3, 2.0, n)
    g = 9.81
    return {
        'mass_and_rhs': (q, qd, Qx, L, m, g),
        'tip': (q, qd, L),
        'tip_acceleration': (q, qd, qdd, L),
        'tip_jacobian': (q, L),
        'gravity_forces': (q, L, m, g),
        'link_energies': (q, qd, L, m),
        'potential': (q, L, m, g),
    }


@pytest.mark.parametrize('n', [2, 3, 4])
def test_closed_form_matches_the_symbolic_derivation(n):
    symbolic = functions(
        equations._derive_source(n) + equations.MASS_INTO_WRAPPER
        if n > equations.SYMBOLIC_LINKS
        else equations._derivation(n)
    )
    chain = functions(equations._chain_source(n))
    rng = np.random.default_rng(n)
    for _ in range(20):
        args = arguments(rng, n)
        for name in FUNCTIONS:
            want = np.array(symbolic[name](*args[name]))
            got = np.array(chain[name](*args[name]))
            assert got.shape == want.shape, name
            scale = max(1.0, np.max(np.abs(want)))
            assert np.max(np.abs(got - want)) <= 1e-12 * scale, (name, got, want)
        # the kernel's form (arrays, not a tuple): the same numbers
        want = np.array(symbolic['mass_and_rhs'](*args['mass_and_rhs']))
        for f in (symbolic, chain):
            S, out = np.zeros(n * n), np.zeros(n)
            f['mass_and_rhs_into'](*args['mass_and_rhs'], S, out)
            got = np.concatenate([S, out])
            assert np.max(np.abs(got - want)) <= 1e-12 * max(1.0, np.max(np.abs(want)))


def kinetic_energy(f, q, qd, L, m):
    n = len(q)
    M = np.array(f['mass_and_rhs'](q, qd, np.zeros(n), L, m, 9.81)[: n * n]).reshape(n, n)
    return 0.5 * qd @ M @ qd, M


def test_long_chain_kinetic_energy_is_the_mass_matrix_form():
    n = 9
    f = functions(equations._chain_source(n))
    rng = np.random.default_rng(1)
    for _ in range(10):
        q, qd = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
        L, m = rng.uniform(0.2, 1.5, n), rng.uniform(0.3, 2.0, n)
        T, M = kinetic_energy(f, q, qd, L, m)
        assert sum(f['link_energies'](q, qd, L, m)) == pytest.approx(T, rel=1e-12)
        assert np.allclose(M, M.T) and np.all(np.linalg.eigvalsh(M) > 0)


def test_long_chain_conserves_energy_in_free_swing():
    """No torque, no contact: T + V stays constant to the integration error (RK4, fixed
    step), which fails if the velocity terms or gravity's forces disagree with T and V."""
    n, dt = 7, 2e-4
    f = functions(equations._chain_source(n))
    L, m = np.linspace(0.3, 0.6, n), np.linspace(1.0, 0.4, n)

    def rate(y):  # through the kernel's form of the equations
        q, qd = y[:n], y[n:]
        S, b = np.zeros(n * n), np.zeros(n)
        f['mass_and_rhs_into'](q, qd, np.zeros(n), L, m, 9.81, S, b)
        return np.concatenate([qd, np.linalg.solve(S.reshape(n, n), b)])

    def energy(y):
        q, qd = y[:n], y[n:]
        return sum(f['link_energies'](q, qd, L, m)) + f['potential'](q, L, m, 9.81)[0]

    y = np.concatenate([np.linspace(0.2, 1.4, n), np.zeros(n)])
    e0 = energy(y)
    swing = max(abs(energy(np.concatenate([y[:n], np.ones(n)])) - e0), 1.0)
    for _ in range(2500):  # 0.5 s
        k1 = rate(y)
        k2 = rate(y + 0.5 * dt * k1)
        k3 = rate(y + 0.5 * dt * k2)
        k4 = rate(y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert abs(np.max(np.abs(y[n:]))) > 1.0  # it did swing
    assert abs(energy(y) - e0) < 1e-6 * swing


def pinocchio_chain(pin, L, m, g):
    """The same chain built in Pinocchio: revolute z joints (relative angles), each link a
    uniform rod along its x axis, gravity along -y."""
    model = pin.Model()
    model.gravity.linear = np.array([0.0, -g, 0.0])
    parent = 0
    for i in range(len(L)):
        offset = pin.SE3(np.eye(3), np.array([L[i - 1] if i else 0.0, 0.0, 0.0]))
        joint = model.addJoint(parent, pin.JointModelRZ(), offset, f'joint{i}')
        rod = np.diag([0.0, m[i] * L[i] ** 2 / 12, m[i] * L[i] ** 2 / 12])
        model.appendBodyToJoint(
            joint, pin.Inertia(m[i], np.array([L[i] / 2, 0.0, 0.0]), rod), pin.SE3.Identity()
        )
        parent = joint
    return model, model.createData()


@pytest.mark.parametrize('n', [4, 6, 9])
def test_long_chain_matches_pinocchio(n):
    """An independent oracle: Pinocchio's mass matrix (CRBA) and inverse dynamics at zero
    acceleration (RNEA: velocity terms and gravity) in relative joint angles θ, against the
    closed form in absolute angles q = T θ (T: lower triangle of ones), i.e.
    M_θ = Tᵀ M_q T and RNEA = Tᵀ (b - Q_g)."""
    pin = pytest.importorskip('pinocchio')
    f = functions(equations._chain_source(n))
    rng = np.random.default_rng(n)
    g = 9.81
    T = np.tril(np.ones((n, n)))
    for _ in range(10):
        L, m = rng.uniform(0.2, 1.5, n), rng.uniform(0.3, 2.0, n)
        q, qd = rng.uniform(-3, 3, n), rng.uniform(-3, 3, n)
        model, data = pinocchio_chain(pin, L, m, g)
        theta, theta_d = np.linalg.solve(T, q), np.linalg.solve(T, qd)
        S, rhs = np.zeros(n * n), np.zeros(n)
        f['mass_and_rhs_into'](q, qd, np.zeros(n), L, m, g, S, rhs)
        M_theta = pin.crba(model, data, theta)
        M_theta = np.triu(M_theta) + np.triu(M_theta, 1).T  # crba fills the upper half
        assert np.allclose(T.T @ S.reshape(n, n) @ T, M_theta, rtol=1e-12, atol=1e-12)
        bias = pin.rnea(model, data, theta, theta_d, np.zeros(n))
        assert np.allclose(-T.T @ rhs, bias, rtol=1e-11, atol=1e-10)


def general_geometry(rng, n):
    """Lengths, centres of mass along and across each link (some behind the joint), inertias
    about them and a contact point off the last link's axis (``equations.GEOMETRY``)."""
    L = rng.uniform(0.2, 1.5, n)
    return np.concatenate(
        [
            L,
            rng.uniform(-0.3, 1.0, n) * L,
            rng.uniform(-0.3, 0.3, n) * L,
            rng.uniform(0.01, 0.3, n),
            [rng.uniform(0.5, 1.2) * L[-1], rng.uniform(-0.2, 0.2) * L[-1]],
        ]
    )


@pytest.mark.parametrize('n', [2, 3])
def test_general_links_closed_form_matches_the_symbolic_derivation(n):
    symbolic = functions(equations._derivation(n, general=True))
    chain = functions(equations._general_chain_source(n))
    assert ('accel' in symbolic) == (n <= equations.GENERAL_SYMBOLIC_ACCEL)
    rng = np.random.default_rng(10 + n)
    for _ in range(20):
        args = arguments(rng, n)
        G = general_geometry(rng, n)
        args = {
            name: tuple(G if isinstance(a, np.ndarray) and a is args['tip'][2] else a for a in v)
            for name, v in args.items()
        }
        for name in FUNCTIONS:
            want = np.array(symbolic[name](*args[name]))
            got = np.array(chain[name](*args[name]))
            assert got.shape == want.shape, name
            assert np.max(np.abs(got - want)) <= 1e-12 * max(1.0, np.max(np.abs(want))), name
        values = np.array(symbolic['mass_and_rhs'](*args['mass_and_rhs']))
        for f in (symbolic, chain):
            S, out = np.zeros(n * n), np.zeros(n)
            f['mass_and_rhs_into'](*args['mass_and_rhs'], S, out)
            got = np.concatenate([S, out])
            assert np.max(np.abs(got - values)) <= 1e-12 * max(1.0, np.max(np.abs(values)))
        if 'accel' in symbolic:
            M = values[: n * n].reshape(n, n)
            want = np.linalg.solve(M, values[n * n :])
            assert np.allclose(symbolic['accel'](*args['mass_and_rhs']), want, rtol=1e-10)


@pytest.mark.parametrize('n', [2, 3, 7])
def test_general_links_with_rod_geometry_are_the_rod_equations(n):
    rods = functions(equations._chain_source(n))
    general = functions(equations._general_chain_source(n))
    rng = np.random.default_rng(n)
    for _ in range(5):
        args = arguments(rng, n)
        L, m = args['tip'][2], args['mass_and_rhs'][4]
        G = np.concatenate([L, L / 2, np.zeros(n), m * L * L / 12, [L[-1], 0.0]])
        for name in FUNCTIONS:
            rod_args = args[name]
            general_args = tuple(G if a is L else a for a in rod_args)
            want = np.array(rods[name](*rod_args))
            got = np.array(general[name](*general_args))
            assert np.max(np.abs(got - want)) <= 1e-13 * max(1.0, np.max(np.abs(want))), name


def test_general_long_chain_conserves_energy_in_free_swing():
    """As for rods: offsets across the links bring the B_ij sin terms into M and the
    velocity terms; an error in any of them breaks T + V conservation."""
    n, dt = 6, 2e-4
    f = functions(equations._general_chain_source(n))
    G = general_geometry(np.random.default_rng(5), n)
    m = np.linspace(1.0, 0.4, n)

    def rate(y):
        q, qd = y[:n], y[n:]
        S, b = np.zeros(n * n), np.zeros(n)
        f['mass_and_rhs_into'](q, qd, np.zeros(n), G, m, 9.81, S, b)
        return np.concatenate([qd, np.linalg.solve(S.reshape(n, n), b)])

    def energy(y):
        q, qd = y[:n], y[n:]
        return sum(f['link_energies'](q, qd, G, m)) + f['potential'](q, G, m, 9.81)[0]

    y = np.concatenate([np.linspace(0.2, 1.4, n), np.zeros(n)])
    e0 = energy(y)
    swing = max(abs(energy(np.concatenate([y[:n], np.ones(n)])) - e0), 1.0)
    for _ in range(2500):
        k1 = rate(y)
        k2 = rate(y + 0.5 * dt * k1)
        k3 = rate(y + 0.5 * dt * k2)
        k4 = rate(y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert abs(np.max(np.abs(y[n:]))) > 1.0
    assert abs(energy(y) - e0) < 1e-6 * swing
    T, M = kinetic_energy(f, y[:n], y[n:], G, m)
    assert sum(f['link_energies'](y[:n], y[n:], G, m)) == pytest.approx(T, rel=1e-12)
