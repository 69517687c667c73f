"""Replay: the schedule (no DDS) and the node observed by a subscriber process over DDS."""

import itertools
import json
import statistics
import subprocess
import sys

import pytest

from impact_arm.io.mcap_ros2 import Ros2McapWriter
from impact_arm.io.replay_plan import ReplayError, ReplayPlan
from ros_helpers import helper_args, node_args, start_process, wait_for

PERIOD_NS = 10_000_000  # recorded joint states every 10 ms
N_JS = 40  # 0.4 s of data
T0 = 1_700_000_000 * 10**9  # recorded wall time, as a live recorder writes it


def write_run(path):
    """A small recording: joint states every 10 ms (stamp = index ms), three impact reports."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    with Ros2McapWriter(path) as w:
        for i in range(N_JS):
            m = JointState(name=['joint1', 'joint2'], position=[float(i), 0.0])
            m.header.stamp.sec, m.header.stamp.nanosec = 0, i * 1_000_000
            w.write_message('/joint_states', m, T0 + i * PERIOD_NS, T0 + i * PERIOD_NS - 1000)
            if i % 15 == 7:
                w.write_message(
                    '/impact_report', String(data=json.dumps({'index': i})), T0 + i * PERIOD_NS + 1
                )
    return path


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    return write_run(tmp_path_factory.mktemp('replay') / 'run.mcap')


# ------------------------------------------------------------------------ schedule
def test_schedule_rate_offset_topics_and_loop(recording):
    plan = ReplayPlan.open(recording)
    events = list(plan.events())
    assert len(events) == N_JS + 3 and plan.message_count == N_JS + 3
    assert [e[0] for e in events] == sorted(e[0] for e in events)
    js = [due for due, m in events if m.topic == '/joint_states']
    assert js == pytest.approx([i * 0.01 for i in range(N_JS)], abs=1e-12)

    fast = ReplayPlan.open(recording, rate=2.0, topics=['/joint_states'], start_offset=0.1)
    events = list(fast.events())
    assert {m.topic for _, m in events} == {'/joint_states'}
    assert [d for d, _ in events] == pytest.approx([i * 0.005 for i in range(N_JS - 10)])
    assert events[0][1].log_time_ns == T0 + 10 * PERIOD_NS
    assert fast.recorded_time_ns(0.05) == T0 + 20 * PERIOD_NS

    looped = ReplayPlan.open(recording, loop=True, topics=['/joint_states'])
    first = list(itertools.islice(looped.events(), 2 * N_JS + 1))
    assert [m.log_time_ns for _, m in first[N_JS : 2 * N_JS]] == [
        m.log_time_ns for _, m in first[:N_JS]
    ]
    assert first[N_JS][0] == pytest.approx(looped.duration)
    assert first[2 * N_JS][0] == pytest.approx(2 * looped.duration)


@pytest.mark.parametrize(
    'kw, match',
    [
        ({'rate': 0}, r'rate = 0\.0: must be in \(0, 1000\]'),
        ({'rate': float('nan')}, 'rate = nan'),
        ({'rate': 'fast'}, "rate = 'fast': must be a number"),
        ({'start_offset': -1}, 'start_offset = -1.0: must be >= 0'),
        ({'start_offset': 5.0}, r'start_offset = 5.0: must be in \[0, 0.39'),
        ({'topics': ['/nope']}, r"topics = \['/nope'\]: not in"),
    ],
)
def test_bad_options_name_the_option(recording, kw, match):
    with pytest.raises(ReplayError, match=match):
        ReplayPlan.open(recording, **kw)


def test_missing_or_broken_file(tmp_path):
    with pytest.raises(ReplayError, match='no such file'):
        ReplayPlan.open(tmp_path / 'nope.mcap')
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not an mcap file at all')
    with pytest.raises(ReplayError, match='not an MCAP file'):
        ReplayPlan.open(bad)


def test_cli_errors_are_one_line(tmp_path, recording):
    for argv, needle in (
        ([str(tmp_path / 'none.mcap')], 'no such file'),
        ([str(recording), '--rate', '-2'], 'rate = -2.0'),
    ):
        p = subprocess.run(
            [sys.executable, '-m', 'impact_arm.tools.cli', 'replay'] + argv,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert p.returncode == 2 and needle in p.stderr and 'Traceback' not in p.stderr


# --------------------------------------------------------------------- over DDS
def observe(
    ros_env, tmp_path, recording, rate, extra=(), topics=('/joint_states', '/impact_report')
):
    """Replay to a subscriber process; returns {topic: [(receive ns, stamp ns)]}."""
    name = f'sub{rate:g}'
    with start_process(
        helper_args('sub', *topics, '--duration', 30), ros_env, tmp_path, name
    ) as sub:
        assert wait_for(lambda: sub.lines(), 20), sub.stderr
        args = node_args(
            'impact_arm.nodes.replay',
            f'file:={recording}',
            f'rate:={rate}',
            'wait_for_subscribers:=1',
            # its writers matched; the subscriber's readers may match up to ~0.3 s later
            'delay:=1.0',
            *extra,
        )
        with start_process(args, ros_env, tmp_path, f'replay{rate:g}') as rep:
            assert rep.wait(60) == 0, rep.stderr
        wanted = N_JS + (3 if '/impact_report' in topics else 0)
        wait_for(lambda: sum('topic' in e for e in sub.lines()) >= wanted, 10)
        got = {}
        for e in sub.lines():
            if 'topic' in e:
                got.setdefault(e['topic'], []).append((e['t'], e['stamp']))
    return got


def median_interval(received):
    times = [t for t, _ in received]
    return statistics.median(b - a for a, b in zip(times, times[1:]))


def test_replay_reproduces_order_and_timing(ros_env, tmp_path, recording):
    normal = observe(ros_env, tmp_path, recording, 1.0)
    fast = observe(
        ros_env,
        tmp_path,
        recording,
        2.0,
        extra=('clock:=50.0', 'topics:=[/joint_states]'),
        topics=('/joint_states', '/clock', '/impact_report'),
    )
    for got in (normal, fast):
        js = got['/joint_states']
        assert [s for _, s in js] == [i * 1_000_000 for i in range(N_JS)]  # all, in order
    assert len(normal['/impact_report']) == 3
    assert '/impact_report' not in fast  # topic selection
    # timing: median intervals (robust to a loaded machine) within 10 %
    assert median_interval(normal['/joint_states']) == pytest.approx(PERIOD_NS, rel=0.1)
    assert median_interval(fast['/joint_states']) == pytest.approx(PERIOD_NS / 2, rel=0.1)
    # the whole run lasts as long as recorded, scaled (looser: one stall of a loaded
    # machine shifts the last message but not the median)
    span = [js[-1][0] - js[0][0] for js in (normal['/joint_states'], fast['/joint_states'])]
    assert span[0] == pytest.approx((N_JS - 1) * PERIOD_NS, rel=0.25)
    assert span[1] == pytest.approx((N_JS - 1) * PERIOD_NS / 2, rel=0.25)
    # /clock carries the recorded time, advancing at twice the wall-clock speed
    clock = [s for _, s in fast['/clock']]
    assert len(clock) >= 5 and clock == sorted(clock)
    assert T0 <= clock[0] and clock[-1] <= T0 + N_JS * PERIOD_NS
