"""Record an offline run (``impact-arm simulate --mcap FILE``) as a ROS 2 MCAP file.

``OfflineRecorder(path, scene)`` is an observer for ``simulate.run``: it writes, as the run goes,
the topics and types the live simulator publishes (docs/topics.md), so
``impact-arm analyze``, ``rosbags``, ``ros2 bag play`` and the replay node treat an offline file
like a live recording. Every time below is *simulated* time: header stamps, and also the MCAP
log and publish times (t = 0 at the start of the run), so time-ordered readers see the run in
order.

Topics
------
``/joint_states`` (sensor_msgs/msg/JointState), one per published sample (scene
``publish_rate``): names ``joint1`` … ``jointN``; position and velocity are the *relative*
encoder angles (joint1 = q1, joint_k = q_k − q_(k−1)) and their rates; effort = the joint
torques applied at that instant (T01, T12 …; zero while the actuators are off in contact).
An arm from a URDF names its moving joints as the URDF does (their values the robot's joint
angles), then every locked joint (``Scene.locked_joints``) at its value, velocity and effort
0, so that robot_state_publisher shows the whole robot.
Header stamp = sample time, frame_id ''. A ``sensors`` section in the scene makes these, and the
wrench below, what a real driver reports (``driver/sensors.py``: encoder counts, noise,
difference rates, latencies); the 3D view and the impact reports stay exact.

``/contact_wrench`` (geometry_msgs/msg/WrenchStamped), one per sample: force.x = tangential
(friction) force, force.y = normal force on the tip in the surface frame, both averaged over the
publish period that ends at the stamp (so the contact impulse is kept); torque = 0.
frame_id ``surface1``, the TF frame of the (first) surface: x tangential, y its outward normal
(world +z; contract.py, "Frames").

``/impact_report`` (std_msgs/msg/String), one per impact: ``data`` is the impact record as one
JSON object, the same fields and values as ``simulate --json`` (docs/outputs.md). Logged at the
separation time t_contact + duration.

``/impact_trace`` (std_msgs/msg/Float64MultiArray), one per impact, logged with its report:
every point the integrator computed inside that impact, at full resolution, as a row-major
matrix::

    layout.dim[0]: label 'row',  size = number of rows,    stride = rows × columns
    layout.dim[1]: label = the column names joined by ',', size = columns, stride = columns
    layout.data_offset = 0
    columns (two links): t,phase,delta,F_n,F_f,v_x,v_y,T1,T2

t [s]; phase 1 elastic, 2 elasto-plastic, 3 restitution; delta = penetration [m]; F_n normal and
F_f friction force [N]; v_x, v_y tip velocity [m/s]; T1 … TN link kinetic energies [J]. The k-th
trace belongs to the k-th report.

``/robot_description``, ``/tf_static`` (once, at t = 0), ``/tf`` and ``/impact_markers`` (at
``tf_rate`` of simulated time, on the joint-state samples, and at each impact's first contact,
maximum compression and separation): the arm in 3D, REP 103 frames (z up), see
io/scene_visuals.py; ``/impact_table`` at each impact's first contact (io/impact_table.py).
The event frames are written when the report comes, before the samples after the
separation, so the file stays in time order. /tf is tf2_msgs/msg/TFMessage with its
full definition and type hash even where the tf2_msgs package is absent.

Stored with the messages
------------------------
metadata ``impact_arm``: version, ros_distro, node ``offline``, mode ``offline``, control
(``continuous`` or ``sampled``), control_rate_hz, publish_rate_hz, preset, scene name;
metadata ``scene``: path and the YAML text; attachment ``<scene>.yaml`` (application/yaml): the
scene file as read, so the run can be reproduced from the recording alone; at ``close`` (when
given the run's result) metadata ``run``: the run summary, why it stopped, any error.

The file is flushed after every impact and at least every ``flush_interval`` seconds of wall
time, so a crashed or killed run keeps what was recorded before (the writer keeps the file a
complete MCAP after each flush).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import json
import math
import os

import numpy as np

from ..contract import (
    CONTACT_FORCE_PEAK,
    CONTACT_WRENCH,
    IMPACT_REPORT,
    IMPACT_TRACE,
    JOINT_STATE_TYPE,
    JOINT_STATES,
    SURFACE_MOUNTS,
    SURFACE_MOUNTS_QOS,
    TOPICS,
    TRACE_QOS,
    TRACE_TYPE,
    WRENCH_FRAME,
)
from ..driver.sensors import Sensors
from ..physics.scene import self_contained_text
from .msgdefs import typestore
from .scene_visuals import DEFAULT_TF_RATE, VisualsWriter, mounted_surfaces

if TYPE_CHECKING:
    from ..physics.impact import Impact
    from ..physics.simulate import RunResult, Sample

OFFLINE_TOPICS = {  # what an offline run records: the simulator's topics and the traces
    **{
        topic: TOPICS[topic][0]
        for topic in (JOINT_STATES, CONTACT_WRENCH, CONTACT_FORCE_PEAK, IMPACT_REPORT)
    },
    IMPACT_TRACE: TRACE_TYPE,
}


def trace_columns(n_links: int) -> list:
    """Column names of an /impact_trace row for an arm of ``n_links`` links."""
    return ['t', 'phase', 'delta', 'F_n', 'F_f', 'v_x', 'v_y'] + [
        f'T{i + 1}' for i in range(n_links)
    ]


def sim_time_ns(t: float) -> int:
    return int(round(t * 1e9))


class OfflineRecorder:
    """Observer of ``simulate.run`` writing the live system's topics to an MCAP file.

    ``control_rate`` / ``preset`` only describe the run in the file's metadata (None: the
    scene's). ``flush_interval``: seconds of wall time between automatic flushes."""

    def __init__(
        self,
        path,
        scene,
        *,
        control_rate=None,
        preset=None,
        flush_interval: float = 0.5,
        compression: str = 'zstd',
        tf_rate: float = DEFAULT_TF_RATE,
    ):
        from .mcap_ros2 import Ros2McapWriter, package_version, ros_distro

        self.path = os.fspath(path)
        self.scene = scene
        self.n = scene.n_links
        self._store = typestore()
        self._types = self._store.types
        # the moving joints, then every locked joint at its value (robot_state_publisher
        # shows the whole robot); the scene's rods have none
        self._names = list(scene.joint_names) + [name for name, _ in scene.locked_joints]
        self._locked = [float(value) for _, value in scene.locked_joints]
        self._locked_zeros = [0.0] * len(self._locked)
        self._columns = trace_columns(self.n)
        self._mount_frames = [frame for frame, _ in mounted_surfaces(scene)]
        self.topics = dict(OFFLINE_TOPICS)
        if self._mount_frames:  # the plates of mounted surfaces
            self.topics[SURFACE_MOUNTS] = JOINT_STATE_TYPE
        self.counts = {topic: 0 for topic in self.topics}
        self.writer = Ros2McapWriter(
            self.path, flush_interval=flush_interval, compression=compression
        )
        for topic, type_name in self.topics.items():
            # the contract's QoS for the contract topics; traces like the reports
            self.writer.add_topic(
                topic,
                type_name,
                TRACE_QOS
                if topic == IMPACT_TRACE
                else SURFACE_MOUNTS_QOS
                if topic == SURFACE_MOUNTS
                else None,
            )
        rate = scene.controller.rate if control_rate is None else float(control_rate)
        version = package_version()
        self.writer.add_metadata(
            'impact_arm',
            {
                'version': version,
                'ros_distro': ros_distro(),
                'node': 'offline',
                'mode': 'offline',
                'control': 'sampled' if rate else 'continuous',
                'control_rate_hz': repr(float(rate)),
                'publish_rate_hz': repr(scene.publish_rate),
                'preset': preset or scene.integrator.preset,
                'scene_name': scene.name,
                'time': 'simulated (log time = header stamp = sim time)',
                'trace_columns': ','.join(self._columns),
                'tf_rate_hz': repr(float(tf_rate)),
                'topics': json.dumps(list(self.topics)),
            },
        )
        text = self_contained_text(scene) or ''  # an arm's URDF inlined
        scene_file = (
            os.path.basename(scene.source_path) if scene.source_path else f'{scene.name}.yaml'
        )
        self.writer.add_metadata(
            'scene',
            {'path': os.path.abspath(scene.source_path) if scene.source_path else '', 'yaml': text},
        )
        self.writer.add_attachment(
            scene_file, text.encode('utf-8'), 'application/yaml', log_time_ns=0, create_time_ns=0
        )
        self.visuals = VisualsWriter(self.writer, scene, tf_rate)
        # the scene's sensors section: the joint states and wrench as a driver reports them
        self.sensors = (
            None if scene.sensors.ideal else Sensors(scene.sensors, scene.publish_rate, self.n)
        )
        self.coordinates = scene.joint_coordinates  # the robot's, on the wire
        self.writer.flush()
        self._closed = False

    # --- observer interface of simulate.run -----------------------------------------------
    def on_sample(self, sample: Sample) -> None:
        t_ns = sim_time_ns(sample.t)
        T = self._types
        coordinates = self.coordinates
        position, velocity = coordinates.positions(sample.q), coordinates.rates(sample.qd)
        effort, wrench = coordinates.efforts(sample.tau), tuple(sample.wrench)
        if self.sensors is not None:
            read = self.sensors.read(position, velocity, effort, wrench)
            position, velocity, effort, wrench = (
                read.position,
                read.velocity,
                read.effort,
                read.wrench,
            )
        js = T['sensor_msgs/msg/JointState'](
            header=self._header(t_ns, ''),
            name=self._names,
            position=np.array(list(position) + self._locked),
            velocity=np.array(list(velocity) + self._locked_zeros),
            effort=np.array(list(effort) + self._locked_zeros, dtype=np.float64),
        )
        self._write(JOINT_STATES, js, t_ns)
        Vector3 = T['geometry_msgs/msg/Vector3']
        ws = T['geometry_msgs/msg/WrenchStamped'](
            header=self._header(t_ns, WRENCH_FRAME),
            wrench=T['geometry_msgs/msg/Wrench'](
                force=Vector3(x=float(wrench[0]), y=float(wrench[1]), z=0.0),
                torque=Vector3(x=0.0, y=0.0, z=0.0),
            ),
        )
        self._write(CONTACT_WRENCH, ws, t_ns)
        peak = T['geometry_msgs/msg/WrenchStamped'](
            header=self._header(t_ns, WRENCH_FRAME),
            wrench=T['geometry_msgs/msg/Wrench'](
                force=Vector3(x=0.0, y=float(sample.force_peak), z=0.0),
                torque=Vector3(x=0.0, y=0.0, z=0.0),
            ),
        )
        self._write(CONTACT_FORCE_PEAK, peak, t_ns)
        if self._mount_frames:
            plates = sample.plates
            mounts = T['sensor_msgs/msg/JointState'](
                header=self._header(t_ns, ''),
                name=self._mount_frames,
                position=np.array(plates[0::2], dtype=np.float64),
                velocity=np.array(plates[1::2], dtype=np.float64),
                effort=np.zeros(0),
            )
            self._write(SURFACE_MOUNTS, mounts, t_ns)
            self.visuals.plates(t_ns, plates)
        self.visuals.state(t_ns, sample.q, sample.wrench)

    def on_impact(self, record: Impact, trace_rows: Sequence[Sequence[float]]) -> None:
        t_ns = sim_time_ns(record.t_contact + record.duration)
        self.visuals.impact(record)  # its frames are stamped from the contact on: first
        self._write(
            IMPACT_REPORT,
            self._types['std_msgs/msg/String'](data=json.dumps(record.to_dict())),
            t_ns,
        )
        self._write(IMPACT_TRACE, self.trace_message(trace_rows), t_ns)
        self.writer.flush()  # an impact is never lost, whatever happens later

    def trace_message(self, rows: Sequence[Sequence[float]]) -> Any:
        """Float64MultiArray holding ``rows`` row-major (layout in the module docstring)."""
        cols = len(self._columns)
        for row in rows:
            if len(row) != cols:
                raise ValueError(
                    f'trace row of {len(row)} values, expected {cols} ({",".join(self._columns)})'
                )
        T = self._types
        Dim = T['std_msgs/msg/MultiArrayDimension']
        return T['std_msgs/msg/Float64MultiArray'](
            layout=T['std_msgs/msg/MultiArrayLayout'](
                dim=[
                    Dim(label='row', size=len(rows), stride=len(rows) * cols),
                    Dim(label=','.join(self._columns), size=cols, stride=cols),
                ],
                data_offset=0,
            ),
            data=np.array(rows, dtype=np.float64).reshape(len(rows) * cols),
        )

    def _header(self, t_ns: int, frame_id: str):
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        T = self._types
        return T['std_msgs/msg/Header'](
            stamp=T['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame_id
        )

    def _write(self, topic: str, msg, t_ns: int):
        # rosbags' CDR (a dataclass per type): faster here than building rclpy messages for
        # msgdefs.serialize_cdr, and the same bytes
        self.writer.write(topic, self._store.serialize_cdr(msg, self.topics[topic]), t_ns, t_ns)
        self.counts[topic] += 1

    def close(self, result: RunResult | None = None) -> None:
        """Flush and close (idempotent). With the run's ``RunResult``, also store its summary
        (metadata ``run``) so the analysis can report how the run ended."""
        if self._closed:
            return
        try:
            self.visuals.finish()
            if result is not None:
                self.writer.add_metadata('run', run_metadata(result))
        finally:
            self._closed = True
            self.writer.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close()


def run_metadata(result: RunResult) -> dict[str, str]:
    """The string map stored as metadata ``run`` (values are JSON)."""
    summary = result.summary()

    def clean(v: Any) -> Any:
        return None if isinstance(v, float) and not math.isfinite(v) else v

    return {
        'summary': json.dumps(
            {k: clean(v) if not isinstance(v, list) else v for k, v in summary.items()}
        ),
        'stopped': result.stopped,
        'error': result.error or '',
    }
