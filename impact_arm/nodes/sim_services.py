"""The simulator's control as ROS 2's standard simulator interface, ``simulation_interfaces``
(the services Gazebo and Isaac Sim offer), beside its own std_srvs services.

Where the package ``simulation_interfaces`` is importable (a ROS install since 2025:
``ros-$ROS_DISTRO-simulation-interfaces``), ``attach(node, controls)`` serves

=========================  ==========================================  ======================
service                    type (simulation_interfaces/srv/...)        maps onto
=========================  ==========================================  ======================
/get_simulator_features    GetSimulatorFeatures                        what is listed below
/get_simulation_state      GetSimulationState                          paused, running, stopped
/set_simulation_state      SetSimulationState                          ~/pause, ~/reset
/reset_simulation          ResetSimulation                             ~/reset
/step_simulation           StepSimulation                              ~/step with ``steps``
=========================  ==========================================  ======================

``SimulationInterfaces`` is the mapping, free of ROS so that it is tested without the
package; ``controls`` (``SimulationControls``) is what the simulator node gives it: reset,
pause, step and its state, the same actions as its ~/reset, ~/pause and ~/step services.

* features: SIMULATION_RESET, SIMULATION_STATE_GETTING, SIMULATION_STATE_SETTING,
  SIMULATION_STATE_PAUSE, STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE. Nothing is
  spawned, there are no entities or worlds to load.
* states: PLAYING while the periods run (realtime: brakes on until the first command),
  PAUSED, STOPPED = paused and reset (set with STOPPED; leaves it on PLAYING, PAUSED or a
  step). A simulation stopped by an error reads STOPPED; every change is then refused
  (RESULT_OPERATION_FAILED with the reason). QUITTING is not served: end the node to quit.
* reset: the arm's reset puts back the initial state *and* t = 0 together, so a scope must
  hold both SCOPE_TIME and SCOPE_STATE (SCOPE_DEFAULT and SCOPE_ALL do); SCOPE_SPAWNED alone
  has nothing to do. The paused or stopped state is kept.
* step: only while paused or stopped (else RESULT_OPERATION_FAILED, as the standard says), 1 to
  ``MAX_STEPS`` periods of the simulator (1 / publish_rate each). Realtime answers once the
  periods have run (they run one per wall period, and only once a command has arrived since
  the start or the last reset: brakes on before); lockstep answers at once, the periods then
  run one per command as always.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from rclpy.node import Node

# the standard's constants (msg/Result, msg/SimulationState, msg/SimulatorFeatures,
# srv/ResetSimulation, srv/SetSimulationState), so the mapping needs no package
(
    RESULT_FEATURE_UNSUPPORTED,
    RESULT_OK,
    RESULT_NOT_FOUND,
    RESULT_INCORRECT_STATE,
    RESULT_OPERATION_FAILED,
) = range(5)
STATE_STOPPED, STATE_PLAYING, STATE_PAUSED, STATE_QUITTING, STATE_NO_WORLD, STATE_LOADING_WORLD = (
    range(6)
)
ALREADY_IN_TARGET_STATE, STATE_TRANSITION_ERROR, INCORRECT_TRANSITION = 101, 102, 103
SCOPE_DEFAULT, SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED, SCOPE_ALL = 0, 1, 2, 4, 255
SIMULATION_RESET = 20
SIMULATION_STATE_GETTING, SIMULATION_STATE_SETTING, SIMULATION_STATE_PAUSE = 24, 25, 26
STEP_SIMULATION_SINGLE, STEP_SIMULATION_MULTIPLE = 31, 32
FEATURES = (
    SIMULATION_RESET,
    SIMULATION_STATE_GETTING,
    SIMULATION_STATE_SETTING,
    SIMULATION_STATE_PAUSE,
    STEP_SIMULATION_SINGLE,
    STEP_SIMULATION_MULTIPLE,
)
MAX_STEPS = 1_000_000  # periods one call may ask for (1000 s at 1 kHz)
STATE_NAMES = {
    STATE_STOPPED: 'stopped',
    STATE_PLAYING: 'playing',
    STATE_PAUSED: 'paused',
    STATE_QUITTING: 'quitting',
    STATE_NO_WORLD: 'no world',
    STATE_LOADING_WORLD: 'loading world',
}
SERVICES = {  # name -> simulation_interfaces/srv type
    '/get_simulator_features': 'GetSimulatorFeatures',
    '/get_simulation_state': 'GetSimulationState',
    '/set_simulation_state': 'SetSimulationState',
    '/reset_simulation': 'ResetSimulation',
    '/step_simulation': 'StepSimulation',
}
CUSTOM_INFO = (
    'impact_arm simulator: a planar arm striking a surface; a step is one period '
    '(1 / publish_rate); std_srvs services ~/reset, ~/pause, ~/step too'
)


@dataclass
class SimulationControls:
    """What the services act on; each action answers (done, message)."""

    reset: Callable[[], tuple]  # initial state, t = 0 (pause kept)
    pause: Callable[[bool], tuple]  # True: pause, False: run
    step: Callable[[int], tuple]  # while paused: run n periods
    is_paused: Callable[[], bool]
    failure: Callable[[], str] = lambda: ''  # why the simulation stopped ('' if it runs)


class SimulationInterfaces:
    """The standard's services in terms of ``SimulationControls`` (module docstring)."""

    def __init__(self, controls: SimulationControls):
        self.controls = controls
        self.stopped = False  # paused and reset by a STOPPED request, not moved since

    def features(self) -> list:
        return list(FEATURES)

    def state(self) -> int:
        if self.controls.failure():
            return STATE_STOPPED
        if self.controls.is_paused():
            return STATE_STOPPED if self.stopped else STATE_PAUSED
        self.stopped = False  # resumed through ~/pause
        return STATE_PLAYING

    def reset(self, scope: int) -> tuple:
        """(result, message) of ResetSimulation with ``scope``."""
        failure = self.controls.failure()
        if failure:
            return RESULT_OPERATION_FAILED, f'the simulation stopped: {failure}'
        both = SCOPE_TIME | SCOPE_STATE
        if scope == SCOPE_SPAWNED:
            return RESULT_OK, 'nothing is spawned: nothing to reset'
        if scope not in (SCOPE_DEFAULT, SCOPE_ALL) and scope & both != both:
            return RESULT_FEATURE_UNSUPPORTED, (
                f'scope = {scope}: the arm resets its time and its state together; use '
                f'SCOPE_DEFAULT, SCOPE_ALL or SCOPE_TIME | SCOPE_STATE'
            )
        done, message = self.controls.reset()
        return (RESULT_OK if done else RESULT_OPERATION_FAILED), message

    def set_state(self, target: int) -> tuple:
        """(result, message) of SetSimulationState to ``target``."""
        failure = self.controls.failure()
        if failure:
            return RESULT_OPERATION_FAILED, f'the simulation stopped: {failure}'
        if target not in STATE_NAMES:
            return RESULT_OPERATION_FAILED, f'state = {target}: not a SimulationState (0-5)'
        if target == self.state():
            return ALREADY_IN_TARGET_STATE, f'already {STATE_NAMES[target]}'
        if target == STATE_PLAYING:
            done, message = self.controls.pause(False)
        elif target == STATE_PAUSED:
            done, message = self.controls.pause(True)
        elif target == STATE_STOPPED:
            done, message = self.controls.pause(True)
            if done:
                done, message = self.controls.reset()
        else:
            return RESULT_FEATURE_UNSUPPORTED, (
                f'state {STATE_NAMES[target]}: not served (one scene, no worlds to load; '
                f'end the node to quit)'
            )
        if not done:
            return STATE_TRANSITION_ERROR, message
        self.stopped = target == STATE_STOPPED
        return RESULT_OK, message

    def step(self, steps: int) -> tuple:
        """(result, message) of StepSimulation with ``steps``."""
        failure = self.controls.failure()
        if failure:
            return RESULT_OPERATION_FAILED, f'the simulation stopped: {failure}'
        if not 1 <= steps <= MAX_STEPS:
            return RESULT_OPERATION_FAILED, f'steps = {steps}: must be 1 to {MAX_STEPS}'
        if not self.controls.is_paused():
            return RESULT_OPERATION_FAILED, 'not paused: set STATE_PAUSED first'
        done, message = self.controls.step(int(steps))
        if done:
            self.stopped = False
        return (RESULT_OK if done else RESULT_OPERATION_FAILED), message


def available() -> bool:
    try:
        import simulation_interfaces.srv  # noqa: F401
    except ImportError:
        return False
    return True


def attach(node: Node, controls: SimulationControls) -> SimulationInterfaces | None:
    """Serve the standard's services on ``node`` where ``simulation_interfaces`` is
    installed. Returns the ``SimulationInterfaces`` served, or None without the package."""
    if not available():
        return None
    from simulation_interfaces import srv

    mapping = SimulationInterfaces(controls)

    def features(request: Any, response: Any) -> Any:
        response.features.features = mapping.features()
        response.features.spawn_formats = []
        response.features.custom_info = CUSTOM_INFO
        return response

    def get_state(request: Any, response: Any) -> Any:
        response.state.state = mapping.state()
        response.result.result = RESULT_OK
        return response

    def answer(response: Any, outcome: tuple[int, str]) -> Any:
        response.result.result, response.result.error_message = outcome
        if response.result.result != RESULT_OK:
            node.get_logger().warning(f'simulation_interfaces: {outcome[1]}')
        return response

    handlers = {
        'GetSimulatorFeatures': features,
        'GetSimulationState': get_state,
        'SetSimulationState': lambda request, response: answer(
            response, mapping.set_state(request.state.state)
        ),
        'ResetSimulation': lambda request, response: answer(response, mapping.reset(request.scope)),
        'StepSimulation': lambda request, response: answer(response, mapping.step(request.steps)),
    }
    for name, type_name in SERVICES.items():
        node.create_service(getattr(srv, type_name), name, handlers[type_name])
    node.get_logger().info('simulation_interfaces services: ' + ', '.join(SERVICES))
    return mapping
