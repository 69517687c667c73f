"""What ``impact-arm run`` prints from the simulator's last status, without DDS."""

from impact_arm.contract import SimulatorStatus, WatchdogPolicy
from impact_arm.driver.session import Level
from impact_arm.tools.runner import SimulatorReport


def report(**fields):
    return SimulatorReport(Level.OK, 'running', SimulatorStatus(**fields))


def test_no_watchdog_line_when_the_commands_never_stalled():
    assert report(watchdog_timeouts=0, longest_command_silence_s=0.012).watchdog_line() == ''


def test_a_braked_stall_is_named_with_its_length_and_the_brake():
    line = report(
        watchdog_timeouts=1,
        longest_command_silence_s=0.5123,
        brake_events=1,
        brake_torque_max_nm=41.25,
        brake_torque_limit_nm=100.0,
    ).watchdog_line()
    assert line.startswith('WATCHDOG: 1 command timeout(s)')
    assert 'longest silence 512.3 ms' in line
    assert 'brakes held the joints (1 times, at most 41.250 of 100 N m)' in line


def test_a_stall_under_the_zero_policy_says_the_arm_fell():
    line = report(
        watchdog_timeouts=2, longest_command_silence_s=0.2, watchdog_policy=WatchdogPolicy.ZERO
    ).watchdog_line()
    assert 'zero torque (the arm fell)' in line and '2 command timeout(s)' in line
