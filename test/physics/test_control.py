"""The sampled PID's anti-windup and output limits (physics/control.py), against hand values."""

import math

import pytest

from impact_arm.physics.control import CycleController, PidIntegrator
from impact_arm.physics.model import ArmModel
from scenes import scene_from

TARGET = [0.0, 0.0]


def controller(strategy, limit, kp=100.0):
    model = ArmModel(scene_from({('controller', 'law'): 'pid'}))
    integral = PidIntegrator(2, antiwindup=strategy, u_clamp_max=limit, u_clamp_min=-limit)
    return CycleController(
        model,
        'pid',
        [kp, kp],
        [0.0, 0.0],
        [5.0, 5.0],
        TARGET,
        TARGET,
        switch_height=10.0,
        surface_height=None,
        integrator=integral,
    )


def run(c, q, samples=10, dt=1e-3):
    for _ in range(samples):
        tau = c.torque(q, [0.0, 0.0], dt)
    return tau


def test_conditional_integration_freezes_the_integral_while_the_output_saturates():
    # error 0.5 rad: P alone asks -50 N m against a 10 N m limit
    c = controller('conditional_integration', 10.0)
    tau = run(c, [0.5, 0.5])
    assert tau == [-10.0, -10.0]
    assert c.integral.value == [0.0, 0.0]


def test_none_integrates_into_the_saturation():
    c = controller('none', 10.0)
    tau = run(c, [0.5, 0.5])
    assert tau == [-10.0, -10.0]
    assert c.integral.value == pytest.approx([10 * 0.5e-3] * 2, rel=1e-12)


def test_conditional_integration_integrates_like_none_below_the_limits():
    # error 0.01 rad: -1 N m, well inside ±10 N m
    free, cond = controller('none', 10.0), controller('conditional_integration', 10.0)
    assert run(free, [0.01, 0.01]) == run(cond, [0.01, 0.01])
    assert cond.integral.value == pytest.approx([10 * 0.01e-3] * 2, rel=1e-12)
    expected = -100.0 * 0.01 - 5.0 * 10 * 0.01e-3
    assert run(cond, [0.01, 0.01], samples=1, dt=0.0) == pytest.approx([expected] * 2)


def test_default_limits_leave_the_output_alone():
    c = controller('none', math.inf, kp=1e6)
    assert run(c, [0.5, 0.5], samples=1, dt=0.0) == pytest.approx([-5e5, -5e5])


def test_refuses_crossed_output_limits():
    with pytest.raises(ValueError, match='u_clamp_min = 1 > u_clamp_max = -1'):
        PidIntegrator(2, u_clamp_max=-1.0, u_clamp_min=1.0)


def test_a_law_set_by_its_text_at_run_time_is_the_law_used():
    """The controller node applies a changed ``law`` parameter as text: the controller
    parses it, and computes that law (the Q law's gravity term, not the PD's error alone)."""
    from impact_arm.contract import ControlLaw, CycleMode

    scene = scene_from()
    model = ArmModel(scene)
    c = CycleController.for_scene(model, scene.controller)
    q, qd = [0.3, -0.2], [0.0, 0.0]
    by_member = c.torque(q, qd)
    c.law = 'pd'
    assert c.law is ControlLaw.PD and c.torque(q, qd) != by_member
    c.law = 'q'
    assert c.law is ControlLaw.Q and c.torque(q, qd) == by_member
    c.mode = 'up'
    assert c.mode is CycleMode.UP
    with pytest.raises(ValueError):
        c.law = 'p'


def test_the_q_laws_float_path_is_the_compiled_law_to_the_bit():
    """``torque`` computes the 'q' law on floats; ``torque_arrays`` through numpy and the
    compiled ``q_law``: the same operations in the same order, the same bits, for either
    target, any state, integer gains (kept as floats) and a zero gain (a signed zero)."""
    import numpy as np

    model = ArmModel(scene_from({}))
    ctrl = CycleController(
        model, 'q', [300, 0], [20.0, 0], [0.0, 0.0], [0.5, -1.0], [-0.2, 0.3], 10.0, None
    )
    assert ctrl.kp == [300.0, 0.0] and all(isinstance(k, float) for k in ctrl.kd)
    rng = np.random.default_rng(11)
    for k in range(200):
        ctrl.mode = ('down', 'up')[k % 2]
        q, qd = rng.uniform(-4.0, 4.0, 2), rng.uniform(-30.0, 30.0, 2)
        for state in ((q.tolist(), qd.tolist()), (q, qd), ([0.0, -0.0], [-0.0, 0.0])):
            got = ctrl.torque(*state)
            assert [v.hex() for v in got] == [v.hex() for v in ctrl.torque_arrays(*state)]
            assert all(type(v) is float for v in got)
    assert ctrl.q_law_terms() == (ctrl.targets[ctrl.mode], ctrl.kp, ctrl.kd)
    ctrl.law = 'pd'
    assert ctrl.q_law_terms() is None


@pytest.mark.parametrize('scene_name', ['paper', 'three_link'])
def test_the_tip_stopped_at_the_surface_is_a_plastic_impulse(scene_name):
    """``stopped_at_surface`` against the impulse's defining properties, computed here by
    other means: the tip's vertical velocity is zero after it, the change of rates is
    M⁻¹ Jᵀ times a scalar (an impulse along the normal at the tip), so of all rates with the
    tip stopped they are the nearest to the approach's in the kinetic-energy metric; the
    tip rises by the depth to first order."""
    import numpy as np

    from impact_arm.physics.control import stopped_at_surface
    from impact_arm.physics.scene import load_scene

    model = ArmModel(load_scene(scene_name))
    n = model.n
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-1.0, 1.0, n)
        qd = rng.uniform(-5.0, 5.0, n)
        depth = 2e-4
        q2, qd2 = (np.array(v) for v in stopped_at_surface(model, q, qd, depth))
        # the tip's vertical velocity where the impulse acts (q), by a finite difference of
        # its height
        h = 1e-7
        y = lambda angles: model.tip(angles, np.zeros(n))[1]  # noqa: E731
        assert abs((y(q + h * qd2) - y(q - h * qd2)) / (2 * h)) < 1e-6 * abs(qd).max()
        assert y(q2) - y(q) == pytest.approx(depth, rel=1e-2)
        # the change is M⁻¹ Jᵀ λ: M Δqd is parallel to the vertical Jacobian row
        mass = model.mass_matrix(q)
        row = np.array([(y(q + h * e) - y(q - h * e)) / (2 * h) for e in np.eye(n)])
        push = mass @ (qd2 - qd)
        assert np.allclose(push, row * (push @ row) / (row @ row), atol=1e-6 * abs(push).max())

        # of the rates that stop the tip, the nearest to the approach's in the kinetic-energy
        # metric (Gauss): any other differs from qd2 by a null-space direction of the row
        for _ in range(3):
            d = rng.normal(size=n)
            d -= row * (d @ row) / (row @ row)
            other = qd2 + 0.1 * d
            assert (other - qd) @ mass @ (other - qd) > (qd2 - qd) @ mass @ (qd2 - qd)
