"""What ``impact-arm run`` prints from the simulator's last status, without DDS."""

import pytest

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


def test_wall_integrating_is_the_simulators_physics_time_not_the_runs():
    """'s wall integrating' in the run's table is the physics' wall time, as offline: the
    simulator's mean per stepped period times the periods it stepped (a realtime run of
    1.07 s simulated printed 9 s, the whole run's wall time from the simulator's start)."""
    from impact_arm.tools.runner import integrating_wall

    status = SimulatorStatus(
        compute_physics_mean_us=20.0, periods_published_until_s=1.066, publish_rate_requested=1000.0
    )
    assert integrating_wall(status, 9.0) == pytest.approx(20e-6 * 1066)
    assert integrating_wall(None, 9.0) == 9.0  # no status: the run's own wall time
    assert integrating_wall(SimulatorStatus(), 2.5) == 2.5  # never stepped
