"""simulation_interfaces, ROS 2's standard simulator services: the mapping onto the
simulator's reset / pause / step (no ROS), then for real over DDS with the interface package
built from its specification (sim_interfaces_build.py) and a client in its own process."""

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from impact_arm.nodes import sim_services as si
from repo_paths import SUPPORT_DIR

HERE = Path(SUPPORT_DIR)  # the client script


class FakeArm:
    """Controls as the simulator gives them, over a tiny state: time in periods."""

    def __init__(self):
        self.paused, self.periods, self.failed, self.calls = False, 7, '', []

    def controls(self):
        def reset():
            self.calls.append('reset')
            self.periods = 0
            return True, 'reset'

        def pause(paused):
            self.calls.append(f'pause {paused}')
            self.paused = paused
            return True, 'paused' if paused else 'running'

        def step(n):
            self.calls.append(f'step {n}')
            self.periods += n
            return True, f'{n} run'

        return si.SimulationControls(reset, pause, step, lambda: self.paused, lambda: self.failed)


def test_features_are_what_the_simulator_can_do():
    features = si.SimulationInterfaces(FakeArm().controls()).features()
    assert set(features) == {20, 24, 25, 26, 31, 32}  # reset, state get/set/pause, stepping


def test_pause_step_stop_and_play_map_onto_the_simulators_controls():
    arm = FakeArm()
    sim = si.SimulationInterfaces(arm.controls())
    assert sim.state() == si.STATE_PLAYING
    assert sim.step(1)[0] == si.RESULT_OPERATION_FAILED and 'not paused' in sim.step(1)[1]
    assert sim.set_state(si.STATE_PAUSED)[0] == si.RESULT_OK and arm.paused
    assert sim.state() == si.STATE_PAUSED
    assert sim.set_state(si.STATE_PAUSED)[0] == si.ALREADY_IN_TARGET_STATE
    assert sim.step(5)[0] == si.RESULT_OK and arm.periods == 12
    for bad in (0, si.MAX_STEPS + 1):
        code, message = sim.step(bad)
        assert code == si.RESULT_OPERATION_FAILED and f'steps = {bad}' in message
    # stopped = paused and reset; a step leaves it paused, play runs it
    assert sim.set_state(si.STATE_STOPPED)[0] == si.RESULT_OK
    assert arm.paused and arm.periods == 0 and sim.state() == si.STATE_STOPPED
    assert sim.set_state(si.STATE_STOPPED)[0] == si.ALREADY_IN_TARGET_STATE
    assert sim.step(2)[0] == si.RESULT_OK and sim.state() == si.STATE_PAUSED
    assert sim.set_state(si.STATE_PLAYING)[0] == si.RESULT_OK and not arm.paused
    assert sim.state() == si.STATE_PLAYING
    assert arm.calls == ['pause True', 'step 5', 'pause True', 'reset', 'step 2', 'pause False']


def test_reset_needs_time_and_state_together_and_quitting_is_not_served():
    arm = FakeArm()
    sim = si.SimulationInterfaces(arm.controls())
    for scope in (si.SCOPE_TIME, si.SCOPE_STATE, si.SCOPE_TIME | si.SCOPE_SPAWNED):
        assert sim.reset(scope)[0] == si.RESULT_FEATURE_UNSUPPORTED and arm.periods == 7
    assert sim.reset(si.SCOPE_SPAWNED)[0] == si.RESULT_OK and arm.periods == 7  # nothing spawned
    for scope in (si.SCOPE_DEFAULT, si.SCOPE_ALL, si.SCOPE_TIME | si.SCOPE_STATE):
        arm.periods = 7
        assert sim.reset(scope)[0] == si.RESULT_OK and arm.periods == 0
    assert sim.state() == si.STATE_PLAYING  # a reset keeps running or paused
    for state in (si.STATE_QUITTING, si.STATE_NO_WORLD, si.STATE_LOADING_WORLD):
        assert sim.set_state(state)[0] == si.RESULT_FEATURE_UNSUPPORTED
    assert sim.set_state(9)[0] == si.RESULT_OPERATION_FAILED


def test_a_stopped_simulation_reads_stopped_and_refuses_every_change():
    arm = FakeArm()
    sim = si.SimulationInterfaces(arm.controls())
    arm.failed = 'penetration exceeds the tip radius'
    assert sim.state() == si.STATE_STOPPED
    for outcome in (sim.set_state(si.STATE_PLAYING), sim.reset(0), sim.step(1)):
        assert outcome[0] == si.RESULT_OPERATION_FAILED and arm.failed in outcome[1]
    assert arm.calls == []


def test_attach_without_the_package_serves_nothing():
    if si.available():
        pytest.skip('simulation_interfaces is installed here')
    assert si.attach(object(), FakeArm().controls()) is None


# ------------------------------------------------------------------------------ over DDS
@pytest.fixture(scope='module')
def interfaces_prefix():
    import sim_interfaces_build

    try:
        return sim_interfaces_build.build()
    except sim_interfaces_build.Unavailable as exc:
        pytest.skip(f'cannot build simulation_interfaces: {exc}')


def test_services_over_dds_reset_pause_step_and_report_state(
    interfaces_prefix, probe, ros_env, tmp_path
):
    """The simulator (realtime, 1 kHz) with the built package on its paths serves the
    standard's services; a client process calls them as a ROS user would, while a stand-in
    controller commands a small torque."""
    from ros_helpers import simulator, start_process, wait_for
    from sim_interfaces_build import environment
    from std_msgs.msg import Float64MultiArray

    env = environment(interfaces_prefix, ros_env)
    commands = probe.publisher(Float64MultiArray, '/effort_controller/commands')
    stop = threading.Event()

    def command_loop():
        while not stop.is_set():
            commands.publish(Float64MultiArray(data=[5.0, 1.0]))
            time.sleep(0.005)

    commander = threading.Thread(target=command_loop, daemon=True)
    with start_process(simulator(), env, tmp_path, 'sim') as sim:
        commander.start()
        try:
            assert wait_for(
                lambda: 'simulation_interfaces services' in sim.stderr or not sim.alive(),
                timeout=60,
            ), sim.stderr
            client = subprocess.run(
                [sys.executable, str(HERE / 'sim_interfaces_client.py')],
                env=env,
                capture_output=True,
                text=True,
                timeout=180,
            )
            assert client.returncode == 0, client.stderr[-3000:] + sim.stderr[-3000:]
            assert sim.alive(), sim.stderr
        finally:
            stop.set()
            commander.join(2)
    seen = json.loads(client.stdout.strip().splitlines()[-1])
    OK, FAILED = si.RESULT_OK, si.RESULT_OPERATION_FAILED
    assert set(seen['features']) == set(si.FEATURES)
    assert seen['state_running'] == si.STATE_PLAYING
    assert seen['step_while_playing'][0] == FAILED and 'not paused' in seen['step_while_playing'][1]
    assert seen['pause'][0] == OK and seen['state_paused'] == si.STATE_PAUSED
    assert seen['pause_again'][0] == si.ALREADY_IN_TARGET_STATE
    # five periods of 1 ms, run before the answer came
    assert seen['step'][0] == OK
    assert seen['t_stepped'] == pytest.approx(seen['t_paused'] + 5e-3, abs=1e-9)
    assert seen['reset_time_only'][0] == si.RESULT_FEATURE_UNSUPPORTED
    # stopped: paused at t = 0 in the initial state
    assert seen['stop'][0] == OK and seen['state_stopped'] == si.STATE_STOPPED
    assert seen['t_stopped'] == 0.0
    assert seen['play'][0] == OK and seen['state_played'] == si.STATE_PLAYING
    assert seen['t_played'] > 0.2
    assert seen['reset'][0] == OK and seen['t_reset'] < seen['t_played']
    assert seen['quit'][0] == si.RESULT_FEATURE_UNSUPPORTED
