"""The simulator's per-period output: /contact_wrench, /joint_states (and the topic
hardware's joint states while someone listens there), /clock, /impact_report and the 3D view,
from pre-serialized messages whose bytes each period only patches with its numbers."""

from __future__ import annotations

import collections
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from geometry_msgs.msg import WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from .. import contract
from ..contract import CLOCK, CONTACT_FORCE_PEAK, CONTACT_WRENCH, IMPACT_REPORT, JOINT_STATES
from ..driver.state_gaps import REBOUND_QUIET_S, StateGaps
from ..io.scene_visuals import mounted_surfaces
from ..io.wire import PatchedMessage
from ._visuals import VisualsPublisher

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile

    from ..driver.arm import Tick
    from ..physics.scene import Scene
    from .param_types import SimulatorParameters


class PeriodPublishers:
    """``publish(tick)`` a period's sensor messages, ``report(tick)`` its impacts.
    ``failures`` counts the samples the middleware refused."""

    def __init__(
        self,
        node: Node,
        scene: Scene,
        joint_names: Sequence[str],
        p: SimulatorParameters,
        lockstep: bool,
    ) -> None:
        def qos(topic: str, depth: int = 1) -> QoSProfile:
            return contract.qos(topic).to_rclpy(depth)

        self.log = node.get_logger()
        # lockstep: enough history on the per-period streams to repair a starved recorder
        depth = contract.WRITER_REPAIR_DEPTH if lockstep else 1
        make = node.create_publisher
        self.joints = make(JointState, JOINT_STATES, qos(JOINT_STATES, depth))
        self.wrench = make(WrenchStamped, CONTACT_WRENCH, qos(CONTACT_WRENCH, depth))
        self.peak = make(WrenchStamped, CONTACT_FORCE_PEAK, qos(CONTACT_FORCE_PEAK, depth))
        self.impact = make(String, IMPACT_REPORT, qos(IMPACT_REPORT))
        self.clock = make(Clock, CLOCK, qos(CLOCK)) if lockstep or p.rate_factor != 1.0 else None
        self.hw_states = make(JointState, p.joint_states_topic, qos(JOINT_STATES, depth))
        # someone listens there (updated at tf_rate; every _visuals.LISTENER_CHECK s while
        # nobody listens to the 3D view)
        self.hw_states_wanted = False
        # realtime: one period's hardware state in ``joint_states_gap`` left out, none in
        # contact and its rebound; lockstep: none (a stack the simulator paces waits for each)
        self.hw_gaps = StateGaps(
            0 if lockstep else p.joint_states_gap, round(REBOUND_QUIET_S * p.publish_rate)
        )
        zeros = [0.0] * len(joint_names)
        fields = ('position', 'velocity', 'effort')
        self.hw_joints = PatchedMessage(
            JointState(name=joint_names, position=zeros, velocity=zeros, effort=zeros), fields
        )
        # /joint_states: the moving joints, then every locked joint at its value (velocity
        # and effort 0), so that robot_state_publisher shows the whole robot; the topic
        # hardware gets the joints its <ros2_control> block names: the moving ones
        locked = [name for name, _ in scene.locked_joints]
        self.wire_joints = self.hw_joints
        # the locked joints' positions and zeros, appended to each period's /joint_states
        self._locked_tails: tuple[list[float], list[float]] | None = None
        if locked:
            names, all_zeros = list(joint_names) + locked, [0.0] * (len(joint_names) + len(locked))
            self.wire_joints = PatchedMessage(
                JointState(name=names, position=all_zeros, velocity=all_zeros, effort=all_zeros),
                fields,
            )
            self._locked_tails = (
                [float(value) for _, value in scene.locked_joints],
                [0.0] * len(locked),
            )
        wrench = WrenchStamped()
        wrench.header.frame_id = p.frame_id
        self.wire_wrench = PatchedMessage(wrench, ('wrench.force.x', 'wrench.force.y'))
        peak = WrenchStamped()  # force.y only: the rest stays 0
        peak.header.frame_id = p.frame_id
        self.wire_peak = PatchedMessage(peak, ('wrench.force.y',))
        self.wire_clock = PatchedMessage(Clock(), (), stamp='clock')
        # a scene with mounted surfaces: their plates' z, ż each period (contract.SURFACE_MOUNTS)
        self.mounts = None
        frames = [frame for frame, _ in mounted_surfaces(scene)]
        if frames:
            self.mounts = make(
                JointState, contract.SURFACE_MOUNTS, contract.SURFACE_MOUNTS_QOS.to_rclpy(depth)
            )
            # serialized once, its floats and stamp patched each period as /joint_states'
            # (a message built and converted by rclpy each period cost the loop ~10 % more)
            plate_zeros = [0.0] * len(frames)
            self.wire_mounts = PatchedMessage(
                JointState(name=frames, position=plate_zeros, velocity=plate_zeros),
                ('position', 'velocity'),
            )
        self.visuals = VisualsPublisher(
            node,
            scene,
            p.tf_rate,
            p.publish_tf,
            on_timer=self._check_hw_listeners,
            rod_radius=p.rod_radius,
        )
        self.failures = 0
        # publisher -> samples published (loss accounting); keyed by the publisher, not its
        # topic_name, which asks rcl under the handle's lock on every call
        self.sent: collections.Counter[Publisher[Any]] = collections.Counter()

    def publish(self, tick: Tick) -> None:
        # the controller waits for this period's wrench and joint state: /clock after them
        sec, nsec = divmod(round(tick.t * 1e9), 1_000_000_000)
        self._send(self.wrench, self.wire_wrench.fill(tick.wrench, (sec, nsec)))
        self._send(self.peak, self.wire_peak.fill((tick.force_peak,), (sec, nsec)))
        if self._locked_tails is not None:
            values, zeros = self._locked_tails
            states = self.wire_joints.fill(
                [*tick.position, *values, *tick.velocity, *zeros, *tick.effort, *zeros], (sec, nsec)
            )
        else:
            states = self.wire_joints.fill(tick.position + tick.velocity + tick.effort, (sec, nsec))
        if self.mounts is not None:
            plates = tick.plates
            self._send(self.mounts, self.wire_mounts.fill(plates[0::2] + plates[1::2], (sec, nsec)))
        self._send(self.joints, states)
        if self.hw_states_wanted and not self.hw_gaps.leave_out(tick.force_peak > 0.0):
            if self.hw_joints is not self.wire_joints:
                hw = self.hw_joints.fill(tick.position + tick.velocity + tick.effort, (sec, nsec))
            else:
                hw = states
            self._send(self.hw_states, hw)
        self.visuals.observe(tick)
        if self.clock is not None:
            self._send(self.clock, self.wire_clock.fill((), (sec, nsec)))

    def report(self, tick: Tick) -> None:
        """Impact reports once the period's sensor messages are out: their JSON takes
        40-200 us, which in the impact's own period made it the slowest of a run."""
        for record, _rows in tick.impacts:
            self._send(self.impact, String(data=json.dumps(record.to_dict())))
        self.visuals.add_impacts(tick)

    def _send(self, publisher: Publisher[Any], data: Any) -> None:
        """A sample the middleware refuses (Fast DDS, when its readers lag too far for too
        long; seen at 5 kHz on two cores) is lost like a dropped packet: counted, logged,
        and the periods go on (it used to end the stepping thread)."""
        try:
            publisher.publish(data)
            self.sent[publisher] += 1
        except RuntimeError as exc:  # rclpy's RCLError: the write failed
            self.failures += 1
            self.log.warning(
                f'{publisher.topic_name}: sample not published ({exc}); '
                f'{self.failures} lost so far',
                throttle_duration_sec=1.0,
            )

    def sent_text(self) -> str:
        """What was published, per topic: what the recorder's loss count is checked against."""
        counts = sorted((p.topic_name, n) for p, n in self.sent.items())
        return 'samples sent: ' + ', '.join(f'{t} {n}' for t, n in counts)

    def _check_hw_listeners(self) -> None:
        # asking DDS for the subscription count costs ~3 us: with the 3D view's timer, not
        # each period
        self.hw_states_wanted = self.hw_states.get_subscription_count() > 0
