"""What a 3D viewer needs to show the arm: robot description, TF and impact markers.

``SceneVisuals(scene, tf_rate)`` turns the arm's state into the messages of design.md §8–9;
the offline recorder, the recorder node and the simulator node all use it, so a live system and
every recording show the same thing:

=====================  =================================  =====================================
topic                  type                               content
=====================  =================================  =====================================
/robot_description     std_msgs/msg/String                the scene's URDF (io/urdf.py), once
/tf_static             tf2_msgs/msg/TFMessage             tip on the last link, surfaces, once
/tf                    tf2_msgs/msg/TFMessage             the joint transforms, at ``tf_rate``
/impact_markers        visualization_msgs/msg/MarkerArray surfaces, contact-force arrow, impact
                                                          points; with each /tf message
=====================  =================================  =====================================

Each MarkerArray carries the whole picture (every surface, the arrow or its deletion, every
impact point so far), so a viewer that jumps to any time shows it right from one message.
The arrow shows the strongest period-averaged contact force (the /contact_wrench value) seen
since the previous MarkerArray, so a contact shorter than the marker period is never missed;
its length grows with the force towards the arm's reach (half of it at ``ARROW_HALF_FORCE``),
because impact forces span several decades.
"""
from __future__ import annotations

import json
import math

from ..contract import IMPACT_MARKERS, ROBOT_DESCRIPTION, TF, TF_STATIC, TF_TYPE, VISUAL_TOPICS
from .msgdefs import append_cdr, sequence_cdr_prefix, serialize_cdr
from .urdf import (SURFACE_THICKNESS_PER_REACH, WORLD, moving_transforms, robot_description,
                   static_transforms, surface_frames)

DEFAULT_TF_RATE = 100.0  # Hz: smooth to the eye, a tenth of the joint-state rate
ARROW_HALF_FORCE = 1000.0  # N at which the arrow is half the reach long


def tip_position(lengths, q) -> tuple:
    """(x, y) of the tip centre B for absolute link angles ``q`` (the model's kinematics)."""
    return (math.fsum(L * math.cos(a) for L, a in zip(lengths, q)),
            math.fsum(L * math.sin(a) for L, a in zip(lengths, q)))


def arrow_length(force: float, reach: float) -> float:
    """Length [m] drawn for a contact force [N]: half the reach at ``ARROW_HALF_FORCE``,
    approaching the reach for far larger forces."""
    return reach * force / (force + ARROW_HALF_FORCE)


def _stamp(header, t_ns: int):
    header.stamp.sec, header.stamp.nanosec = divmod(int(t_ns), 1_000_000_000)


class SceneVisuals:
    """Builds the visual messages of one scene; ``due`` paces /tf and the markers."""

    def __init__(self, scene, tf_rate: float = DEFAULT_TF_RATE):
        from .msgdefs import message_class
        if not (math.isfinite(tf_rate) and tf_rate > 0):
            raise ValueError(f'tf_rate = {tf_rate!r}: must be > 0 Hz')
        self.scene = scene
        self.tf_rate = float(tf_rate)
        self._TF = message_class(TF_TYPE)   # the stand-in where tf2_msgs is missing
        from geometry_msgs.msg import Point, TransformStamped
        from std_msgs.msg import String
        from visualization_msgs.msg import Marker
        self._TransformStamped, self._String, self._Point = TransformStamped, String, Point
        self._Marker = Marker
        self.reach = math.fsum(scene.lengths)
        self._next_tf = 0           # index k of the next /tf time k / tf_rate
        self._strongest = None      # (|F|, q, (F_t, F_n)) since the last markers
        self.impact_points = []     # (x, y) where each impact touched the surface
        self._fixed_markers = []   # surfaces, then impact points, as drawn so far
        self._drawn_points = 0
        self._prefix = None        # their CDR, the start of every MarkerArray

    # ------------------------------------------------------------------ once per run
    def description(self):
        return self._String(data=robot_description(self.scene))

    def tf_static(self, t_ns: int = 0):
        return self._TF(transforms=[self._transform(t, t_ns)
                                    for t in static_transforms(self.scene)])

    # ------------------------------------------------------------------ per state
    def due(self, t: float) -> bool:
        """True once per 1 / tf_rate of simulated time (at the first ``t`` reaching it)."""
        if t * self.tf_rate < self._next_tf * (1 - 1e-12) - 1e-9:
            return False
        self._next_tf = math.floor(t * self.tf_rate * (1 + 1e-12) + 1e-9) + 1
        return True

    def tf(self, q, t_ns: int):
        """The joint transforms for absolute link angles ``q``."""
        return self._TF(transforms=[self._transform(t, t_ns)
                                    for t in moving_transforms(self.scene.lengths, q)])

    def observe_force(self, q, wrench):
        """Keep the strongest contact force until the next ``markers`` call."""
        magnitude = math.hypot(wrench[0], wrench[1])
        if magnitude > 0 and (self._strongest is None or magnitude > self._strongest[0]):
            self._strongest = (magnitude, tuple(q), (float(wrench[0]), float(wrench[1])))

    def add_impact(self, record):
        """An impact report (the JSON record): where B touched the surface becomes a
        marker."""
        if isinstance(record, (str, bytes)):
            record = json.loads(record)
        # the model's contact begins when the tip centre B reaches the surface plane
        self.impact_points.append(tip_position(self.scene.lengths, [
            math.radians(a) for a in record['q_contact_deg']]))

    def markers(self, t_ns: int) -> bytes:
        """The serialized MarkerArray at ``t_ns``: surfaces, impact points, then the arrow.
        Surfaces and impact points sit in fixed frames, so their markers are built and
        serialized once (stamp 0: the latest transform) and only the arrow is added: building
        and serializing every marker each time took 0.7 + 2.9 ms with 15 impacts, at tf_rate
        in the simulator and the recorder."""
        M = self._Marker
        if self._prefix is None:
            thickness = SURFACE_THICKNESS_PER_REACH * self.reach
            for i, frame in enumerate(surface_frames(self.scene)):
                m = self._marker('surface', i, M.CUBE, frame, 0, (0.6, 0.6, 0.6, 0.5))
                m.pose.position.y = -thickness / 2
                m.scale.x, m.scale.y, m.scale.z = 2 * self.reach, thickness, self.reach / 2
                self._fixed_markers.append(m)
        if self._prefix is None or self._drawn_points < len(self.impact_points):
            for k in range(self._drawn_points, len(self.impact_points)):
                x, y = self.impact_points[k]
                m = self._marker('impact_points', k, M.SPHERE, WORLD, 0, (1.0, 0.8, 0.0, 1.0))
                m.pose.position.x, m.pose.position.y = x, y
                m.scale.x = m.scale.y = m.scale.z = 0.02 * self.reach
                self._fixed_markers.append(m)
            self._drawn_points = len(self.impact_points)
            self._prefix = sequence_cdr_prefix(self._fixed_markers, len(self._fixed_markers) + 1)
        arrow = self._marker('contact_force', 0, M.ARROW, WORLD, t_ns, (1.0, 0.2, 0.1, 1.0))
        if self._strongest is None:
            arrow.action = M.DELETE
        else:
            magnitude, q, (f_t, f_n) = self._strongest
            x, y = tip_position(self.scene.lengths, q)   # the force acts on the tip B
            length = arrow_length(magnitude, self.reach)
            arrow.points = [self._Point(x=x, y=y),
                            self._Point(x=x + length * f_t / magnitude,
                                        y=y + length * f_n / magnitude)]
            arrow.scale.x, arrow.scale.y = 0.01 * self.reach, 0.02 * self.reach  # shaft, head
        self._strongest = None
        return append_cdr(self._prefix, arrow)

    # ------------------------------------------------------------------ helpers
    def _transform(self, t, t_ns):
        msg = self._TransformStamped()
        _stamp(msg.header, t_ns)
        msg.header.frame_id, msg.child_frame_id = t.parent, t.child
        msg.transform.translation.x, msg.transform.translation.y = t.x, t.y
        r = msg.transform.rotation
        r.x, r.y, r.z, r.w = t.quaternion()
        return msg

    def _marker(self, ns, marker_id, kind, frame, t_ns, rgba):
        m = self._Marker()
        _stamp(m.header, t_ns)
        m.header.frame_id, m.ns, m.id, m.type, m.action = frame, ns, marker_id, kind, \
            self._Marker.ADD
        m.pose.orientation.w = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = rgba
        return m


class VisualsWriter:
    """Adds the visual topics to an MCAP writer from the recorded state: the offline recorder
    and the recorder node feed it what they write, it writes /robot_description and
    /tf_static first, then /tf and /impact_markers at ``tf_rate`` of the state's stamps."""

    def __init__(self, writer, scene, tf_rate: float = DEFAULT_TF_RATE,
                 log_time_ns: int = 0):
        self.visuals = SceneVisuals(scene, tf_rate)
        self.writer = writer
        self.counts = {topic: 0 for topic in VISUAL_TOPICS}
        for topic, (type_name, qos) in VISUAL_TOPICS.items():
            writer.add_topic(topic, type_name, qos)
        self._write(ROBOT_DESCRIPTION, self.visuals.description(), log_time_ns)
        self._write(TF_STATIC, self.visuals.tf_static(0), log_time_ns)
        self._last = None                # (stamp, q, log time) of the latest state
        self._shown = None               # stamp of the latest /tf written

    def state(self, t_ns: int, q, wrench, log_time_ns: int = None):
        """One joint state (absolute angles ``q``) and its contact wrench (F_t, F_n)."""
        v = self.visuals
        v.observe_force(q, wrench)
        log = t_ns if log_time_ns is None else log_time_ns
        self._last = (t_ns, q, log)
        if v.due(t_ns * 1e-9):
            self._frame(t_ns, q, log)

    def finish(self):
        """The last state, if /tf has not shown it yet: the file ends on the final pose and
        every impact point (the last report comes after the last paced frame)."""
        if self._last is not None and self._last[0] != self._shown:
            self._frame(*self._last)

    def _frame(self, t_ns, q, log):
        self._write(TF, self.visuals.tf(q, t_ns), log)
        self._write(IMPACT_MARKERS, self.visuals.markers(t_ns), log)
        self._shown = t_ns

    def force(self, q, wrench):
        """A contact wrench (F_t, F_n) that arrived apart from its joint state."""
        self.visuals.observe_force(q, wrench)

    def impact(self, record):
        self.visuals.add_impact(record)

    def _write(self, topic, msg, log_time_ns):
        """``msg``: a message, or its CDR bytes."""
        data = msg if isinstance(msg, bytes) else serialize_cdr(msg)
        self.writer.write(topic, data, log_time_ns, log_time_ns)
        self.counts[topic] += 1

