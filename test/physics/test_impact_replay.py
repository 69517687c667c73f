"""The impact replay (physics/replay.py) against physics that does not go through it: an
impact integrated again from its contact state is the impact of the full run it came from
(contact and separation times, CoR, indentations, force, energies after), and the mechanical
energy it loses is the contact's plastic work, a quadrature of the force laws alone. For the
article's two-link scene and a three-link one; each check shown able to fail."""

import copy
import os

import numpy as np
import pytest
import yaml
from scipy.integrate import quad

from impact_arm.physics import simulate
from impact_arm.physics.contact import (
    YIELD_ONSET_FACTOR,
    hertz_force,
    jackson_green_force,
    restitution_radius,
)
from impact_arm.physics.kinds import ImpactSide
from impact_arm.physics.integrator import IntegratorOptions
from impact_arm.physics.kinds import EventKind
from impact_arm.physics.model import ArmModel
from impact_arm.physics.replay import (
    CONTACT_LEAD,
    Replay,
    ReplayStart,
    contact_rates,
    replay_impact,
)
from impact_arm.physics.scene import parse_scene
from repo_paths import CONFIG

SCENES = ['paper', 'three_link']
# the reference preset in the run and the replay: what is left between them is the
# integrator's error on a different step sequence (the run also stops at each sample)
OPTIONS = 'reference'
TIGHT = 1e-9


def scene_named(name, **surface):
    with open(os.path.join(CONFIG, f'{name}.yaml'), encoding='utf-8') as f:
        data = yaml.safe_load(f.read().replace('e9', 'e+9'))
    data = copy.deepcopy(data)
    data['surfaces'][0].update(surface)
    return parse_scene(data, origin='test')


def full_run(scene):
    """The scene's first impacts in a whole run (continuous control, samples, 1 kHz)."""
    result = simulate.run(scene, t_max=0.7, preset=OPTIONS)
    assert result.impacts and not result.error
    return result


def contact_of(model, result, record):
    """(q, q̇) absolute at the reported contact: q̇ from the tip velocity (and the link
    energies beyond two links, from the last sample's rates)."""
    q = np.radians(record.q_contact_deg)
    v = np.asarray(record.v_before, float)
    if model.n == 2:
        return q, np.linalg.solve(np.asarray(model.tip_jacobian(q)).reshape(2, 2), v)
    last = [s for s in result.samples if s.t <= record.t_contact][-1]
    energies = np.asarray(record.T_before[: model.n], float)
    return q, contact_rates(model, q, v, energies, np.asarray(last.qd, float))


def exact_start(model, record, q, qd):
    """The state CONTACT_LEAD before contact, backed out along the free flight (gravity
    alone: the replay holds no torque) to second order, so that the replay reaches the
    reported contact state, not one a gravity step (~1e-6 rad/s) away from it."""
    h = CONTACT_LEAD
    qdd = np.linalg.solve(model.mass_matrix(q), model.free_forces(q, qd))
    return ReplayStart(record.t_contact - h, q - qd * h + 0.5 * qdd * h * h, qd - qdd * h)


def replayed(model, start):
    options = IntegratorOptions.of_scene(model.scene.integrator, preset=OPTIONS)
    return replay_impact(model, start, options, start.t + 1e-3)


def disagreement(replay_record, record) -> dict:
    """Relative (absolute for times [s]) differences of what the run reported."""
    out = {
        't_contact': abs(replay_record.t_contact - record.t_contact),
        't_separation': abs(
            replay_record.t_contact + replay_record.duration - record.t_contact - record.duration
        ),
    }
    for key in ('cor_kinematic', 'delta_m', 'delta_r', 'F_max'):
        out[key] = abs(getattr(replay_record, key) / getattr(record, key) - 1)
    for key in ('T_before', 'T_after', 'cor_energetic'):
        out[key] = float(
            np.max(np.abs(np.divide(getattr(replay_record, key), getattr(record, key)) - 1))
        )
    return out


@pytest.mark.parametrize('name', SCENES)
def test_a_replayed_impact_is_the_impact_of_the_full_run(name):
    scene = scene_named(name)
    result = full_run(scene)
    model = ArmModel(scene)
    for record in result.impacts[:2]:
        q, qd = contact_of(model, result, record)
        replay = replayed(model, exact_start(model, record, q, qd))
        assert replay.end is not None and replay.end.kind == EventKind.SEPARATION
        assert replay.contact is not None and replay.record is not None
        assert [e.kind for e in replay.events] == [
            'contact',
            'yield',
            'max_compression',
            'separation',
        ]
        off = disagreement(replay.record, record)
        assert off['t_contact'] < 1e-14 and off['t_separation'] < 1e-13, off
        assert max(v for k, v in off.items() if not k.startswith('t_')) < TIGHT, off


@pytest.mark.parametrize('name', SCENES)
def test_the_comparison_with_the_run_tells_a_start_a_micro_radian_per_second_off(name):
    """Not vacuous: the same replay from rates 1e-6 off (relative), as a start that left
    out gravity's step would be, is beyond the tolerance; so is a replay from the start
    moved back along q̇ alone (``before_contact``: the analysis tool's, whose contact state
    is that step off)."""
    scene = scene_named(name)
    result = full_run(scene)
    model = ArmModel(scene)
    record = result.impacts[0]
    q, qd = contact_of(model, result, record)
    start = exact_start(model, record, q, qd)
    nudged = ReplayStart(start.t, start.q, start.qd * (1 + 1e-6))
    for other in (nudged, ReplayStart.before_contact(record.t_contact, q, qd)):
        off = disagreement(replayed(model, other).record, record)
        assert max(v for k, v in off.items() if not k.startswith('t_')) > 10 * TIGHT, off
        # ... while both are still the same impact to a micro-part
        assert off['cor_kinematic'] < 1e-5 and off['t_contact'] < 1e-12


def plastic_work(constants, delta_m, delta_r, law) -> float:
    """The normal force's work on the arm over one impact, a loss: compression work
    (Hertz to 1.9 δc, Jackson–Green beyond) less what the restitution curve from (δm, Pm)
    to δr returns. 0 for an elastic (Hertz) contact."""
    if law == 'hertz':
        return 0.0
    c = constants
    onset = YIELD_ONSET_FACTOR * c.delta_c
    tight = dict(epsabs=0.0, epsrel=1e-12, limit=200)
    loading = quad(lambda d: hertz_force(d, c.E, c.R), 0.0, min(delta_m, onset), **tight)[0]
    peak = hertz_force(delta_m, c.E, c.R)
    if delta_m > onset:
        loading += quad(lambda d: jackson_green_force(d, c), onset, delta_m, **tight)[0]
        peak = jackson_green_force(delta_m, c)
    radius = restitution_radius(delta_m, delta_r, peak, c.E)
    returned = quad(lambda d: hertz_force(d - delta_r, c.E, radius), delta_r, delta_m, **tight)
    return loading - returned[0]


def energy_balance(name, **surface):
    """(mechanical energy lost, plastic work, kinetic energy at contact) of the first
    impact replayed on the scene with ``surface`` changes."""
    scene = scene_named(name, **surface)
    result = full_run(scene)
    model = ArmModel(scene)
    record = result.impacts[0]
    q, qd = contact_of(model, result, record)
    made = replayed(model, exact_start(model, record, q, qd)).record
    assert made is not None
    before = made.T_before[-1] + model.potential_energy(np.radians(made.q_contact_deg))
    after = made.T_after[-1] + model.potential_energy(np.radians(made.q_separation_deg))
    work = plastic_work(
        model.surfaces[0].constants, made.delta_m, made.delta_r, scene.surfaces[0].law
    )
    return before - after, work, made.T_before[-1]


@pytest.mark.parametrize('name', SCENES)
@pytest.mark.parametrize('law', ['elastoplastic', 'hertz'])
def test_a_frictionless_replay_loses_the_contacts_plastic_work_and_nothing_else(name, law):
    lost, work, kinetic = energy_balance(name, mu=0.0, law=law)
    if law == 'elastoplastic':
        assert work > 0.05 * kinetic  # a real loss to account for
    assert abs(lost - work) < 1e-8 * kinetic, (lost, work)


@pytest.mark.parametrize('name', SCENES)
def test_the_energy_balance_sees_the_frictions_work(name):
    """Not vacuous: with Coulomb friction (the scenes' own μ = 0.2) the contact does
    work the plastic balance leaves out, far beyond its tolerance."""
    lost, work, kinetic = energy_balance(name)
    assert lost - work > 1e-3 * kinetic


@pytest.mark.parametrize('name', SCENES)
def test_a_replay_ended_at_yield_and_the_fits_stepping_replay_see_the_runs_phases(name):
    """``end_at`` yield ends at the reported elastic phase's end, with no impact record;
    a ``Replay`` driven to past the separation counts one contact, and its first contact
    and last separation are the run's."""
    scene = scene_named(name)
    result = full_run(scene)
    model = ArmModel(scene)
    record = result.impacts[0]
    q, qd = contact_of(model, result, record)
    start = exact_start(model, record, q, qd)
    options = IntegratorOptions.of_scene(scene.integrator, preset=OPTIONS)
    elastic = replay_impact(model, start, options, start.t + 1e-3, end_at=('yield',))
    assert elastic.record is None and elastic.end is not None and elastic.end.kind == 'yield'
    assert elastic.end.t - record.t_contact == pytest.approx(record.phase_durations[0], rel=1e-9)
    stepping = Replay(model, start, options)
    assert stepping.side is ImpactSide.BEFORE
    t_after = record.t_contact + 2 * record.duration
    while stepping.integrator.state.t < t_after:
        stepping.advance(t_after, stop_at=('contact', 'separation'))
    assert stepping.contacts == 1 and stepping.side is ImpactSide.AFTER
    assert stepping.first is not None and stepping.last is not None
    assert abs(stepping.first.t - record.t_contact) < 1e-14
    assert abs(stepping.last.t - record.t_contact - record.duration) < 1e-13


def test_a_replay_refuses_an_end_that_is_not_an_impacts_nor_plates_it_cannot_place():
    scene = scene_named('paper')
    model = ArmModel(scene)
    start = ReplayStart(0.0, np.zeros(2), np.zeros(2))
    options = IntegratorOptions.of_scene(scene.integrator)
    with pytest.raises(ValueError, match='cannot end an impact'):
        replay_impact(model, start, options, 1e-3, end_at=('contact',))
    with pytest.raises(ValueError, match='plate states'):
        Replay(model, ReplayStart(0.0, np.zeros(2), np.zeros(2), plates=np.zeros(2)), options)
