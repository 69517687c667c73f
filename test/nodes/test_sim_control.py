"""Simulation control and robustness over DDS, real processes: ~/reset, ~/pause,
~/step and /e_stop change what /joint_states and /diagnostics show; a controller that loses
every wrench sample still cycles; start-up in either order, or with the controller late,
never stops the simulator."""

import json
import time

import pytest

from ros_helpers import (
    controller,
    from_simulator,
    simulator,
    simulator_report,
    stamp,
    start_process,
    wait_for,
)

from impact_arm.driver.session import Level

ARTICLE_PERIOD = 0.397


def call(probe, srv_type, name, request, timeout=10.0):
    with probe.lock:
        client = probe.node.create_client(srv_type, name)
    try:
        assert client.wait_for_service(timeout_sec=timeout), f'{name} not offered'
        future = client.call_async(request)
        assert wait_for(future.done, timeout=timeout), f'{name}: no answer'
        return future.result()
    finally:
        with probe.lock:
            probe.node.destroy_client(client)


def latest_diagnostics(diags, after):
    """The first simulator report (runner.SimulatorReport) received after wall time
    ``after``."""
    assert wait_for(lambda: any(t > after for t, _ in diags), timeout=5.0), 'no /diagnostics'
    return next(simulator_report(m) for t, m in diags if t > after)


def test_reset_pause_step_and_e_stop(probe, ros_env, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Bool, Float64MultiArray
    from std_srvs.srv import SetBool, Trigger

    states = probe.listen(JointState, '/joint_states', depth=5000)
    diags = probe.listen(DiagnosticArray, '/diagnostics', keep=from_simulator)
    commands = probe.publisher(Float64MultiArray, '/effort_controller/commands')
    e_stop = probe.publisher(Bool, '/e_stop')
    # a small constant torque (the arm swings slowly) from a stand-in controller at ~200 Hz
    stop_commanding = []

    def command_loop():
        while not stop_commanding:
            commands.publish(Float64MultiArray(data=[5.0, 1.0]))
            time.sleep(0.005)

    import threading

    commander = threading.Thread(target=command_loop, daemon=True)
    with start_process(
        simulator('step_periods:=5', 'diagnostics_period:=0.2'), ros_env, tmp_path, 'sim'
    ) as sim:
        try:
            commander.start()
            assert wait_for(lambda: states and stamp(states[-1][1]) > 0.2, timeout=60), sim.stderr
            # the efforts echo the command (on a loaded machine the probe's command thread can
            # stall past command_timeout: the watchdog's brake torques show until it resumes)
            assert wait_for(lambda: tuple(states[-1][1].effort) == (5.0, 1.0), timeout=5)

            # e-stop: zero torque at once, latched, on /diagnostics
            e_stop.publish(Bool(data=True))
            sent = time.monotonic()
            assert wait_for(
                lambda: states[-1][0] > sent + 0.1 and tuple(states[-1][1].effort) == (0.0, 0.0),
                timeout=5,
            ), sim.stderr
            d = latest_diagnostics(diags, time.monotonic())
            assert d.status.e_stop and d.level is Level.ERROR, d
            time.sleep(0.3)  # commands keep arriving: latched
            assert tuple(states[-1][1].effort) == (0.0, 0.0)
            e_stop.publish(Bool(data=False))
            assert wait_for(lambda: tuple(states[-1][1].effort) == (5.0, 1.0), timeout=5)
            assert not latest_diagnostics(diags, time.monotonic()).status.e_stop

            # pause: the held state goes on being published, its time frozen
            assert call(probe, SetBool, '/simulator/pause', SetBool.Request(data=True)).success
            paused_at = time.monotonic()

            def held():  # the newest 100 received since: one stamp (a lagging probe first
                # drains states from before the pause, so no fixed wait suffices)
                tail = [m for t, m in states if t > paused_at][-100:]
                return len(tail) == 100 and len({stamp(m) for m in tail}) == 1 and tail

            frozen = wait_for(held, timeout=10)
            assert frozen, 'nothing published while paused, or its time not frozen'
            assert len({tuple(m.position) for m in frozen}) == 1
            t_frozen = stamp(frozen[-1])
            assert latest_diagnostics(diags, time.monotonic()).status.paused
            # step: exactly step_periods periods
            assert call(probe, Trigger, '/simulator/step', Trigger.Request()).success
            assert wait_for(lambda: stamp(states[-1][1]) >= t_frozen + 5e-3 - 1e-9, timeout=5)
            time.sleep(0.3)  # and no period more
            assert stamp(states[-1][1]) == pytest.approx(t_frozen + 5e-3, abs=1e-9)
            assert call(probe, SetBool, '/simulator/pause', SetBool.Request(data=False)).success
            assert wait_for(lambda: stamp(states[-1][1]) > t_frozen + 0.1, timeout=5)

            # reset: the initial state at t = 0, counts reset; the commands start it again
            before = latest_diagnostics(diags, time.monotonic()).status
            reset_at = time.monotonic()
            assert call(probe, Trigger, '/simulator/reset', Trigger.Request()).success
            assert wait_for(
                lambda: any(stamp(m) < 0.05 for t, m in states if t > reset_at), timeout=5
            ), 'time did not go back to 0'
            first = next(m for t, m in states if t > reset_at and stamp(m) < 0.05)
            initial = states[0][1]
            assert stamp(first) == 0.0 and tuple(first.position) == tuple(initial.position)
            after = latest_diagnostics(diags, time.monotonic() + 0.1).status
            assert after.sim_time < before.sim_time
            assert after.commands < before.commands
            assert sim.alive(), sim.stderr
        finally:
            stop_commanding.append(True)
            commander.join(2)
    probe.forget(states, diags)


def reports_of(store):
    return sorted(json.loads(m.data)['t_contact'] for _, m in store)


def test_controller_that_loses_every_wrench_sample_still_cycles(probe, ros_env, tmp_path):
    """Its /contact_wrench comes from a relay that forwards nothing: a publisher it matches,
    no sample ever. The down-up switch must come from the joint states alone."""
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import String

    reports = probe.listen(String, '/impact_report', transient=True)
    relay = probe.publisher(WrenchStamped, '/relayed_wrench')  # never publishes
    relayed = controller() + ['-r', '/contact_wrench:=/relayed_wrench']
    with start_process(relayed, ros_env, tmp_path, 'ctl') as ctl:
        # the controller must know the relay before the run starts: a publisher it has not
        # discovered yet is no wrench source (it would tick without waiting, as it should)
        assert wait_for(lambda: relay.get_subscription_count() > 0, timeout=30), ctl.stderr
        with start_process(
            simulator('mode:=lockstep', 'rate_factor:=0.0'), ros_env, tmp_path, 'sim'
        ) as sim:
            assert wait_for(
                lambda: len(reports) >= 5 or not sim.alive() or not ctl.alive(), timeout=120
            ), f'{len(reports)} impacts\n{ctl.stderr[-2000:]}'
            assert sim.alive() and ctl.alive(), sim.stderr + ctl.stderr
            # a wrench source that never delivered holds no state: nothing waits for it
            assert 'ticking on the next state without it' not in ctl.stderr
    times = reports_of(reports)[:5]
    gaps = [b - a for a, b in zip(times, times[1:])]
    # one impact per cycle, at the article's period (a missed switch re-strikes at once)
    assert all(abs(g / ARTICLE_PERIOD - 1) < 0.05 for g in gaps), gaps
    probe.forget(reports)


@pytest.mark.parametrize('order', ['simulator_first', 'controller_first', 'controller_late'])
def test_start_up_in_any_order_never_stops_the_simulator(probe, ros_env, tmp_path, order):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    reports = probe.listen(String, '/impact_report', transient=True)
    diags = probe.listen(DiagnosticArray, '/diagnostics', keep=from_simulator)
    first, second = (
        (controller(), simulator()) if order == 'controller_first' else (simulator(), controller())
    )
    with start_process(first, ros_env, tmp_path, f'{order}_1') as a:
        if order == 'controller_late':
            time.sleep(2.0)
        with start_process(second, ros_env, tmp_path, f'{order}_2') as b:
            sim = a if order != 'controller_first' else b
            assert wait_for(lambda: len(reports) >= 2 or not sim.alive(), timeout=90), sim.stderr
            assert sim.alive(), sim.stderr
            assert not any(simulator_report(m).stopped for _, m in diags), sim.stderr
    # (the cycle period under load is bench starts' business: a loaded machine can delay the
    # controller's switch into a re-strike, which is no stop)
    probe.forget(reports, diags)


def test_interpreted_kernel_is_announced_at_start(ros_env, tmp_path):
    env = dict(ros_env, IMPACT_ARM_JIT='0')
    with start_process(simulator(), env, tmp_path, 'interpreted') as sim:
        assert wait_for(
            lambda: 'INTERPRETED kernel' in sim.stderr or not sim.alive(), timeout=60
        ), sim.stderr
        line = next(ln for ln in sim.stderr.splitlines() if 'INTERPRETED' in ln)
    assert line.startswith('[WARN]') and 'IMPACT_ARM_JIT=0' in line and 'Fix:' in line
