"""Offline runs stream their samples (``run(keep_samples=False)``, what ``impact-arm simulate``
does): the observer gets the same samples a run that keeps them holds, and memory stays
bounded however many samples the run produces."""

import math
import tracemalloc

import pytest

from impact_arm.physics.errors import SceneError
from impact_arm.physics.simulate import MAX_KEPT_SAMPLES, run

from scenes import scene_from

MEMORY_BUDGET = 5e6  # bytes: a run holding 2e4 samples or more needs well over this


class Collect:
    def __init__(self):
        self.samples = []

    def on_sample(self, sample):
        self.samples.append(sample)


class Count:
    count = 0

    def on_sample(self, sample):
        self.count += 1


@pytest.mark.parametrize('control_rate', [0.0, 1000.0])
def test_streamed_samples_are_the_kept_ones(control_rate):
    scene = scene_from(t_max=0.6, cycles=0)
    kept, streamed = Collect(), Collect()
    full = run(scene, control_rate=control_rate, observer=kept)
    lean = run(scene, control_rate=control_rate, observer=streamed, keep_samples=False)
    assert len(full.samples) == round(0.6 * scene.publish_rate) + 1
    assert streamed.samples == kept.samples == full.samples
    assert lean.samples == []
    # the summary's ranges, kept as the run goes, are those of the samples
    summary, q1 = lean.summary(), [math.degrees(s.q[0]) for s in full.samples]
    assert summary['q1_range_deg'] == [min(q1), max(q1)]
    for key in (
        'impacts',
        't_end',
        'q1_range_deg',
        'q2_range_deg',
        'vx_range',
        'vy_range',
        'rhs_evaluations',
    ):
        assert summary[key] == full.summary()[key], key


@pytest.mark.parametrize(
    'control_rate, publish_rate, t_max',
    [
        (0.0, 1e5, 0.5),  # continuous control: samples from the integrator's output rows
        (1000.0, 2e4, 1.0),  # sampled control: one sample per period on the merged clock
    ],
)
def test_streaming_holds_memory_bounded(control_rate, publish_rate, t_max):
    scene = scene_from(publish_rate=publish_rate, t_max=t_max, cycles=0)
    run(scene, control_rate=control_rate, t_max=0.01)  # kernel and laws loaded outside
    counter = Count()
    tracemalloc.start()
    try:
        result = run(scene, control_rate=control_rate, observer=counter, keep_samples=False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert counter.count == round(publish_rate * t_max) + 1 and not result.error
    assert peak < MEMORY_BUDGET, f'{peak / 1e6:.1f} MB held for {counter.count} samples'


def test_a_run_keeping_its_samples_refuses_more_than_memory_holds():
    scene = scene_from(publish_rate=1e6, t_max=60.0)  # a scene the loader accepts
    with pytest.raises(SceneError, match=r'publish_rate = 1e\+06 .* 6e\+07 samples'):
        run(scene)
    assert 1e6 * 60.0 > MAX_KEPT_SAMPLES
