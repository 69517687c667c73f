"""Comparisons for the API: the impacts of two recordings, or of a recording and a scene."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from ..contract import JOINT_STATES
from .scenes import SceneLike


def is_recording(path: Any) -> bool:
    """True for a rosbag2 folder or an MCAP file (a scene is anything else)."""
    if not isinstance(path, (str, os.PathLike)):
        return False
    p = os.fspath(path)
    return os.path.isdir(p) or (os.path.isfile(p) and p.endswith('.mcap'))


def compare(
    a: str | os.PathLike[str],
    b: str | os.PathLike[str] | SceneLike,
    *,
    scene: SceneLike | None = None,
    joints: Sequence[str] | None = None,
    controller: bool = False,
    states_topic: str = JOINT_STATES,
    wrench_topic: str | None = None,
) -> dict[str, Any]:
    """The impacts of recording ``a`` beside those of ``b``, matched one to one by time.

    Args:
        a: a recording (rosbag2 folder or MCAP file).
        b: a second recording, or a scene (anything ``load_scene`` takes): by default the
            scene replays each impact of ``a`` from its recorded state with ``a``'s efforts.
        scene: the scene whose kinematics read both recordings; None: the one ``a`` stores.
            Unused when ``b`` is a scene (its own kinematics are used).
        joints: the joint names to read, when the recordings name them otherwise.
        controller: ``b`` a scene: simulate it with its own controller instead.
        states_topic: the ``JointState`` topic of the recordings.
        wrench_topic: their ``WrenchStamped`` topic; None: ``/contact_wrench`` if recorded.

    Returns:
        {'a': rows, 'b': rows, 'pairs': [(i, j)], 'table': [...], 'what': text,
        'unmatched_a': int, 'unmatched_b': int}; a row holds 't' [s], 'impact_speed' [m/s],
        'cor', 'impulse_n', 'impulse_t' [N s] and 'qd_after' [rad/s]; a table entry the
        matched pair's values (``_a``, ``_b``) and differences ('d_cor', 'd_impulse_n',
        'd_qd_after'). The same as ``impact-arm compare``'s table.json.

    Raises:
        RecordingInputError: a recording that cannot be read, or no scene given or stored.
        SceneError: a bad scene.
        IdentifyError: a recording with too few samples around its impacts.
    """
    from ..calibration.compare import impact_table, recorded_impacts, replayed_impacts
    from ..calibration.study import Study
    from ..io.recording import read_recording
    from .recordings import recording_scene

    b_is_recording = is_recording(b)
    if not b_is_recording:
        kin_scene: Any = b
    else:  # a scene given is read as given (a name, a file), else the one ``a`` stores
        kin_scene = scene if scene is not None else recording_scene(a)
    study = Study(kin_scene)
    kin = study.scene()

    def read(path: str | os.PathLike[str]) -> Any:
        return read_recording(
            path,
            joints,
            None,
            states_topic,
            wrench_topic,
            scene_joints=kin.joint_names,
            coordinates=kin.joint_coordinates,
        )

    rec_a = read(a)
    a_rows, preds, _ = recorded_impacts(rec_a, study)
    if b_is_recording:
        b_rows = recorded_impacts(read(b), study)[0]  # type: ignore[arg-type]
        what = f'recording {b}'
    elif controller:
        from ..io.synthetic import synthetic_recording

        rec_b = synthetic_recording(b, noise={}, publish_rate=1.0 / rec_a.period)
        b_rows = recorded_impacts(rec_b, study)[0]
        what = f'scene {b} with its own controller'
    else:
        from ..physics.model import ArmModel

        b_rows = replayed_impacts(preds, ArmModel(study.scene()))
        what = f'scene {b} replaying each impact of {a} from its recorded state and efforts'
    return impact_table(a_rows, b_rows, what)
