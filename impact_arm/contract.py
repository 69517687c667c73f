"""The contract every layer shares: topic names, message types and QoS (docs/topics.md), joint names
and the joint-angle convention, and the names of integrator presets, control laws and
anti-windup strategies. Nothing here imports ROS or the rest of the package, so core, io, nodes
and tools all import their names from this one place.

===========================  ===================================  =============================
topic                        type                                 QoS
===========================  ===================================  =============================
/joint_states                sensor_msgs/msg/JointState           reliable, volatile, 100
/contact_wrench              geometry_msgs/msg/WrenchStamped      reliable, volatile, 100
/impact_report               std_msgs/msg/String                  reliable, transient_local, 100
/diagnostics                 diagnostic_msgs/msg/DiagnosticArray  reliable, volatile, 10
/clock                       rosgraph_msgs/msg/Clock              best_effort, volatile, 1
/effort_controller/commands  std_msgs/msg/Float64MultiArray       reliable, volatile, 100
/impact_trace (offline only) std_msgs/msg/Float64MultiArray       reliable, transient_local, 100
/robot_description           std_msgs/msg/String                  reliable, transient_local, 1
/tf_static                   tf2_msgs/msg/TFMessage               reliable, transient_local, 1
/tf                          tf2_msgs/msg/TFMessage               reliable, volatile, 100
/impact_markers              visualization_msgs/msg/MarkerArray   reliable, volatile, 10
===========================  ===================================  =============================

All keep_last; deadline, lifespan and liveliness lease infinite; liveliness automatic.
The depth is what readers ask for; in lockstep the writers of the per-period streams keep
``WRITER_REPAIR_DEPTH`` samples (see there).
``/impact_report`` is transient_local so a late subscriber (recorder, analysis) still gets
every impact. ``/clock`` is best effort like rclcpp's ClockQoS.

Joint angles on the wire are relative (encoder) angles, joint1 = q1, joint_i = q_i - q_{i-1};
the physics uses absolute link angles q_i. ``to_joint_space``/``to_absolute`` convert.

Frames (REP 103): the physics works in its own plane, x to the right and y up, gravity along
-y, angles positive counter-clockwise about the plane's z. Everything a ROS tool reads (URDF,
/tf, markers, wrench frames) is in a REP 103 world instead: z up, gravity along -z. The one
mapping between the two (``plane_to_world``): the model's plane is the world's x-z plane,

    world x = model x,   world y = 0,   world z = model y,

so the model's z axis (its rotation axis) is the world's -y: a positive joint angle turns
about -y, and every URDF joint axis is ``0 -1 0``. A joint angle keeps its value and sign;
only the axis it is drawn about is named differently.
The contact frames ``surface1`` ... (``SURFACE_FRAME``) keep the model's axes, rotated by
``PLANE_FRAME_ROTATION`` (+90 deg about world x): x tangential, y the surface's outward
normal (world +z), z = world -y. /contact_wrench is given in ``surface1`` (``WRENCH_FRAME``):
force.x tangential, force.y normal, the numbers the physics computes.
"""

from __future__ import annotations

import dataclasses
import math
from enum import Enum
from typing import Any, Callable, Mapping, Optional

# ------------------------------------------------------------------------------- topics
JOINT_STATES = '/joint_states'
CONTACT_WRENCH = '/contact_wrench'
# the largest normal contact force of each period (WrenchStamped like /contact_wrench, force.y):
# an impact's peak beside the period average, which spreads its ~0.15 ms over the period
CONTACT_FORCE_PEAK = '/contact_force_peak'
IMPACT_REPORT = '/impact_report'
DIAGNOSTICS = '/diagnostics'
# the names of the nodes' DiagnosticStatus (both publish on /diagnostics); the simulator's
# values are ``SimulatorStatus`` (below, after the names it uses)
SIMULATOR_STATUS = 'impact_arm: simulator'
CONTROLLER_STATUS = 'impact_arm: controller'


@dataclasses.dataclass(frozen=True)
class ControllerStatus:
    """The controller's /diagnostics values (status ``CONTROLLER_STATUS``) with one codec both
    ways: ``values()`` is what the node publishes, ``parse(values)`` what a reader (``impact-arm
    run``, the tests, a stand-in) makes of them. Counts are since the node started."""

    chatter: str = ''  # the joints whose commands alternated in sign and grew ('' : none)
    commands_sent: int = 0
    strikes: int = 0  # cycles whose down half an impact ended
    cycles_completed: int = 0  # cycles whose up half ended
    down_half_start: float = 0.0  # the latest down half's start (sample stamp) [s]
    repeated_states: int = 0  # the driver's repetitions of a sample, not new periods
    # of which a command was computed on (the latest state predicted a period further)
    repetition_ticks: int = 0
    latency_periods: int = 0  # commands in flight the latest command was predicted over
    latency_periods_max: int = 0
    # the run's measured latencies: (periods, count), ascending
    latency_histogram: tuple[tuple[int, int], ...] = ()
    implicit_commands: int = 0  # computed with the implicit law (the latency varied)
    # how the driver showed it applies the commands ('' : not yet), and the ticks that sent
    # the first command again until it did
    driver_answered: str = ''
    unanswered_ticks: int = 0
    # the inputs dropped, by reason (each a key of its own on the wire), in the node's order
    dropped: tuple[tuple[str, int], ...] = ()

    def values(self) -> list[tuple[str, str]]:
        """The key-value pairs of the DiagnosticStatus, in this order."""
        out: list[tuple[str, str]] = []
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.name == 'dropped':
                out.extend((reason, str(count)) for reason, count in value)
            elif field.name == 'latency_histogram':
                out.append((field.name, ' '.join(f'{k}:{n}' for k, n in value)))
            elif field.name == 'down_half_start':
                out.append((field.name, repr(float(value))))
            else:
                out.append((field.name, str(value)))
        return out

    @classmethod
    def parse(cls, values: dict[str, str]) -> ControllerStatus:
        """The status from its key-values (a DiagnosticStatus's, as a dict). A key the fields
        do not name is a dropped-input counter; a value that is not of its field's kind
        raises ValueError naming the key."""
        known = {field.name: field for field in dataclasses.fields(cls)}
        kwargs: dict = {}
        dropped = []
        for key, text in values.items():
            try:
                if key == 'latency_histogram':
                    pairs = (pair.split(':') for pair in text.split())
                    kwargs[key] = tuple((int(k), int(n)) for k, n in pairs)
                elif key in ('chatter', 'driver_answered'):
                    kwargs[key] = text
                elif key == 'down_half_start':
                    kwargs[key] = float(text)
                elif key in known:
                    kwargs[key] = int(text)
                else:
                    dropped.append((key, int(text)))
            except ValueError:
                raise ValueError(f'controller status {key} = {text!r}: not a valid value') from None
        return cls(**kwargs, dropped=tuple(dropped))

    def dropped_count(self, reason: str) -> int:
        """Inputs dropped for ``reason`` (0 when the node does not count it)."""
        return dict(self.dropped).get(reason, 0)


RECORDER_STATUS = 'impact_arm: recorder'
# MCAP metadata record where the recorder writes the samples lost per topic
# ('lost:/joint_states': '12', 'before_first:/joint_states': '0', ...)
LOSSES_METADATA = 'recording/losses'
CLOCK = '/clock'
COMMANDS = '/effort_controller/commands'
# the plates of mounted surfaces (scene surfaces[i].mount), published and recorded only for a
# scene that has one: sensor_msgs/JointState, one entry per mounted surface named by its frame
# (surface1, ...), position z [m] from rest (up), velocity ż [m/s]
SURFACE_MOUNTS = '/surface_mounts'
IMPACT_TRACE = '/impact_trace'  # written by offline runs only: the contact phase, densely
ROBOT_DESCRIPTION = '/robot_description'  # the visual topics (io/scene_visuals.py)
TF_STATIC = '/tf_static'
TF = '/tf'
IMPACT_MARKERS = '/impact_markers'
# every impact so far, rounded, one JSON String at each impact (io/impact_table.py): what a
# viewer's table shows after a seek
IMPACT_TABLE = '/impact_table'
E_STOP = '/e_stop'  # std_msgs/msg/Bool: true = zero torque, latched (simulator)
# the simulator's topics with one stamped sample per period (the held initial state included)
PERIOD_TOPICS = (JOINT_STATES, CONTACT_WRENCH, CONTACT_FORCE_PEAK, SURFACE_MOUNTS)
# builtin_interfaces/msg/Time: the stamp up to which the recorder has written every one of the
# ``PERIOD_TOPICS`` it records that has a publisher (none until each has a sample). In
# lockstep the simulator stays at most ``recorder_window`` periods ahead of it, so a
# recording is complete however long the recorder stalls (docs/nodes.md, "Recording in
# lockstep").
RECORDER_PROGRESS = '/recorder/progress'
RECORDER_PROGRESS_TYPE = 'builtin_interfaces/msg/Time'

JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
STRING_TYPE = 'std_msgs/msg/String'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
COMMAND_TYPE = 'std_msgs/msg/Float64MultiArray'
TRACE_TYPE = 'std_msgs/msg/Float64MultiArray'
TF_TYPE = 'tf2_msgs/msg/TFMessage'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
WORLD_FRAME = 'world'


def surface_frame(index: int) -> str:
    """TF frame of the scene's surface ``index`` (0-based): 'surface1', 'surface2', ..."""
    return f'surface{index + 1}'


# every surface is horizontal, so the first one's frame orients the wrench of any of them
WRENCH_FRAME = surface_frame(0)

# RMW_DURATION_INFINITE as rosbag2 writes it
INFINITE_SEC, INFINITE_NSEC = 9223372036, 854775807
INFINITE_NS = INFINITE_SEC * 1_000_000_000 + INFINITE_NSEC


@dataclasses.dataclass(frozen=True)
class TopicQos:
    """A QoS profile in rosbag2's terms. Durations in ns; None = infinite."""

    reliability: str = 'reliable'
    durability: str = 'volatile'
    depth: int = 10
    history: str = 'keep_last'
    deadline_ns: Optional[int] = None
    lifespan_ns: Optional[int] = None
    liveliness: str = 'automatic'
    liveliness_lease_ns: Optional[int] = None
    avoid_ros_namespace_conventions: bool = False

    def as_dict(self) -> dict:
        """The mapping rosbag2 serializes (key order as rosbag2 writes it)."""

        def dur(ns):
            ns = INFINITE_NS if ns is None or ns <= 0 or ns >= INFINITE_NS else ns
            return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}

        return {
            'history': self.history,
            'depth': int(self.depth),
            'reliability': self.reliability,
            'durability': self.durability,
            'deadline': dur(self.deadline_ns),
            'lifespan': dur(self.lifespan_ns),
            'liveliness': self.liveliness,
            'liveliness_lease_duration': dur(self.liveliness_lease_ns),
            'avoid_ros_namespace_conventions': bool(self.avoid_ros_namespace_conventions),
        }

    @classmethod
    def from_dict(cls, d: dict) -> 'TopicQos':
        def ns(v):
            t = int(v['sec']) * 1_000_000_000 + int(v['nsec'])
            return None if t == 0 or t >= INFINITE_NS else t

        return cls(
            str(d['reliability']),
            str(d['durability']),
            int(d.get('depth', 0)),
            str(d.get('history', 'keep_last')),
            ns(d['deadline']),
            ns(d['lifespan']),
            str(d['liveliness']),
            ns(d['liveliness_lease_duration']),
            bool(d.get('avoid_ros_namespace_conventions', False)),
        )

    @classmethod
    def from_rclpy(cls, p) -> 'TopicQos':
        def ns(d):
            t = d.nanoseconds
            return None if t <= 0 or t >= INFINITE_NS else t

        return cls(
            p.reliability.name.lower(),
            p.durability.name.lower(),
            int(p.depth),
            p.history.name.lower(),
            ns(p.deadline),
            ns(p.lifespan),
            p.liveliness.name.lower(),
            ns(p.liveliness_lease_duration),
            bool(p.avoid_ros_namespace_conventions),
        )

    def to_rclpy(self, min_depth: int = 1):
        """An rclpy QoSProfile; 'unknown' policies (as discovery reports them) become defaults."""
        from rclpy.duration import Duration
        from rclpy.qos import (
            DurabilityPolicy,
            HistoryPolicy,
            LivelinessPolicy,
            QoSProfile,
            ReliabilityPolicy,
        )

        def pol(enum, name, default):
            return default if name in ('unknown', '') else enum[name.upper()]

        kw = {}
        for key, attr in (
            ('deadline', 'deadline_ns'),
            ('lifespan', 'lifespan_ns'),
            ('liveliness_lease_duration', 'liveliness_lease_ns'),
        ):
            if getattr(self, attr) is not None:
                kw[key] = Duration(nanoseconds=getattr(self, attr))
        return QoSProfile(
            history=pol(HistoryPolicy, self.history, HistoryPolicy.KEEP_LAST),
            depth=max(int(self.depth), min_depth),
            reliability=pol(ReliabilityPolicy, self.reliability, ReliabilityPolicy.RELIABLE),
            durability=pol(DurabilityPolicy, self.durability, DurabilityPolicy.VOLATILE),
            liveliness=pol(LivelinessPolicy, self.liveliness, LivelinessPolicy.AUTOMATIC),
            avoid_ros_namespace_conventions=self.avoid_ros_namespace_conventions,
            **kw,
        )


RELIABLE_100 = TopicQos(depth=100)
LATCHED_100 = TopicQos(durability='transient_local', depth=100)
TOPICS = {  # topic -> (type, QoS) of every topic the nodes exchange; see the docstring
    JOINT_STATES: (JOINT_STATE_TYPE, RELIABLE_100),
    CONTACT_WRENCH: (WRENCH_TYPE, RELIABLE_100),
    CONTACT_FORCE_PEAK: (WRENCH_TYPE, RELIABLE_100),
    IMPACT_REPORT: (STRING_TYPE, LATCHED_100),
    DIAGNOSTICS: (DIAGNOSTICS_TYPE, TopicQos(depth=10)),
    CLOCK: (CLOCK_TYPE, TopicQos(reliability='best_effort', depth=1)),
    # depth 100 like the joint states: a recorder that is briefly slower than a lockstep loop
    # must not lose commands the driver already acknowledged
    COMMANDS: (COMMAND_TYPE, RELIABLE_100),
}
TRACE_QOS = LATCHED_100
SURFACE_MOUNTS_QOS = RELIABLE_100
# History of the lockstep writers of the per-period streams (joint states, wrench, commands).
# A reliable keep-last writer can resend only what its history still holds: a recorder
# descheduled for 0.5 s under load (a lockstep run makes ~2 400 periods a second) lost ~1 000
# joint states with a history of 100 and none with 2 000. Realtime keeps 100: Fast DDS
# settles a batch of acknowledgements under the writer's lock, ~1 us per sample, and with
# 2 000 a publish then took ~1.1 ms once or more per run (bench starts: worst periods
# <= 1 ms in 0 of 10 starts, 62 % with 100). Readers keep their own depth: the simulator's
# command reader takes at most its depth a period and must stay at 100.
WRITER_REPAIR_DEPTH = 2000
# Seconds the controller waits after its start before its first command (realtime), so the
# arm starts moving only after DDS discovery has settled: when a participant discovers
# another one late (Fast DDS announces every 3 s, and a participant started before ours is
# often heard only then), Fast DDS's shared-memory health check can stop all of a process's
# reception for 0.33 s (eProsima/Fast-DDS#6535; docs/nodes.md). Lockstep needs no hold: a
# stall there only delays the next period.
STARTUP_HOLD = 4.0
# Periods a lockstep simulator may run ahead of the recorder's progress when a run is
# recorded (``impact-arm run``, the launch file). Well inside WRITER_REPAIR_DEPTH, so every
# sample not yet taken by the recorder is still in its writer's history and is resent; large
# enough that the recorder's 10 ms polls never hold the loop back (~30 periods a poll).
RECORDER_WINDOW = 500
# latched: a reader that joins late (the runner, a simulator) still gets the newest stamp
PROGRESS_QOS = TopicQos(durability='transient_local', depth=1)
LATCHED_1 = TopicQos(durability='transient_local', depth=1)
VISUAL_TOPICS = {  # topic -> (type, QoS); latched ones as robot_state_publisher offers them
    ROBOT_DESCRIPTION: (STRING_TYPE, LATCHED_1),
    TF_STATIC: (TF_TYPE, LATCHED_1),
    TF: (TF_TYPE, TopicQos(depth=100)),
    IMPACT_MARKERS: (MARKERS_TYPE, TopicQos(depth=10)),
    IMPACT_TABLE: (STRING_TYPE, LATCHED_1),  # the newest holds every row: a late reader too
}


def qos(topic: str, default: TopicQos = TopicQos()) -> TopicQos:
    """The QoS the contract gives ``topic`` (remapped names fall back to ``default``)."""
    if topic == SURFACE_MOUNTS:
        # not in TOPICS (only a scene with mounted surfaces publishes it), but a reader that
        # subscribes before its publisher exists (the recorder) must still ask for reliable
        # delivery: a best-effort reader got no repair and lost plate samples under load
        return SURFACE_MOUNTS_QOS
    return TOPICS.get(topic, (None, default))[1]


# ------------------------------------------------------------------------------- joints
def joint_names(n_links: int) -> list:
    return [f'joint{i + 1}' for i in range(n_links)]


def to_joint_space(values) -> list:
    """Absolute link angles (or rates) -> relative joint angles: [a1, a2 - a1, ...]."""
    values = [float(v) for v in values]
    return [values[0]] + [values[i] - values[i - 1] for i in range(1, len(values))]


def to_absolute(values) -> list:
    """Relative joint angles (or rates) -> absolute link angles (cumulative sum)."""
    out, acc = [], 0.0
    for v in values:
        acc += float(v)
        out.append(acc)
    return out


@dataclasses.dataclass(frozen=True)
class JointCoordinates:
    """The robot's joint coordinates against the model's absolute link angles q.

    A robot's joint angle θ_k (its URDF's zero and sign, as its driver reports it) is the
    model's relative angle r_k = q_k - q_(k-1) up to a sign and an offset:
    r_k = sign_k θ_k + offset_k; its torque τ_k acts on r_k as sign_k τ_k. Everything on the
    wire (/joint_states, the commands, recordings, the controller's targets) is in the
    robot's coordinates; the physics in q. For the scene's own rods, and a URDF written in
    the model's convention, every sign is 1 and every offset 0: θ = r (``to_joint_space``)."""

    signs: tuple[float, ...]
    offsets: tuple[float, ...]

    @classmethod
    def identity(cls, n: int) -> 'JointCoordinates':
        return cls((1.0,) * n, (0.0,) * n)

    @property
    def is_identity(self) -> bool:
        return all(s == 1.0 for s in self.signs) and not any(self.offsets)

    def positions(self, q) -> list:
        """Absolute link angles -> the robot's joint angles."""
        r = to_joint_space(q)
        if self.is_identity:
            return r
        return [s * (v - c) for s, v, c in zip(self.signs, r, self.offsets)]

    def rates(self, qd) -> list:
        """Absolute link rates -> the robot's joint rates."""
        r = to_joint_space(qd)
        return r if self.is_identity else [s * v for s, v in zip(self.signs, r)]

    def efforts(self, tau) -> list:
        """The model's joint torques (on r) -> the robot's joint efforts."""
        return [float(v) if s == 1.0 else s * v for s, v in zip(self.signs, tau)]

    def absolute(self, theta) -> list:
        """The robot's joint angles -> absolute link angles."""
        if self.is_identity:
            return to_absolute(theta)
        return to_absolute([s * float(v) + c for s, v, c in zip(self.signs, theta, self.offsets)])

    def absolute_rates(self, theta_d) -> list:
        """The robot's joint rates -> absolute link rates."""
        return to_absolute(self.efforts(theta_d))

    def model_efforts(self, effort) -> list:
        """The robot's joint efforts -> the model's joint torques (the sign is its own
        inverse)."""
        return self.efforts(effort)

    def relative(self, theta) -> list:
        """The robot's joint angles -> the model's relative angles r."""
        return [s * float(v) + c for s, v, c in zip(self.signs, theta, self.offsets)]


# ------------------------------------------------------------------------------- frames
PLANE_AXIS_IN_WORLD = (0.0, -1.0, 0.0)  # the model's z (positive angles) in the world
GRAVITY_IN_WORLD = (0.0, 0.0, -1.0)  # the model's -y


def plane_to_world(x: float, y: float) -> tuple:
    """A point (or vector) of the model's plane in the REP 103 world: (x, 0, y)."""
    return float(x), 0.0, float(y)


def plane_rotation(angle: float) -> tuple:
    """Quaternion (x, y, z, w) in the world of a rotation by ``angle`` [rad] about the
    model's z axis (= world -y): how a joint at that angle turns its child frame."""
    return 0.0, -math.sin(angle / 2), 0.0, math.cos(angle / 2)


# Quaternion (x, y, z, w) of a frame with the model's axes (x, y in the plane, z = world -y)
# in the world: +90 deg about world x. The surface frames use it.
PLANE_FRAME_ROTATION = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))


# ------------------------------------------------------------------------------- names
class TextEnum(str, Enum):
    """An enum whose members behave as their text (``str(m) == m.value``, ``f'{m}'``,
    dictionary keys, JSON), like Python 3.11's StrEnum, for Python 3.10 as well: the names
    below are parsed once where text comes in (a scene file, a parameter) and compared as
    members inside, while files and messages keep their text."""

    __str__ = str.__str__
    __hash__ = str.__hash__

    def __format__(self, spec: str) -> str:
        return str.__format__(self.value, spec)

    def __repr__(self) -> str:
        return f'{type(self).__name__}.{self.name}'


class IntegratorPreset(TextEnum):
    REFERENCE = 'reference'
    ACCURATE = 'accurate'
    BALANCED = 'balanced'
    FAST = 'fast'


class StepMethod(TextEnum):
    DOPRI5 = 'dopri5'
    ROSENBROCK = 'rosenbrock'


class ControlLaw(TextEnum):
    Q = 'q'  # the article's eq. 9
    PID = 'pid'  # eq. 10
    PD = 'pd'  # eq. 10 with Ki = 0
    NONE = 'none'  # no controller (zero torque)


class PidSpace(TextEnum):
    """The angles the PID/PD acts on."""

    ABSOLUTE = 'absolute'
    JOINT = 'joint'


class AntiWindup(TextEnum):
    NONE = 'none'
    LEGACY = 'legacy'
    CONDITIONAL_INTEGRATION = 'conditional_integration'


class CycleMode(TextEnum):
    """The striking cycle's half: down to the surface, up to the switch height."""

    DOWN = 'down'
    UP = 'up'


INTEGRATOR_PRESETS = tuple(m.value for m in IntegratorPreset)
INTEGRATOR_METHODS = tuple(m.value for m in StepMethod)
CONTROL_LAWS = tuple(m.value for m in ControlLaw)
FEEDBACK_LAWS = (ControlLaw.Q.value, ControlLaw.PID.value, ControlLaw.PD.value)  # the node's
PID_SPACES = tuple(m.value for m in PidSpace)
ANTIWINDUP_STRATEGIES = tuple(m.value for m in AntiWindup)


class SimulatorMode(TextEnum):
    """How the simulator runs its periods (its ``mode`` parameter, ``impact-arm run --mode``)."""

    REALTIME = 'realtime'  # paced by the wall clock
    LOCKSTEP = 'lockstep'  # one period per received command


class ControlTrigger(TextEnum):
    """What makes the controller compute a command (its ``trigger`` parameter)."""

    JOINT_STATES = 'joint_states'  # each joint state whose stamp reaches the next tick
    TIMER = 'timer'  # a timer at the control rate on the node clock


class StartAfter(TextEnum):
    """What the controller's start-up hold counts from: the first joint state, or the first
    contact wrench (a simulator's own sample: through a driver stack the joint states may be
    the stack's initial values, published before the hardware runs)."""

    JOINT_STATE = 'joint_state'
    WRENCH = 'wrench'


class WatchdogState(TextEnum):
    """waiting: no command yet (brakes on); ok: a fresh command is held; timeout: the newest
    command is older than the timeout (the policy acts)."""

    WAITING = 'waiting'
    OK = 'ok'
    TIMEOUT = 'timeout'


class WatchdogPolicy(TextEnum):
    """What the driver does on a command timeout. brake: hold the joints where they are
    (``SimulatedArm.brake``), as a real drive's safe stop does; zero: zero torque, the arm
    falls under gravity (onto the part, where it chatters)."""

    BRAKE = 'brake'
    ZERO = 'zero'


SIMULATOR_MODES = tuple(m.value for m in SimulatorMode)
CONTROL_TRIGGERS = tuple(m.value for m in ControlTrigger)
START_AFTER = tuple(m.value for m in StartAfter)


def _shown(spec: str) -> dict:
    """Field metadata: the format spec its number is written with on the wire."""
    return {'format': spec}


def _flag(text: str) -> bool:
    if text not in ('true', 'false'):
        raise ValueError(text)
    return text == 'true'


def _times(text: str) -> tuple[float, ...]:
    return tuple(float(t) for t in text.split())


@dataclasses.dataclass(frozen=True)
class SimulatorStatus:
    """The simulator's /diagnostics values (status ``SIMULATOR_STATUS``) with one codec both
    ways: ``values()`` is what the node publishes, ``parse(values)`` what a reader (``impact-arm
    run``, the benchmarks, the tests) makes of them. Numbers are held as the wire shows them
    (rounded by their format), so a parsed status writes the same text again. The jitter,
    rate and ``compute_max_us`` cover the time since the previous status; ``*_run_*``,
    ``*_worst_*``, the means and the counts the whole run (since the start or a reset)."""

    mode: SimulatorMode = SimulatorMode.REALTIME
    publish_rate_requested: float = dataclasses.field(default=0.0, metadata=_shown('g'))
    publish_rate_achieved: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    jitter_p50_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    jitter_p99_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    jitter_max_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    jitter_run_p50_us: float = dataclasses.field(default=0.0, metadata=_shown('.0f'))
    jitter_run_p99_us: float = dataclasses.field(default=0.0, metadata=_shown('.0f'))
    jitter_run_max_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    jitter_run_max_at_s: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))
    periods_published: int = 0
    periods_published_until_s: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))
    wall_time: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))  # since the start
    overruns: int = 0
    # periods skipped after stalls (simulated time fell behind by as many periods)
    periods_skipped: int = 0
    # the simulated times of the latest stalls that skipped periods [s], oldest first
    periods_skipped_at_s: tuple[float, ...] = dataclasses.field(default=(), metadata=_shown('.6f'))
    # periods that left commands queued (a flood): the rest waited a period
    commands_flooded: int = 0
    # commands taken but not checked: a newer valid one of the same period held
    commands_superseded: int = 0
    watchdog_timeouts: int = 0
    # the longest wait between two commands taken [s]: a stall of the transport
    longest_command_silence_s: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))
    # realtime periods run with no command newer than the previous period's
    periods_without_new_command: int = 0
    paused: bool = False
    e_stop: bool = False
    kernel: str = ''  # 'compiled (numba)' or 'interpreted (<why>)'
    compute_max_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_worst_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_worst_at_s: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))
    period_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    # where a realtime period's time goes (whole-run means): taking commands, the physics,
    # publishing the period's messages (the driver's PERIOD_PARTS)
    compute_commands_mean_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_physics_mean_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_publish_mean_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    # lockstep only (None: not on the wire): the mean wait for each period's command
    lockstep_wait_mean_us: Optional[float] = dataclasses.field(default=None, metadata=_shown('.1f'))
    # and the worst period's (is it the physics of an impact, or a stall?)
    compute_worst_commands_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_worst_physics_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    compute_worst_publish_us: float = dataclasses.field(default=0.0, metadata=_shown('.1f'))
    watchdog: WatchdogState = WatchdogState.WAITING
    watchdog_policy: WatchdogPolicy = WatchdogPolicy.BRAKE
    # each timeout the brake policy answered by holding the joints, and the largest torque the
    # brake needed (each joint's is limited to brake_torque_limit_nm)
    brake_events: int = 0
    brake_torque_limit_nm: float = dataclasses.field(default=0.0, metadata=_shown('g'))
    brake_torque_max_nm: float = dataclasses.field(default=0.0, metadata=_shown('.3f'))
    scheduling: str = ''  # what the stepping thread obtained ('normal', a priority, ...)
    commands: int = 0
    commands_rejected: int = 0
    commands_clipped: int = 0
    # the periods beyond the robot's position and velocity limits ('' : none)
    limits: str = ''
    # all-zero commands that did not release the brakes (release_on)
    zero_commands_before_release: int = 0
    publish_failures: int = 0
    # realtime: periods whose state was left out on joint_states_topic (joint_states_gap)
    hardware_states_left_out: int = 0
    # lockstep only (None: not on the wire): periods published again unanswered, periods that
    # waited for the recorder, periods run braked before the release (release_after)
    lockstep_repeats: Optional[int] = None
    periods_waiting_for_recorder: Optional[int] = None
    braked_periods: Optional[int] = None
    sim_time: float = dataclasses.field(default=0.0, metadata=_shown('.6f'))
    # simulated over wall time since the first command (None: no command yet, '0' on the wire)
    real_time_factor: Optional[float] = dataclasses.field(default=None, metadata=_shown('.3f'))
    impacts: int = 0
    rhs_evaluations: int = 0
    steps: int = 0
    rejected_steps: int = 0
    events: int = 0

    def values(self) -> list[tuple[str, str]]:
        """The key-value pairs of the DiagnosticStatus, in this order."""
        out: list[tuple[str, str]] = []
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            spec = field.metadata.get('format', '')
            if value is None:
                if field.name == 'real_time_factor':
                    out.append((field.name, '0'))
                continue  # a lockstep value of a realtime simulator: not on the wire
            if isinstance(value, bool):
                text = str(value).lower()
            elif isinstance(value, tuple):
                text = ' '.join(format(t, spec) for t in value)
            else:
                text = format(value, spec)  # (a TextEnum formats as its text)
            out.append((field.name, text))
        return out

    @classmethod
    def parse(cls, values: Mapping[str, str]) -> SimulatorStatus:
        """The status from its key-values (a DiagnosticStatus's, as a dict); a key left out
        keeps its default. A key the status does not name, or a value that is not of its
        field's kind, raises ValueError naming the key."""
        kinds = {field.name: _SIMULATOR_KINDS[str(field.type)] for field in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, text in values.items():
            if key not in kinds:
                raise ValueError(f'simulator status {key} = {text!r}: not a key of the status')
            if key == 'real_time_factor' and text == '0':
                continue  # no command yet
            try:
                kwargs[key] = kinds[key](text)
            except ValueError:
                raise ValueError(f'simulator status {key} = {text!r}: not a valid value') from None
        return cls(**kwargs)


# how ``SimulatorStatus.parse`` reads a field of each declared type
_SIMULATOR_KINDS: dict[str, Callable[[str], Any]] = {
    'SimulatorMode': SimulatorMode,
    'WatchdogState': WatchdogState,
    'WatchdogPolicy': WatchdogPolicy,
    'float': float,
    'Optional[float]': float,
    'int': int,
    'Optional[int]': int,
    'str': str,
    'bool': _flag,
    'tuple[float, ...]': _times,
}
