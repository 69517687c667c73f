"""What `impact-arm run` says of its file: in lockstep a gap is a defect (INCOMPLETE); in
realtime a period may run on the previous command (a late controller), so fewer commands
than periods is not called incomplete, and the recorder's loss count is what tells."""

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
    assert 'lost on the way (counted by the recorder): /joint_states 5' in text
