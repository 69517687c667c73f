"""The contract module: one spelling of every shared name, joint-space conversion, progress."""

import io
import pathlib
import re

import pytest

from impact_arm import contract
from impact_arm.tools.progress import Progress

PACKAGE = pathlib.Path(contract.__file__).parent


def test_topic_names_are_spelled_only_in_the_contract():
    names = [
        contract.JOINT_STATES,
        contract.CONTACT_WRENCH,
        contract.CONTACT_FORCE_PEAK,
        contract.IMPACT_REPORT,
        contract.TF,
        contract.ROBOT_DESCRIPTION,
        contract.TF_STATIC,
        contract.IMPACT_MARKERS,
        contract.DIAGNOSTICS,
        contract.CLOCK,
        contract.COMMANDS,
        contract.IMPACT_TRACE,
    ]
    spelled = re.compile('|'.join(rf"""['"]{re.escape(n)}['"]""" for n in names))
    offenders = [
        f'{p.relative_to(PACKAGE)}:{k}'
        for p in PACKAGE.rglob('*.py')
        if p.name != 'contract.py'
        for k, line in enumerate(p.read_text().splitlines(), 1)
        if spelled.search(line)
    ]
    assert offenders == []


def test_joint_space_round_trip_and_convention():
    q = [0.3, -1.2, 2.5]
    assert contract.to_joint_space(q) == pytest.approx([0.3, -1.5, 3.7], abs=1e-15)
    assert contract.to_absolute(contract.to_joint_space(q)) == pytest.approx(q, abs=1e-15)
    assert contract.joint_names(3) == ['joint1', 'joint2', 'joint3']


def test_every_topic_has_a_type_and_qos():
    assert contract.qos(contract.IMPACT_REPORT).durability == 'transient_local'
    assert contract.qos('/remapped', contract.TopicQos(depth=3)).depth == 3
    assert all(t.count('/') == 2 for t, _ in contract.TOPICS.values())


class _Stream(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def test_progress_on_a_terminal_rewrites_one_line_with_an_eta():
    now = [100.0]
    out = _Stream(tty=True)
    line = Progress(total=10, prefix='  ', stream=out, clock=lambda: now[0])
    now[0] += 8.0
    line.show('cycle 5/10', done=4)  # 4 of 10 in 8 s: 12 s left
    assert out.getvalue() == '\r\033[K  cycle 5/10   40 %  ETA 12 s'
    line.end()
    assert out.getvalue().endswith('\r\033[K')  # erased, the results follow


def test_progress_off_a_terminal_prints_only_marked_lines_without_eta():
    out = _Stream(tty=False)
    line = Progress(total=10, stream=out, clock=lambda: 0.0)
    line.show('tick', done=3)
    line.show('impact 1', done=3, log=True)
    line.end()
    assert out.getvalue() == 'impact 1\n'


def test_every_layer_is_a_package_setup_installs():
    """setup.py's find_packages skips folders without __init__.py: a plain install would
    lack them."""
    from setuptools import find_packages

    found = set(find_packages(str(PACKAGE.parent), include=['impact_arm', 'impact_arm.*']))
    folders = {
        '.'.join(p.parent.relative_to(PACKAGE.parent).parts)
        for p in PACKAGE.rglob('*.py')
        if '__pycache__' not in p.parts
    }
    assert folders <= found


def test_compile_notice_announces_a_long_compile_once_and_its_end():
    """The one-time compile is announced once with its progress however many bursts it takes,
    ends with 'compiled in N s', and a short compile says nothing."""
    import io
    import time

    from impact_arm.physics import jit
    from impact_arm.tools.progress import COMPILE_NOTICE, CompileNotice

    out = io.StringIO()
    with CompileNotice(stream=out) as notice:
        notice.SETTLE = 0.6
        jit.compile_started()
        time.sleep(1.6)  # a long first burst: announced
        jit.compile_ended()
        jit.compile_started()  # a second burst right after: the same notice
        time.sleep(0.2)
        jit.compile_ended()
        time.sleep(1.5)  # settled: the notice ends by itself
        text = out.getvalue()
        jit.compile_started()  # a short compile later: nothing printed
        time.sleep(0.1)
        jit.compile_ended()
    lines = out.getvalue().splitlines()
    assert out.getvalue() == text
    assert lines[0] == f'{COMPILE_NOTICE} ...'
    assert lines[-1].startswith(f'{COMPILE_NOTICE}: compiled in ')
    assert lines[-1].endswith(' s, cached for next time')
    assert sum(COMPILE_NOTICE in line for line in lines) == 2
    assert notice.total > 1.7


def test_progress_lines_wait_for_the_compile_notice_to_end():
    """A progress line shown while the compile notice counts (its counter runs in a thread)
    comes after the notice's last line, never between its lines."""
    import io
    import time

    from impact_arm.physics import jit
    from impact_arm.tools.progress import COMPILE_NOTICE, CompileNotice

    out = io.StringIO()
    line = Progress(prefix='analyze: ', stream=out)
    with CompileNotice(stream=out) as notice:
        notice.SETTLE = 0.6
        line.show('before the compile', log=True)
        jit.compile_started()
        time.sleep(1.6)  # announced
        line.show('figure 1/2', log=True)  # the main thread goes on while the notice is open
        jit.compile_ended()
        line.show('figure 2/2', log=True)  # compiled, the notice not settled yet
        time.sleep(1.5)
    lines = out.getvalue().splitlines()
    assert lines[0] == 'analyze: before the compile'
    assert lines[1] == f'{COMPILE_NOTICE} ...'
    assert lines[2].startswith(f'{COMPILE_NOTICE}: compiled in ')
    assert lines[3:] == ['analyze: figure 1/2', 'analyze: figure 2/2']


def test_the_plate_topic_has_its_contract_qos_before_any_publisher_exists():
    """The recorder subscribes to /surface_mounts before the simulator publishes it: the
    contract, not the (absent) publishers' offer, gives its QoS, reliable and deep enough for
    the lockstep writers' repairs."""
    from impact_arm import contract

    mounts = contract.qos(contract.SURFACE_MOUNTS, contract.TopicQos(reliability='best_effort'))
    assert mounts == contract.SURFACE_MOUNTS_QOS and mounts.reliability == 'reliable'


def test_the_controller_status_codec_round_trips_and_names_a_bad_value():
    import pytest

    from impact_arm.contract import ControllerStatus
    from impact_arm.driver.control_inputs import DROPPED

    status = ControllerStatus(
        chatter='joint2',
        commands_sent=6251,
        strikes=16,
        cycles_completed=15,
        down_half_start=5.123456789,
        latency_periods=2,
        latency_histogram=((0, 1), (2, 6000), (3, 40)),
        driver_answered='effort',
        unanswered_ticks=1,
        dropped=tuple((reason, k) for k, reason in enumerate(DROPPED)),
    )
    values = dict(status.values())
    assert values['latency_histogram'] == '0:1 2:6000 3:40'
    assert values['stamp_jumps'] == str(DROPPED.index('stamp_jumps'))  # a key of its own
    assert ControllerStatus.parse(values) == status
    assert ControllerStatus.parse(values).dropped_count('stamp_jumps') == DROPPED.index(
        'stamp_jumps'
    )
    with pytest.raises(ValueError, match='strikes'):
        ControllerStatus.parse({**values, 'strikes': 'many'})


def test_the_simulator_status_codec_round_trips_and_names_a_bad_value():
    import pytest

    from impact_arm.contract import SimulatorMode, SimulatorStatus, WatchdogState

    status = SimulatorStatus(
        mode=SimulatorMode.LOCKSTEP,
        publish_rate_requested=1000.0,
        publish_rate_achieved=2411.3,
        jitter_run_p99_us=37.0,
        periods_published=6251,
        periods_skipped=2,
        periods_skipped_at_s=(1.25, 3.5),
        paused=True,
        kernel='compiled (numba)',
        lockstep_wait_mean_us=412.5,
        watchdog=WatchdogState.TIMEOUT,
        brake_torque_limit_nm=200.0,
        limits='joint2 velocity at 1.000000 s',
        lockstep_repeats=1,
        periods_waiting_for_recorder=0,
        braked_periods=4,
        sim_time=6.25,
        real_time_factor=2.411,
    )
    values = status.values()
    shown = dict(values)
    assert values[0] == ('mode', 'lockstep') and values[-1] == ('events', '0')
    assert shown['periods_skipped_at_s'] == '1.250000 3.500000'
    assert shown['paused'] == 'true' and shown['publish_rate_requested'] == '1000'
    assert shown['jitter_run_p99_us'] == '37' and shown['real_time_factor'] == '2.411'
    assert SimulatorStatus.parse(shown) == status
    # realtime: no lockstep values on the wire; no command yet: a real-time factor of '0'
    realtime = dict(SimulatorStatus().values())
    assert 'lockstep_wait_mean_us' not in realtime and 'braked_periods' not in realtime
    assert realtime['real_time_factor'] == '0'
    assert SimulatorStatus.parse(realtime) == SimulatorStatus()
    with pytest.raises(ValueError, match='overruns'):
        SimulatorStatus.parse({**shown, 'overruns': 'many'})
    with pytest.raises(ValueError, match='paused'):
        SimulatorStatus.parse({**shown, 'paused': 'yes'})
    with pytest.raises(ValueError, match='watchdog'):
        SimulatorStatus.parse({**shown, 'watchdog': 'asleep'})
    with pytest.raises(ValueError, match='overrun_count'):
        SimulatorStatus.parse({**shown, 'overrun_count': '0'})
