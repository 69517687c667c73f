"""Readers of recordings order by stamp, never by file position or log time: a recorder that
stalled writes what reached it late after newer messages (impact reports [5..15, 1..4] were
seen), and a table that began with impact 5 would call impact 5 the first. The test writes
such a file on purpose and analyses it."""

import subprocess
import sys

import numpy as np

from impact_arm import contract
from impact_arm.io.mcap_ros2 import Ros2McapWriter, iter_raw, read_metadata
from impact_arm.tools.analysis import load


def scrambled_copy(source, target):
    """``source``'s joint states, wrenches and impact reports in a scrambled file order, each
    logged when 'received' (the log time grows with the file position): the second half of
    the joint states and of the reports first, then the first half."""
    messages = list(
        iter_raw(source, [contract.JOINT_STATES, contract.CONTACT_WRENCH, contract.IMPACT_REPORT])
    )
    by_topic = {}
    for m in messages:
        by_topic.setdefault(m.topic, []).append(m)
    order = []
    for ms in by_topic.values():
        half = len(ms) // 2
        order += ms[half:] + ms[:half]
    metadata = read_metadata(source)
    with Ros2McapWriter(target) as writer:
        writer.add_metadata('scene', metadata['scene'])
        for topic, ms in by_topic.items():
            writer.add_topic(topic, ms[0].type_name)
        for k, m in enumerate(order):
            writer.write(m.topic, m.data, 1_000_000 * k, 1_000_000 * k)
    return len(by_topic[contract.IMPACT_REPORT])


def test_a_scrambled_recording_is_analysed_in_stamp_order(tmp_path):
    source, target = tmp_path / 'run.mcap', tmp_path / 'scrambled.mcap'
    sim = subprocess.run(
        [
            sys.executable,
            '-m',
            'impact_arm.tools.cli',
            'simulate',
            '--scene',
            'paper',
            '--mcap',
            str(source),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    assert sim.returncode == 0, sim.stderr
    reports = scrambled_copy(source, target)
    assert reports == 15
    in_file = [m for m in iter_raw(target, [contract.IMPACT_REPORT], log_time_order=False)]
    original, scrambled = load(source), load(target)
    # the file really is out of order ...
    assert [m.data for m in in_file] != [m.data for m in iter_raw(source, [contract.IMPACT_REPORT])]
    # ... and the analysis reads it as the run happened
    assert [r.index for r in scrambled.impacts] == list(range(1, 16))
    assert scrambled.impacts == original.impacts
    assert np.all(np.diff(scrambled.t) > 0)
    np.testing.assert_array_equal(scrambled.t, original.t)
    np.testing.assert_array_equal(scrambled.q, original.q)
