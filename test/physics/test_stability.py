"""A sampled control law unstable at its rate is refused at load, and chatter is found in runs.

The stability analysis (physics/stability.py) is checked against offline sampled runs of the
nonlinear arm (``simulate.run(control_rate=...)``), never against itself: a damping just
inside the largest stable kd it reports must not chatter, one just outside must.
"""

import copy
import math
import os
import warnings

import numpy as np
import pytest
import yaml

from impact_arm.physics import stability
from impact_arm.physics.errors import SceneError, UnstableControlWarning
from impact_arm.physics.scene import installed_scenes, load_scene, parse_scene
from impact_arm.physics.simulate import StopReason, format_table, run
from scenes import arm_dict
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
THREE_LINK = os.path.join(ROOT, 'config', 'three_link.yaml')
OLD_THREE_LINK_GAINS = {'kp': [600.0, 300.0, 150.0], 'kd': [100.0, 100.0, 50.0]}
NODE_RATE = 1000.0  # the controller node's default rate: impact-arm run, launch


def three_link_dict():
    with open(THREE_LINK, encoding='utf-8') as f:
        return yaml.safe_load(f.read().replace('e9', 'e+9'))


def with_controller(data, **changes):
    data = copy.deepcopy(data)
    data['controller'].update(changes)
    return data


# ------------------------------------------------------------------ the check at load
def test_the_old_three_link_gains_are_refused_at_1khz_naming_joint_margin_and_largest_kd():
    data = with_controller(three_link_dict(), rate=NODE_RATE, **OLD_THREE_LINK_GAINS)
    with pytest.raises(SceneError) as info:
        parse_scene(data, origin='three_link.yaml')
    text = str(info.value)
    assert '\n' not in text
    assert "scene 'three_link.yaml': controller.kd[" in text and 'unstable at 1000 Hz' in text
    assert 'joint3: kd 50, largest stable' in text and 'margin -' in text
    assert 'allow_unstable' in text
    # the same gains continuous (rate 0) are accepted: nothing is sampled
    parse_scene(with_controller(data, rate=0.0))


def test_simulate_refuses_a_control_rate_the_law_is_unstable_at_with_exit_2(tmp_path, capsys):
    from impact_arm.tools.cli import main

    path = tmp_path / 'old.yaml'
    path.write_text(yaml.safe_dump(with_controller(three_link_dict(), **OLD_THREE_LINK_GAINS)))
    assert main(['simulate', '--scene', str(path), '--control-rate', '1000']) == 2
    err = capsys.readouterr().err
    assert 'unstable at 1000 Hz' in err and 'largest stable' in err and 'Traceback' not in err


def test_allow_unstable_warns_runs_and_the_run_reports_the_chatter():
    data = with_controller(
        three_link_dict(), rate=NODE_RATE, allow_unstable=True, **OLD_THREE_LINK_GAINS
    )
    data['t_max'] = 0.3
    with pytest.warns(UnstableControlWarning, match='unstable at 1000 Hz'):
        scene = parse_scene(data, origin='old')
    result = run(scene, keep_samples=False)
    assert result.stop_reason == StopReason.T_MAX_REACHED, result.stopped
    assert {c.name for c in result.chatter} >= {'joint3'}
    assert 'CHATTER: joint' in format_table(result)
    assert result.summary()['chatter'] and result.summary()['chatter'][0]['periods'] >= 16


def shipped_scenes():
    names = [os.path.join(ROOT, 'config', f'{name}.yaml') for name in installed_scenes()]
    examples = os.path.join(ROOT, 'examples')
    for entry in sorted(os.listdir(examples)):
        path = os.path.join(examples, entry)
        if entry.endswith('.yaml'):
            with open(path, encoding='utf-8') as f:
                if any(line.startswith(('links:', 'arm:')) for line in f):
                    names.append(path)
    return names


@pytest.mark.parametrize('path', shipped_scenes(), ids=os.path.basename)
def test_every_shipped_scene_loads_and_is_stable_at_its_rate_and_the_nodes_rate(path):
    with warnings.catch_warnings():
        warnings.simplefilter('error', UnstableControlWarning)
        scene = load_scene(path)
    assert not scene.controller.allow_unstable
    for rate in {scene.controller.rate or NODE_RATE, NODE_RATE}:
        report = stability.analyse(scene, rate)
        assert report is not None and report.stable, report and report.refusal()
        assert all(j.margin > 0.25 for j in report.joints), [j.text() for j in report.joints]


@pytest.mark.parametrize('n_links', [3, 4])
def test_the_test_arms_of_3_and_4_links_are_stable_at_1khz(n_links):
    report = stability.analyse(parse_scene(arm_dict(n_links)), NODE_RATE)
    assert report.stable and all(j.margin > 0.25 for j in report.joints), report.refusal()


def test_the_three_link_scene_strikes_at_1khz_without_chatter():
    scene = load_scene(THREE_LINK)
    result = run(scene, control_rate=NODE_RATE)
    assert result.stop_reason == StopReason.CYCLES_COMPLETED, result.stopped
    assert len(result.impacts) >= scene.cycles and not result.chatter
    tau = np.array([s.tau for s in result.samples])
    # the largest torque is the shoulder's swing, not a runaway (the old gains: ~1e5 N m)
    assert np.abs(tau).max() < 3000.0
    first = result.impacts[0]
    assert -6.0 < first.v_before[1] < -4.0  # the strike as before the gains changed (-4.6)


# ------------------------------------------------------------------ analysis vs simulation
def held_at_rest(law, space, kd, posture_deg, gravity):
    """The three-link arm held at its target (no surface, the target its start) and nudged:
    the linearisation the analysis makes is then the motion's."""
    data = with_controller(
        three_link_dict(),
        law=law,
        space=space,
        kd=[float(x) for x in kd],
        down_target_deg=posture_deg,
        up_target_deg=posture_deg,
        allow_unstable=True,
    )
    data.update(surfaces=[], cycles=0, t_max=0.8, gravity=gravity)
    data['initial'] = {'q_deg': posture_deg, 'qd': [0.0, 0.0, 0.01]}
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', UnstableControlWarning)
        return parse_scene(data, origin='held')


@pytest.mark.filterwarnings('ignore::impact_arm.physics.errors.UnstableControlWarning')
@pytest.mark.parametrize(
    'law, space, posture, gravity, joint',
    [
        ('q', 'absolute', [0.0, 0.0, 0.0], 9.81, 2),
        ('q', 'absolute', [-80.0, -70.0, -60.0], 9.81, 1),
        ('pid', 'joint', [20.0, -10.0, 30.0], 0.0, 2),
    ],
)
def test_just_inside_the_largest_stable_kd_does_not_chatter_and_just_outside_does(
    law, space, posture, gravity, joint
):
    kd = [100.0, 30.0, 20.0]
    report = stability.analyse(held_at_rest(law, space, kd, posture, gravity), NODE_RATE)
    assert report.stable
    kd_max = report.joints[joint].kd_max
    assert kd_max is not None and kd[joint] < kd_max < math.inf
    amplitude = {}
    for factor in (0.97, 1.03):
        trial = list(kd)
        trial[joint] = factor * kd_max
        scene = held_at_rest(law, space, trial, posture, gravity)
        assert stability.analyse(scene, NODE_RATE, margins=False).stable == (factor < 1)
        result = run(scene, control_rate=NODE_RATE)
        assert result.stop_reason == StopReason.T_MAX_REACHED, result.stopped
        tau = np.array([s.tau for s in result.samples])
        steps = np.abs(np.diff(tau, axis=0))
        first = steps[1:101].max()
        # the command steps of the last 100 periods, and at their largest, over the first 100
        amplitude[factor] = steps[-100:].max() / first, steps.max() / first
        assert bool(result.chatter) == (factor > 1), [c.text() for c in result.chatter]
    assert amplitude[0.97][0] < 1.0 and amplitude[0.97][1] < 2.0
    assert amplitude[1.03][1] > 10.0


def test_a_decoupled_joint_by_joint_limit_would_miss_the_old_three_link_chatter():
    """Why the analysis takes the whole arm: each link alone (its own inertia about its
    joint, the other joints rigid) allows kd up to 2 M_ii / h, far beyond the old gains; the
    coupled arm does not."""
    scene = parse_scene(with_controller(three_link_dict(), **OLD_THREE_LINK_GAINS))
    from impact_arm.physics.model import ArmModel

    model = ArmModel(scene)
    mass = model.mass_matrix(scene.q0)
    alone = 2 * np.diag(mass) * NODE_RATE
    assert all(kd < limit for kd, limit in zip(OLD_THREE_LINK_GAINS['kd'], alone))
    report = stability.analyse(scene, NODE_RATE, model=model)
    assert not report.stable


# ------------------------------------------------------------------ the chatter detector
NAMES = ('a', 'b')


def test_alternating_growing_commands_are_chatter_on_their_joint_only():
    k = np.arange(200)
    t = k * 1e-3
    smooth = 10 * np.sin(2 * np.pi * 2 * t)
    chatter = 5.0 + 0.01 * 1.05**k * (-1.0) ** k + smooth
    found = stability.find_chatter(t, np.column_stack([smooth, chatter]), NAMES)
    assert [c.name for c in found] == ['b']
    # from where the alternation outgrows the sine's own steps (0.13 N m) to the end
    assert found[0].t_start < 0.05 and found[0].periods >= 150 and found[0].growth > 4
    assert found[0].peak == pytest.approx(abs(chatter).max())
    assert found[0].text().startswith('b chatters from t = ')


def test_smooth_decaying_and_noisy_commands_are_not_chatter():
    rng = np.random.default_rng(1)
    k = np.arange(20000)
    t = k * 1e-3
    fast_swing = 300 * np.sin(2 * np.pi * 40 * t)  # 25 periods per swing
    decaying = 50 * 0.9**k * (-1.0) ** k + 20 * np.cos(3 * t)
    noise = 2 * rng.normal(size=k.size) + 100 * np.sin(t)
    for series in (fast_swing, decaying, noise):
        assert stability.find_chatter(t, np.column_stack([series, series]), NAMES) == []


def test_a_held_command_repeated_at_a_faster_sample_rate_is_one_period():
    k = np.arange(100)
    per_period = 0.1 * 1.1**k * (-1.0) ** k
    sampled = np.repeat(per_period, 4)  # published at 4x the control rate
    t = np.arange(sampled.size) * 2.5e-4
    found = stability.find_chatter(t, np.column_stack([sampled, 0 * sampled]), NAMES)
    assert [c.name for c in found] == ['a'] and found[0].periods >= 90


# ------------------------------------------------------------------ analyze
def test_analyze_reads_the_chatter_from_a_recordings_efforts(tmp_path):
    from impact_arm.tools import analysis
    from impact_arm.tools.cli import main

    files = {}
    for label, gains in (('old', OLD_THREE_LINK_GAINS), ('new', {})):
        data = with_controller(three_link_dict(), allow_unstable=True, **gains)
        data['t_max'] = 0.25
        path = tmp_path / f'{label}.yaml'
        path.write_text(yaml.safe_dump(data))
        files[label] = tmp_path / f'{label}.mcap'
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', UnstableControlWarning)
            code = main(
                [
                    'simulate',
                    '--scene',
                    str(path),
                    '--control-rate',
                    '1000',
                    '--mcap',
                    str(files[label]),
                ]
            )
        assert code == 0
    found = analysis.chatter(analysis.load(files['old']))
    assert 'joint3' in {c.name for c in found}
    assert analysis.chatter(analysis.load(files['new'])) == []
