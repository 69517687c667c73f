"""The simulator's 3D view: /robot_description and /tf_static once (transient local), then
/tf and /impact_markers at ``tf_rate`` from a timer of the executor thread that reads the
latest published period, and at each impact's first contact, maximum compression and
separation (from the impact report, io/scene_visuals.py), so they cost the realtime loop
nothing but one reference. While nobody listens to either, the ``tf_rate`` timer stops and a
slower one looks for listeners (``LISTENER_CHECK``)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from std_msgs.msg import String

from ..contract import IMPACT_MARKERS, IMPACT_TABLE, ROBOT_DESCRIPTION, TF, TF_STATIC, VISUAL_TOPICS
from ..io.msgdefs import has_type_support
from ..io.scene_visuals import SceneVisuals

if TYPE_CHECKING:
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from rclpy.qos import QoSProfile

    from ..driver.arm import Tick
    from ..physics.scene import Scene

# s between two looks for a listener while nobody listens to /tf or /impact_markers: woken at
# tf_rate only to find no listener, the executor thread took ~1.5 % of a core at 100 Hz
LISTENER_CHECK = 0.2


class VisualsPublisher:
    def __init__(
        self,
        node: Node,
        scene: Scene,
        tf_rate: float,
        publish_tf: bool,
        on_timer: Callable[[], None] = lambda: None,
        rod_radius: float = 0.0,
    ) -> None:
        from visualization_msgs.msg import MarkerArray

        def qos(topic: str) -> QoSProfile:
            return VISUAL_TOPICS[topic][1].to_rclpy()

        self.visuals = SceneVisuals(scene, tf_rate, rod_radius)
        self.lock = threading.Lock()
        self.latest: Tick | None = None  # the latest published period
        self._stamp: float | None = None
        self._on_timer = on_timer
        node.create_publisher(String, ROBOT_DESCRIPTION, qos(ROBOT_DESCRIPTION)).publish(
            self.visuals.description()
        )
        self.pub_markers = node.create_publisher(MarkerArray, IMPACT_MARKERS, qos(IMPACT_MARKERS))
        # latched: a viewer that connects later still gets every impact so far
        self.pub_table = node.create_publisher(String, IMPACT_TABLE, qos(IMPACT_TABLE))
        tf_class = type(self.visuals.tf_static())
        self.pub_tf = None
        # without tf2_msgs rclpy has no type support for TFMessage, so no live TF: the
        # recordings still hold it (the recorder derives it from /joint_states)
        if publish_tf and has_type_support(tf_class):
            node.create_publisher(tf_class, TF_STATIC, qos(TF_STATIC)).publish(
                self.visuals.tf_static()
            )
            self.pub_tf = node.create_publisher(tf_class, TF, qos(TF))
        elif publish_tf:  # (false: robot_state_publisher owns /tf, tf:=rsp)
            node.get_logger().info(
                'tf2_msgs is not installed: no live /tf or /tf_static '
                '(recordings still hold them; launch with tf:=rsp on a '
                'ROS install)'
            )
        self.timer = node.create_timer(1.0 / tf_rate, self._publish)
        node.create_timer(LISTENER_CHECK, self._look_for_listeners)

    def observe(self, tick: Tick) -> None:
        """A published period (any thread). Its period-averaged force draws no arrow: it
        belongs to no single pose (the arrows come from the impact reports' events)."""
        self.latest = tick

    def add_impacts(self, tick: Tick) -> None:
        with self.lock:
            for record, _rows in tick.impacts:
                self.visuals.add_impact(record)
            table = self.visuals.table() if tick.impacts else None
        if table is not None:  # one message a tick, at impacts only
            try:
                self.pub_table.publish(table)
            except RuntimeError:  # refused by the middleware: lost like a dropped packet,
                pass  # the next impact's table holds this row again

    def _listeners(self) -> tuple[Publisher[Any] | None, Publisher[Any] | None]:
        """The publishers of /tf and /impact_markers that have a subscriber (None for the
        others): built and sent only while someone subscribes, since at 100 Hz the markers
        alone took ~5 % of a core of the simulator's executor thread (asking costs ~3 us)."""
        tf = self.pub_tf if self.pub_tf and self.pub_tf.get_subscription_count() else None
        markers = self.pub_markers if self.pub_markers.get_subscription_count() else None
        return tf, markers

    def _look_for_listeners(self) -> None:
        """While the tf_rate timer is stopped: restart it once someone listens; until then
        drop the impacts' events (nobody is there to be shown them, as at tf_rate)."""
        if not self.timer.is_canceled():
            return
        self._on_timer()
        if self._listeners() == (None, None):
            with self.lock:
                self.visuals.take_events()
        else:
            self.timer.reset()

    def _publish(self) -> None:
        self._on_timer()
        tf, markers = self._listeners()
        if tf is None and markers is None:
            self.timer.cancel()  # until someone listens (_look_for_listeners)
        with self.lock:  # each impact's events first: their stamps are older (the arm only)
            events = [
                (tf and self.visuals.tf(q, t_ns), markers and self.visuals.markers(t_ns))
                for t_ns, q in self.visuals.take_events()
            ]
        for tf_msg, markers_msg in events:
            if tf is not None:
                tf.publish(tf_msg)
            if markers is not None:
                markers.publish(markers_msg)
        tick = self.latest
        if tick is None or tick.t == self._stamp or (tf is None and markers is None):
            return  # nothing new (paused lockstep, waiting), or nobody to tell
        self._stamp = tick.t
        t_ns = round(tick.t * 1e9)
        if tf is not None:
            plates = tick.plates if self.visuals.mounted else None
            q = self.visuals.scene.joint_coordinates.absolute(tick.position)
            tf.publish(self.visuals.tf(q, t_ns, plates))
        if markers is not None:
            with self.lock:
                markers_msg = self.visuals.markers(t_ns)
            markers.publish(markers_msg)
