"""The diagnosis of a recording before its fit (calibration/diagnose/): each detector runs on
recordings the synthetic tool makes with and without its effect (through the simulated
driver's sensor chain), fires on the one and stays quiet on the other, and estimates the
effect; each correction removes what it corrects; ``impact-arm fit`` says what it found."""

import dataclasses
import json

import numpy as np
import pytest

from impact_arm.calibration.diagnose import (
    Corrections,
    FindingKind,
    SampleTimes,
    central_rates,
    correct,
    diagnose,
    stamp_jitter,
)
from impact_arm.calibration.fit import EffortTiming
from impact_arm.calibration.study import Study
from impact_arm.physics.model import ArmModel
from impact_arm.io.synthetic import driver_recording, synthetic_recording
from repo_paths import EXAMPLES

PERIOD = 1e-3
ENCODER = {'sensors.counts_per_revolution': 1 << 17}
EFFORT_LATE = {'sensors.effort_latency': 0.002, 'sensors.effort_noise': 0.05}


@pytest.fixture(scope='module')
def model():
    return ArmModel(Study('paper').scene())


@pytest.fixture(scope='module')
def plain():
    """Realistic noise, 2 % of the samples lost: none of the effects."""
    return synthetic_recording(cycles=4, drop=0.02, seed=5)


def recording(overrides=None, **kw):
    kw.setdefault('cycles', 4)
    return synthetic_recording(overrides=overrides, seed=5, **kw)


def kinds(rec, model):
    return diagnose(rec, model).kinds()


def test_a_recording_without_effects_gives_no_finding(plain, model):
    diagnosis = diagnose(plain, model)
    assert diagnosis.findings == []
    assert FindingKind.EFFORT_DELAY in diagnosis.checked
    assert FindingKind.WRENCH_LAG in diagnosis.checked
    # unquantised positions: the resolution is unknown, and the report says so
    assert FindingKind.POSITION_NOISE in diagnosis.skipped
    assert 'nothing found' in diagnosis.lines()[0]


@pytest.mark.parametrize('rate', ['difference', 'exact', 'filtered'])
def test_rates_that_are_differences_of_the_positions_are_named(rate, model):
    over = {**ENCODER, 'sensors.position_noise': 2e-5, 'sensors.rate': rate}
    if rate == 'filtered':
        over['sensors.rate_cutoff'] = 300.0
    diagnosis = diagnose(recording(over), model)
    found = diagnosis.kinds()
    assert (FindingKind.DIFFERENCE_RATES in found) == (rate == 'difference'), found
    assert (FindingKind.FILTERED_RATES in found) == (rate == 'filtered'), found
    if rate == 'filtered':  # the cut-off estimated from the rates
        assert diagnosis.estimates[FindingKind.FILTERED_RATES] == pytest.approx(300.0, rel=1e-6)
        assert '--difference-rates' in diagnosis.findings[0].advice


def test_central_difference_rates_are_named_too(plain, model):
    rec = dataclasses.replace(plain, velocity=central_rates(plain.t, plain.position))
    assert FindingKind.DIFFERENCE_RATES in kinds(rec, model)
    assert FindingKind.DIFFERENCE_RATES not in kinds(plain, model)


def test_jittered_stamps_are_named_with_their_rms(plain, model):
    jitter = 1e-4  # uniform +-: rms jitter / sqrt(3)
    diagnosis = diagnose(recording(jitter=jitter, drop=0.02), model)
    assert FindingKind.STAMP_JITTER in diagnosis.kinds()
    estimate = diagnosis.estimates[FindingKind.STAMP_JITTER]
    assert estimate == pytest.approx(jitter / np.sqrt(3), rel=0.1)
    assert 'regular period' in diagnosis.findings[0].seen
    # lost samples are gaps of whole periods, not jitter; nor is a scatter of a few us (the
    # fit's effort readings and free-flight fits do not feel it)
    assert FindingKind.STAMP_JITTER not in kinds(plain, model)
    assert FindingKind.STAMP_JITTER not in kinds(recording(jitter=5e-6), model)


def test_irregular_sampling_with_true_stamps_is_no_jitter(model):
    """Samples taken at irregular times and stamped truly (picked from a 4 kHz run, a quarter
    period early or late at random): the positions advance with the stamps, nothing to
    correct."""
    fine = recording(publish_rate=4000.0, noise={})
    rng = np.random.default_rng(1)
    pick = np.arange(4, len(fine.t) - 4, 4) + rng.integers(-1, 2, (len(fine.t) - 8 + 3) // 4)
    rec = dataclasses.replace(
        fine,
        t=fine.t[pick] - fine.t[pick[0]],
        position=fine.position[pick],
        velocity=fine.velocity[pick],
        effort=fine.effort[pick],
    )
    jitter, follows = stamp_jitter(rec)
    assert jitter > 1e-4 and follows is SampleTimes.STAMPS
    assert FindingKind.STAMP_JITTER not in kinds(rec, model)


@pytest.mark.parametrize('latency', [0.002, 0.005])
def test_late_efforts_are_named_with_their_delay(latency, plain, model):
    rec = recording({**EFFORT_LATE, 'sensors.effort_latency': latency})
    diagnosis = diagnose(rec, model)
    assert FindingKind.EFFORT_DELAY in diagnosis.kinds()
    assert diagnosis.estimates[FindingKind.EFFORT_DELAY] == pytest.approx(latency, abs=0.3e-3)
    assert abs(diagnose(plain, model).estimates[FindingKind.EFFORT_DELAY]) < 0.3e-3


def test_efforts_unrelated_to_the_motion_give_no_delay(plain, model):
    """Efforts that are noise: some delay balances the energy least, by chance, but no better
    than the noise explains (F far below its threshold)."""
    rng = np.random.default_rng(3)
    rec = dataclasses.replace(plain, effort=rng.normal(0.0, 5.0, plain.effort.shape))
    assert FindingKind.EFFORT_DELAY not in kinds(rec, model)


def test_late_joint_states_show_as_early_efforts(model):
    diagnosis = diagnose(recording({'sensors.state_latency': 0.003}), model)
    assert diagnosis.estimates[FindingKind.EFFORT_DELAY] == pytest.approx(-0.003, abs=0.3e-3)
    assert 'early' in next(f.seen for f in diagnosis.findings if f.kind.value == 'effort_delay')


def test_a_drivers_held_efforts_are_no_delay_until_they_are_late(model):
    """The simulator node reports the command held over the period that ends at the stamp:
    half a period, which the fit's reading of the efforts absorbs."""
    held = diagnose(driver_recording(cycles=4), model)
    assert FindingKind.EFFORT_DELAY not in held.kinds()
    late = diagnose(driver_recording(cycles=4, overrides={'sensors.effort_latency': 0.003}), model)
    assert FindingKind.EFFORT_DELAY in late.kinds()
    assert late.estimates[FindingKind.EFFORT_DELAY] == pytest.approx(0.0035, abs=0.3e-3)


def test_a_delay_the_scene_states_is_advised_without_the_option():
    """A delay found in the recording that the scene already states (and the fit replays):
    the advice is to give no option (it would shift the signal twice), and to correct the
    scene's value when it differs from the one found."""

    def advice(overrides, scene_overrides, kind):
        rec = recording(overrides)
        stating = ArmModel(Study('paper').scene(scene_overrides))
        return next(f.advice for f in diagnose(rec, stating).findings if f.kind is kind)

    late = {**EFFORT_LATE, 'sensors.effort_latency': 0.002}
    said = advice(late, {'sensors.effort_latency': 0.002}, FindingKind.EFFORT_DELAY)
    assert 'the scene states it' in said and 'give no --effort-latency' in said, said
    assert 'differs' not in said
    said = advice(late, {'sensors.effort_latency': 0.005}, FindingKind.EFFORT_DELAY)
    assert "but it differs from the delay found: correct the scene's sensors.effort_" in said
    said = advice(
        {'sensors.wrench_latency': 0.002}, {'sensors.wrench_latency': 0.002}, FindingKind.WRENCH_LAG
    )
    assert 'give no --wrench-latency' in said and 'differs' not in said, said
    assert 'fit with --wrench-latency' in advice(
        {'sensors.wrench_latency': 0.002}, {}, FindingKind.WRENCH_LAG
    )


@pytest.mark.parametrize('noise, fires', [(1e-5, False), (1e-3, True)])
def test_position_noise_far_above_the_encoder_resolution_is_named(noise, fires, model):
    rec = recording({**ENCODER, 'sensors.position_noise': noise})
    diagnosis = diagnose(rec, model)
    assert FindingKind.POSITION_NOISE in diagnosis.checked
    assert (FindingKind.POSITION_NOISE in diagnosis.kinds()) == fires
    if fires:
        finding = diagnosis.findings[0]
        assert finding.estimate == pytest.approx(noise, rel=0.2)
        assert f'{2 * np.pi / (1 << 17):.3g} rad' in finding.seen


@pytest.mark.parametrize('latency', [0.002, -0.003])
def test_a_wrench_that_lags_the_impacts_is_named(latency, plain, model):
    rec = recording({'sensors.wrench_latency': max(latency, 0.0)})
    if latency < 0:  # a wrench stamped early: its stamps moved, the values kept
        rec.wrench_t = rec.wrench_t + latency
    diagnosis = diagnose(rec, model)
    assert FindingKind.WRENCH_LAG in diagnosis.kinds()
    assert diagnosis.estimates[FindingKind.WRENCH_LAG] == pytest.approx(latency, abs=0.2e-3)
    assert diagnose(plain, model).estimates[FindingKind.WRENCH_LAG] == 0.0


def test_joint_samples_lost_after_the_contacts_are_no_wrench_lag(plain, model):
    """The first two joint samples after each impact lost: the wrench still rises between the
    last sample before and the first after, on time."""
    from impact_arm.calibration.identify import find_impacts

    lost = {k for a in find_impacts(plain) for k in (a + 1, a + 2)}
    keep = np.array([k not in lost for k in range(len(plain.t))])
    rec = dataclasses.replace(
        plain,
        t=plain.t[keep],
        position=plain.position[keep],
        velocity=plain.velocity[keep],
        effort=plain.effort[keep],
    )
    diagnosis = diagnose(rec, model)
    assert FindingKind.WRENCH_LAG in diagnosis.checked
    assert diagnosis.estimates[FindingKind.WRENCH_LAG] == 0.0


def test_without_a_wrench_or_a_scene_the_checks_say_why_not(model):
    rec = recording(wrench=False)
    diagnosis = diagnose(rec)
    assert diagnosis.skipped[FindingKind.WRENCH_LAG] == 'no wrench recorded'
    assert 'scene' in diagnosis.skipped[FindingKind.EFFORT_DELAY]


# ------------------------------------------------------------------------- corrections
def test_nothing_is_changed_unless_asked(model):
    rec = recording(EFFORT_LATE)
    diagnosis = diagnose(rec, model)
    assert correct(rec, Corrections(), diagnosis) is rec
    assert diagnosis.findings[0].corrected_by == '' and diagnosis.corrections == []


def test_a_known_effort_latency_is_taken_out(model):
    exact = recording({'sensors.effort_noise': 0.05})
    late = recording(EFFORT_LATE)
    diagnosis = diagnose(late, model)
    fixed = correct(late, Corrections(effort_latency=0.002), diagnosis)
    assert FindingKind.EFFORT_DELAY not in kinds(fixed, model)
    # the efforts are back at their stamps: those of the recording without the latency
    # (same noise draws: the latency moves the noisy readings)
    np.testing.assert_allclose(fixed.effort, exact.effort[: len(fixed.effort)], atol=1e-9)
    assert len(fixed.t) == len(late.t) - 2
    assert diagnosis.findings[0].corrected_by == '--effort-latency'
    assert any('--effort-latency' in note for note in fixed.notes)


def test_a_known_wrench_latency_is_taken_out(model):
    rec = recording({'sensors.wrench_latency': 0.002})
    fixed = correct(rec, Corrections(wrench_latency=0.002))
    assert FindingKind.WRENCH_LAG not in kinds(fixed, model)


def test_regular_stamps_restore_the_sampling_grid(model):
    regular = recording(drop=0.02)
    jittered = recording(drop=0.02, jitter=1e-4)
    fixed = correct(jittered, Corrections(regular_stamps=True))
    assert FindingKind.STAMP_JITTER not in kinds(fixed, model)
    # the same samples are lost in both (one seed): the least-squares grid is the true one
    # to a fraction of the jitter (its slope and offset carry the jitter's mean over 1600
    # samples: ~3e-6 s at the ends); the jittered stamps were up to 1e-4 s off
    error = (fixed.t - fixed.t[0]) - (regular.t - regular.t[0])
    assert np.max(np.abs(error)) < 2e-5 < np.max(np.abs(jittered.t - regular.t))
    assert np.max(np.abs(np.diff(error))) < 1e-8  # the grid is regular


def test_central_rates_are_the_derivative_at_the_stamps():
    t = np.array([0.0, 0.001, 0.0021, 0.003, 0.0042])
    q = np.stack([3 * t**2 - t, -2 * t**2], axis=1)
    np.testing.assert_allclose(
        central_rates(t, q), np.stack([6 * t - 1, -4 * t], axis=1), rtol=1e-12, atol=1e-12
    )


TRUTH = {'surfaces[0].mu': 0.3, 'materials.steel.S_y': 1e9}


def test_difference_rates_are_read_as_the_mean_rates_of_their_periods():
    """A recording of difference rates keeps every sample and its rates, now read as period
    means; one of filtered rates (same positions: same run, same noise draws) gets the
    differences of its positions, and loses the samples whose predecessor is lost."""
    from impact_arm.calibration.diagnose import rates_as_period_means
    from impact_arm.calibration.identify import RateMeaning

    over = {**TRUTH, **ENCODER, 'sensors.position_noise': 2e-5}
    difference = recording({**over, 'sensors.rate': 'difference'}, noise={})
    fixed = rates_as_period_means(difference)
    assert fixed.rates is RateMeaning.PERIOD_MEAN and fixed.rate_period == pytest.approx(PERIOD)
    np.testing.assert_array_equal(fixed.velocity, difference.velocity)
    filtered = {**over, 'sensors.rate': 'filtered', 'sensors.rate_cutoff': 100.0}
    lossy = recording(filtered, noise={}, drop=0.02)
    fixed = rates_as_period_means(lossy)
    # the samples whose predecessor is recorded one period before
    kept = np.flatnonzero(np.abs(np.diff(lossy.t) - PERIOD) < 0.5 * PERIOD) + 1
    assert len(lossy.t) - len(fixed.t) >= 0.015 * len(lossy.t)  # ~2 % lost, each successor too
    assert len(kept) == len(fixed.t)
    # the same run with difference rates and the same samples lost
    lost = recording({**over, 'sensors.rate': 'difference'}, noise={}, drop=0.02)
    np.testing.assert_allclose(fixed.velocity, lost.velocity[kept], rtol=1e-12, atol=1e-12)
    assert not np.allclose(lossy.velocity[kept], lost.velocity[kept], atol=1e-3)


@pytest.mark.parametrize(
    'rates',
    [{'sensors.rate': 'difference'}, {'sensors.rate': 'filtered', 'sensors.rate_cutoff': 200.0}],
)
def test_a_fit_of_difference_rates_is_corrected_by_comparing_mean_rates(rates, model):
    """Rates a driver computes from its encoder (differences, or differences low-passed)
    fitted as measured rates do not fit, and the diagnosis names them; fitted with its
    advice (--difference-rates: the replay's mean rate over each period compared with the
    recorded one) they fit and the intervals cover the truth."""
    from impact_arm.calibration.fit import fit

    over = {**TRUTH, **ENCODER, **rates, 'sensors.position_noise': 2e-5}
    rec = synthetic_recording('paper', over, cycles=8, seed=3, noise={'wrench': 2.0}, drop=0.02)
    kind = (
        FindingKind.DIFFERENCE_RATES
        if rates['sensors.rate'] == 'difference'
        else FindingKind.FILTERED_RATES
    )
    diagnosis = diagnose(rec, model)
    assert kind in diagnosis.kinds()
    assert '--difference-rates' in diagnosis.findings[0].advice
    bounds = {'surfaces[0].mu': (0.05, 1.0), 'materials.steel.S_y': (2e8, 5e9)}
    as_is = fit(rec, 'paper', bounds)
    assert as_is.verdict.startswith('does not fit'), as_is.verdict
    fixed = fit(correct(rec, Corrections(difference_rates=True), diagnosis), 'paper', bounds)
    assert fixed.fits, fixed.verdict
    for key, value in TRUTH.items():
        lo, hi = fixed.parameters[key].ci95
        assert lo < value < hi, (key, lo, value, hi)
    assert diagnosis.findings[0].corrected_by == '--difference-rates'


def test_bad_corrections_are_refused_in_one_line():
    with pytest.raises(ValueError, match='--effort-latency = nan'):
        Corrections(effort_latency=float('nan'))
    with pytest.raises(ValueError, match='--wrench-latency = 5'):
        Corrections(wrench_latency=5.0)


# --------------------------------------------------------------------------------- CLI
def test_fit_says_what_the_diagnosis_found_and_reports_it(tmp_path, capsys):
    from impact_arm.tools.cli import main
    from impact_arm.io.synthetic import write_rosbag2

    folder = tmp_path / 'late_bag'
    write_rosbag2(recording(EFFORT_LATE, cycles=6), str(folder), extra_joint=False)
    out = tmp_path / 'fit'
    args = ['fit', str(folder), '--param', 'surfaces[0].mu=0.05:1', '--out', str(out)]
    main([*args, '--effort-latency', '0.002'])
    text = capsys.readouterr().out
    assert 'recording diagnosis: the efforts are' in text and 'ms late' in text
    data = json.loads((out / 'fit.json').read_text())
    (finding,) = data['diagnosis']['findings']
    assert finding['kind'] == 'effort_delay' and finding['corrected_by'] == '--effort-latency'
    assert finding['estimate'] == pytest.approx(0.002, abs=0.3e-3)
    assert '## The recording' in (out / 'report.md').read_text()
    assert main([*args, '--effort-latency', 'inf']) == 2
    err = capsys.readouterr().err
    assert '--effort-latency = inf' in err and err.count('\n') == 1


def test_the_encoder_grid_is_found_when_no_step_is_a_single_count():
    """A fast joint on a fine encoder moves two counts or more every period: the grid is
    still the count, not the smallest step (which made the noise check 'not checked')."""
    from impact_arm.calibration.diagnose import encoder_resolution
    from impact_arm.calibration.identify import JointRecording

    count = 2 * np.pi / (1 << 17)
    steps = np.array([[2, 1], [3, 1], [5, 2], [2, 7]] * 10)  # joint 1: never a single count
    position = np.cumsum(steps, axis=0) * count
    t = np.arange(len(position)) * 1e-3
    rec = JointRecording(t, position, np.zeros_like(position), np.zeros_like(position))
    assert encoder_resolution(rec) == pytest.approx([count, count], rel=1e-9)
    off_grid = position + np.random.default_rng(1).normal(0.0, 1e-3 * count, position.shape)
    assert encoder_resolution(dataclasses.replace(rec, position=off_grid)) is None


def test_the_real_arm_example_with_difference_rates_fits_with_the_advice():
    """examples/real_arm.yaml (three links, joint friction, a mounted plate) seen through a
    17-bit encoder whose driver differentiates the counts, nothing else: mu alone does not
    fit from the rates as measured ones, and fits with the diagnosis's --difference-rates
    (before, the rates were read at the periods' middles and it did not fit either, at 1.5-2.9x
    the noise: the wrist's fast mode after an impact bends the rates within a period)."""
    import os

    from impact_arm.calibration.fit import fit

    scene = os.path.join(EXAMPLES, 'real_arm.yaml')
    rec = synthetic_recording(scene, {'sensors.rate': 'difference'}, cycles=3, seed=3, noise={})
    diagnosis = diagnose(rec, ArmModel(Study(scene).scene()))
    assert FindingKind.DIFFERENCE_RATES in diagnosis.kinds()
    bounds = {'surfaces[0].mu': (0.05, 1.0, 0.4)}
    assert not fit(rec, scene, bounds).fits
    fixed = fit(correct(rec, Corrections(difference_rates=True)), scene, bounds)
    assert fixed.fits, fixed.verdict
    lo, hi = fixed.parameters['surfaces[0].mu'].ci95
    assert lo < 0.2 < hi


def test_a_known_effort_latency_changes_the_fit_of_the_real_arm_example(tmp_path):
    """examples/real_arm.yaml recorded with efforts 2 ms late: as recorded it does not fit;
    with --effort-latency 0.002 (the CLI's path: diagnosis, correction, fit) it fits. With
    the scene's continuous controller the fit then reads the efforts as that controller, so
    the option says that it acted only on which samples count as taken in a contact (on a
    recording without the latency it changes no digit: that is why)."""
    import os

    from impact_arm.tools.fit import fit_recording
    from impact_arm.io.synthetic import write_rosbag2

    scene = os.path.join(EXAMPLES, 'real_arm.yaml')
    late = synthetic_recording(scene, {'sensors.effort_latency': 0.002}, cycles=3, seed=3, noise={})
    folder = tmp_path / 'late'
    write_rosbag2(late, str(folder), extra_joint=False)
    bounds = {'surfaces[0].mu': (0.05, 1.0, 0.4)}

    def run(latency):
        return fit_recording(
            str(folder),
            scene,
            bounds,
            out=False,
            say=lambda *a: None,
            corrections=Corrections(effort_latency=latency),
        )

    as_recorded, corrected = run(0.0), run(0.002)
    assert not as_recorded.fits, as_recorded.verdict
    assert corrected.fits, corrected.verdict
    lo, hi = corrected.parameters['surfaces[0].mu'].ci95
    assert lo < 0.2 < hi
    assert corrected.timing is EffortTiming.CONTROLLER
    assert any(w.startswith('--effort-latency 0.002 moved the efforts') for w in corrected.warnings)


def difference_rates_fit(sensors):
    """The simulated driver's loop (a 1 kHz controller on the published difference rates,
    with the encoder and noise of ``sensors``) fitted with --difference-rates, mu and S_y
    free: it must read the efforts as 'previous', say `fits` and cover the truth."""
    from impact_arm.calibration.fit import fit
    from impact_arm.calibration.study import apply_overrides

    sampled = {'controller.rate': 1000.0}
    over = {**TRUTH, **sampled, 'sensors.rate': 'difference'}
    rec = driver_recording('paper', over | sensors, cycles=10)
    scene = apply_overrides(Study('paper').data, sampled)
    bounds = {'surfaces[0].mu': (0.05, 1.0), 'materials.steel.S_y': (2e8, 5e9)}
    result = fit(correct(rec, Corrections(difference_rates=True)), scene, bounds)
    assert result.timing is EffortTiming.PREVIOUS
    assert result.fits, result.verdict
    for key, value in TRUTH.items():
        lo, hi = result.parameters[key].ci95
        assert lo < value < hi, (key, lo, value, hi)
    return result


def test_a_driver_loops_difference_rates_fit_with_the_advice():
    """The simulated driver's loop (efforts held over each period, a 1 kHz controller acting
    on the published difference rates of a 20-bit encoder): with --difference-rates the
    efforts' reading is chosen from mean rates too (the rate at the first sample after the
    impact shot so that the replay reproduces the recorded first mean), 'previous' is found,
    and the fit covers the truth (before: the midpoint reading, S_y 11 % off)."""
    difference_rates_fit({'sensors.counts_per_revolution': 1 << 20})


@pytest.mark.parametrize('extra', [{}, {'sensors.position_noise': 2e-5, 'sensors.seed': 2}])
def test_a_driver_loop_on_a_coarse_encoders_difference_rates_covers_the_truth(extra):
    """The same loop with a 17-bit encoder: each command carries the quantisation noise of
    the difference rates it was computed from. The command of the period in which the
    contact begins is not recorded (the next sample is taken in the contact, actuators off):
    standing in the command before it (S_y came out 0.7-1 % low with `fits`) moved the
    replayed impact in step with the noise of the sample the fit starts from; it is now the
    scene's sampled controller at that sample as recorded. And the state before the impact
    is the model's flight under the recorded efforts through the positions before it (a cubic
    cannot follow the torque's jumps from period to period): S_y within a fraction of its
    interval, the interval covering the truth and a tenth of a percent wide, not half one."""
    result = difference_rates_fit(ENCODER | extra)
    lo, hi = result.parameters['materials.steel.S_y'].ci95
    assert hi / lo - 1 < 0.004, (lo, hi)  # the cubic's start left +-0.5 %


def test_the_contact_periods_command_is_recomputed_only_by_the_recordings_controller():
    """The command the contact's period does not record is recomputed by the scene's sampled
    controller only where that controller gives the recorded commands before the impact: a
    scene whose gains are 10 % off is not trusted with it (the command before stands in)."""
    from impact_arm.calibration.fit.problem import read_impacts
    from impact_arm.calibration.study import apply_overrides

    sampled = {'controller.rate': 1000.0}
    over = {**TRUTH, **sampled, 'sensors.rate': 'difference'}
    rec = correct(
        driver_recording('paper', over | ENCODER, cycles=4), Corrections(difference_rates=True)
    )
    kp = list(Study('paper').scene().controller.kp)
    right = read_impacts(rec, Study(apply_overrides(Study('paper').data, sampled)))
    assert right.windows and all(w.own_command for w in right.windows)
    off = apply_overrides(Study('paper').data, {**sampled, 'controller.kp': [1.1 * k for k in kp]})
    wrong = read_impacts(rec, Study(off))
    assert wrong.windows and not any(w.own_command for w in wrong.windows)


def test_a_latency_option_on_a_scene_that_states_it_is_refused(tmp_path, capsys):
    """The fit replays the scene's sensor latencies, so --effort-latency (or
    --wrench-latency) on top of a scene that states the same delay, or of a fit that frees
    it, would shift the efforts (the wrench) twice: refused in one line naming both and what
    to do. A scene whose latencies cancel (effort as late as the states) takes the option."""
    import yaml

    from impact_arm.calibration.study import apply_overrides
    from impact_arm.tools.cli import main
    from impact_arm.io.synthetic import write_rosbag2

    folder = tmp_path / 'bag'
    write_rosbag2(recording(EFFORT_LATE, cycles=2), str(folder), extra_joint=False)

    def scene_file(name, overrides):
        path = tmp_path / f'{name}.yaml'
        path.write_text(yaml.safe_dump(apply_overrides(Study('paper').data, overrides)))
        return str(path)

    late = scene_file('late', {'sensors.effort_latency': 0.002, 'sensors.wrench_latency': 0.001})
    fit = ['fit', str(folder), '--out', str(tmp_path / 'fit')]
    mu = ['--param', 'surfaces[0].mu=0.05:1']
    for option, key in (('--effort-latency', 'effort'), ('--wrench-latency', 'wrench')):
        assert main([*fit, '--scene', late, *mu, option, '0.002']) == 2
        err = capsys.readouterr().err
        assert err.count('\n') == 1, err
        assert f"{option} 0.002 and the scene's sensors.{key}_latency" in err
        assert f'drop {option}' in err
    freed = ['--param', 'sensors.effort_latency=0:0.005']
    assert main([*fit, *mu, *freed, '--effort-latency', '0.002']) == 2
    err = capsys.readouterr().err
    assert '--effort-latency 0.002 and the fitted sensors.effort_latency' in err, err
    assert err.count('\n') == 1
    state = ['--param', 'sensors.state_latency=0:0.005']
    assert main([*fit, *mu, *state, '--wrench-latency', '0.001']) == 2
    assert 'the fitted sensors.state_latency' in capsys.readouterr().err
    # the same delay of the efforts and the states: nothing shifted, the option is taken
    level = scene_file('level', {'sensors.effort_latency': 0.002, 'sensors.state_latency': 0.002})
    assert main([*fit, '--scene', level, *mu, '--effort-latency', '0.002']) in (0, 1)
    assert 'wrote' in capsys.readouterr().out
