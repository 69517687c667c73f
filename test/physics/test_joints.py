"""Joint damping, Coulomb friction and armature (scene ``joints``): checked against closed forms,
an energy balance and Pinocchio, never against numbers the code produced."""

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.physics.errors import SceneError
from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel

from scenes import scene_from
from repo_paths import EXAMPLES


def joints(n=2, **values):
    """``joints`` entries: each keyword a list with one value per joint."""
    return [{k: float(v[i]) for k, v in values.items()} for i in range(n)]


def free_scene(joint_values, gravity=9.81, **top):
    """The article's arm without surfaces or controller, with the given joints."""
    top.setdefault('surfaces', [])
    top.setdefault('cycles', 0)
    return scene_from({('controller', 'law'): 'none'}, gravity=gravity, joints=joint_values, **top)


def held_integrator(scene, q0, qd0, tau):
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, preset='reference', control='held')
    integ.set_state(0.0, q0, qd0)
    integ.set_held_torque(tau)
    return model, integ


def test_ideal_joints_are_the_default_and_off():
    model = ArmModel(scene_from())
    assert not model.damping.any() and not model.friction.any() and not model.armature.any()
    assert model.friction_v_d.tolist() == [0.01, 0.01]
    P = model.parameters(1e-8, 1e-10, 1.0)
    assert P[model.eq.P_JFRIC_ON] == 0.0 and P[model.eq.P_ARM_ON] == 0.0


@pytest.mark.parametrize(
    'entry, message',
    [
        ({'damping': -1.0}, 'joints[0].damping = -1 is out of range: must be >= 0'),
        ({'friction': math.inf}, 'joints[0].friction = inf is not finite'),
        ({'friction_v_d': 0.0}, 'joints[0].friction_v_d = 0 is out of range: must be >= 1e-06'),
        ({'armature': -0.1}, 'joints[0].armature = -0.1 is out of range'),
        ({'stiction': 1.0}, 'joints[0].stiction is not a known key'),
        # decay rates beyond what explicit steps can follow
        ({'damping': 1e6}, 'joints[0].damping = 1e+06 is out of range: gives a decay rate'),
        (
            {'friction': 1e3, 'friction_v_d': 1e-6},
            'joints[0].friction = 1000 is out of range: gives a decay rate',
        ),
        ({'armature': 1e6}, 'joints[0].armature = 1e+06 is out of range: must be <= 10000 times'),
    ],
)
def test_bad_joint_values_are_refused_in_one_line(entry, message):
    with pytest.raises(SceneError) as err:
        scene_from(joints=[entry, {}])
    assert message in str(err.value)
    assert '\n' not in str(err.value)


def test_one_joint_entry_per_link():
    with pytest.raises(SceneError, match=r'joints has 1 entries: must have one per link \(2\)'):
        scene_from(joints=[{'damping': 1.0}])


def test_coulomb_smoothing_at_1e_4_and_armature_100x_are_accepted():
    scene = scene_from(joints=[{'friction': 0.5, 'friction_v_d': 1e-4}, {'armature': 100 * 0.5}])
    assert scene.joints[0].friction_v_d == 1e-4 and scene.joints[1].armature == 50.0


def pinocchio_chain(pin, L, m, g):
    """The chain in Pinocchio: revolute z joints (relative angles θ), uniform rods along x."""
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


@pytest.mark.parametrize('n', [2, 4])
def test_accelerations_with_joint_friction_and_armature_match_pinocchio(n):
    """q̈ of the kernel's right-hand side (held motor torques, damping, smoothed Coulomb
    friction, armature) against Pinocchio in relative angles θ: (M_θ + diag(J)) θ̈ =
    τ + τ_f(θ̇) - RNEA(θ, θ̇, 0), with τ_f,i = -(d_i θ̇_i + f_i tanh(θ̇_i / v_i)); q = cumsum θ."""
    pin = pytest.importorskip('pinocchio')
    rng = np.random.default_rng(n)
    links = [
        {'length': float(x), 'mass': float(y)}
        for x, y in zip(rng.uniform(0.4, 1.2, n), rng.uniform(0.5, 2, n))
    ]
    gains = {
        'kp': [0.0] * n,
        'kd': [0.0] * n,
        'down_target_deg': [0.0] * n,
        'up_target_deg': [0.0] * n,
    }
    d, f, v, J = (rng.uniform(0.05, 2.0, n) for _ in range(4))
    v *= 0.1
    scene = scene_from(
        {('controller', 'law'): 'none'},
        links=links,
        controller=gains,
        initial={'q_deg': [10.0] * n},
        surfaces=[],
        cycles=0,
        joints=joints(n, damping=d, friction=f, friction_v_d=v, armature=J),
    )
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, control='held')
    L, m = model.L, model.m
    pmodel, pdata = pinocchio_chain(pin, L, m, model.g)
    T = np.tril(np.ones((n, n)))  # q = T θ
    for _ in range(5):
        theta, theta_d = rng.uniform(-2, 2, n), rng.uniform(-0.3, 0.3, n)
        tau = rng.uniform(-5, 5, n)
        integ.set_held_torque(tau)
        ydot = integ.rhs(0.0, np.concatenate([T @ theta, T @ theta_d]))
        M = pin.crba(pmodel, pdata, theta)
        M = np.triu(M) + np.triu(M, 1).T + np.diag(J)
        bias = pin.rnea(pmodel, pdata, theta, theta_d, np.zeros(n))
        tau_f = -(d * theta_d + f * np.tanh(theta_d / v))
        theta_dd = np.linalg.solve(M, tau + tau_f - bias)
        assert np.allclose(ydot[n:], T @ theta_dd, rtol=1e-10, atol=1e-10)


def rigid_rotation_torques(model, alpha, friction=0.0):
    """Held torques that turn the straight arm (q1 = q2) as one rigid body at angular
    acceleration α, gravity off: joint 2 carries link 2's inertial moment about itself,
    α m2 (L2²/3 + L1 L2/2) (centripetal forces point along the straight arm and have no
    moment); joint 1 the whole arm's about O plus its rotor, and its Coulomb friction (the arm
    turns far faster than the smoothing rate: tanh = 1). Joint 2 does not turn relatively
    (ω2 = 0): its armature and friction do nothing."""
    (L1, L2), (m1, m2) = model.L, model.m
    inertia = m1 * L1**2 / 3 + m2 * (L2**2 / 12 + (L1 + L2 / 2) ** 2) + model.armature[0]
    return [alpha * inertia + friction, alpha * m2 * (L2**2 / 3 + L1 * L2 / 2)]


@pytest.mark.parametrize('coulomb', [0.0, 1.5])
def test_rigid_rotation_with_armature_and_friction_follows_the_closed_form(coulomb):
    """q1(t) = q1(0) + ω0 t + ½ α t² with the rotor and the joint's Coulomb friction in the
    balance; armature 100x link 1's own inertia, friction and armature on joint 2 too (its
    relative rate stays zero: a law acting on absolute rates would bend the arm)."""
    rod = 1.0 * 1.0**2 / 12  # the article's links: 1 m, 1 kg
    scene = free_scene(
        joints(2, armature=[100 * rod, 3 * rod], friction=[coulomb, 2.0]), gravity=0.0
    )
    model = ArmModel(scene)
    alpha, omega0, q0 = 2.0, 1.0, 0.3
    _, integ = held_integrator(
        scene, [q0, q0], [omega0, omega0], rigid_rotation_torques(model, alpha, coulomb)
    )
    for t in (0.1, 0.5, 1.0):
        integ.advance(t)
        expected = q0 + omega0 * t + 0.5 * alpha * t**2
        y = integ.state.y
        assert y[0] == pytest.approx(expected, rel=1e-9)
        assert y[1] == pytest.approx(expected, rel=1e-9)
        assert y[2] == pytest.approx(omega0 + alpha * t, rel=1e-9)


def test_torque_below_coulomb_friction_only_creeps():
    """At rest under τ1 = ½ f (f on both joints), the arm creeps at most at the smoothed law's
    balance rate v_d atanh(τ/f) (0.0055 rad/s) instead of accelerating; the same torque
    without friction turns link 1 by 0.37 rad within the second."""
    f, v_d, tau1 = 1.0, 0.01, 0.5
    creep = v_d * math.atanh(tau1 / f)
    scene = free_scene(joints(2, friction=[f, f], friction_v_d=[v_d, v_d]), gravity=0.0)
    _, integ = held_integrator(scene, [0.3, 0.3], [0.0, 0.0], [tau1, 0.0])
    peak = 0.0
    for k in range(1, 101):
        integ.advance(0.01 * k)
        peak = max(peak, float(np.max(np.abs(integ.state.y[2:4]))))
    assert peak <= creep * (1 + 1e-6)
    assert integ.state.y[2] == pytest.approx(creep, rel=1e-3)  # the balance, reached
    _, ideal = held_integrator(free_scene([], gravity=0.0), [0.3, 0.3], [0.0, 0.0], [tau1, 0.0])
    ideal.advance(1.0)
    assert abs(ideal.state.y[0] - 0.3) > 50 * abs(integ.state.y[0] - 0.3)


def simpson(values, dt):
    values = np.asarray(values)
    assert len(values) % 2 == 1
    return dt / 3 * (values[0] + values[-1] + 4 * values[1:-1:2].sum() + 2 * values[2:-1:2].sum())


def energy_and_dissipation(model, integ, times):
    """Total mechanical energy (links, rotors, gravity) at ``times`` and the power the
    joints' damping and friction dissipate there, computed from the scene's values."""
    n = model.n
    energy, power = [], []
    for t in times:
        integ.advance(t)
        q, qd = integ.state.y[:n], integ.state.y[n : 2 * n]
        omega = np.diff(qd, prepend=0.0)
        energy.append(
            sum(model.eq.link_energies(q, qd, model.L, model.m))
            + float(np.sum(0.5 * model.armature * omega**2))
            + model.potential_energy(q)
        )
        power.append(
            float(
                np.sum(
                    model.damping * omega**2
                    + model.friction * omega * np.tanh(omega / model.friction_v_d)
                )
            )
        )
    return np.array(energy), np.array(power)


def test_energy_lost_equals_the_dissipation_integral():
    """Swinging under gravity with damping, Coulomb friction and armature: E(0) - E(t) =
    ∫ Σ (d ω² + f ω tanh(ω/v_d)) dt (Simpson's rule on a 0.1 ms grid)."""
    scene = free_scene(
        joints(
            2,
            damping=[0.05, 0.02],
            friction=[0.1, 0.05],
            friction_v_d=[0.05, 0.05],
            armature=[0.2, 0.1],
        )
    )
    model, integ = held_integrator(scene, [0.3, 1.2], [0.0, 0.0], [0.0, 0.0])
    dt = 1e-4
    times = np.arange(0, 20001) * dt
    energy, power = energy_and_dissipation(model, integ, times)
    lost = energy[0] - energy[-1]
    assert lost > 0.05 * abs(energy[0])  # it did dissipate
    assert lost == pytest.approx(simpson(power, dt), rel=1e-6)


def test_friction_acts_during_contact():
    """The balance holds through an elastic (Hertz) impact, whose contact energy
    (8/15) E* √R δ^(5/2) is conservative: the joints' losses in contact are accounted for."""
    scene = scene_from(
        {('controller', 'law'): 'none'},
        surfaces=[{'height': -1.2, 'law': 'hertz', 'material': 'steel'}],
        cycles=0,
        joints=joints(2, damping=[0.5, 0.3], friction=[0.2, 0.2], friction_v_d=[0.1, 0.1]),
    )
    model, integ = held_integrator(
        scene, [math.radians(-30), math.radians(-40)], [0.0, 0.0], [0, 0]
    )
    events = integ.advance(5.0, stop_at_event=('contact',))
    assert events and events[-1].kind == 'contact'
    t0 = integ.state.t
    surface = model.surfaces[0]
    k = 8 / 15 * surface.constants.E * math.sqrt(surface.constants.R)
    dt = 2e-7
    times = t0 + np.arange(0, 4001) * dt  # 0.8 ms: the whole contact
    n = model.n
    energy, power, in_contact = [], [], []
    for t in times:
        e, p = energy_and_dissipation(model, integ, [t])
        delta = surface.height - model.tip(integ.state.y[:n], integ.state.y[n : 2 * n])[1]
        in_contact.append(delta > 0)
        energy.append(e[0] + (k * delta**2.5 if delta > 0 else 0.0))
        power.append(p[0])
    assert any(in_contact) and not in_contact[-1]  # struck and left
    assert energy[0] - energy[-1] == pytest.approx(simpson(power, dt), rel=1e-5)
    assert energy[0] - energy[-1] > 0


def test_reported_effort_is_the_motor_torque_not_the_friction():
    from impact_arm.driver.arm import SimulatedArm

    scene = free_scene(joints(2, damping=[2.0, 2.0], friction=[1.0, 1.0]))
    arm = SimulatedArm(scene, rate=1000.0)
    arm.apply([3.0, -1.0])
    tick = arm.step()
    tick = arm.step()
    assert tick.effort == [3.0, -1.0]
    assert any(abs(v) > 0.01 for v in tick.velocity)  # it moved: friction was acting


JOINT_LEAVES = st.one_of(
    st.sampled_from([0.0, 1e-4, 0.01, 1.0, 100 / 12, 1e3, 1e6, -1.0, 5e-324, 1e308]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.none(),
    st.text(max_size=3),
)


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(
    st.lists(
        st.dictionaries(
            st.sampled_from(['damping', 'friction', 'friction_v_d', 'armature', 'extra']),
            JOINT_LEAVES,
            max_size=4,
        ),
        min_size=1,
        max_size=3,
    )
)
def test_any_joints_run_to_a_finite_end_or_are_refused_in_one_line(entries):
    """Fuzzed ``joints`` on the article's scene: refused in one line, or a run (its first
    impact, with the article's controller) whose every number is finite or which stops by
    name at a limit."""
    from impact_arm.physics.simulate import run

    try:
        scene = scene_from(joints=entries, cycles=1, t_max=0.6)
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    result = run(scene, keep_samples=False)
    if result.error:
        assert '\n' not in result.error
        return
    values = json.dumps(result.to_json())
    assert 'NaN' not in values and 'Infinity' not in values


def test_joint_values_are_sweep_keys_even_where_the_scene_states_no_joints():
    """A sweep over joints[1].damping on the article's scene (which has no ``joints``): the
    run is the scene with that joint damped: its first impact comes at another time."""
    from impact_arm.calibration.study import Study

    study = Study('paper')
    scene = study.scene({'joints[1].damping': 2.0})
    assert [j.damping for j in scene.joint_specs] == [0.0, 2.0]
    ideal, damped = study.run({'cycles': 1}), study.run({'cycles': 1, 'joints[1].damping': 2.0})
    assert not ideal.error and not damped.error
    assert abs(damped.impacts[0].t_contact - ideal.impacts[0].t_contact) > 1e-3
    refused = study.run({'joints[2].damping': 2.0})
    assert 'joints[2]' in refused.error and 'has 2 entries' in refused.error


def test_joint_values_are_fit_parameters():
    from impact_arm.calibration.fit import parameter_specs
    from impact_arm.calibration.study import Study, apply_overrides

    scene = apply_overrides(Study('paper').data, {'joints[0].friction': 0.5})
    (spec,) = parameter_specs(Study(scene), {'joints[0].friction': (0.0, 3.0)})
    assert (spec.key, spec.start) == ('joints[0].friction', 0.5)


def test_a_recording_of_an_arm_with_joint_friction_fits_once_the_scene_has_it():
    """A recording of the article's arm with 1 N m of Coulomb friction in both joints: fitted
    with ideal joints it does not fit (the fit blames the contact); with the joints' friction
    free it fits, finds the contact's μ and S_y, and its intervals hold the friction drawn."""
    from impact_arm.calibration.fit import fit
    from impact_arm.calibration.study import Study, apply_overrides
    from impact_arm.io.synthetic import synthetic_recording

    truth = {'joints[0].friction': 1.0, 'joints[1].friction': 1.0}
    rec = synthetic_recording('paper', truth, cycles=6, drop=0.02, clock_offset=1.7e9, seed=5)
    contact = {'surfaces[0].mu': (0.05, 1.0), 'materials.steel.S_y': (2e8, 5e9)}
    assert fit(rec, 'paper', contact).verdict.startswith('does not fit')
    scene = apply_overrides(Study('paper').data, {k: 0.5 for k in truth})
    result = fit(rec, scene, {**contact, **{k: (0.0, 3.0) for k in truth}})
    assert result.fits, result.verdict
    assert result.parameters['surfaces[0].mu'].value == pytest.approx(0.2, rel=0.02)
    assert result.parameters['materials.steel.S_y'].value == pytest.approx(1.12e9, rel=0.03)
    for key in truth:
        lo, hi = result.parameters[key].ci95
        assert lo < 1.0 < hi


def test_a_urdf_arms_dynamics_act_and_the_scene_may_override_them():
    """examples/three_link.urdf's <dynamics damping friction> become the model's joint
    damping and friction; the scene's ``joints`` sets a value on top (a key left out keeps
    the file's) and adds what a URDF has no words for (armature). A URDF arm's scene states
    its joints list (empty entries) for that: its length is the URDF's."""
    import os

    from impact_arm.calibration.study import Study

    path = os.path.join(EXAMPLES, 'three_link.yaml')
    study = Study(path, {'joints': [{}, {}, {}]})
    model = ArmModel(study.scene())
    assert model.damping.tolist() == [0.05, 0.05, 0.02]
    assert model.friction.tolist() == [0.2, 0.15, 0.1]
    override = ArmModel(study.scene({'joints[0].damping': 0.5, 'joints[2].armature': 0.01}))
    assert override.damping[0] == 0.5 and override.damping[1] == model.damping[1]
    assert override.friction.tolist() == model.friction.tolist()
    assert override.armature.tolist() == [0.0, 0.0, 0.01]
