"""impact-arm fit / compare: parameters drawn here are written into recordings by the
simulator (with sensor noise, lost samples and a wall-clock offset) and must come back within
the targets; a contact the scene cannot express must be refused as a fit; bad input is
refused in one line naming what is wrong."""

import json
import os

import numpy as np
import pytest

from impact_arm.physics.errors import ImpactArmError
from impact_arm.calibration.fit import FitError, fit
from impact_arm.calibration.identify import IdentifyError, JointRecording, LocalFit, find_impacts
from impact_arm.io.recording import RecordingInputError, read_recording
from impact_arm.tools.synthetic import synthetic_recording, write_rosbag2

BOUNDS = {'surfaces[0].mu': (0.05, 1.0), 'materials.steel.S_y': (2e8, 5e9)}
WALL_CLOCK = 1.7e9  # stamps of a machine's clock, not from zero


def drawn(seed):
    rng = np.random.default_rng(seed)
    return {
        'surfaces[0].mu': float(rng.uniform(0.12, 0.6)),
        'materials.steel.S_y': float(np.exp(rng.uniform(np.log(5e8), np.log(2e9)))),
    }


def recording(truth, seed, cycles=6, **kw):
    return synthetic_recording(
        'paper', truth, cycles=cycles, drop=0.02, clock_offset=WALL_CLOCK, seed=seed, **kw
    )


def relative_errors(result, truth):
    return {k: abs(result.parameters[k]['value'] / v - 1) for k, v in truth.items()}


@pytest.mark.parametrize('seed', [11, 12])
def test_fit_with_wrench_recovers_drawn_parameters(seed):
    truth = drawn(seed)
    result = fit(recording(truth, seed), 'paper', BOUNDS)
    assert result.used_wrench
    assert result.fits, result.verdict
    for key, err in relative_errors(result, truth).items():
        assert err < 0.05, (key, result.parameters[key], truth[key])
        lo, hi = result.parameters[key]['ci95']
        assert lo < truth[key] < hi, (key, lo, truth[key], hi)
        assert result.parameters[key]['identifiable']


def test_fit_from_joint_states_alone():
    truth = drawn(21)
    result = fit(recording(truth, 21, wrench=False), 'paper', BOUNDS)
    assert not result.used_wrench
    assert result.fits, result.verdict
    for key, err in relative_errors(result, truth).items():
        assert err < 0.10, (key, result.parameters[key], truth[key])
    # the noise the fit estimated is the noise the recording was given
    assert np.allclose(result.noise['velocity'], 2e-3, rtol=0.2)
    assert np.allclose(result.noise['position'], 2e-5, rtol=0.2)


def test_contact_the_scene_cannot_express_does_not_fit():
    # the arm hit a far softer floor than the scene states; only mu is free
    rec = recording({'materials.steel.E': 40e9}, 31)
    result = fit(rec, 'paper', {'surfaces[0].mu': (0.05, 1.0)})
    assert result.verdict.startswith('does not fit: '), result.verdict
    # the same recording fitted with E free fits, and finds E
    free = fit(rec, 'paper', {'surfaces[0].mu': (0.05, 1.0), 'materials.steel.E': (1e10, 5e11)})
    assert free.fits, free.verdict
    assert abs(free.parameters['materials.steel.E']['value'] / 40e9 - 1) < 0.1


def test_local_fit_differentiates_a_cubic_exactly():
    t = np.linspace(0.0, 0.014, 15)
    c = np.array([0.3, -2.0, 40.0, 900.0])
    q = (c[0] + c[1] * t + c[2] * t**2 + c[3] * t**3)[:, None]
    qd = (c[1] + 2 * c[2] * t + 3 * c[3] * t**2)[:, None]
    fitted = LocalFit(t, q, qd, t[-1], np.array([1e-5]), np.array([1e-3]))
    t_out = 0.0155  # extrapolated past the window, as at an impact
    q1, qd1, cov = fitted.state(t_out)
    assert q1[0] == pytest.approx(
        c[0] + c[1] * t_out + c[2] * t_out**2 + c[3] * t_out**3, abs=1e-12
    )
    assert qd1[0] == pytest.approx(c[1] + 2 * c[2] * t_out + 3 * c[3] * t_out**2, abs=1e-9)
    assert cov[1, 1] > 0


def test_a_rate_step_is_an_impact_a_rate_kink_is_not():
    t = np.arange(0, 0.2, 1e-3)
    v = np.where(t < 0.1005, -2.0, 1.0) + np.where(t > 0.0505, 3000 * (t - 0.0505), 0.0)
    v = np.column_stack([v, 0.5 * v])
    rng = np.random.default_rng(0)
    v = v + rng.normal(0, 2e-3, v.shape)
    rec = JointRecording(t, np.zeros_like(v), v, np.zeros_like(v))
    found = find_impacts(rec)
    assert [round(t[a], 4) for a in found] == [0.1]


# ------------------------------------------------------------------------- files, CLI, refusals
@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """A rosbag2 folder written by the rosbags library (not by us): an extra joint first."""
    truth = drawn(41)
    rec = recording(truth, 41)
    folder = tmp_path_factory.mktemp('bags') / 'arm_bag'
    write_rosbag2(rec, str(folder))
    return str(folder), truth


def test_cli_fits_a_rosbag2_folder_and_writes_a_scene_that_runs(bag, tmp_path, capsys):
    from impact_arm.physics.scene import load_scene
    from impact_arm.physics.simulate import run
    from impact_arm.tools.cli import main

    folder, truth = bag
    out = tmp_path / 'fit'
    code = main(
        [
            'fit',
            folder,
            '--scene',
            'paper',
            '--joints',
            'joint1,joint2',
            '--param',
            'surfaces[0].mu=0.05:1',
            '--param',
            'materials.steel.S_y=2e8:5e9',
            '--json',
            str(tmp_path / 'r.json'),
            '--out',
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    data = json.loads((tmp_path / 'r.json').read_text())
    assert set(data) >= {
        'parameters',
        'verdict',
        'residual_rms',
        'noise_rms',
        'impacts_used',
        'scene',
    }
    assert data['verdict'] == 'fits'
    for key, value in truth.items():
        p = data['parameters'][key]
        assert set(p) == {'value', 'ci95', 'identifiable'}
        assert abs(p['value'] / value - 1) < 0.05
    for name in ('fitted.yaml', 'report.md', 'impacts.png', 'cor.png', 'fit.json'):
        assert (out / name).is_file(), name
        assert f'wrote {out / name}' in text
    scene = load_scene(data['scene'])
    assert scene.surfaces[0].mu == pytest.approx(data['parameters']['surfaces[0].mu']['value'])
    assert not run(scene, samples=False).error


def test_compare_checks_a_fitted_scene_against_another_recording(bag, tmp_path):
    from impact_arm.tools.compare import compare

    folder, truth = bag
    scene = tmp_path / 'truth.yaml'
    from impact_arm.tools.fit import write_fitted_scene

    write_fitted_scene('paper', truth, str(scene))
    right = compare(folder, str(scene))
    wrong = compare(folder, 'paper')
    d_right = np.array([r['d_cor'] for r in right['table']])
    d_wrong = np.array([r['d_cor'] for r in wrong['table']])
    assert len(d_right) >= 4 and right['unmatched_a'] == 0
    assert np.sqrt(np.mean(d_right**2)) < 0.2 * np.sqrt(np.mean(d_wrong**2))


@pytest.mark.parametrize(
    'kwargs, message',
    [
        ({'joints': ['shoulder', 'elbow']}, '--joints: shoulder, elbow not in /joint_states'),
        ({'states_topic': '/arm/joint_states'}, '--states-topic /arm/joint_states: not in'),
        ({'wrench_topic': '/ft_sensor'}, '--wrench-topic /ft_sensor: not in'),
    ],
)
def test_bad_recording_input_is_refused_in_one_line(bag, kwargs, message):
    with pytest.raises(RecordingInputError) as exc:
        read_recording(bag[0], **kwargs)
    assert message in str(exc.value) and '\n' not in str(exc.value)


@pytest.mark.parametrize(
    'bounds, message',
    [
        ({'surfaces[0].gamma': (0.1, 1.0)}, "no 'gamma' in surfaces[0]"),
        ({'materials.brass.E': (1e9, 1e12)}, "no 'brass' in materials"),
        ({'surfaces[0].mu': (0.3, 1.0)}, "the bounds exclude the scene's value 0.2"),
        ({'surfaces[0].mu': (1.0, 0.3)}, 'bounds must be finite with LO < HI'),
    ],
)
def test_bad_parameters_are_refused_in_one_line(bounds, message):
    rec = recording({}, 51, cycles=2)
    with pytest.raises(FitError) as exc:
        fit(rec, 'paper', bounds)
    assert message in str(exc.value) and '\n' not in str(exc.value)


def test_a_recording_without_impact_is_refused(tmp_path, capsys):
    from impact_arm.tools.cli import main

    # the arm is sent down to the horizontal only: it never reaches the floor
    rec = synthetic_recording(
        'paper', {'controller.down_target_deg': [0.0, 0.0], 't_max': 1.5}, seed=61
    )
    with pytest.raises(IdentifyError, match='no impact in the recording'):
        fit(rec, 'paper', {'surfaces[0].mu': (0.05, 1.0)})
    folder = tmp_path / 'quiet_bag'
    write_rosbag2(rec, str(folder))
    assert (
        main(['fit', str(folder), '--param', 'surfaces[0].mu=0.05:1', '--out', str(tmp_path / 'o')])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'no impact in the recording' in err[0]


def test_param_syntax_is_refused_in_one_line():
    from impact_arm.tools.fit import parse_param

    with pytest.raises(ImpactArmError, match="--param 'surfaces\\[0\\].mu=0.1': expected"):
        parse_param('surfaces[0].mu=0.1')
    assert parse_param('tip_radius=1e-3:1e-2') == ('tip_radius', (1e-3, 1e-2))
    assert os.sep not in parse_param('a.b=1:2')[0]


def test_fit_a_driver_recording_of_another_material_and_posture():
    """The simulator node's reading of efforts (each stamp reports the command held over
    the period before it, sampled 1 kHz control), an aluminium-like arm and floor, other
    targets and start: the reading is told from the free flight, the values come back."""
    from impact_arm.calibration.study import Study, apply_overrides
    from impact_arm.tools.synthetic import driver_recording

    variant = {
        'materials.steel.E': 70e9,
        'materials.steel.nu': 0.33,
        'materials.steel.S_y': 2.5e8,
        'surfaces[0].mu': 0.3,
        'controller.rate': 1000.0,
        'controller.down_target_deg': [-70.0, -85.0],
        'initial.q_deg': [40.0, 60.0],
        'surfaces[0].height': -1.1,
    }
    truth = {'materials.steel.S_y': 3.1e8, 'surfaces[0].mu': 0.42}
    rec = driver_recording('paper', {**variant, **truth}, cycles=6, seed=71)
    scene = apply_overrides(Study('paper').data, variant)
    result = fit(rec, scene, {'materials.steel.S_y': (5e7, 2e9), 'surfaces[0].mu': (0.05, 1.0)})
    assert result.timing == 'previous'
    assert result.fits, result.verdict
    for key, err in relative_errors(result, truth).items():
        assert err < 0.05, (key, result.parameters[key], truth[key])


def test_joints_in_the_wrong_order_are_told_not_fitted():
    rec = recording({}, 81, cycles=2)
    for name in ('position', 'velocity', 'effort'):
        setattr(rec, name, getattr(rec, name)[:, ::-1].copy())  # elbow first
    with pytest.raises(
        IdentifyError,
        match='none with the tip near a surface of the scene '
        r'\(check --joints order',
    ):
        fit(rec, 'paper', {'surfaces[0].mu': (0.05, 1.0)})


def test_noise_free_recording_with_a_start_up_hold_is_fitted_exactly():
    """No sensor noise at all, and two seconds at rest first (a driver's start-up hold): the
    noise floors and the robust scales must not break down; the values come back to 1e-4."""
    truth = {'surfaces[0].mu': 0.35, 'materials.steel.S_y': 1.5e9}
    rec = synthetic_recording('paper', truth, cycles=5, seed=6, noise={})
    hold = 2000
    rec.t = np.concatenate([np.arange(hold) * 1e-3, rec.t + hold * 1e-3])
    rec.position = np.concatenate([np.repeat(rec.position[:1], hold, axis=0), rec.position])
    rec.velocity = np.concatenate([np.zeros((hold, 2)), rec.velocity])
    rec.effort = np.concatenate([np.zeros((hold, 2)), rec.effort])
    rec.wrench_t = rec.wrench_t + hold * 1e-3
    result = fit(rec, 'paper', BOUNDS)
    assert result.fits and result.impacts_used == 5, (result.verdict, result.notes)
    for key, err in relative_errors(result, truth).items():
        assert err < 1e-4, (key, result.parameters[key])


def test_compare_two_recordings_matches_their_impacts(bag, tmp_path):
    """Two recordings of the same arm (other noise, other lost samples, another clock, no
    extra joint in the second): every impact matched, the CoR the same within the noise."""
    from impact_arm.tools.compare import compare

    folder, truth = bag
    other = tmp_path / 'other_bag'
    write_rosbag2(
        synthetic_recording('paper', truth, cycles=6, drop=0.03, clock_offset=5e8, seed=42),
        str(other),
        extra_joint=False,
    )
    result = compare(folder, str(other))
    d = np.array([r['d_cor'] for r in result['table']])
    assert len(d) == len(result['a']) == len(result['b'])
    assert np.max(np.abs(d)) < 0.01


# ------------------------------------------------------------------ an arm of three links
@pytest.fixture(scope='module')
def three_link_recording(tmp_path_factory):
    """A recording of a three-link arm with its scene stored in it, as `impact-arm run`'s
    recorder and `simulate --mcap` write it; the scene's S_y is not the article's."""
    import yaml

    from impact_arm.tools.cli import main
    from scenes import arm_dict

    folder = tmp_path_factory.mktemp('three')
    data = arm_dict(3)
    data['materials']['steel']['S_y'] = 8.0e8
    scene = folder / 'arm3.yaml'
    scene.write_text(yaml.safe_dump(data, sort_keys=False))
    mcap = folder / 'arm3.mcap'
    assert (
        main(['simulate', '--scene', str(scene), '--control-rate', '1000', '--mcap', str(mcap)])
        == 0
    )
    return mcap


def test_fit_and_compare_read_a_three_link_arm_with_the_scene_it_stores(
    three_link_recording, tmp_path, capsys
):
    from impact_arm.tools.cli import main
    from impact_arm.tools.compare import compare

    mcap = three_link_recording
    code = main(
        [
            'fit',
            str(mcap),
            '--param',
            'materials.steel.S_y=2e8:5e9',
            '--json',
            str(tmp_path / 'r.json'),
            '--out',
            str(tmp_path / 'fit'),
        ]
    )
    assert code == 0, capsys.readouterr().out
    result = json.loads((tmp_path / 'r.json').read_text())
    assert result['verdict'] == 'fits' and result['impacts_used'] >= 2
    assert result['parameters']['materials.steel.S_y']['value'] == pytest.approx(8e8, rel=0.01)
    both = compare(mcap, mcap)
    assert both['pairs'] and all(i == j for i, j in both['pairs'])


def test_a_recording_of_more_joints_than_the_scene_has_is_refused(three_link_recording):
    with pytest.raises(RecordingInputError, match=r'names joint3 besides .*--scene'):
        read_recording(three_link_recording, n_joints=2)
