"""The simulator node's parameters, declared once: ``parameter_table(scene)`` gives each its
default (the joint names from the scene), range, description (``ros2 param describe``) and,
through ``params.declare``, the typed object the node reads (param_types.SimulatorParameters,
generated from this table)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from .. import contract
from ..contract import (
    COMMANDS,
    INTEGRATOR_PRESETS,
    JOINT_STATES,
    SIMULATOR_MODES,
    SimulatorMode,
    WatchdogPolicy,
)
from ..driver.arm import DEFAULT_BRAKE_TORQUE
from ..driver.realtime import DEFAULT_COMMAND_TIMEOUT, DEFAULT_WATCHDOG_POLICY
from ..driver.session import Release
from ..io.scene_visuals import DEFAULT_TF_RATE
from ..io.urdf import JOINT_COMMANDS_TOPIC, JOINT_STATES_TOPIC
from .params import Param, ParameterError, check_joints, scene_joint_names

if TYPE_CHECKING:
    from ..physics.scene import Scene
    from .param_types import SimulatorParameters


# a gap every 20 periods drains topic_based_ros2_control's queue of states without a cost to
# the cycle once the controller predicts over a repeated state (docs/benchmarks.md, "The
# queue of states"); every 10 drained no better, every 50 too little
JOINT_STATES_GAP = 20


def parameter_table(scene: Scene) -> tuple[Param, ...]:
    """The simulator's parameters; the joint names and their number come from ``scene``."""
    return (
        _PARAMS_BEFORE_JOINTS
        + (
            Param(
                'joints',
                scene_joint_names(scene),
                "joint order of the command array (default: the scene's joints, base first)",
                'strs',
                size=scene.n_links,
                read_only=True,
                shown_default="the scene's: its URDF's joint names, else `[joint1, …, jointN]`",
            ),
        )
        + _PARAMS_AFTER_JOINTS
    )


_PARAMS_BEFORE_JOINTS = (
    Param(
        'scene',
        '',
        'scene YAML file or installed scene name (empty: paper, the article); its sensors '
        'section (docs/scene.md) sets how /joint_states and /contact_wrench report the state',
        'str',
        read_only=True,
    ),
    Param(
        'publish_rate',
        1000.0,
        'rate of /joint_states and /contact_wrench [Hz]',
        low=1.0,
        high=100000.0,
        read_only=True,
    ),
    Param(
        'mode',
        SimulatorMode.REALTIME.value,
        'realtime: paced by the wall clock; lockstep: one period per received command',
        'str',
        choices=SIMULATOR_MODES,
        read_only=True,
        enum=SimulatorMode,
    ),
    Param(
        'rate_factor',
        1.0,
        'simulated seconds per wall second (lockstep: 0 = as fast as '
        'commands arrive); /clock is published unless realtime at 1.0',
        low=0.0,
        high=1000.0,
        read_only=True,
    ),
    # lower bounds: a watchdog under 1 ms fires between 1 kHz commands and a torque limit
    # under 1 mN m clips every command to nothing; either would silently disable control
    Param(
        'command_timeout',
        DEFAULT_COMMAND_TIMEOUT,
        'seconds without a valid command '
        'before the watchdog acts (watchdog_policy; a few control periods)',
        low=1e-3,
        high=3600.0,
        doc='; /diagnostics then WARNs. 20 periods at 1 kHz: a few periods of your controller',
    ),
    # brake by default: zero torque drops the arm onto the part, where it chatters (a 0.33 s
    # middleware stall gave ~300 impact events in one simulated second); a real drive's safe
    # stop holds the joints. zero stays for a controller that must see the arm go limp.
    Param(
        'watchdog_policy',
        DEFAULT_WATCHDOG_POLICY.value,
        'on a command timeout: brake (hold '
        "the joints where they are, each joint's torque limited to brake_torque, until the "
        'next valid command) or zero (zero torque: the arm falls)',
        'str',
        choices=tuple(p.value for p in WatchdogPolicy),
        read_only=True,
        enum=WatchdogPolicy,
        doc=' (see "The watchdog" below)',
    ),
    Param(
        'brake_torque',
        DEFAULT_BRAKE_TORQUE,
        "the brake's torque limit per joint [N m] (watchdog_policy brake)",
        low=1e-3,
        high=1e9,
        doc='; /diagnostics reports it and the largest brake torque used',
    ),
    # the arm stays braked with time stopped until a controller drives it: ros2_control's
    # TopicBasedSystem sends zero commands from its activation on, seconds before any
    # controller runs, and taking those as the start dropped the arm onto the part
    Param(
        'release_on',
        Release.NONZERO_JOINT_COMMAND.value,
        'which command releases the brakes and starts time (at start-up, after a reset): '
        'first_command (any), nonzero_command (one with a non-zero torque; all-zero ones '
        'before it are ignored) or nonzero_joint_command (non-zero for JointState commands on '
        'joint_commands_topic, any for command arrays)',
        'str',
        choices=tuple(r.value for r in Release),
        read_only=True,
        enum=Release,
    ),
    # a driver stack on simulated time (ros2_control_node with use_sim_time) updates only
    # when /clock advances: with time stopped until its controller's torque it never takes it
    Param(
        'release_after',
        0.0,
        'lockstep: > 0: every command before the release runs a braked period (time advances, '
        'no faster than real time, the arm held, /clock published) and the brakes release at '
        'the first command release_on '
        'takes from this simulated time on [s]: a stack on use_sim_time keeps updating and '
        'starts at a fixed time; 0: time stopped until the release',
        low=0.0,
        high=1e6,
        read_only=True,
        doc=' (docs/ros2_control.md, "A reproducible run on simulated time")',
    ),
    Param(
        'command_latency_periods',
        0,
        "periods a command takes to reach the actuators: a driver stack's latency, "
        "simulated (each period's newest command acts this many periods later; the first "
        'command, which releases the brakes, at once)',
        'int',
        low=0,
        high=1000,
        read_only=True,
    ),
    Param(
        'max_effort',
        5000.0,
        'commanded torques are clipped to +-max_effort [N m]',
        low=1e-3,
        high=1e9,
        doc=(
            " (the article's Q law peaks near 2 kN m); each joint also at its own effort "
            "limit, the scene's joints[i].max_effort or its URDF's, where that is lower"
        ),
    ),
)
_PARAMS_AFTER_JOINTS = (
    Param(
        'preset',
        '',
        "integrator preset (empty: the scene's)",
        'str',
        choices=('',) + INTEGRATOR_PRESETS,
        read_only=True,
    ),
    Param(
        'thread_priority',
        50,
        'SCHED_FIFO priority of the realtime loop thread and of the '
        'middleware threads that deliver its commands (0: normal scheduling; needs '
        'CAP_SYS_NICE or an rtprio limit, else it falls back with a note in /diagnostics)',
        'int',
        low=0,
        high=99,
        read_only=True,
        doc='. Under load, middleware threads at normal scheduling held samples back '
        'for 100–450 ms',
    ),
    Param(
        'diagnostics_period',
        1.0,
        'seconds between /diagnostics messages',
        low=0.05,
        high=60.0,
        read_only=True,
    ),
    Param(
        'step_periods',
        1,
        'periods one ~/step call advances while paused',
        'int',
        low=1,
        high=1000000,
    ),
    Param(
        'frame_id',
        contract.WRENCH_FRAME,
        'TF frame of /contact_wrench (x tangential, y normal)',
        'str',
        read_only=True,
        doc=' (docs/topics.md, "Frames")',
    ),
    Param(
        'joint_commands_topic',
        JOINT_COMMANDS_TOPIC,
        'sensor_msgs/JointState commands '
        '(effort by joint name), as topic_based_ros2_control sends them',
        'str',
        read_only=True,
        doc=' (docs/ros2_control.md)',
    ),
    Param(
        'joint_states_topic',
        JOINT_STATES_TOPIC,
        'joint states again, for topic_based_ros2_control (not /joint_states)',
        'str',
        read_only=True,
        doc='; published while someone subscribes',
    ),
    Param(
        'joint_states_gap',
        JOINT_STATES_GAP,
        'periods between two periods whose state is left out on joint_states_topic '
        '(0: none), so that a driver taking one queued state per update '
        '(topic_based_ros2_control) does not keep a standing queue of old states',
        'int',
        low=0,
        high=100000,
        read_only=True,
        doc=(
            '; none in contact nor in the 50 ms after it (a gap due then waits). An update '
            'that finds its queue empty keeps the previous state, which the broadcaster '
            "publishes again; the project's controller computes that update's command on its "
            'latest state predicted a period further (docs/ros2_control.md, "The queue of '
            'states"). Realtime only: in lockstep every state goes out (a stack the simulator '
            'paces takes each)'
        ),
    ),
    Param(
        'tf_rate',
        DEFAULT_TF_RATE,
        'rate of /tf and /impact_markers [Hz] (wall clock)',
        low=0.0,
        high=1000.0,
        open_low=True,
        read_only=True,
        doc=", from a timer outside the realtime loop; also at each impact's first contact, "
        'maximum compression and separation (docs/topics.md, "Markers")',
    ),
    Param(
        'recorder_window',
        0,
        'lockstep: periods simulated time may run ahead of what the '
        f'recorder reports written on {contract.RECORDER_PROGRESS}, so a stalled recorder '
        'holds the run instead of losing samples (0: do not wait for a recorder)',
        'int',
        low=0,
        high=contract.WRITER_REPAIR_DEPTH // 2,
        read_only=True,
        doc=f'. `impact-arm run` and the launch file set {contract.RECORDER_WINDOW} in lockstep',
    ),
    Param(
        'rod_radius',
        0.0,
        'radius the rods are drawn with [m] (0: 1 % of the shortest link)',
        low=0.0,
        high=1e3,
        read_only=True,
    ),
    Param(
        'publish_tf',
        True,
        'publish /tf and /tf_static (false when robot_state_publisher does, launch tf:=rsp)',
        'bool',
        read_only=True,
    ),
)


def check(p: SimulatorParameters, names: Sequence[str]) -> list[int]:
    """What no single parameter's range says: ParameterError naming the parameters.
    Returns the command order (the index in ``names`` of each entry of ``joints``)."""
    order = check_joints(p.joints, names)
    if (
        p.joint_states_topic in (JOINT_STATES, JOINT_STATES.lstrip('/'))
        or p.joint_commands_topic == COMMANDS
    ):
        raise ParameterError(
            f'parameter joint_states_topic = {p.joint_states_topic!r}, '
            f'joint_commands_topic = {p.joint_commands_topic!r}: the topic hardware '
            f'needs its own topics (not /joint_states, not {COMMANDS})'
        )
    if p.mode is SimulatorMode.REALTIME and p.release_after > 0.0:
        raise ParameterError(
            f'parameter release_after = {p.release_after}: lockstep only (realtime: 0.0)'
        )
    if p.mode is SimulatorMode.REALTIME and p.rate_factor == 0.0:
        raise ParameterError(
            'parameter rate_factor = 0.0: realtime mode needs a pace '
            '> 0 (use mode lockstep to run as fast as possible)'
        )
    return order
