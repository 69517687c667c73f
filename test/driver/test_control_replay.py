"""The controller's per-sample path on a recorded stream: its commands are, to the last bit,
those of the straightforward path it was made faster from (the law through numpy arrays and
the compiled ``q_law``, the prediction and the implicit law stepped on Python floats, the
general elimination), with both computed here, in the same run."""

import struct

import pytest

from impact_arm.contract import joint_names
from impact_arm.driver.control_inputs import ControlInputs
from impact_arm.physics import prediction
from impact_arm.physics.control import CycleController
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import load_scene, resolve_scene_path
from impact_arm.tools.latency_study import closed_loop
from repo_paths import EXAMPLES

RATE = 1000.0


class StraightforwardController(CycleController):
    """The law as it was computed before its float path: numpy arrays, compiled law."""

    def torque(self, q, qd, dt=0.0):
        return self.torque_arrays(q, qd, dt)

    def q_law_terms(self):
        return None  # the implicit law calls ``torque`` back, in Python

    def _tip(self, q, qd):
        return self.model.tip(q, qd)


def record(scene, seconds):
    """The samples the controller gets in a closed loop whose latency varies (2-3 periods:
    the prediction and the implicit law both run), as ``(sec, nanosec, fields)``."""
    samples = []

    def tap(sec, nanosec, tick):
        samples.append(
            (sec, nanosec, tuple(tick.wrench), list(tick.position), list(tick.velocity))
            + (list(tick.effort),)
        )

    closed_loop(scene, 2, -1, t_max=seconds, jitter=0.3, seed=3, tap=tap)
    return samples


def replay(scene, samples, controller_class):
    model = ArmModel(scene)
    ctrl = controller_class.for_scene(model, scene.controller)
    sent = []
    names = joint_names(model.n)
    inputs = ControlInputs(
        ctrl,
        names,
        list(range(model.n)),
        RATE,
        'joint_states',
        sent.append,
        latency_periods=-1,
        implicit_periods=1,
        clock=lambda: 0.0,
    )
    if controller_class is StraightforwardController:
        assert inputs.predictor is not None
        inputs.predictor._compiled = inputs.predictor._compiled_implicit = None
    for sec, nanosec, wrench, position, velocity, effort in samples:
        inputs.wrench(sec, nanosec, (wrench[0], wrench[1], 0.0))
        inputs.joint_state(sec, nanosec, names, position, velocity, effort)
    return sent, inputs


def bits(commands):
    return [struct.pack(f'<{len(c)}d', *c) for c in commands]


@pytest.mark.parametrize(
    'scene_path',
    [resolve_scene_path('paper'), f'{EXAMPLES}/real_arm.yaml'],
    ids=['article', 'three general links'],
)
def test_the_commands_are_the_straightforward_paths_to_the_bit(scene_path, monkeypatch):
    scene = load_scene(scene_path)
    samples = record(scene, 1.2)
    fast, fast_inputs = replay(scene, samples, CycleController)
    assert fast_inputs.predictor._compiled is not None  # the compiled path ran
    with monkeypatch.context() as patch:
        patch.setattr(prediction, '_solve2', prediction.eliminate)
        reference, reference_inputs = replay(scene, samples, StraightforwardController)
    assert len(fast) == len(samples)
    assert bits(fast) == bits(reference)
    # the stream exercised what was made faster: predictions over 2-3 commands in flight
    # and the implicit law on most commands
    assert fast_inputs.implicit_commands == reference_inputs.implicit_commands > len(fast) / 2
    assert {2, 3} <= set(fast_inputs.latency_seen)
