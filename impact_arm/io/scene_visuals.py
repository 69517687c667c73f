"""What a 3D viewer needs to show the arm: robot description, TF and impact markers.

``SceneVisuals(scene, tf_rate)`` turns the arm's state into the visual messages; the offline
recorder, the recorder node and the simulator node all use it, so a live system and every
recording show the same thing. Frames are REP 103 (z up; contract.py, io/urdf.py):

=====================  =================================  =====================================
topic                  type                               content
=====================  =================================  =====================================
/robot_description     std_msgs/msg/String                the scene's URDF (io/urdf.py), once
/tf_static             tf2_msgs/msg/TFMessage             tip on the last link, surfaces, once
/tf                    tf2_msgs/msg/TFMessage             the joint transforms, at ``tf_rate``
                                                          and at each impact's events
/impact_markers        visualization_msgs/msg/MarkerArray surfaces, contact-force arrow, impact
                                                          points; with each /tf message
/impact_table          std_msgs/msg/String                every impact so far, rounded
                                                          (io/impact_table.py), at each impact
=====================  =================================  =====================================

A contact lasts ~0.1 ms, far less than a /tf period (10 ms): sampled at ``tf_rate`` alone an
impact would never be seen. So each impact adds three frames, /tf and markers stamped at its
events (first contact, maximum compression, separation: ``add_impact`` reads their states
from the impact report) and computed from those states. At the first-contact frame the tip
frame lies on the surface.

The force arrow starts at the contact point (the tip centre B at first contact, on the
surface) and points along the surface's outward normal; its length grows with the impact's
peak normal force F_max towards the arm's reach (half of it at ``ARROW_HALF_FORCE``), because
impact forces span several decades. It lives ``ARROW_HOLD`` seconds from the contact (marker
lifetime; each MarkerArray in that window adds it again with the lifetime left), so at 1x
playback it is on screen for ~20 rendered frames. No message deletes it: a frame published
before the report arrived (live, the report follows its period's joint state) cannot hide it.

Each MarkerArray carries every surface and every impact point so far (persistent), so a
viewer that jumps to any time shows them right from one message.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import math

from ..contract import (
    IMPACT_MARKERS,
    IMPACT_TABLE,
    ROBOT_DESCRIPTION,
    TF,
    TF_STATIC,
    TF_TYPE,
    PLANE_FRAME_ROTATION,
    VISUAL_TOPICS,
    plane_to_world,
)
from ..physics.errors import ImpactArmError
from ..physics.impact import Impact, impact_from_json
from .impact_table import table_json, table_row
from .msgdefs import append_cdr, sequence_cdr_prefix, serialize_cdr
from .urdf import (
    IMPACT_PLANE,
    SURFACE_THICKNESS_PER_REACH,
    WORLD,
    WholeRobot,
    Transform,
    moving_transforms,
    robot_description,
    rod_radius_of,
    scene_link_names,
    static_transforms,
    surface_frames,
    tip_position,
)

if TYPE_CHECKING:
    from ..physics.scene import Scene

DEFAULT_TF_RATE = 100.0  # Hz: smooth to the eye, a tenth of the joint-state rate
ARROW_HALF_FORCE = 1000.0  # N at which the arrow is half the reach long
# s the force arrow stays after a contact: >= 0.3 s, ~20 frames at 1x, and gone before the
# article's next impact (0.4 s later)
ARROW_HOLD = 0.35
# the impact points: beads resting on the surface, 6 % of the reach across (120 mm on the
# article's 2 m arm, ~15 pixels in the shipped view at 1x). Inside the slab under the contact
# point (as drawn before) the opaque face of the surface hid them at any zoom; on top of it
# nothing of the surface stands between them and a camera above the surface plane.
IMPACT_POINT_PER_REACH = 0.06
# their colour: the impact's peak normal force on a log scale, cyan at FORCE_COLOURS[0][0]
# and below, magenta at the last stop and above (impact forces span decades: 28-31 kN for
# the article's arm, a few kN for soft contacts); no red, which is the tip's and the arrow's
FORCE_COLOURS = (
    (1e3, (0.2, 0.9, 1.0)),  # cyan
    (1e4, (0.55, 1.0, 0.3)),  # green
    (3e4, (1.0, 0.9, 0.2)),  # yellow
    (1e5, (1.0, 0.3, 1.0)),  # magenta
)
# the surface: opaque, so that no viewer's transparency sorting draws it over the beads
SURFACE_RGBA = (0.45, 0.45, 0.5, 1.0)
IMPACT_EVENTS = ('contact', 'max_compression', 'separation')


def arrow_length(force: float, reach: float) -> float:
    """Length [m] drawn for a contact force [N]: half the reach at ``ARROW_HALF_FORCE``,
    approaching the reach for far larger forces."""
    return reach * force / (force + ARROW_HALF_FORCE)


def force_colour(force: float) -> tuple[float, float, float, float]:
    """RGBA of an impact point whose peak normal force is ``force`` [N]: linear in log F
    between the stops of ``FORCE_COLOURS``, clamped at both ends. A non-finite or negative
    force is refused (the reports' forces are checked finite before)."""
    if not (math.isfinite(force) and force >= 0):
        raise ValueError(f'force {force!r} N: no colour for it')
    stops = FORCE_COLOURS
    if force <= stops[0][0]:
        return (*stops[0][1], 1.0)
    for (f0, c0), (f1, c1) in zip(stops, stops[1:]):
        if force <= f1:
            w = math.log(force / f0) / math.log(f1 / f0)
            r, g, b = (a + w * (b_ - a) for a, b_ in zip(c0, c1))
            return (r, g, b, 1.0)
    return (*stops[-1][1], 1.0)


def event_states(record: Impact) -> list[tuple[str, int, list[float]]]:
    """[(event, stamp [ns], absolute link angles [rad])] of an impact: first contact,
    maximum compression and separation. The contact stamp is rounded up and the separation
    stamp down to the ns, so both lie inside the contact interval."""
    t0 = float(record.t_contact)
    t_max = t0 + math.fsum(record.phase_durations[:2])
    t_sep = t0 + float(record.duration)
    out = [
        ('contact', math.ceil(t0 * 1e9 - 1e-6), record.q_contact_deg),
        ('max_compression', round(t_max * 1e9), record.q_max_compression_deg),
        ('separation', math.floor(t_sep * 1e9 + 1e-6), record.q_separation_deg),
    ]
    return [(kind, int(t), [math.radians(a) for a in q]) for kind, t, q in out]


def mounted_surfaces(scene: Scene) -> list[tuple[str, float]]:
    """(frame, rest height [m]) of each surface on a compliant mount, in the order of the
    plates' states (``ArmModel.plate_states``, /surface_mounts): their frames move on /tf."""
    frames = surface_frames(scene)
    return [
        (frames[i], float(s.height))
        for i, s in enumerate(scene.surfaces)
        if s.mount is not None and s.law != 'none'
    ]


def _stamp(header, t_ns: int):
    header.stamp.sec, header.stamp.nanosec = divmod(int(t_ns), 1_000_000_000)


class SceneVisuals:
    """Builds the visual messages of one scene; ``due`` paces /tf and the markers,
    ``add_impact`` queues an impact's event frames (``take_events``)."""

    def __init__(self, scene, tf_rate: float = DEFAULT_TF_RATE, rod_radius=None):
        from .msgdefs import message_class

        if not (math.isfinite(tf_rate) and tf_rate > 0):
            raise ValueError(f'tf_rate = {tf_rate!r}: must be > 0 Hz')
        self.scene = scene
        self.tf_rate = float(tf_rate)
        self.rod_radius = rod_radius_of(scene, rod_radius)
        self._TF = message_class(TF_TYPE)  # the stand-in where tf2_msgs is missing
        from geometry_msgs.msg import Point, TransformStamped
        from std_msgs.msg import String
        from visualization_msgs.msg import Marker

        self._TransformStamped, self._String, self._Point = TransformStamped, String, Point
        self._Marker = Marker
        self.reach = math.fsum(scene.lengths)
        self.mounted = mounted_surfaces(scene)
        self.links = scene_link_names(scene)  # the frames /tf moves, as the description names them
        # a URDF arm: the whole robot, its joints as robot_state_publisher moves them, and the
        # model's plane in frame impact_plane; the rods: the model's plane is the world's x-z
        self.robot = WholeRobot(scene) if scene.plane is not None and scene.urdf_text else None
        self.frame = WORLD if self.robot is None else IMPACT_PLANE
        self._next_tf = 0  # index k of the next /tf time k / tf_rate
        self.impacts: list[tuple] = []  # (contact stamp [ns], contact point (x, z), F_max [N])
        self.rows: list[dict] = []  # the impacts as /impact_table rows
        self._events: list[tuple] = []  # event frames not yet taken: (stamp [ns], q)
        self._fixed_markers: list = []  # surfaces, then impact points, as drawn so far
        self._drawn_points = 0
        self._prefixes: Any = None  # their CDR, the start of every MarkerArray (see markers)

    @property
    def impact_points(self) -> list:
        """(x, z) in the world where each impact touched the surface."""
        return [point for _, point, _ in self.impacts]

    # ------------------------------------------------------------------ once per run
    def description(self) -> Any:
        return self._String(data=robot_description(self.scene, rod_radius=self.rod_radius))

    def tf_static(self, t_ns: int = 0) -> Any:
        """The fixed transforms; a mounted surface's frame moves, so it is on /tf instead."""
        moving = {frame for frame, _ in self.mounted}
        return self._TF(
            transforms=[
                self._transform(t, t_ns)
                for t in (self.robot.static() if self.robot else static_transforms(self.scene))
                if t.child not in moving
            ]
        )

    # ------------------------------------------------------------------ per state
    def due(self, t: float) -> bool:
        """True once per 1 / tf_rate of simulated time (at the first ``t`` reaching it)."""
        if t * self.tf_rate < self._next_tf * (1 - 1e-12) - 1e-9:
            return False
        self._next_tf = math.floor(t * self.tf_rate * (1 + 1e-12) + 1e-9) + 1
        return True

    def tf(self, q: Sequence[float], t_ns: int, plates: Sequence[float] | None = None) -> Any:
        """The joint transforms for absolute link angles ``q``; with ``plates`` ((z, ż) per
        mounted surface, flat, of the same instant) also each mounted surface's frame."""
        if self.robot is not None:
            transforms = self.robot.moving(q)
        else:
            transforms = moving_transforms(self.scene.lengths, q, self.links)
        if plates is not None:
            transforms += self._surface_transforms(plates)
        return self._TF(transforms=[self._transform(t, t_ns) for t in transforms])

    def surface_tf(self, t_ns: int, plates: Sequence[float]) -> Any:
        """The mounted surfaces' frames alone, at their rest heights moved by their plates'
        z (``plates``: (z, ż) per mounted surface, flat, at ``t_ns``)."""
        return self._TF(
            transforms=[self._transform(t, t_ns) for t in self._surface_transforms(plates)]
        )

    def _surface_transforms(self, plates):
        return [
            Transform(
                self.frame, frame, 0.0, 0.0, height + float(plates[2 * j]), PLANE_FRAME_ROTATION
            )
            for j, (frame, height) in enumerate(self.mounted)
        ]

    def add_impact(self, record: Impact | str | bytes) -> None:
        """An impact (its ``Impact``, or the JSON text of its report as it came from the
        wire): its contact point becomes a marker, its force the arrow, and its event frames
        are queued (``take_events``). A report that is no usable record (not the record's
        fields, or values that are no finite numbers) raises ValueError."""
        try:
            impact = impact_from_json(record) if isinstance(record, (str, bytes)) else record
            events = event_states(impact)
            row = table_row(impact)
            force = float(impact.F_max)
            _, t_contact, q_contact = events[0]
            # the model's contact begins when the tip centre B reaches the surface plane
            x, _, z = plane_to_world(
                *tip_position(self.scene.lengths, q_contact, self.scene.contact_point)
            )
            n = self.scene.n_links
            numbers = [force, x, z] + [a for _, _, q in events for a in q]
        except (
            ImpactArmError,
            KeyError,
            TypeError,
            IndexError,
            AttributeError,
            OverflowError,
            ValueError,
        ) as e:  # ValueError: NaN or infinite numbers in the maths
            raise ValueError(f'impact report not usable: {type(e).__name__} {e}') from None
        if not all(math.isfinite(v) for v in numbers) or any(len(q) != n for _, _, q in events):
            raise ValueError(f'impact report not usable: non-finite values or not {n} angles')
        self.impacts.append((t_contact, (x, z), force))
        self.rows.append(row)
        self._events.extend((t, q) for _, t, q in events)

    def table(self) -> Any:
        """The /impact_table message: every impact so far as a rounded row."""
        return self._String(data=table_json(self.rows))

    def take_events(self) -> list:
        """[(stamp [ns], absolute link angles)] of the event frames queued since the last
        call, in time order: publish ``tf`` and ``markers`` at each."""
        events, self._events = self._events, []
        return events

    def markers(self, t_ns: int) -> bytes:
        """The serialized MarkerArray at ``t_ns``: surfaces, impact points, then the arrow.
        Surfaces and impact points sit in fixed frames, so their markers are built and
        serialized once (stamp 0: the latest transform) and only the arrow is added: building
        and serializing every marker each time took 0.7 + 2.9 ms with 15 impacts, at tf_rate
        in the simulator and the recorder."""
        M = self._Marker
        if not self._fixed_markers:
            thickness = SURFACE_THICKNESS_PER_REACH * self.reach
            for i, frame in enumerate(surface_frames(self.scene)):
                m = self._marker('surface', i, M.CUBE, frame, 0, SURFACE_RGBA)
                # the surface frame's y is the normal: the slab lies below the plane
                m.pose.position.y = -thickness / 2
                m.scale.x, m.scale.y, m.scale.z = 2 * self.reach, thickness, self.reach / 2
                self._fixed_markers.append(m)
        if self._prefixes is None or self._drawn_points < len(self.impacts):
            for k in range(self._drawn_points, len(self.impacts)):
                _, (x, z), force = self.impacts[k]
                m = self._marker('impact_points', k, M.SPHERE, self.frame, 0, force_colour(force))
                size = IMPACT_POINT_PER_REACH * self.reach
                # the bead rests on the surface at the contact point: above the slab's top
                # face, where the surface cannot hide it
                m.pose.position.x, m.pose.position.z = x, z + size / 2
                m.scale.x = m.scale.y = m.scale.z = size
                self._fixed_markers.append(m)
            self._drawn_points = len(self.impacts)
            n = len(self._fixed_markers)  # the CDR starts with the count: without, with arrow
            self._prefixes = (
                sequence_cdr_prefix(self._fixed_markers, n),
                sequence_cdr_prefix(self._fixed_markers, n + 1),
            )
        held = self._held_impact(t_ns)
        if held is None:
            return self._prefixes[0]
        t_contact, (x, z), force = held
        arrow = self._marker('contact_force', 0, M.ARROW, self.frame, t_ns, (1.0, 0.2, 0.1, 1.0))
        # from the contact point along the outward normal (world +z): the force on the tip
        length = arrow_length(force, self.reach)
        arrow.points = [self._Point(x=x, z=z), self._Point(x=x, z=z + length)]
        arrow.scale.x, arrow.scale.y = 2 * self.rod_radius, 4 * self.rod_radius  # shaft, head
        left = t_contact + round(ARROW_HOLD * 1e9) - t_ns
        arrow.lifetime.sec, arrow.lifetime.nanosec = divmod(left, 1_000_000_000)
        return append_cdr(self._prefixes[1], arrow)

    def _held_impact(self, t_ns):
        """The latest impact whose arrow is still shown at ``t_ns``, or None."""
        hold = round(ARROW_HOLD * 1e9)
        for impact in reversed(self.impacts):
            if impact[0] <= t_ns:
                return impact if t_ns < impact[0] + hold else None
        return None

    # ------------------------------------------------------------------ helpers
    def _transform(self, t, t_ns):
        msg = self._TransformStamped()
        _stamp(msg.header, t_ns)
        msg.header.frame_id, msg.child_frame_id = t.parent, t.child
        p = msg.transform.translation
        p.x, p.y, p.z = t.x, t.y, t.z
        r = msg.transform.rotation
        r.x, r.y, r.z, r.w = t.quaternion()
        return msg

    def _marker(self, ns, marker_id, kind, frame, t_ns, rgba):
        m = self._Marker()
        _stamp(m.header, t_ns)
        m.header.frame_id, m.ns, m.id, m.type, m.action = (
            frame,
            ns,
            marker_id,
            kind,
            self._Marker.ADD,
        )
        m.pose.orientation.w = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = rgba
        return m


class VisualsWriter:
    """Adds the visual topics to an MCAP writer from the recorded state: the offline recorder
    and the recorder node feed it what they write, it writes /robot_description and
    /tf_static first, then /tf and /impact_markers at ``tf_rate`` of the state's stamps and at
    each impact's events."""

    def __init__(
        self, writer, scene, tf_rate: float = DEFAULT_TF_RATE, log_time_ns: int = 0, rod_radius=None
    ):
        self.visuals = SceneVisuals(scene, tf_rate, rod_radius)
        self.writer = writer
        self.counts = {topic: 0 for topic in VISUAL_TOPICS}
        for topic, (type_name, qos) in VISUAL_TOPICS.items():
            writer.add_topic(topic, type_name, qos)
        self._write(ROBOT_DESCRIPTION, self.visuals.description(), log_time_ns)
        self._write(TF_STATIC, self.visuals.tf_static(0), log_time_ns)
        self._last: tuple | None = None  # (stamp, q, log time) of the latest state
        self._shown: int | None = None  # stamp of the latest /tf written
        self._next_plates = 0  # index k of the next mounted-surface frames, at k / tf_rate

    def state(
        self,
        t_ns: int,
        q: Sequence[float],
        wrench: Sequence[float] | None = None,
        log_time_ns: int | None = None,
    ) -> None:
        """One joint state (absolute angles ``q``; ``wrench`` is not drawn, see ``force``)."""
        log = t_ns if log_time_ns is None else log_time_ns
        self._last = (t_ns, q, log)
        if self.visuals.due(t_ns * 1e-9):
            self._frame(t_ns, q, log)

    def plates(self, t_ns: int, plates: Sequence[float], log_time_ns: int | None = None) -> None:
        """One sample of the mounted surfaces' plates ((z, ż) each, flat, /surface_mounts):
        their frames on /tf, stamped with it, at ``tf_rate`` of its stamps (on their own: a
        plate's sample and the joint state of its period may reach a recorder in either
        order)."""
        t = t_ns * 1e-9
        if t * self.visuals.tf_rate < self._next_plates * (1 - 1e-12) - 1e-9:
            return
        self._next_plates = math.floor(t * self.visuals.tf_rate * (1 + 1e-12) + 1e-9) + 1
        log = t_ns if log_time_ns is None else log_time_ns
        self._write(TF, self.visuals.surface_tf(t_ns, plates), log)

    def finish(self) -> None:
        """The last state, if /tf has not shown it yet: the file ends on the final pose and
        every impact point (the last report comes after the last paced frame)."""
        if self._last is not None and self._last[0] != self._shown:
            self._frame(*self._last)

    def _frame(self, t_ns, q, log):
        self._write(TF, self.visuals.tf(q, t_ns), log)
        self._write(IMPACT_MARKERS, self.visuals.markers(t_ns), log)
        self._shown = t_ns

    def force(self, q: Sequence[float], wrench: Sequence[float]) -> None:
        """A sampled contact wrench: accepted and not drawn. The arrow comes from the impact
        reports, whose contact point is exact; a period-averaged force belongs to no pose."""

    def impact(self, record: Impact | str | bytes, log_time_ns: int | None = None) -> None:
        """An impact (or its report's text): writes its event frames
        (``SceneVisuals.add_impact``). Their log time is ``log_time_ns`` if given, else their
        stamp shifted by the latest state's (log time - stamp): the stamp itself where log
        time is simulated time."""
        self.visuals.add_impact(record)
        offset = 0 if self._last is None else self._last[2] - self._last[0]
        events = self.visuals.take_events()
        log = [t + offset if log_time_ns is None else log_time_ns for t, _ in events]
        # the table first, logged with the contact's frame (in time order): a seek to the
        # impact shows its row
        self._write(IMPACT_TABLE, self.visuals.table(), log[0])
        for (t_ns, q), log_ns in zip(events, log):
            self._frame_at_event(t_ns, q, log_ns)

    def _frame_at_event(self, t_ns, q, log):
        self._write(TF, self.visuals.tf(q, t_ns), log)
        self._write(IMPACT_MARKERS, self.visuals.markers(t_ns), log)

    def _write(self, topic, msg, log_time_ns):
        """``msg``: a message, or its CDR bytes."""
        data = msg if isinstance(msg, bytes) else serialize_cdr(msg)
        self.writer.write(topic, data, log_time_ns, log_time_ns)
        self.counts[topic] += 1
