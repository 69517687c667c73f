"""Every path runs every arm the offline path runs: ``impact-arm run`` over DDS with arms of 3
and 4 links (scenes the tests write themselves), read back with rosbags; and a run in which a
node failed is never called complete.

Kept short (two cycles each): a whole run over DDS costs tens of seconds on two cores, and a
new scene shape compiles its kernel once (~50 s, then cached).
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from types import SimpleNamespace


from impact_arm import contract
from impact_arm.physics.scene import load_scene
from impact_arm.physics.simulate import run
from scenes import arm_dict, impact_at, write_arm_scene
from tf_frames import stamp_ns, tip_in_world
from cli_runs import impact_arm_run, read_back
from repo_paths import EXAMPLES, REPO_ROOT


def tip_from_angles(lengths, q_abs):
    """The end of the last link in the REP 103 world (x, 0, z), by plain trigonometry: the
    arm's plane is the world's x-z plane, absolute link angles from the x axis."""
    return np.array(
        [
            sum(length * math.cos(q) for length, q in zip(lengths, q_abs)),
            0.0,
            sum(length * math.sin(q) for length, q in zip(lengths, q_abs)),
        ]
    )


@pytest.mark.slow
@pytest.mark.parametrize('n_links', [3, 4])
def test_lockstep_run_of_an_arm_of_n_links_completes_records_and_draws_it(
    ros_env, tmp_path, n_links
):
    cycles = 2
    scene_path = write_arm_scene(tmp_path, n_links, cycles=cycles)
    code, out = impact_arm_run(
        ['--scene', scene_path, '--mode', 'lockstep', '--name', 'arm', '--out', 'runs'],
        ros_env,
        tmp_path,
    )
    assert code == 0, out
    assert ': complete' in out and 'failed' not in out, out
    by_topic = read_back(tmp_path / 'runs' / 'arm.mcap')
    joints = [f'joint{i + 1}' for i in range(n_links)]

    # every period, from the held initial state at stamp 0 to the end, of every joint
    states = by_topic['/joint_states']
    assert all(list(m.name) == joints and len(m.position) == n_links for m in states)
    stamps = sorted({round(stamp_ns(m.header) * 1e-6) for m in states})
    assert stamps == list(range(stamps[-1] + 1)), 'periods missing from the recording'
    commands = by_topic['/effort_controller/commands']
    assert len(commands) >= stamps[-1] and all(len(c.data) == n_links for c in commands)

    # the impact reports, numbered, at least one per cycle; the run went on until the
    # controller had struck in every cycle (an arm that bounces reports more impacts)
    reports = [json.loads(m.data) for m in by_topic['/impact_report']]
    assert [r['index'] for r in reports] == list(range(1, len(reports) + 1))
    assert len(reports) >= cycles
    strikes = [
        int(value.value)
        for m in by_topic['/diagnostics']
        for status in m.status
        if status.name == contract.CONTROLLER_STATUS
        for value in status.values
        if value.key == 'strikes'
    ]
    assert strikes and max(strikes) >= cycles, strikes
    # the same scene offline, its controller sampled at the same 1 kHz: the same impacts
    offline = run(load_scene(scene_path), control_rate=1000.0)
    times = [i.t_contact for i in offline.impacts]
    shared = min(len(times), len(reports))
    assert shared >= cycles
    assert [r['t_contact'] for r in reports[:shared]] == pytest.approx(times[:shared], abs=1e-9)

    # TF: at each impact, a frame inside its contact puts the tip on the surface, where the
    # link lengths and the reported contact angles put the end of the arm
    data = arm_dict(n_links)
    lengths = [link['length'] for link in data['links']]
    height = data['surfaces'][0]['height']
    (static,) = by_topic['/tf_static']
    tip = next(t for t in static.transforms if t.child_frame_id == 'tip')
    for report in reports:
        t0 = round(report['t_contact'] * 1e9)
        t1 = round((report['t_contact'] + report['duration']) * 1e9)
        inside = [
            m for m in by_topic['/tf'] if t0 - 1 <= stamp_ns(m.transforms[0].header) <= t1 + 1
        ]
        assert inside, f'no /tf frame during impact {report["index"]}'
        first_contact = tip_in_world(inside[0], tip)
        assert first_contact[2] == pytest.approx(height, abs=1e-6)
        q_contact = np.radians(report['q_contact_deg'])
        assert len(q_contact) == n_links
        assert first_contact == pytest.approx(tip_from_angles(lengths, q_contact), abs=1e-9)


@pytest.mark.slow
def test_run_in_which_a_node_failed_is_not_complete_and_exits_non_zero(ros_env, tmp_path):
    """The controller refuses its joints at start: the run must say it failed, never call
    the recording complete, and exit 1."""
    script = (
        'import argparse, sys\n'
        'from impact_arm.tools import runner\n'
        'parser = argparse.ArgumentParser()\n'
        'runner.add_arguments(parser)\n'
        'args = parser.parse_args(sys.argv[1:])\n'
        "args.controller_params = ['joints:=[joint2,joint2]']\n"
        'sys.exit(runner.cli(args))\n'
    )
    proc = subprocess.run(
        [sys.executable, '-c', script, '--name', 'failed', '--out', 'runs'],
        env=ros_env,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=300,
    )
    out = proc.stdout
    assert proc.returncode == 1, out
    assert 'controller exited with status 2' in out and 'the run failed' in out, out
    assert ': complete' not in out, out


def test_a_cycle_counts_once_its_strike_and_the_report_of_its_impact_are_in():
    """The runner's end of a run: cycles are the controller's strikes, not impact reports (an
    arm that bounces reports several per cycle), and the strike's own report must be in."""
    from impact_arm.contract import SimulatorMode
    from impact_arm.tools.runner import Run

    def report(t):
        return impact_at([-45.0, -20.0], t_contact=t)

    run = Run.__new__(Run)  # the counting alone: no processes, no DDS
    run.mode, run.scene = SimulatorMode.REALTIME, SimpleNamespace(cycles=2)
    run.strikes, run.down_half_start, run.cycles_completed = 0, {}, 0
    # cycle 1: the strike's impact and two bounces while the arm goes up again
    run.impacts = [report(0.211), report(0.213), report(0.216)]
    assert not run._struck(2) and not run._struck(1)
    run.strikes, run.down_half_start[1] = 1, 0.0
    assert run._struck(1) and not run._struck(2)
    # cycle 2 (its down half began at 0.41 s): the controller's count arrives first
    run.strikes, run.down_half_start[2] = 2, 0.41
    assert not run._struck(2)
    run.impacts.append(report(0.619))
    assert run._struck(2)
    # lockstep: the recording ends where the controller stopped, at the scene's count
    run.mode = SimulatorMode.LOCKSTEP
    assert not run._struck(2)
    run.cycles_completed = 2
    assert run._struck(2)


def write_urdf_arm_scene(directory, cycles=1) -> Path:
    """The example three-link URDF arm (examples/three_link.yaml and .urdf) copied into
    ``directory``, ``cycles`` down/up cycles; returns the scene's path."""
    import yaml

    examples = Path(EXAMPLES)
    data = yaml.safe_load((examples / 'three_link.yaml').read_text(encoding='utf-8'))
    (directory / data['arm']['urdf']).write_text(
        (examples / data['arm']['urdf']).read_text(encoding='utf-8'), encoding='utf-8'
    )
    data['cycles'], data['t_max'] = cycles, 10.0
    path = directory / 'three_link.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
    return path


@pytest.mark.slow
def test_a_urdf_arm_runs_under_its_own_joint_names_and_its_recording_reads_back(ros_env, tmp_path):
    import xml.etree.ElementTree as ET

    from impact_arm.io.recording import read_recording, recorded_scene
    from impact_arm.tools.fit import fit_recording

    urdf_joints = ['shoulder', 'elbow', 'wrist']  # examples/three_link.urdf's joints
    cycles = 2  # the first impact has free samples after it, to fit
    scene_path = write_urdf_arm_scene(tmp_path, cycles)
    code, out = impact_arm_run(
        ['--scene', str(scene_path), '--mode', 'lockstep', '--name', 'arm', '--out', 'runs'],
        ros_env,
        tmp_path,
    )
    assert code == 0, out
    assert ': complete' in out and 'failed' not in out, out
    recording = tmp_path / 'runs' / 'arm.mcap'
    by_topic = read_back(recording)

    # the simulator publishes, and the controller drives, the URDF's joints by their names
    states = by_topic['/joint_states']
    assert states and all(list(m.name) == urdf_joints for m in states)
    commands = by_topic['/effort_controller/commands']
    assert commands and all(len(c.data) == len(urdf_joints) for c in commands)
    reports = [json.loads(m.data) for m in by_topic['/impact_report']]
    assert len(reports) >= cycles
    # the robot description names them so too (its revolute joints; the rest are fixed)
    (description,) = by_topic['/robot_description']
    robot = ET.fromstring(description.data)
    moving = [j.get('name') for j in robot.findall('joint') if j.get('type') != 'fixed']
    assert moving == urdf_joints
    # whose links, the URDF's, are the frames /tf moves
    links = [
        j.find('child').get('link') for j in robot.findall('joint') if j.get('type') != 'fixed'
    ]
    assert links == ['upper_arm', 'forearm', 'hand']
    assert all([t.child_frame_id for t in m.transforms][:3] == links for m in by_topic['/tf'])

    # read back as fit and compare read it: the joints of the scene the recording stores
    stored = recorded_scene(recording)
    assert list(stored.joint_names) == urdf_joints
    rec = read_recording(recording, scene_joints=stored.joint_names)
    assert list(rec.joints) == urdf_joints
    assert rec.position.shape[1] == len(urdf_joints) and len(rec.position) > len(states) / 2
    assert np.all(np.isfinite(rec.position))
    # and fitted (scene=None: the stored scene): the yield strength the arm was simulated with
    # comes back from the recorded joint rates, started 40 % off
    result = fit_recording(
        recording, None, {'materials.steel.S_y': (0.5e9, 2e9, 0.7e9)}, out=False, say=lambda s: None
    )
    assert result.impacts_used >= 1
    assert result.parameters['materials.steel.S_y'].value == pytest.approx(1.12e9, rel=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize('scene_name', ['three_link', 'examples/three_link.yaml'])
def test_a_shipped_scene_runs_in_lockstep_as_offline_at_the_same_rate(
    ros_env, tmp_path, scene_name
):
    """The shipped three-link arms (rods, and from their URDF with effort limits) through
    ``impact-arm run`` in lockstep at 1 kHz and offline with the controller sampled at
    1 kHz: the same impacts, to 1e-9 s."""
    from impact_arm.physics.scene import resolve_scene_path

    repo = Path(REPO_ROOT)
    path = str(repo / scene_name) if '/' in scene_name else resolve_scene_path(scene_name)
    code, out = impact_arm_run(
        ['--scene', path, '--mode', 'lockstep', '--name', 'arm', '--out', 'runs'], ros_env, tmp_path
    )
    assert code == 0 and ': complete' in out, out
    reports = [
        json.loads(m.data) for m in read_back(tmp_path / 'runs' / 'arm.mcap')['/impact_report']
    ]
    offline = run(load_scene(path), control_rate=1000.0)
    shared = min(len(reports), len(offline.impacts))
    assert shared >= load_scene(path).cycles
    assert [r['t_contact'] for r in reports[:shared]] == pytest.approx(
        [i.t_contact for i in offline.impacts[:shared]], abs=1e-9
    )
