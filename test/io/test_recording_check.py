"""What `impact-arm run` says of its file: in lockstep a gap is a defect (INCOMPLETE); in
realtime a period may run on the previous command (a late controller), so fewer commands
than periods is not called incomplete, and the recorder's loss count is what tells."""

import numpy as np

from impact_arm.io.recording_check import RecordingCheck


def test_lockstep_names_what_is_missing():
    check = RecordingCheck(100, [7, 8], 90, 3, [2], {'/joint_states': 2})
    text = check.summary(lockstep=True)
    assert not check.complete
    assert 'INCOMPLETE' in text and '2 periods missing (first: period 7)' in text
    assert '9 commands missing' in text and 'impact reports missing: [2]' in text
    assert RecordingCheck(100, [], 99, 3).summary().endswith(': complete')


def test_realtime_reports_counts_and_losses_without_calling_late_commands_missing():
    text = RecordingCheck(100, [], 92, 3, [], {'/joint_states': 5}).summary(lockstep=False)
    assert 'INCOMPLETE' not in text and 'commands missing' not in text
    assert '92 commands' in text and '0 periods not in the file' in text
    assert 'received no joint state' not in text  # a file that holds every period
    assert 'lost on the way (counted by the recorder): /joint_states 5' in text


def _recording(folder, periods, wrench_gaps=(), commands=None):
    """A rosbag2 folder written by rosbags: joint states for ``periods`` periods at 1 kHz, the
    wrench and the force peak for the same periods but ``wrench_gaps``, a command each
    period after the first. Returns the MCAP file's path."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {
        name: store.types[name]
        for name in (
            'sensor_msgs/msg/JointState',
            'geometry_msgs/msg/WrenchStamped',
            'std_msgs/msg/Float64MultiArray',
        )
    }
    JS, WS, FA = types.values()
    H = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    W, V = store.types['geometry_msgs/msg/Wrench'], store.types['geometry_msgs/msg/Vector3']
    L = store.types['std_msgs/msg/MultiArrayLayout']
    with Writer(folder, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        js = writer.add_connection('/joint_states', JS.__msgtype__, typestore=store)
        ws = writer.add_connection('/contact_wrench', WS.__msgtype__, typestore=store)
        peak = writer.add_connection('/contact_force_peak', WS.__msgtype__, typestore=store)
        cmd = writer.add_connection('/effort_controller/commands', FA.__msgtype__, typestore=store)
        for k in range(periods):
            ns = k * 1_000_000
            header = H(stamp=Time(sec=0, nanosec=ns), frame_id='surface')
            if k:
                command = FA(layout=L(dim=[], data_offset=0), data=np.zeros(2))
                writer.write(cmd, ns, store.serialize_cdr(command, FA.__msgtype__))
            zeros = np.zeros(2)
            state = JS(
                header=header,
                name=['joint1', 'joint2'],
                position=zeros,
                velocity=zeros,
                effort=zeros,
            )
            writer.write(js, ns, store.serialize_cdr(state, JS.__msgtype__))
            wrench = WS(
                header=header, wrench=W(force=V(x=0.0, y=0.0, z=0.0), torque=V(x=0.0, y=0.0, z=0.0))
            )
            writer.write(peak, ns, store.serialize_cdr(wrench, WS.__msgtype__))
            if k not in wrench_gaps:
                writer.write(ws, ns, store.serialize_cdr(wrench, WS.__msgtype__))
    (mcap,) = folder.glob('*.mcap')
    return mcap


def test_every_per_period_topic_of_the_file_must_cover_every_period(tmp_path):
    """Joint states all there but two periods of the wrench lost: incomplete, naming the
    topic; a topic the run expects (a mount's plates) and the file lacks misses them all."""
    from impact_arm.io.recording_check import check_recording

    whole_file = _recording(tmp_path / 'whole', 50)
    whole = check_recording(whole_file, 1000.0)
    assert whole.complete, whole.summary()
    assert whole.missing_on == {'/contact_wrench': [], '/contact_force_peak': []}

    gaps = check_recording(_recording(tmp_path / 'gaps', 50, wrench_gaps=(7, 8)), 1000.0)
    assert gaps.periods == 50 and not gaps.missing_periods
    assert not gaps.complete
    assert '2 periods missing on /contact_wrench (first: period 7)' in gaps.summary()

    mounts = check_recording(whole_file, 1000.0, ('/surface_mounts',))
    assert mounts.missing_on['/surface_mounts'] == list(range(50))
    assert '50 periods missing on /surface_mounts (first: period 0)' in mounts.summary()


def test_periods_after_the_files_last_sample_count_up_to_the_runs_end(tmp_path):
    """A recorder that stopped receiving has no gap to show: the run's own end (``until``)
    makes its lost tail missing periods, in lockstep and in realtime."""
    from impact_arm.io.recording_check import check_recording

    mcap = _recording(tmp_path / 'short', 50)  # periods 0..49: t = 0..0.049 s
    assert check_recording(mcap, 1000.0, until=0.049).complete
    cut = check_recording(mcap, 1000.0, until=0.0595)
    assert cut.missing_periods == list(range(50, 60)), cut.missing_periods
    assert not cut.complete
    assert cut.lost_tail == 10
    assert (
        '10 periods not in the file (the file ends at t = 0.049 s, the run at 0.059 s: '
        'the recorder received nothing after it)' in cut.summary(lockstep=False)
    )
    assert 'the file ends' not in check_recording(mcap, 1000.0).summary(lockstep=False)
    empty = check_recording(_recording(tmp_path / 'empty', 0), 1000.0, until=0.0095)
    assert empty.missing_periods == list(range(10))
    assert empty.summary(lockstep=False).endswith(
        '10 periods not in the file (the recorder received no joint state)'
    )
