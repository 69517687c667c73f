"""A ROS user's client of the simulator's simulation_interfaces services, as a separate
process (it needs the built package on its paths, see sim_interfaces_build.py). Runs one
scenario and prints what it saw as one JSON object: every service answer, and the stamp of
the latest /joint_states after each call."""

import json
import sys
import threading
import time

import rclpy
from sensor_msgs.msg import JointState
from simulation_interfaces.msg import SimulationState
from ros_helpers import wait_for
from simulation_interfaces.srv import (
    GetSimulationState,
    GetSimulatorFeatures,
    ResetSimulation,
    SetSimulationState,
    StepSimulation,
)


def main():
    rclpy.init()
    node = rclpy.create_node('sim_interfaces_client')
    latest = {}
    node.create_subscription(
        JointState,
        '/joint_states',
        lambda m: latest.update(
            t=m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, position=list(m.position)
        ),
        100,
    )
    spinner = threading.Thread(target=rclpy.spin, args=(node,), daemon=True)
    spinner.start()
    seen = {}

    def call(srv_type, name, **fields):
        client = node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=20.0):
            raise SystemExit(f'{name} not offered')
        request = srv_type.Request()
        for key, value in fields.items():
            if key == 'state':
                request.state.state = value
            else:
                setattr(request, key, value)
        future = client.call_async(request)
        end = time.monotonic() + 20.0
        while not future.done() and time.monotonic() < end:
            time.sleep(0.01)
        if not future.done():
            raise SystemExit(f'{name}: no answer')
        node.destroy_client(client)
        return future.result()

    def result(label, response):
        seen[label] = [response.result.result, response.result.error_message]

    def settle(label, wait=0.3):
        time.sleep(wait)
        seen[label] = latest.get('t')

    def settle_until(label, done, then=0.3, timeout=10.0):
        # this reader may lag the 1 kHz stream by more than a fixed wait on a busy machine:
        # wait for the state the call should lead to, then a while for anything beyond it
        wait_for(lambda: latest.get('t') is not None and done(latest['t']), timeout, 0.01)
        settle(label, then)

    def settle_still(label, still=0.3, timeout=10.0):
        # paused: the newest stamp this reader holds stops changing (a fixed wait may still
        # show a backlog of states from before the pause)
        end, last, since = time.monotonic() + timeout, None, time.monotonic()
        while time.monotonic() < end:
            now = latest.get('t')
            if now != last:
                last, since = now, time.monotonic()
            elif time.monotonic() - since >= still:
                break
            time.sleep(0.01)
        seen[label] = latest.get('t')

    def state(label):
        seen[label] = call(GetSimulationState, '/get_simulation_state').state.state

    end = time.monotonic() + 30.0
    while latest.get('t', 0.0) < 0.2 and time.monotonic() < end:  # running, commanded
        time.sleep(0.02)
    seen['features'] = list(call(GetSimulatorFeatures, '/get_simulator_features').features.features)
    state('state_running')
    result('step_while_playing', call(StepSimulation, '/step_simulation', steps=3))
    result(
        'pause',
        call(SetSimulationState, '/set_simulation_state', state=SimulationState.STATE_PAUSED),
    )
    state('state_paused')
    settle_still('t_paused')
    result(
        'pause_again',
        call(SetSimulationState, '/set_simulation_state', state=SimulationState.STATE_PAUSED),
    )
    result('step', call(StepSimulation, '/step_simulation', steps=5))
    settle_until('t_stepped', lambda t: t >= seen['t_paused'] + 5e-3 - 1e-9)
    result(
        'reset_time_only',
        call(ResetSimulation, '/reset_simulation', scope=ResetSimulation.Request.SCOPE_TIME),
    )
    result(
        'stop',
        call(SetSimulationState, '/set_simulation_state', state=SimulationState.STATE_STOPPED),
    )
    state('state_stopped')
    settle_until('t_stopped', lambda t: t == 0.0)
    seen['position_stopped'] = latest.get('position')
    result(
        'play',
        call(SetSimulationState, '/set_simulation_state', state=SimulationState.STATE_PLAYING),
    )
    state('state_played')
    settle('t_played', 0.5)
    result(
        'reset',
        call(ResetSimulation, '/reset_simulation', scope=ResetSimulation.Request.SCOPE_DEFAULT),
    )
    settle_until('t_reset', lambda t: t < seen['t_played'], then=0.0)
    result(
        'quit',
        call(SetSimulationState, '/set_simulation_state', state=SimulationState.STATE_QUITTING),
    )
    print(json.dumps(seen))
    sys.stdout.flush()
    rclpy.try_shutdown()  # ends the spin; then the thread, then the node
    spinner.join(5.0)
    node.destroy_node()


if __name__ == '__main__':
    main()
