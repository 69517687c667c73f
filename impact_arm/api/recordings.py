"""Recordings for the API: a recording's joint states read with its arm's scene."""

from __future__ import annotations

import os
from collections.abc import Sequence

from ..calibration.identify import JointRecording
from ..contract import JOINT_STATES
from ..io.recording import RecordingInputError, recorded_scene
from ..physics.scene import Scene
from .scenes import SceneLike, load_scene


def recording_scene(recording: str | os.PathLike[str], scene: SceneLike | None = None) -> Scene:
    """The scene to read ``recording`` with: ``scene`` when given, else the one the recording
    stores (the recorder and ``simulate(mcap=...)`` store it).

    Raises:
        RecordingInputError: no ``scene`` given and the recording stores none, or the
            recording cannot be read.
        SceneError: a bad ``scene``.
    """
    if scene is not None:
        return load_scene(scene)
    stored = recorded_scene(recording)
    if stored is None:
        raise RecordingInputError(
            f'recording {os.fspath(recording)}: stores no scene, so its arm is unknown: '
            f"pass scene= (the recorded arm's scene name, file or data)"
        )
    scene_found: Scene = stored
    return scene_found


def read_recording(
    path: str | os.PathLike[str],
    scene: SceneLike | None = None,
    *,
    joints: Sequence[str] | None = None,
    states_topic: str = JOINT_STATES,
    wrench_topic: str | None = None,
) -> JointRecording:
    """The joint states (and contact wrench, when recorded) of a recording, in the model's
    coordinates.

    Args:
        path: a rosbag2 folder (metadata.yaml + MCAP files) or an MCAP file, of any robot
            that publishes ``sensor_msgs/JointState``.
        scene: the recorded arm's scene (anything ``load_scene`` takes); None: the scene the
            recording stores. It gives the joints read and their coordinates.
        joints: the joint names to read, when the recording names them otherwise than the
            scene does (in the scene's order).
        states_topic: the ``JointState`` topic.
        wrench_topic: the ``WrenchStamped`` topic; None reads ``/contact_wrench`` when the
            recording has it.

    Returns:
        A ``JointRecording``: ``t`` [s] from the first sample, ``position`` [rad],
        ``velocity`` [rad/s], ``effort`` [N m] (samples x joints), ``wrench_t``/``wrench``
        [N] (tangential, normal) or None, ``joints``, ``notes``.

    Raises:
        RecordingInputError: no such recording, a topic or joint not in it, too few samples,
            or no ``scene`` and none stored (one line saying which).
        SceneError: a bad ``scene``.
    """
    from ..io.recording import read_recording as read

    sc = recording_scene(path, scene)
    return read(
        path,
        joints,
        None,
        states_topic,
        wrench_topic,
        scene_joints=sc.joint_names,
        coordinates=sc.joint_coordinates,
    )
