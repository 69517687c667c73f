"""A mounted surface over DDS: the simulator node publishes its plate on /surface_mounts and
the recorder, given the scene, records it and moves the surface's frame on /tf (real node
processes, random domain; the file read back with rosbags)."""

from pathlib import Path

import pytest
import yaml

from ros_helpers import controller, node_args, simulator, start_process, wait_for
from scenes import paper_dict


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def test_the_plate_is_published_recorded_and_moves_its_frame(probe, ros_env, tmp_path):
    from rosbags.highlevel import AnyReader
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    data = paper_dict()
    data['surfaces'][0]['mount'] = {'mass': 5.0, 'stiffness': 2e7, 'damping_ratio': 0.05}
    path = tmp_path / 'mounted.yaml'
    path.write_text(yaml.safe_dump(data))
    mcap = tmp_path / 'mounted.mcap'
    reports = probe.listen(String, '/impact_report', transient=True)
    plates = probe.listen(JointState, '/surface_mounts', depth=1000)
    scene = f'scene:={path}'
    recorder = node_args('impact_arm.nodes.recorder', f'output:={mcap}', scene)
    with start_process(recorder, ros_env, tmp_path, 'rec') as rec:
        assert wait_for(lambda: 'waiting for their publishers' in rec.stderr, timeout=60), (
            rec.stderr
        )
        with (
            start_process(
                simulator('mode:=lockstep', 'rate_factor:=0.0', scene), ros_env, tmp_path, 'sim'
            ) as sim,
            start_process(controller(scene), ros_env, tmp_path, 'ctl') as ctl,
        ):
            assert wait_for(
                lambda: len(reports) >= 2 or not sim.alive() or not ctl.alive(), timeout=180
            ), sim.stderr[-2000:] + ctl.stderr[-2000:]
    probe.forget(reports, plates)
    assert plates and {tuple(m.name) for _, m in plates} == {('surface1',)}
    assert max(abs(m.position[0]) for _, m in plates) > 1e-7  # struck: the plate moved
    z, moved, static = {}, [], []
    with AnyReader([Path(mcap)]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == '/surface_mounts':
                z[stamp_ns(msg.header)] = msg.position[0]
            elif conn.topic in ('/tf', '/tf_static'):
                for t in msg.transforms:
                    if conn.topic == '/tf_static':
                        static.append(t.child_frame_id)
                    elif t.child_frame_id == 'surface1':
                        moved.append((stamp_ns(t.header), t.transform.translation.z))
    assert len(z) > 100 and any(abs(v) > 1e-7 for v in z.values())
    assert 'surface1' not in static
    # the recorder draws each surface frame from the plate sample of its stamp
    matched = [(z[t], height) for t, height in moved if t in z]
    assert len(matched) > 10 and len(matched) == len(moved)
    assert all(height == pytest.approx(-1.0 + dz, abs=1e-12) for dz, height in matched)
    assert any(abs(dz) > 1e-7 for dz, _ in matched)


def test_impact_arm_run_records_every_period_of_the_plate(ros_env, tmp_path):
    """``impact-arm run`` (lockstep) of a scene with a mounted floor: complete, and the plate's
    topic recorded for every period the joint states were, from t = 0 (the run waits for the
    recorder to have written it too before the first command). The held initial state goes
    out every 0.1 s until then, so t = 0 may be recorded more often on one topic than on the
    other: periods are compared by their stamps, not counted."""
    import subprocess
    import sys

    from rosbags.highlevel import AnyReader

    data = paper_dict()
    data['surfaces'][0]['mount'] = {'mass': 5.0, 'stiffness': 2e7, 'damping_ratio': 0.05}
    data['cycles'] = 3
    path = tmp_path / 'mounted.yaml'
    path.write_text(yaml.safe_dump(data))
    argv = ['run', '--scene', str(path), '--mode', 'lockstep', '--name', 'm']
    run = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', *argv, '--out', str(tmp_path / 'runs')],
        env=ros_env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=400,
    )
    out = run.stdout + run.stderr
    assert run.returncode == 0, out[-3000:]
    assert ': complete' in out, out[-3000:]
    stamps = {'/surface_mounts': [], '/joint_states': []}
    with AnyReader([tmp_path / 'runs' / 'm.mcap']) as reader:
        wanted = [c for c in reader.connections if c.topic in stamps]
        for conn, _, raw in reader.messages(connections=wanted):
            stamps[conn.topic].append(stamp_ns(reader.deserialize(raw, conn.msgtype).header))
    periods = sorted(set(stamps['/joint_states']))
    assert sorted(set(stamps['/surface_mounts'])) == periods
    assert len(periods) > 100 and periods[0] == 0
    assert periods == [round(i * 1e9 / data['publish_rate']) for i in range(len(periods))]
