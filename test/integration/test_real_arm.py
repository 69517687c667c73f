"""The arm of examples/real_arm.yaml, as a user runs it: a three-link arm read from its URDF,
with joint damping and Coulomb friction, striking a plate on a compliant mount, seen through an
encoder. Each part has its own tests; these check that they work together."""

import json
import math
import os
import re
import shutil

import numpy as np
import pytest
from repo_paths import EXAMPLES

REAL_ARM = os.path.join(EXAMPLES, 'real_arm.yaml')


def test_a_urdf_arm_takes_a_mounted_plate_and_joint_friction():
    """The mount's contact-time check takes the contact sphere's radius from the URDF (a URDF
    scene has no ``tip_radius`` key)."""
    from impact_arm.physics.scene import load_scene

    scene = load_scene(REAL_ARM)
    assert scene.general_links and scene.tip_radius == 0.005
    assert scene.surfaces[0].mount is not None and scene.surfaces[0].mount.mass == 10.0
    assert [j.friction for j in scene.joints] == [0.2, 0.3, 0.1]


def test_prediction_keeps_a_urdf_arms_cycle_under_command_latency():
    """The example's arm (general links from its URDF, joint friction, a mounted plate) with
    the controller and the simulated driver in one process: one period of command latency
    makes it strike twice per cycle; predicting over the measured latency (one or two
    periods), it strikes once per cycle, when the arm without latency does. (The predictor
    once took the rod lengths for a general link's geometry: every prediction left the
    range and was refused, and the arm struck twice.)"""
    from impact_arm.physics.scene import load_scene
    from impact_arm.tools.latency_study import closed_loop

    scene = load_scene(REAL_ARM)
    base = closed_loop(scene, 0, 0, t_max=2.0)
    assert base.second_strikes == 0 and base.impacts == 5
    assert closed_loop(scene, 1, 0, t_max=2.0).second_strikes >= 4
    for latency in (1, 2):
        run = closed_loop(scene, latency, -1, t_max=2.0)
        assert not run.failed and run.second_strikes == 0 and run.impacts == base.impacts
        assert run.t_contact == pytest.approx(base.t_contact, abs=5e-3)
        assert max(run.delta_m) == pytest.approx(max(base.delta_m), rel=0.02)


@pytest.mark.slow
def test_a_real_arm_runs_over_dds_is_recorded_analysed_and_fitted(
    ros_env, tmp_path, capsys, monkeypatch
):
    """The issue's end: the URDF arm with joint friction and a mounted plate through
    ``impact-arm run`` (simulator, controller and recorder over DDS, lockstep, 3 cycles), the
    recording read back complete, ``impact-arm analyze`` with its defaults, and ``impact-arm
    fit`` freeing a contact parameter and a joint's friction, started away from the truth:
    ``fits``, each interval covering the scene's value."""
    from cli_runs import impact_arm_run, read_back

    from impact_arm.tools.cli import main

    examples = os.path.dirname(REAL_ARM)
    shutil.copy(os.path.join(examples, 'three_link.urdf'), tmp_path)
    shutil.copy(REAL_ARM, tmp_path / 'arm.yaml')
    code, out = impact_arm_run(
        ['--scene', 'arm.yaml', '--mode', 'lockstep', '--name', 'arm', '--out', 'runs'],
        ros_env,
        tmp_path,
    )
    assert code == 0 and ': complete' in out, out
    recording = tmp_path / 'runs' / 'arm.mcap'
    by_topic = read_back(recording)
    states = by_topic['/joint_states']
    stamps = np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in states])
    # lockstep: the initial state is repeated until the controller answers, then every period
    # once, none lost
    periods = np.unique(stamps)
    assert np.allclose(np.diff(periods), 1e-3, atol=1e-9) and np.all(np.diff(stamps) >= 0)
    assert len(periods) == int(re.search(r'wrote \S+: (\d+) periods', out).group(1))
    assert all(len(s.position) == 3 for s in states)
    counts = np.array([s.position for s in states]) * 131072 / (2 * math.pi)
    assert np.allclose(counts, np.round(counts), rtol=0, atol=1e-6)  # the encoder's readings
    reports = [json.loads(m.data) for m in by_topic['/impact_report']]
    # exactly the scene's 3 cycles (one strike each): in lockstep the controller stops at the
    # end of the third itself (its cycles parameter), however late the run stops the nodes
    assert [r['index'] for r in reports] == [1, 2, 3]
    for report in reports:  # the impact table gives every link's contact angle
        angles = ','.join(f'{a:>7.2f}' for a in report['q_contact_deg'])
        assert f'{report["t_contact"]:>9.5f} {angles} ' in out, out
    plate = np.array([m.position[0] for m in by_topic['/surface_mounts']])
    assert plate[0] == 0.0 and plate.min() < -1e-7  # the plate gives way under the strikes

    monkeypatch.chdir(tmp_path)
    assert main(['analyze', str(recording), '--out', 'analysis']) == 0
    figures = sorted(p.name for p in (tmp_path / 'analysis').glob('fig*.png'))
    assert 'fig3_controllers.png' in figures and 'fig4_link_angles.png' in figures
    # a live three-link recording: its impact integrated again from the report
    assert 'fig8_indentation.png' in figures and 'fig11_kinetic_energy.png' in figures

    truth = {'surfaces[0].mu': 0.2, 'joints[1].friction': 0.3}
    argv = ['fit', str(recording), '--scene', 'arm.yaml', '--out', 'fit']
    argv += ['--param', 'surfaces[0].mu=0.05:1@0.4', '--param', 'joints[1].friction=0:1@0.5']
    capsys.readouterr()
    assert main(argv) == 0
    assert capsys.readouterr().out.rstrip().endswith(': fits')
    result = json.load(open(tmp_path / 'fit' / 'fit.json'))
    assert result['verdict'] == 'fits'
    for key, value in truth.items():
        low, high = result['parameters'][key]['ci95']
        assert low <= value <= high, (key, low, high)


def test_the_figures_of_a_three_link_recording_show_every_link(tmp_path):
    """Figures 3 and 4 (and the compared recordings) draw one panel per link: a three-link
    arm's third link was left out of them."""
    from impact_arm.tools.run_data import Run
    from impact_arm.tools.figures import fig3_controllers, fig4_link_angles, fig_recordings

    t = np.linspace(0.0, 1.0, 50)
    q = np.stack([np.cos(t), np.sin(t), -t], axis=1)
    run = Run('three links', t, q, np.gradient(q, t, axis=0), law='q')
    run.target = np.array([-1.0, -1.2, -1.0])
    for fig in (fig4_link_angles(run, tmp_path), fig_recordings([run, run], tmp_path)):
        axes = [ax for ax in fig.axes if ax.get_ylabel()]
        assert [ax.get_ylabel() for ax in axes] == ['q1 [deg]', 'q2 [deg]', 'q3 [deg]']
        assert np.allclose(axes[2].lines[0].get_ydata(), np.degrees(q[:, 2]))
    fig = fig3_controllers([run], tmp_path)
    titles = [ax.get_title() for ax in fig.axes if ax.get_title().startswith('(')]
    assert titles == [
        f'({p}) response of link {k + 1} (target {t:g}°)'
        for k, (p, t) in enumerate(zip('abc', np.degrees(run.target)))
    ]


def test_a_fitted_urdf_scene_reads_its_urdf_from_the_fit_folder(tmp_path, monkeypatch):
    """``impact-arm fit`` writes runs/fit_<name>/fitted.yaml, away from the scene's folder: a
    relative ``arm.urdf`` is written relative to the new file, so the fitted scene loads from
    any working directory (it was refused: the URDF was looked for beside the fitted file)."""
    from impact_arm.physics.scene import load_scene
    from impact_arm import write_fitted_scene

    scenes = tmp_path / 'scenes'
    scenes.mkdir()
    shutil.copy(os.path.join(os.path.dirname(REAL_ARM), 'three_link.urdf'), scenes)
    shutil.copy(REAL_ARM, scenes / 'arm.yaml')
    (tmp_path / 'runs' / 'fit_arm').mkdir(parents=True)
    monkeypatch.chdir(tmp_path)
    write_fitted_scene('scenes/arm.yaml', {'surfaces[0].mu': 0.3}, 'runs/fit_arm/fitted.yaml')
    monkeypatch.chdir(tmp_path / 'runs')
    fitted = load_scene(str(tmp_path / 'runs' / 'fit_arm' / 'fitted.yaml'))
    assert fitted.n_links == 3 and fitted.surfaces[0].mu == 0.3


def test_the_step_response_of_a_mounted_plate_scene_runs_on_its_arms_kernel():
    """analyze's Figure 3 takes the surfaces away; a mounted plate is part of the kernel's
    shape, so it is kept, out of reach: the same compiled equations as the recorded run's (no
    second compile), and the arm moves as with no surface at all."""
    from dataclasses import replace

    from impact_arm.physics.model import ArmModel
    from impact_arm.physics.scene import load_scene
    from impact_arm.tools.step_responses import step_response, surfaces_out_of_reach

    scene = load_scene(REAL_ARM)
    assert len(surfaces_out_of_reach(scene)) == 1
    response = step_response(scene, 'q', t_max=1.0)
    assert ArmModel(response.scene).eq is ArmModel(scene).eq
    bare = step_response(replace(scene, surfaces=()), 'q', t_max=1.0)
    assert not response.impacts and len(response.t) == len(bare.t) > 900
    assert np.allclose(response.q, bare.q, rtol=0, atol=1e-7)
