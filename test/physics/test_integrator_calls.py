"""The calls a user of ``PhaseIntegrator`` changes it by: ``set_held_torque`` (a new command)
and ``set_state`` (the arm placed elsewhere). After either, the integration must be the one a
fresh integrator started there would take: nothing cached from before may leak into it."""

import numpy as np
import pytest

from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel

from scenes import scene_from

OPTIONS = dict(control='held', rtol=1e-8, atol=1e-10)


def _fresh(model, t, y, tau):
    state = model.initial_state()
    state.t = t
    state.y[: 2 * model.n] = y[: 2 * model.n]
    integ = PhaseIntegrator(model, state, **OPTIONS)
    integ.set_held_torque(tau)
    return integ


def test_a_new_held_torque_acts_as_on_a_fresh_integrator():
    model = ArmModel(scene_from())
    integ = PhaseIntegrator(model, **OPTIONS)
    integ.set_held_torque([1.0, -0.5])
    integ.advance(0.05)
    t, y = integ.state.t, integ.state.y.copy()
    integ.set_held_torque([40.0, 15.0])  # a step in torque: the cached derivative is stale
    integ.advance(0.1)
    fresh = _fresh(model, t, y, [40.0, 15.0])
    fresh.advance(0.1)
    assert np.allclose(integ.state.y, fresh.state.y, rtol=1e-7, atol=1e-9)
    # and the torque really changed the motion (the check above is not of two equal runs)
    held = _fresh(model, t, y, [1.0, -0.5])
    held.advance(0.1)
    assert not np.allclose(held.state.y, fresh.state.y, rtol=1e-4)


def test_a_state_set_from_outside_is_integrated_from_there():
    model = ArmModel(scene_from())
    integ = PhaseIntegrator(model, **OPTIONS)
    integ.advance(0.05)
    q, qd = np.array([0.3, -0.2]), np.array([1.5, -2.0])
    integ.set_state(0.2, q, qd)
    assert integ.state.t == 0.2
    integ.advance(0.25)
    y0 = np.concatenate([q, qd])
    fresh = _fresh(model, 0.2, y0, integ.state.held_torque)
    fresh.advance(0.25)
    assert np.allclose(integ.state.y, fresh.state.y, rtol=1e-7, atol=1e-9)


def test_integrator_options_one_record_from_the_scene_or_the_caller():
    from dataclasses import replace

    from impact_arm.physics.integrator import IntegratorOptions

    scene = scene_from()
    spec = replace(scene.integrator, rtol=1e-9, atol=1e-11, max_step=0.01, method='rosenbrock')
    own = IntegratorOptions.of_scene(spec)
    assert (own.rtol, own.atol, own.max_step, own.method) == (1e-9, 1e-11, 0.01, 'rosenbrock')
    # a preset named by the caller: its tolerances, not the scene's; method and max_step stay
    named = IntegratorOptions.of_scene(spec, preset='fast')
    assert (named.preset, named.rtol, named.atol) == ('fast', None, None)
    assert (named.max_step, named.method) == (0.01, 'rosenbrock')
    assert named.free_rtol() == 1e-5
    integ = PhaseIntegrator(ArmModel(scene), options=named)
    assert integ.rtol == 1e-5 and integ.contact_rtol == 3e-7 and integ.max_step == 0.01
    with pytest.raises(TypeError, match='not both'):
        PhaseIntegrator(ArmModel(scene), options=named, rtol=1e-6)
