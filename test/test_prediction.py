"""The controller's state predictor (physics/prediction.py): the model's free motion over the
periods a command is in flight, checked against conservation, a static equilibrium, the
order of its integration and a constant joint torque's work."""

import math

import numpy as np
import pytest

from impact_arm.physics.model import ArmModel
from impact_arm.physics.prediction import StatePredictor
from impact_arm.physics.scene import load_scene, resolve_scene_path

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
