"""Physics checks that use no article number: closed forms, conservation laws, convergence."""

import math

import numpy as np
import pytest
from scipy.special import beta

from impact_arm.physics.contact import (
    contact_constants,
    hertz_force,
    jackson_green_force,
    residual_indentation,
    restitution_force,
    restitution_radius,
)
from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import Material
from impact_arm.physics.simulate import run

from scenes import scene_from
from two_rods import generalized_momentum, mass_matrix_by_hand, vertical_strike_scene

STEEL = Material(E=210e9, nu=0.29, S_y=1.12e9)


def free_scene(**top):
    top.setdefault('surfaces', [])
    top.setdefault('cycles', 0)
    return scene_from({('controller', 'law'): 'none'}, **top)


def test_generated_mass_matrix_matches_hand_derivation():
    model = ArmModel(free_scene(gravity=0.0))
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-3, 3, 2).tolist()
        assert np.allclose(model.mass_matrix(q), mass_matrix_by_hand(q), rtol=1e-13, atol=1e-13)


def test_energy_is_conserved_in_free_motion_without_control():
    scene = free_scene(t_max=10.0, publish_rate=100.0)
    result = run(scene, preset='reference')
    model = ArmModel(scene)
    energy = [
        sum(model.link_energies(s.q, s.qd)) + model.potential_energy(s.q) for s in result.samples
    ]
    scale = max(abs(model.potential_energy(s.q)) for s in result.samples)
    assert result.samples[-1].t == pytest.approx(10.0)
    assert max(abs(e - energy[0]) for e in energy) / scale < 1e-8
    # the arm really moved: a test that ends at rest would prove nothing
    assert max(sum(model.link_energies(s.q, s.qd)) for s in result.samples) > 5.0


def test_hertz_impact_matches_closed_form_indentation_and_duration():
    v = 0.5
    result = run(vertical_strike_scene(v), preset='accurate')
    assert len(result.impacts) == 1
    impact = result.impacts[0]
    c = contact_constants(STEEL, STEEL, 0.005)
    m_eff = 4.0 / 3.0
    k = 4.0 / 3.0 * c.E * math.sqrt(c.R)
    delta_m = (5 * m_eff * v**2 / (4 * k)) ** 0.4  # ½mv² = (2/5) k δm^(5/2)
    duration = 2 * (2 / 5) * beta(2 / 5, 1 / 2) * delta_m / v  # ∫ dδ / δ̇ over load + unload
    assert impact.delta_m == pytest.approx(delta_m, rel=1e-6)
    assert impact.duration == pytest.approx(duration, rel=1e-6)
    assert impact.F_max == pytest.approx(k * delta_m**1.5, rel=1e-6)
    assert impact.delta_r == 0.0
    assert impact.cor_kinematic == pytest.approx(1.0, abs=1e-6)  # Hertz is elastic


def test_sliding_friction_impulse_is_mu_times_normal_impulse():
    mu = 0.2
    scene = vertical_strike_scene(0.5, law='elastoplastic', mu=mu, qd2=2.0)  # tip slides at 2 m/s
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, preset='accurate', trace=True)
    states = {}
    while 'separation' not in states:
        for event in integ.advance(0.002, stop_at_event=True):
            states[event.kind] = event.y
    assert set(states) == {'contact', 'yield', 'max_compression', 'separation'}
    assert min(abs(row[5]) for row in integ.trace) > 50 * 0.02  # sliding all through
    # impulses from the momentum change across the impact, not from the force law
    dp = generalized_momentum(states['separation']) - generalized_momentum(states['contact'])
    normal, tangential = dp  # at this pose Jy = (1, 0) and Jx = (0, 1)
    assert normal > 0.5  # a real impact
    # 0.5 %: over the ~0.2 ms impact link 2 turns by ~4e-4 rad, so the Jacobian and the
    # velocity-product terms leak ~0.2 % between the two momenta
    assert tangential / normal == pytest.approx(-mu, rel=5e-3)


def test_contact_force_laws_join_where_the_model_says():
    c = contact_constants(STEEL, STEEL, 0.005)
    d_y = 1.9 * c.delta_c
    jump = jackson_green_force(d_y, c) / hertz_force(d_y, c.E, c.R) - 1
    assert 0.001 < jump < 0.01  # docs/model.md: about +0.6 % at 1.9 δc
    # restitution starts exactly at (δm, Pm) and ends at zero force at δr
    delta_m = 100 * c.delta_c
    p_m = jackson_green_force(delta_m, c)
    delta_r = residual_indentation(delta_m, c)
    r_r = restitution_radius(delta_m, delta_r, p_m, c.E)
    assert 0 < delta_r < delta_m
    assert restitution_force(delta_m, delta_r, c.E, r_r) == pytest.approx(p_m, rel=1e-12)
    assert restitution_force(delta_r, delta_r, c.E, r_r) == 0.0
    # below yield the contact unloads along its own Hertz curve
    assert residual_indentation(0.5 * c.delta_c, c) == 0.0
    assert restitution_radius(
        0.5 * c.delta_c, 0.0, hertz_force(0.5 * c.delta_c, c.E, c.R), c.E
    ) == pytest.approx(c.R, rel=1e-12)


def first_impact(rtol):
    scene = scene_from(cycles=1)
    return run(scene, rtol=rtol, atol=rtol * 1e-2).impacts[0]


def test_first_impact_metrics_converge_as_tolerances_tighten():
    reference = first_impact(1e-12)
    keys = ('delta_m', 'F_max', 'duration', 'cor_kinematic')

    def error(impact):
        rel = [abs(getattr(impact, k) / getattr(reference, k) - 1) for k in keys]
        rel.append(abs(impact.v_after[1] / reference.v_after[1] - 1))
        return max(rel)

    errors = [error(first_impact(rtol)) for rtol in (1e-4, 1e-6, 1e-8, 1e-10)]
    assert errors[0] > errors[1] > errors[2] > errors[3] or errors[3] < 1e-9, errors
    assert errors[-1] < 1e-7
    assert errors[0] < 0.05


def step_response(law):
    scene = scene_from(
        {('controller', 'law'): law, ('controller', 'down_target_deg'): [80.0, 70.0]},
        surfaces=[],
        cycles=0,
        t_max=6.0,
        publish_rate=100.0,
    )
    result = run(scene)
    q = np.degrees(np.array([s.q for s in result.samples]))
    return q - [80.0, 70.0]


def test_q_controller_reaches_target_without_steady_error():
    error = step_response('q')
    assert np.all(np.abs(error[-1]) < 1e-4)


def test_pd_controller_stops_short_of_the_target_against_gravity():
    error = step_response('pd')
    assert np.all(error[-1] < -0.1)  # degrees short, both links
    assert np.all(np.abs(error[-1] - error[-50]) < 1e-3)  # and it stays there


def test_pid_controller_overshoots_then_settles():
    error = step_response('pid')
    assert np.all(error.max(axis=0) > 1.0)  # overshoot of more than a degree
