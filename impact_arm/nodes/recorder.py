"""recorder: subscribes to topics as serialized data and writes a crash-safe ROS 2 MCAP file.

Parameters: output, topics, scene, param_nodes, flush_interval, tf_rate, log_time (see their
descriptions). Messages are stored as received (no deserialization): log time = the newest
/clock or /joint_states stamp (simulated time, one clock for the whole file; an
/impact_report is logged at its impact's separation; ``log_time: reception`` keeps the wall
clock), publish time = the publisher's source timestamp. The file
also holds the scene YAML (attachment and metadata), the parameters of ``param_nodes`` at
start and at shutdown, the package version and the samples lost on the way per topic (from
the writers' sequence numbers: ``contract.LOSSES_METADATA``, also on /diagnostics).

After each drain the recorder publishes on /recorder/progress the stamp up to which it has
written every per-period topic it records (``contract.PERIOD_TOPICS``) that has a publisher:
a lockstep simulator with ``recorder_window`` waits for it, and `impact-arm run` starts the
controller only once it has one (what a per-period topic sent before its writer matched the
recorder's reader was not for us, and its first stamp proves the match).

With a ``scene``, the file also shows the arm in 3D by itself (docs/topics.md): the recorder
derives /robot_description and /tf_static (once, at the start), /tf and /impact_markers (at
``tf_rate`` of the joint-state stamps) and /impact_table (at each impact) from the scene and the recorded /joint_states,
/contact_wrench and /impact_report, exactly as ``simulate --mcap`` does (io/scene_visuals.py).
It does not subscribe to those topics: /tf needs tf2_msgs, which PyPI does not provide, and a
derived stream does not depend on the simulator's tf settings.

The subscriptions live on a second node, ``_recorder_reader``, that no executor waits on: the
recording loop takes whatever has arrived every ``POLL_PERIOD``. One executor cycle per message
cost about as much CPU as the simulator's whole period; in lockstep that CPU is taken from the
loop being recorded. DDS keeps acknowledging in the background (reader history
``RECORDER_MIN_DEPTH``), so nothing waits for the poll.
"""

from __future__ import annotations

import functools
import heapq
import json
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NoReturn

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rcl_interfaces.srv import GetParameters, ListParameters
from rosbags.serde import SerdeError

from .. import contract
from ..contract import TOPICS, TopicQos
from ..io.mcap_ros2 import (
    RecordingError,
    Ros2McapWriter,
    message_class,
    package_version,
    ros_distro,
)
from ..io.msgdefs import typestore
from ..io.scene_visuals import VisualsWriter
from ..io.wire import MalformedMessage, header_stamp_ns, joint_state_fields, wrench_stamped_fields
from ..physics.errors import ImpactArmError
from ..physics.impact import Impact, impact_from_json
from ._runner import reader_node, run, take_raw
from .params import (
    NODE_OPTIONS,
    ParameterError,
    declare,
    refuse_unknown,
    scene_joint_names,
    validator,
)
from .param_types import RecorderParameters
from .recorder_params import PARAMS

if TYPE_CHECKING:
    from rclpy.client import Client
    from rclpy.executors import Executor
    from rclpy.task import Future
    from rclpy.subscription import MessageInfo, Subscription

POLL_PERIOD = 0.01  # s between two drains of the subscriptions
# reader history: absorbs bursts while a chunk is compressed/written, and a writer's whole
# repair after the recorder was descheduled (contract.WRITER_REPAIR_DEPTH)
RECORDER_MIN_DEPTH = contract.WRITER_REPAIR_DEPTH
MATCH_GRACE = 2.0  # s after the start: then name the topics no publisher is matched on yet
MATCHED_LINE = 'publishers matched on'  # the log lines `impact-arm run` waits for
FLOWING_LINE = 'first samples on'


def _string_reader() -> Callable[[bytes], Any]:
    """CDR of a std_msgs/msg/String -> the message, by rosbags; built here because its first
    use loads the type store and generates the reader (~1 s on a loaded machine), which the
    drain loop must not spend at the first impact."""
    store = typestore()
    read = functools.partial(store.deserialize_cdr, typename=contract.STRING_TYPE)
    read(store.serialize_cdr(store.types[contract.STRING_TYPE](data=''), contract.STRING_TYPE))
    return read


class Recorder(Node):
    def __init__(self) -> None:
        super().__init__('recorder', **NODE_OPTIONS)
        self._declare()
        self._configure()
        self._activate()

    # ------------------------------------------------------------------------ start-up
    def _declare(self) -> None:
        """The parameters as ``self.p``; ParameterError for a bad value or an unknown name."""
        self.p: RecorderParameters = declare(self, PARAMS, RecorderParameters)
        refuse_unknown(self, PARAMS)

    def _configure(self) -> None:
        """The MCAP file with the run's metadata (and scene), the topics to record and the
        3D view derived from the scene; nothing subscribed yet."""
        p = self.p
        self.output = p.output or f'runs/{time.strftime("%Y%m%d-%H%M%S")}.mcap'
        self.param_nodes = [n for n in p.param_nodes if n]
        self.by_stamps = p.log_time == 'stamps'
        self.now_ns = 0  # stamps: the newest /clock or /joint_states stamp
        scene, scene_text = self._read_scene()
        self._open_writer(scene, scene_text)
        self.failed = False
        self.received = 0
        self.losses = Losses()
        self.malformed = 0  # samples stored but not drawn (malformed payloads)
        self.wanted: dict[str, str] = {}  # topic -> type name ('' until discovered)
        for entry in p.topics:
            name, _, type_name = entry.partition(':')
            self.wanted[name] = type_name or TOPICS.get(name, ('',))[0]
        self.visuals: VisualsWriter | None = None
        # reads /impact_report: its log time (stamps) and its 3D event frames (a scene)
        self._read_string = _string_reader() if self.by_stamps or scene_text else None
        if scene_text is not None:
            self._configure_visuals(scene, scene_text)
        self._init_progress()

    def _read_scene(self) -> tuple[str, str | None]:
        """(path, text) of the ``scene`` parameter, an installed name resolved as the
        simulator resolves it, an arm from a URDF file made self-contained; ('', None)
        without a scene. ParameterError for a file that cannot be read."""
        scene = self.p.scene
        if not scene:
            return scene, None
        from ..physics.scene import resolve_scene_path

        scene = resolve_scene_path(scene)  # an installed scene name, as the simulator's
        try:
            with open(scene, encoding='utf-8') as f:
                scene_text = f.read()
        except OSError as e:
            raise ParameterError(
                f'parameter scene = {scene!r}: cannot read ({e.strerror})'
            ) from None
        from ..physics.scene import scene_from_text, self_contained_text

        # an arm from a URDF file: the file's text goes into the recording's scene
        return scene, self_contained_text(scene_from_text(scene_text, scene, path=scene))

    def _open_writer(self, scene: str, scene_text: str | None) -> None:
        """The MCAP file with the recording's metadata: package, node, topics, this node's
        parameters and the scene (attachment and metadata)."""
        try:
            self.writer = Ros2McapWriter(self.output, flush_interval=self.p.flush_interval)
        except RecordingError as e:
            raise RecordingError(f'output = {self.output!r}: {e}') from None
        self.writer.add_metadata(
            'impact_arm',
            {
                'version': package_version(),
                'ros_distro': ros_distro(),
                'node': 'recorder',
                'start_time_ns': str(time.time_ns()),
                'topics': json.dumps(self.p.topics),
            },
        )
        self.writer.add_metadata(
            'parameters/recorder',
            {
                name: json.dumps(self.output if name == 'output' else value.value)
                for name, value in self.get_parameters_by_prefix('').items()
            },
        )
        if scene_text is not None:
            self.writer.add_attachment(
                os.path.basename(scene), scene_text.encode(), 'application/yaml'
            )
            self.writer.add_metadata('scene', {'path': os.path.abspath(scene), 'yaml': scene_text})

    def _configure_visuals(self, scene: str, scene_text: str) -> None:
        """The 3D view of the scene, derived from the recorded topics: those the view derives
        itself are not subscribed to, the plates of mounted surfaces are."""
        from ..physics.scene import scene_from_text

        visuals = self.visuals = VisualsWriter(
            self.writer,
            scene_from_text(scene_text, scene),
            self.p.tf_rate,
            log_time_ns=0 if self.by_stamps else time.time_ns(),
        )
        if visuals.visuals.mounted and contract.SURFACE_MOUNTS not in self.wanted:
            # the scene's plates move its surfaces: their topic is recorded and drawn
            self.wanted[contract.SURFACE_MOUNTS] = contract.JOINT_STATE_TYPE
        derived = sorted(set(self.wanted) & set(contract.VISUAL_TOPICS))
        if derived:
            self.get_logger().info(f'not subscribing to {derived}: derived from the scene')
        for topic in derived:
            del self.wanted[topic]
        self._q: list[float] | None = None  # absolute link angles of the latest joint state
        self._joints = scene_joint_names(visuals.visuals.scene)
        self._coordinates = visuals.visuals.scene.joint_coordinates

    def _init_progress(self) -> None:
        """What is subscribed, matched, flowing, written and asked so far: nothing."""
        self.subs: dict[str, Subscription[Any]] = {}
        self.written_until: int | None = None  # ns: every per-period topic written up to here
        self.period_written: dict[str, int] = {}  # per-period topic -> newest stamp written
        self.announced: int | None = None  # ns: the newest published on RECORDER_PROGRESS
        self.matched: set[str] = set()  # topics whose subscription has matched a publisher
        self.flowing: set[str] = set()  # topics a sample has arrived on
        self.named_unmatched = False
        self.params: dict[str, str] = {}  # node -> 'start'/'end'; queries never block the recording

    def _activate(self) -> None:
        """Parameter changes refused, the progress publisher, the subscriptions, the
        flush, diagnostics, discovery and match timers, the parameter clients."""
        # every parameter is fixed at start-up: a change is refused, not silently ignored
        self.add_on_set_parameters_callback(validator(PARAMS, lambda values: None))
        # what has been written, for a lockstep simulator that waits for the recording
        self.progress = self.create_publisher(
            Time, contract.RECORDER_PROGRESS, contract.PROGRESS_QOS.to_rclpy()
        )
        self.reader = reader_node(self, 'reader')  # ignores launch's __node remap
        self._subscribe_known()
        self.create_timer(self.p.flush_interval, self._flush)
        self.pub_diag = self.create_publisher(
            DiagnosticArray, contract.DIAGNOSTICS, contract.qos(contract.DIAGNOSTICS).to_rclpy()
        )
        self.create_timer(1.0, self._publish_diagnostics)
        self.create_timer(0.5, self._discover)
        self.started = time.monotonic()
        self.match_timer = self.create_timer(0.05, self._check_matched)
        self.param_clients = self._parameter_clients()
        self.get_logger().info(
            f'subscribed to {len(self.wanted)} topics, writing '
            f'{self.output}; waiting for their publishers'
        )

    def _parameter_clients(self) -> dict[str, tuple[Client[Any, Any], Client[Any, Any]]]:
        """node -> (list, get) clients of the parameter services of each ``param_nodes``."""
        return {
            n: (
                self.create_client(ListParameters, f'{n}/list_parameters'),
                self.create_client(GetParameters, f'{n}/get_parameters'),
            )
            for n in self.param_nodes
        }

    @property
    def done(self) -> bool:
        return self.failed

    # ---------------------------------------------------------------- subscriptions
    def _subscribe_known(self) -> None:
        for topic, type_name in self.wanted.items():
            if type_name and topic not in self.subs:
                qos = contract.qos(topic, self._offered_default(topic)).to_rclpy(RECORDER_MIN_DEPTH)
                self.subs[topic] = self.reader.create_subscription(
                    message_class(type_name), topic, _never_called, qos, raw=True
                )

    def _check_matched(self) -> None:
        """Say "recording" only once a publisher is matched on every topic: a subscription
        in the graph is not yet a matched reader, and what is published before the match is
        lost (1-2.4 s at the start of a run). After MATCH_GRACE, name the topics still
        without one; each newly matched topic is logged (`impact-arm run` waits for those of
        the simulator before the first command)."""
        now = {t for t, sub in self.subs.items() if sub.get_publisher_count() > 0}
        new = sorted(now - self.matched)
        self.matched |= now
        if new:
            self.get_logger().info(f'{MATCHED_LINE} {" ".join(new)}')
        missing = sorted(set(self.wanted) - self.matched)
        if not missing:
            self.get_logger().info(
                f'recording {len(self.wanted)} topics to {self.output}: every topic has a publisher'
            )
            self.destroy_timer(self.match_timer)
        elif not self.named_unmatched and time.monotonic() - self.started >= MATCH_GRACE:
            self.named_unmatched = True
            self.get_logger().warning(
                f'recording to {self.output}; no publisher yet on {" ".join(missing)}'
            )

    def _offered_default(self, topic: str) -> TopicQos:
        """For a topic outside the contract: a QoS every current publisher is compatible with."""
        offers = [
            TopicQos.from_rclpy(i.qos_profile) for i in self.get_publishers_info_by_topic(topic)
        ]
        reliable = offers and all(q.reliability == 'reliable' for q in offers)
        durable = offers and all(q.durability == 'transient_local' for q in offers)
        return TopicQos(
            reliability='reliable' if reliable else 'best_effort',
            durability='transient_local' if durable else 'volatile',
        )

    def _discover(self) -> None:
        """Find the types of topics given without one, once someone publishes them."""
        missing = [t for t, ty in self.wanted.items() if not ty]
        if missing:
            graph = dict(self.get_topic_names_and_types())
            for topic in missing:
                if graph.get(topic):
                    self.wanted[topic] = graph[topic][0]
            self._subscribe_known()
        self._query_parameters('start')

    def spin(self, executor: Executor, should_stop: Callable[[], bool]) -> None:
        """Timers and parameter replies through the executor, messages by polling."""
        while not should_stop() and not self.failed:
            executor.spin_once(timeout_sec=POLL_PERIOD)
            self._drain()

    def _drain(self) -> None:
        """Take every queued message of every topic; write them in order of reception, each
        topic's messages strictly in the order they were taken."""
        per_topic = []
        for topic, sub in list(self.subs.items()):
            taken = []
            while (message := take_raw(sub)) is not None:
                data, info = message
                self.losses.count(topic, info)
                received = info.get('received_timestamp') or time.time_ns()
                taken.append((received, topic, data, info.get('source_timestamp') or received))
            per_topic.append(taken)
            if taken and topic not in self.flowing:
                # matched is not yet flowing: the writer may match our reader later than we
                # match it, and what it sends before that is not for us
                self.flowing.add(topic)
                self.get_logger().info(f'{FLOWING_LINE} {topic}')
        for received, topic, data, published in heapq.merge(*per_topic, key=lambda m: m[0]):
            if self.failed:
                break
            self._store(topic, data, received, published)
        written = self.written_until = self._written_every_period_topic()
        if written is not None and written != self.announced and not self.failed:
            self.announced = written
            sec, nanosec = divmod(written, 1_000_000_000)
            self.progress.publish(Time(sec=sec, nanosec=nanosec))

    def _written_every_period_topic(self) -> int | None:
        """The newest stamp [ns] every recorded per-period topic has been written up to;
        None while one that has a publisher in the graph has no sample written yet (a topic
        nobody publishes, a scene's plates when it has none, is not waited for)."""
        unwritten = [
            t for t in contract.PERIOD_TOPICS if t in self.subs and t not in self.period_written
        ]
        # asks the graph only until each topic has its first sample
        if any(self.count_publishers(t) > 0 for t in unwritten):
            return None
        return min(self.period_written.values(), default=None)

    @staticmethod
    def _stamp(topic: str, data: bytes) -> int | None:
        """The stamp [ns] of a sample of a per-period topic or /clock (each begins with a
        builtin_interfaces/Time, in its header or as itself), None for other topics and for
        one that is no time."""
        if topic not in contract.PERIOD_TOPICS and topic != contract.CLOCK:
            return None
        try:
            stamp = header_stamp_ns(data)
        except MalformedMessage:
            return None
        return stamp if 0 <= stamp < 1 << 63 else None  # a hostile peer's negative stamp

    def _report(self, data: bytes) -> Impact | None:
        """The impact record in an /impact_report sample (read once, here), None for one
        that is not (or when neither the log time nor the 3D view needs it: no reader was
        built)."""
        if self._read_string is None:
            return None
        try:
            return impact_from_json(self._read_string(data).data)
        except (SerdeError, ImpactArmError) as e:
            self.get_logger().warning(f'impact report not read: {e}')
            return None

    @staticmethod
    def _separation_ns(record: Impact) -> int | None:
        """Simulated time [ns] an impact record ends (its separation), None if a record
        from the wire has no number there."""
        try:
            t = float(record.t_contact) + float(record.duration)
        except (TypeError, ValueError):
            return None
        return round(t * 1e9) if 0.0 <= t < 9e9 else None

    def _store(self, topic: str, data: bytes, received: int, published: int) -> None:
        try:
            stamp = self._stamp(topic, data)
            record = self._report(data) if topic == contract.IMPACT_REPORT else None
            if self.by_stamps:
                # simulated time, one clock for the whole file: a viewer plays it at 1x
                # and its index is in stamp order
                if stamp is not None and topic in (contract.JOINT_STATES, contract.CLOCK):
                    self.now_ns = stamp
                received = self.now_ns
                # a report is logged when its impact ended, as offline files log it: a
                # recorder that was descheduled receives it only after the states that
                # followed it, and the newest stamp would then log it late, even after
                # the next impact's report
                ended = None if record is None else self._separation_ns(record)
                received = received if ended is None else ended
            if not self.writer.has_topic(topic):
                # Like rosbag2: store the QoS the publishers actually offer, else the contract's.
                pubs = self.get_publishers_info_by_topic(topic)
                offered = [TopicQos.from_rclpy(p.qos_profile) for p in pubs] or None
                thash = str(pubs[0].topic_type_hash) if pubs else None
                self.writer.add_topic(
                    topic,
                    self.wanted[topic],
                    offered,
                    None if thash in (None, 'INVALID') else thash,
                )
            self.writer.write(topic, data, received, published)
            self.received += 1
            if stamp is not None and topic in contract.PERIOD_TOPICS:
                self.period_written[topic] = stamp
            if self.visuals is not None:
                self._derive_visuals(self.visuals, topic, data, received, record)
        except RecordingError as e:
            self._fail(e)
        except MalformedMessage as e:
            # stored as it came (a recording keeps what was on the wire), not drawn
            self.malformed += 1
            self.get_logger().warning(
                f'{topic}: malformed sample not drawn ({e}); {self.malformed} so far',
                throttle_duration_sec=2.0,
            )

    def _derive_visuals(
        self,
        visuals: VisualsWriter,
        topic: str,
        data: bytes,
        received: int,
        record: Impact | None = None,
    ) -> None:
        """Feed the recorded state to the visuals; a wrench may arrive before or after the
        joint state of its period, so it is drawn at the latest known arm pose."""
        if topic == contract.CONTACT_WRENCH:
            if self._q is not None:
                visuals.force(self._q, wrench_stamped_fields(data)[2][:2])
        elif topic == contract.JOINT_STATES:
            sec, nanosec, names, position, _ = joint_state_fields(data)
            by_name = dict(zip(names, position))
            try:
                self._q = self._coordinates.absolute([by_name[j] for j in self._joints])
            except KeyError:
                return  # not this scene's joints: nothing to draw
            visuals.state(sec * 1_000_000_000 + nanosec, self._q, (0.0, 0.0), received)
        elif topic == contract.SURFACE_MOUNTS:
            # the mounted surfaces' frames, drawn from their own samples and stamps
            sec, nanosec, _, position, velocity = joint_state_fields(data)
            plates = [v for pair in zip(position, velocity) for v in pair]
            visuals.plates(sec * 1_000_000_000 + nanosec, plates, received)
        elif topic == contract.IMPACT_REPORT and record is not None:
            try:
                visuals.impact(record)
            except (ValueError, KeyError, TypeError) as e:
                self.get_logger().warning(f'impact report not drawn: {e}')

    def _publish_diagnostics(self) -> None:
        lost = self.losses.lost_total()
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if lost else DiagnosticStatus.OK,
            name=contract.RECORDER_STATUS,
            hardware_id='impact_arm_recorder',
            message=f'{lost} samples lost' if lost else 'recording, nothing lost',
            values=[KeyValue(key=k, value=v) for k, v in self.losses.as_metadata().items()]
            + [KeyValue(key='messages_written', value=str(self.received))],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def _flush(self) -> None:
        try:
            if self.losses.changed:  # (the diagnostics read it too: only the file resets it)
                self.writer.add_metadata(contract.LOSSES_METADATA, self.losses.as_metadata())
                self.losses.changed = False
            self.writer.flush()
        except RecordingError as e:
            self._fail(e)

    def _fail(self, err: Exception) -> None:
        if not self.failed:
            self.get_logger().error(f'recording stopped: {err}')
        self.failed = True
        for sub in self.subs.values():
            self.reader.destroy_subscription(sub)
        self.subs.clear()

    # ------------------------------------------------------------------- parameters
    def _query_parameters(self, phase: str) -> None:
        """Ask each param node (list, then get) without waiting; results become metadata."""
        for name, (list_cli, get_cli) in self.param_clients.items():
            if (
                self.params.get(name) in (phase, phase + ' asked')
                or not list_cli.service_is_ready()
                or not get_cli.service_is_ready()
            ):
                continue
            self.params[name] = phase + ' asked'
            future = list_cli.call_async(ListParameters.Request())
            future.add_done_callback(functools.partial(self._on_list, name, phase))

    def _on_list(self, name: str, phase: str, future: Future[Any]) -> None:
        listed = future.result()
        names = list(listed.result.names) if listed else []
        future = self.param_clients[name][1].call_async(GetParameters.Request(names=names))
        future.add_done_callback(functools.partial(self._on_get, name, phase, names))

    def _on_get(self, name: str, phase: str, names: list[str], future: Future[Any]) -> None:
        from rclpy.parameter import parameter_value_to_python

        answer = future.result()
        if answer is None or self.failed:
            return
        values = {
            n: json.dumps(parameter_value_to_python(v), default=str)
            for n, v in zip(names, answer.values)
        }
        self.writer.add_metadata(f'parameters/{name}/{phase}', values)
        self.params[name] = phase

    def finish(self, executor: Executor | None) -> int:
        """Final parameter query (≤ 1 s, recording continues meanwhile), then close."""
        if executor is not None and not self.failed:
            self._query_parameters('end')
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline and any(
                s == 'end asked' for s in self.params.values()
            ):
                executor.spin_once(timeout_sec=POLL_PERIOD)
                self._drain()
        if not self.failed:
            self._drain()
        try:
            if self.visuals is not None and not self.failed:
                self.visuals.finish()
            if not self.failed:
                self.writer.add_metadata(contract.LOSSES_METADATA, self.losses.as_metadata())
            self.writer.close()
        except RecordingError as e:
            self._fail(e)
        lost = self.losses.lost_total()
        if lost:
            self.get_logger().warning(f'lost on the way: {self.losses.describe()}')
        self.get_logger().info(
            f'{self.writer.message_count} messages in {self.output}'
            if not self.failed
            else f'recording failed; {self.output} holds the data flushed before the error'
        )
        return 1 if self.failed else 0

    def destroy_node(self) -> None:
        if getattr(self, 'reader', None) is not None:  # absent if the output was refused
            self.reader.destroy_node()
        super().destroy_node()


class Losses:
    """Samples that never reached the recorder, per topic, from each writer's publication
    sequence numbers (every rmw since Iron reports them; a gap is what a reliable writer's
    history no longer held, or a best-effort sample dropped). ``before_first`` counts what a
    writer published before its first sample reached us (before the match). Like rosbag2's
    lost-message events, but exact and independent of the middleware's event support."""

    def __init__(self) -> None:
        self.last: dict[tuple[str, bytes], int] = {}  # (topic, writer gid) -> last sequence number
        self.lost: dict[str, int] = {}  # topic -> samples missing between two received
        self.before_first: dict[str, int] = {}  # topic -> samples published before the first
        self.changed = False

    def count(self, topic: str, info: MessageInfo) -> None:
        seq = info.get('publication_sequence_number')
        gid = (info.get('publisher_gid') or {}).get('data')
        if not seq or gid is None:
            return  # an rmw that does not say: nothing to count
        key = (topic, bytes(gid))
        last = self.last.get(key)
        if last is None:
            self.before_first[topic] = self.before_first.get(topic, 0) + seq - 1
            self.lost.setdefault(topic, 0)  # a counted topic says 0, not nothing
        elif seq > last + 1:
            self.lost[topic] = self.lost.get(topic, 0) + seq - last - 1
            self.changed = True
        self.last[key] = seq if last is None else max(seq, last)

    def lost_total(self) -> int:
        return sum(self.lost.values())

    def as_metadata(self) -> dict[str, str]:
        out = {f'lost:{t}': str(n) for t, n in sorted(self.lost.items())}
        out.update({f'before_first:{t}': str(n) for t, n in sorted(self.before_first.items())})
        return out

    def describe(self) -> str:
        return ', '.join(f'{t} {n}' for t, n in sorted(self.lost.items()) if n)


def _never_called(msg: bytes) -> None:
    """Subscriptions of the reader node are drained by ``Recorder._drain``."""


def main(args: list[str] | None = None) -> NoReturn:
    raise SystemExit(run(Recorder, args))


if __name__ == '__main__':
    main()
