"""The controller node's parameters, declared once: ``parameter_table(scene)`` gives each its
default (from the scene's controller section), range and description; through
``params.declare``, the typed object the node reads (param_types.ControllerParameters,
generated from this table)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from .. import contract
from ..contract import (
    ANTIWINDUP_STRATEGIES,
    COMMANDS,
    CONTROL_TRIGGERS,
    FEEDBACK_LAWS,
    PID_SPACES,
    START_AFTER,
    ControlTrigger,
    StartAfter,
)
from ..driver.control_inputs import DEFAULT_IMPLICIT_WINDOW, REBOUND_HOLD_S, SENT_HISTORY
from .params import Param, ParameterError, check_joints, scene_joint_names

if TYPE_CHECKING:
    from ..physics.scene import Scene
    from .param_types import ControllerParameters


def parameter_table(scene: Scene) -> tuple[Param, ...]:
    """The controller's parameters; defaults come from the scene's controller section."""
    c, n = scene.controller, scene.n_links
    surfaces = [s.height for s in scene.surfaces]
    return (
        Param(
            'scene',
            '',
            'scene YAML file or installed scene name (empty: paper): the model '
            'the controller knows (kinematics, gravity) and its default gains',
            'str',
            read_only=True,
        ),
        Param(
            'law',
            c.law if c.law in FEEDBACK_LAWS else 'q',
            'q (article eq. 9: PD on link angles + gravity compensation), pid or pd',
            'str',
            choices=FEEDBACK_LAWS,
            shown_default="scene's",
        ),
        Param('rate', 1000.0, 'command rate [Hz]', low=0.1, high=100000.0, read_only=True),
        Param(
            'trigger',
            ControlTrigger.JOINT_STATES.value,
            'joint_states: compute on each joint state reaching '
            'the next tick; timer: compute at rate on the node clock',
            'str',
            choices=CONTROL_TRIGGERS,
            read_only=True,
            enum=ControlTrigger,
            doc=' (joint_states: sensor-synchronous, deterministic on simulated time)',
        ),
        Param(
            'p',
            list(c.kp),
            'proportional gains per joint [N m/rad]',
            'floats',
            low=0.0,
            size=n,
            shown_default="scene's",
            doc=' (control_toolbox names: `p`, `i`, `d`)',
        ),
        Param(
            'i',
            list(c.ki),
            'integral gains per joint [N m/(rad s)] (law pid)',
            'floats',
            low=0.0,
            size=n,
            shown_default="scene's",
        ),
        Param(
            'd',
            list(c.kd),
            'derivative gains per joint [N m s/rad]',
            'floats',
            low=0.0,
            size=n,
            shown_default="scene's",
        ),
        Param(
            'i_clamp_max',
            math.inf,
            'upper clamp of the integral term [N m] (legacy)',
            high=math.inf,
            doc=' (with `antiwindup_strategy: legacy`)',
        ),
        Param(
            'i_clamp_min',
            -math.inf,
            'lower clamp of the integral term [N m] (legacy)',
            low=-math.inf,
            doc=' (with `antiwindup_strategy: legacy`)',
        ),
        Param(
            'u_clamp_max',
            math.inf,
            "upper limit of each joint's PID output [N m]",
            high=math.inf,
            doc=' (laws pid, pd)',
        ),
        Param(
            'u_clamp_min',
            -math.inf,
            "lower limit of each joint's PID output [N m]",
            low=-math.inf,
            doc=' (laws pid, pd)',
        ),
        Param(
            'antiwindup_strategy',
            'none',
            'integral anti-windup: none, legacy (i_clamp on '
            'the integral term), conditional_integration (integral frozen while the output '
            'is at a u_clamp limit)',
            'str',
            choices=ANTIWINDUP_STRATEGIES,
            doc='; none integrates regardless',
        ),
        Param(
            'space',
            c.space,
            'angles the PID acts on: absolute link angles or relative joint angles',
            'str',
            choices=PID_SPACES,
            shown_default="scene's",
        ),
        Param(
            'down_target',
            scene.joint_coordinates.positions(c.down_target),
            'joint positions aimed at on the way down [rad]',
            'floats',
            low=-4 * math.pi,
            high=4 * math.pi,
            size=n,
            shown_default="scene's",
            doc=" (the robot's joint angles; for rods joint_k = q_k − q_(k−1))",
        ),
        Param(
            'up_target',
            scene.joint_coordinates.positions(c.up_target),
            'joint positions aimed at on the way up [rad]',
            'floats',
            low=-4 * math.pi,
            high=4 * math.pi,
            size=n,
            shown_default="scene's",
        ),
        Param(
            'switch_height',
            c.switch_height,
            'tip height that ends the up phase [m]',
            low=-1e3,
            high=1e3,
            shown_default="scene's",
        ),
        Param(
            'surface_height',
            min(surfaces) if surfaces else -1e3,
            'height of the struck surface, for velocity-reversal detection [m]',
            low=-1e3,
            high=1e3,
            shown_default='lowest surface',
        ),
        Param('force_threshold', 1.0, 'contact normal force that means impact [N]', low=0.0),
        Param(
            'reversal_band',
            0.01,
            'tip velocity reversal within this height above the surface means impact [m]',
            low=0.0,
            high=10.0,
        ),
        Param(
            'latency_periods',
            -1,
            'control periods a command takes to reach the actuators (a driver stack adds '
            'one or two): the controller acts on the state predicted from the model and the '
            'commands still in flight; -1: measured from the efforts the driver reports '
            '(0 until one matches a command sent; set it for a driver that reports measured '
            "torques); 0: no prediction, also for an arm the scene's model does not describe "
            "(the prediction would steer it by the model's dynamics)",
            'int',
            low=-1,
            high=SENT_HISTORY - 1,
            read_only=True,
        ),
        Param(
            'anticipate_impacts',
            True,
            'with prediction (latency_periods not 0): when the predicted state has the tip '
            "in the surface, the command is the up half's, computed on that state with the "
            "tip's approach stopped (a plastic impulse at the tip), as a sample in contact "
            'would show it; false: the cycle switches only when a sample shows the impact, '
            'and the commands in flight push the tip into the surface meanwhile (the cycle '
            'then lengthens with the latency)',
            'bool',
            read_only=True,
        ),
        Param(
            'implicit_periods',
            1,
            'periods of its own command the law looks ahead when the measured latency '
            'varies (two latencies recur within a second: an unsynchronised driver stack, '
            'where a command acts a period early or late and is held one period or two): '
            'the torque is the law evaluated on the state that torque itself leads to after '
            'this many periods (implicit, a Newton step on the model), so that a command '
            'held longer than planned does not overshoot; at least the recurring '
            f"latencies' spread plus one period in the rebound's first "
            f'{REBOUND_HOLD_S * 1e3:g} ms (the longest a '
            'command may then act, where its torque is largest) and half that spread, rounded '
            'up, after it; with a steady latency the law is '
            "the scene's; 0: never (needs latency_periods -1)",
            'int',
            low=0,
            high=8,
            read_only=True,
        ),
        Param(
            'implicit_window',
            DEFAULT_IMPLICIT_WINDOW,
            'how long after the cycle switches to its up half (an impact) the implicit law '
            '(implicit_periods) acts while the latency varies [s]: in the rebound a command '
            'held longer than planned turns the arm back into the surface; in the swing the '
            'explicit law only oscillates a little, where the implicit one slows the cycle '
            '(~1 % offline); a window longer than the cycle: always',
            low=0.0,
            high=1e3,
            read_only=True,
        ),
        Param(
            'wrench_tolerance',
            0.01,
            's: a joint state waits for the contact wrench of its instant only while the '
            'newest wrench is at most this far behind it on the same clock; a wrench on '
            'another clock, late or absent is used as it comes (the largest force since the '
            'last command), never a reason to hold or drop states',
            low=0.0,
            high=10.0,
            read_only=True,
        ),
        Param(
            'joints',
            scene_joint_names(scene),
            "joint order of the command array (default: the scene's joints, base first)",
            'strs',
            size=n,
            read_only=True,
            shown_default="the scene's: its URDF's joint names, else `[joint1, …, jointN]`",
        ),
        Param(
            'command_readers',
            1,
            'readers of the command topic (the driver, a recorder) '
            'matched before the first command; the arm is held until then, so nothing of the '
            'run goes unrecorded',
            'int',
            low=1,
            high=100,
            read_only=True,
            doc='. `impact-arm run` and the launch file set 2 when they record',
        ),
        Param(
            'startup_hold',
            contract.STARTUP_HOLD,
            'seconds after the first joint state (or wrench: '
            'start_after) before the first command: the arm is held while DDS discovery '
            'settles, because Fast DDS can '
            "stop a process's reception for 0.33 s when it discovers a participant late "
            '(docs/nodes.md); impact-arm run and the launch file set 0 in lockstep',
            low=0.0,
            high=60.0,
            read_only=True,
        ),
        Param(
            'start_after',
            StartAfter.JOINT_STATE.value,
            'what startup_hold counts from: joint_state, the '
            "first joint state; wrench, the first contact wrench (the simulator's own sample: "
            'behind a driver stack the joint states start as its initial values, before the '
            'simulator runs)',
            'str',
            choices=START_AFTER,
            read_only=True,
            enum=StartAfter,
            doc=' (docs/ros2_control.md sets wrench)',
        ),
        Param(
            'command_history',
            contract.qos(COMMANDS).depth,
            'commands the writer keeps to '
            'resend to a reader that fell behind (a recorder); impact-arm run sets '
            f'{contract.WRITER_REPAIR_DEPTH} in lockstep. Realtime keeps the default: a '
            'deep history makes a publish stall ~1 us per sample when acknowledgements '
            'arrive',
            'int',
            low=1,
            high=100000,
            read_only=True,
        ),
        Param(
            'cycles',
            0,
            'down/up cycles after which the controller sends no further command (0: it '
            'never stops); a cycle ends as the arm rises through switch_height after its '
            "strike, where an offline run of the scene ends (counted from the node's start; a "
            're-armed cycle is no cycle). In lockstep the simulator waits for the next command, '
            'so simulated time stops there however long the nodes run on',
            'int',
            low=0,
            high=1_000_000,
            read_only=True,
            doc=". `impact-arm run` sets the scene's `cycles` in lockstep",
        ),
        Param(
            'thread_priority',
            49,
            'SCHED_FIFO priority of the control thread and of the '
            'middleware threads that deliver its samples (0: normal scheduling; falls back '
            "when the system refuses); one below the simulator loop's default, as a "
            'controller manager sits below its hardware driver',
            'int',
            low=0,
            high=99,
            read_only=True,
        ),
    )


def check(p: ControllerParameters, names: Sequence[str]) -> list[int]:
    """What no single parameter's range says: ParameterError naming the parameters.
    Returns the command order (the index in ``names`` of each entry of ``joints``)."""
    order = check_joints(p.joints, names)
    for name in ('i_clamp', 'u_clamp'):
        low, high = getattr(p, f'{name}_min'), getattr(p, f'{name}_max')
        if low > high:
            raise ParameterError(f'{name}_min = {low:g} > {name}_max = {high:g}')
    return order
