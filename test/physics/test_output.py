"""Output on a time grid from each step's continuous extension (PhaseIntegrator.start_output),
checked against integrations that step exactly to each grid time, and against momentum."""

import numpy as np
import pytest

from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel
from impact_arm.physics.simulate import run

from scenes import scene_from
from two_rods import generalized_momentum, vertical_strike_scene

DT = 1e-3


def stepped(model, times, **kw):
    """States, torques and impulses at ``times``, the integration ending a step at each."""
    integ = PhaseIntegrator(model, **kw)
    states, torques, impulses = [], [], []
    for t in times:
        integ.advance(t)
        states.append(integ.state.y.copy())
        tau = integ.torque()
        torques.append(tau if tau is not None else (0.0,) * model.n)
        impulses.append(integ.take_impulse())
    return np.array(states), np.array(torques), np.array(impulses), integ.stats


def with_output(model, t_end, dt, **kw):
    integ = PhaseIntegrator(model, **kw)
    integ.start_output(dt, 1)
    integ.advance(t_end)
    return integ.take_output(), integ.stats


@pytest.mark.parametrize('method, rtol', [('dopri5', 1e-6), ('dopri5', 1e-4), ('rosenbrock', 1e-5)])
def test_grid_output_is_as_accurate_as_stepping_to_each_grid_time(method, rtol):
    """The article's first strike and rebound (1.5 s, four impacts): the interpolated states
    are as close to the reference as those of an integration that stops at every sample,
    at a fraction of its steps."""
    model = ArmModel(scene_from())
    times = DT * np.arange(1, 1501)
    reference, _, _, _ = stepped(model, times, preset='reference')
    options = dict(rtol=rtol, atol=rtol * 1e-2, method=method)
    states, torques, impulses, stepped_stats = stepped(model, times, **options)
    rows, stats = with_output(model, times[-1], DT, **options)
    n, size, eq = model.n, model.size, model.eq
    assert np.array_equal(rows[:, 0], times)  # exactly the grid, nothing skipped
    scale = np.abs(reference[:, : 2 * n]).max(axis=0) + 1e-3

    def error(y):
        return np.max(np.abs(y[:, : 2 * n] - reference[:, : 2 * n]) / scale)

    # (after the impacts the trajectories of both part from the reference alike: the
    # rebound amplifies the impact's error, so the bound is relative to the stepped run's)
    assert error(rows[:, eq.R_Y : eq.R_Y + size]) <= 3 * error(states) + 1e-9, (
        error(rows[:, eq.R_Y : eq.R_Y + size]),
        error(states),
    )
    assert stats.steps < 0.7 * stepped_stats.steps, (stats.steps, stepped_stats.steps)
    # torque and impulse of each row: what the stepped integration saw over that period
    tau = rows[:, eq.R_TAU : eq.R_TAU + n]
    assert np.max(np.abs(tau - torques)) < 10 * rtol * np.abs(torques).max()
    impulse = rows[:, eq.R_JT : eq.R_JN + 1]
    assert np.max(np.abs(impulse - impulses)) < 10 * rtol * np.abs(impulses).max()
    assert np.abs(impulses[:, 1]).max() > 1.0  # the window really holds impacts


@pytest.mark.parametrize('law', ['hertz', 'elastoplastic'])
@pytest.mark.parametrize('preset, rel', [('fast', 1e-4), ('accurate', 5e-6)])
def test_output_rows_split_an_impact_impulse_without_losing_any(law, preset, rel):
    """A 0.5 m/s vertical strike sampled every 20 us: the rows' normal impulses (and what
    remains after the last row) add up to the momentum the impact reverses (at this pose the
    tip's vertical direction is joint 1's), to the step's accuracy: Simpson's rule over each
    contact step (the trapezoid rule read ~1 % low at the fast preset)."""
    scene = vertical_strike_scene(0.5, law=law)
    model = ArmModel(scene)
    integ = PhaseIntegrator(model, preset=preset)
    integ.start_output(2e-5, 1)
    states = {}
    while 'separation' not in states:
        for event in integ.advance(0.002, stop_at_event=True):
            states[event.kind] = event.y
    rows = integ.take_output()
    normal = rows[:, model.eq.R_JN]
    dp = generalized_momentum(states['separation']) - generalized_momentum(states['contact'])
    assert (normal > 0).sum() >= 5  # spread over several rows
    assert normal.sum() + integ.take_impulse()[1] == pytest.approx(dp[0], rel=rel)
    assert np.allclose(np.diff(rows[:, 0]), 2e-5, rtol=1e-9, atol=0)


def test_simulate_samples_come_from_the_grid_and_match_a_stepped_run():
    """run() with continuous control samples from the output rows; its impacts agree with
    the event-to-event integration (the samples no longer cut the steps)."""
    scene = scene_from()
    result = run(scene, preset='accurate')
    times = [s.t for s in result.samples]
    assert times == [k * (1.0 / scene.publish_rate) for k in range(len(times))]
    assert result.stopped == f'{scene.cycles} cycles completed'
    assert len(result.impacts) == scene.cycles
    model = ArmModel(scene)
    k = len(times) // 2
    reference, _, _, _ = stepped(model, [times[k]], preset='reference')
    sample = result.samples[k]
    assert np.allclose(sample.q + sample.qd, reference[0, : 2 * model.n], rtol=1e-4, atol=1e-6)


def test_output_period_must_be_positive():
    integ = PhaseIntegrator(ArmModel(scene_from()))
    with pytest.raises(ValueError, match='output period'):
        integ.start_output(0.0, 1)
