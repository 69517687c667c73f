"""The peak normal contact force of each period (/contact_force_peak): offline on both clocks
(continuous control, samples from the integrator's output rows; sampled control), and in the
driver's periods (the simulator node's ticks)."""

import numpy as np
import pytest

from impact_arm.driver.arm import SimulatedArm
from impact_arm.physics.simulate import run
from scenes import scene_from


def _check_periods(t, peak, mean, impacts, traces, dt):
    """Each impact's largest force is the peak of the period it reached maximum compression
    in; a peak is never below its period's mean (the averaged wrench); no contact, no peak."""
    t, peak, mean = np.asarray(t), np.asarray(peak), np.asarray(mean)
    assert len(impacts) >= 1
    for record, rows in zip(impacts, traces):
        rows = np.asarray(rows, float)
        t_max = record.t_contact + sum(record.phase_durations[:2])
        k = int(np.searchsorted(t, t_max - 1e-12))  # the period (t[k-1], t[k]] holding it
        assert peak[k] == pytest.approx(record.F_max, rel=1e-12)
        assert record.F_max == pytest.approx(rows[:, 3].max(), rel=1e-12)  # the trace's F_n
    assert np.all(peak >= mean - 1e-9 * np.abs(mean).max())
    touching = mean > 0
    assert np.all(peak[~touching] == 0.0)
    assert np.count_nonzero(peak) == np.count_nonzero(touching)
    assert peak.max() > 5 * mean.max()  # an impact's peak is far above its period's mean


@pytest.mark.parametrize('control_rate', [0.0, 1000.0])
def test_offline_samples_carry_each_periods_peak(control_rate):
    scene = scene_from(cycles=2)
    result = run(scene, control_rate=control_rate)
    assert not result.error
    samples = result.samples
    dt = 1.0 / scene.publish_rate
    _check_periods(
        [s.t for s in samples],
        [s.force_peak for s in samples],
        [s.wrench[1] for s in samples],
        result.impacts,
        result.traces,
        dt,
    )


def test_the_drivers_periods_carry_their_peak():
    scene = scene_from(cycles=1)
    arm = SimulatedArm(scene, 1000.0, trace=True)
    ticks = []
    # no command: the arm falls onto its surface and bounces; a few impacts complete
    while arm.t < 3.0 and sum(len(tick.impacts) for tick in ticks) < 3:
        ticks.append(arm.step())
    for _ in range(5):  # the last impact's periods are over
        ticks.append(arm.step())
    impacts = [i for tick in ticks for i in tick.impacts][:3]
    _check_periods(
        [tick.t for tick in ticks],
        [tick.force_peak for tick in ticks],
        [tick.wrench[1] for tick in ticks],
        [record for record, _ in impacts],
        [rows for _, rows in impacts],
        1e-3,
    )
