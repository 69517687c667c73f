"""Joint states (and an optional contact wrench) out of a recording made by anyone.

A recording is a rosbag2 folder (``metadata.yaml`` + MCAP files, as ``ros2 bag record`` writes
it) or a single MCAP file. Only what a real driver publishes is read: ``sensor_msgs/JointState``
(positions, rates, efforts, matched to the wanted joints by name in every message) and
``geometry_msgs/WrenchStamped`` (force.x tangential, force.y normal, period-averaged). Stamps
are the headers' (any clock: the times are returned from the first sample on), or the log
times when a publisher leaves its stamps at zero. Nothing our simulator writes besides these
(impact reports, traces, metadata) is used, so a recording of real hardware reads the same.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import glob
import os
from operator import attrgetter

import numpy as np

from ..contract import CONTACT_WRENCH, JOINT_STATES, SURFACE_MOUNTS, JointCoordinates, joint_names
from ..physics.errors import ImpactArmError
from ..calibration.identify import JointRecording
from .wire import CdrReader, _doubles_at, _header, _strings


class RecordingInputError(ImpactArmError):
    """A recording that cannot be used: the message says what and where, in one line."""


def mcap_files(path: str | os.PathLike) -> list[str]:
    """The MCAP files of a recording: the file itself, or a rosbag2 folder's (in the order
    its metadata.yaml lists them)."""
    path = os.fspath(path)
    if os.path.isfile(path):
        return [path]
    if not os.path.isdir(path):
        raise RecordingInputError(f'recording {path}: no such file or folder')
    meta = os.path.join(path, 'metadata.yaml')
    if not os.path.isfile(meta):
        # a recorder killed before it wrote metadata.yaml leaves its MCAP files readable
        files = sorted(glob.glob(os.path.join(path, '*.mcap')))
        if files:
            return files
        raise RecordingInputError(
            f'recording {path}: a folder with neither metadata.yaml nor '
            f'MCAP files is not a rosbag2 recording'
        )
    import yaml

    try:
        with open(meta, encoding='utf-8') as f:
            info = (yaml.safe_load(f) or {}).get('rosbag2_bagfile_information', {})
    except (OSError, yaml.YAMLError) as exc:
        raise RecordingInputError(f'recording {meta}: unreadable ({exc})') from None
    storage = info.get('storage_identifier', 'mcap')
    if storage != 'mcap':
        raise RecordingInputError(
            f'recording {path}: storage {storage!r} is not supported; '
            f'record with --storage mcap (or convert with ros2 bag convert)'
        )
    listed = [os.path.join(path, p) for p in info.get('relative_file_paths', [])]
    files = [p for p in listed if os.path.isfile(p)] or sorted(
        glob.glob(os.path.join(path, '*.mcap'))
    )
    if not files:
        raise RecordingInputError(f'recording {path}: no MCAP file in the folder')
    return files


def _topics(files) -> dict:
    from .mcap_ros2 import topics_info, unreadable_reason

    out: dict = {}
    for f in files:
        try:
            for topic, info in topics_info(f).items():
                out.setdefault(topic, info.type_name)
        except Exception as exc:  # noqa: BLE001 - any reader failure: not an MCAP file
            raise RecordingInputError(f'recording {f}: {unreadable_reason(f, exc)}') from None
    return out


def _joint_state(raw: bytes):
    r = CdrReader(raw)
    sec, nanosec = _header(r)
    names = _strings(r)
    position = _doubles_at(r)[0]
    velocity = _doubles_at(r)[0]
    effort = _doubles_at(r)[0]
    return sec * 1_000_000_000 + nanosec, names, position, velocity, effort


def _wrench(raw: bytes):
    r = CdrReader(raw)
    sec, nanosec = _header(r)
    r.align(8)
    return sec * 1_000_000_000 + nanosec, r.unpack('d', 8, 3)


def read_recording(
    path: str | os.PathLike,
    joints: Sequence[str] | None = None,
    n_joints: int | None = None,
    states_topic: str = JOINT_STATES,
    wrench_topic: str | None = None,
    progress: Callable[..., Any] | None = None,
    scene_joints: Sequence[str] | None = None,
    coordinates: JointCoordinates | None = None,
) -> JointRecording:
    """The joint states of ``joints`` (default ``scene_joints``, the recorded arm's scene's
    ``Scene.joint_names``; without it joint1..joint``n_joints``; without that, the joints and
    coordinates of the scene the recording stores, refused when it stores none: no arm's
    joint count is assumed) and, if recorded, the wrench.

    ``wrench_topic`` None reads ``/contact_wrench`` when the recording has it; a topic named
    explicitly must be there. Samples whose values are not finite are dropped and counted in
    ``notes``; refused in one line: a missing topic, joints not in the messages, no samples.

    ``coordinates``: the scene's ``Scene.joint_coordinates``; the recording holds the robot's
    joint angles, efforts and rates, the result the model's relative ones (r = sign θ +
    offset), as the model's equations take them."""
    files = mcap_files(path)
    topics = _topics(files)
    given = bool(joints)
    if states_topic not in topics:
        raise RecordingInputError(
            f'--states-topic {states_topic}: not in the recording '
            f'(topics: {", ".join(sorted(topics)) or "none"})'
        )
    explicit = wrench_topic is not None
    wrench_topic = wrench_topic if explicit else CONTACT_WRENCH
    if wrench_topic not in topics:
        if explicit:
            raise RecordingInputError(
                f'--wrench-topic {wrench_topic}: not in the recording '
                f'(topics: {", ".join(sorted(topics))})'
            )
        wrench_topic = None
    if not (joints or scene_joints or n_joints):
        stored = recorded_scene(path)
        if stored is None:
            raise RecordingInputError(
                f'recording {os.fspath(path)}: stores no scene, so its joints are unknown: '
                f"give the recorded arm's scene (--scene) or its joints (--joints)"
            )
        scene_joints = stored.joint_names
        coordinates = stored.joint_coordinates if coordinates is None else coordinates
    joints = list(joints or scene_joints or joint_names(n_joints or 0))
    from .mcap_ros2 import iter_raw

    # the mounted surfaces' plates, when recorded (the simulator's recordings have them):
    # the fit starts each impact's replay from their state
    plates_topic = SURFACE_MOUNTS if SURFACE_MOUNTS in topics else None
    wanted = [states_topic] + [x for x in (wrench_topic, plates_topic) if x]
    notes: list[str]
    states, wrenches, seen_names, notes = [], [], set(), []
    plates: list = []
    for f in files:
        # read in the file's order and sorted by log time here (stable: ties stay in the
        # file's order, as the reader's own log-time merge keeps them): the reader's merge
        # compares messages in Python, a third of the reading
        messages = sorted(iter_raw(f, wanted, log_time_order=False), key=attrgetter('log_time_ns'))
        for m in messages:
            try:
                if m.topic == states_topic:
                    stamp, names, pos, vel, eff = _joint_state(m.data)
                    seen_names.update(names)
                    index = {name: k for k, name in enumerate(names)}
                    if not all(j in index for j in joints):
                        continue
                    cols = [index[j] for j in joints]
                    states.append(
                        (
                            stamp,
                            m.log_time_ns,
                            *(_pick(v, cols, len(names)) for v in (pos, vel, eff)),
                        )
                    )
                elif m.topic == plates_topic:
                    stamp, _, z, zd, _ = _joint_state(m.data)
                    if len(z) == len(zd):
                        flat = [x for pair in zip(z, zd) for x in pair]
                        plates.append((stamp, m.log_time_ns, flat))
                else:
                    stamp, force = _wrench(m.data)
                    wrenches.append((stamp, m.log_time_ns, force[0], force[1]))
            except ValueError as exc:
                raise RecordingInputError(
                    f'recording {f}: a {m.topic} message is not a {topics[m.topic]} ({exc})'
                ) from None
    if not states:
        missing = [j for j in joints if j not in seen_names]
        if missing:
            raise RecordingInputError(
                f'--joints: {", ".join(missing)} not in {states_topic} (its joints: '
                f'{", ".join(sorted(seen_names)) or "none"})'
            )
        raise RecordingInputError(f'{states_topic}: no message names all of {joints}')
    more = sorted(set(joint_names(len(seen_names))) & seen_names - set(joints))
    if not given and more:
        # the default names of an arm of more links than the scene has: the scene is not
        # this arm's (reading the first joints only would fit another arm's motion)
        raise RecordingInputError(
            f"{states_topic} names {', '.join(more)} besides the scene's {len(joints)} "
            f"joints: give the recorded arm's scene (--scene) or its joints (--joints)"
        )
    rec = _assemble(states, wrenches, joints, os.fspath(path), notes)
    if coordinates is not None and not coordinates.is_identity:
        to_model(rec, coordinates)
    widths = {len(p[2]) for p in plates}
    if plates and len(widths) == 1 and widths != {0}:
        stamps = _stamps([p[0] for p in plates], [p[1] for p in plates])
        values = np.array([p[2] for p in plates], float)
        order = np.argsort(stamps, kind='stable')
        good = np.isfinite(values[order]).all(axis=1)
        rec.plates_t = ((stamps[order] - rec.t0_ns) * 1e-9)[good]
        rec.plates = values[order][good]
    return rec


def to_model(rec: JointRecording, coordinates: JointCoordinates) -> None:
    """A recording in the robot's joint coordinates to the model's relative angles, in place."""
    signs = np.asarray(coordinates.signs, float)
    rec.position = rec.position * signs + np.asarray(coordinates.offsets, float)
    rec.velocity = rec.velocity * signs
    rec.effort = rec.effort * signs


def recorded_scene(path: str | os.PathLike) -> Any:
    """The scene a recording stores (the recorder's and ``simulate --mcap``'s ``scene``
    metadata), as a ``Scene``; None when it stores none."""
    from ..physics.scene import scene_from_text
    from .mcap_ros2 import read_metadata, unreadable_reason

    for f in mcap_files(path):
        try:
            stored = read_metadata(f).get('scene', {})
        except Exception as exc:  # noqa: BLE001 - any reader failure: not an MCAP file
            raise RecordingInputError(f'recording {f}: {unreadable_reason(f, exc)}') from None
        if stored.get('yaml'):
            return scene_from_text(
                stored['yaml'], origin=f'the scene stored in {f}', path=stored.get('path', '')
            )
    return None


def _pick(values, cols, count):
    """The wanted joints' values, or NaN when a field does not give one per name."""
    return [values[c] for c in cols] if len(values) == count else [np.nan] * len(cols)


def _stamps(header_ns, log_ns):
    """Header stamps, or log times when the publisher left the stamps at zero."""
    header_ns = np.asarray(header_ns, dtype=np.int64)
    return header_ns if np.any(header_ns != header_ns[0]) else np.asarray(log_ns, np.int64)


def _assemble(states, wrenches, joints, source, notes) -> JointRecording:
    stamps = _stamps([s[0] for s in states], [s[1] for s in states])
    pos = np.array([s[2] for s in states], float)
    vel = np.array([s[3] for s in states], float)
    eff = np.array([s[4] for s in states], float)
    order = np.argsort(stamps, kind='stable')
    stamps, pos, vel, eff = stamps[order], pos[order], vel[order], eff[order]
    keep = np.isfinite(pos).all(axis=1)
    if not np.all(np.isnan(vel)):
        keep &= np.isfinite(vel).all(axis=1)
    keep[1:] &= np.diff(stamps) > 0  # a repeated stamp carries no new time
    if not keep.all():
        notes.append(
            f'{int((~keep).sum())} joint-state samples dropped (non-finite values '
            f'or repeated stamps)'
        )
    stamps, pos, vel, eff = stamps[keep], pos[keep], vel[keep], eff[keep]
    if len(stamps) < 20:
        raise RecordingInputError(
            f'recording {source}: {len(stamps)} usable joint-state samples; at least 20 are needed'
        )
    if not np.isfinite(eff).all():
        notes.append('efforts missing or not finite: zero torque assumed around the impacts')
        eff = np.where(np.isfinite(eff), eff, 0.0)
    t0 = int(stamps[0])
    w_t = w = None
    if wrenches:
        ws = _stamps([w[0] for w in wrenches], [w[1] for w in wrenches])
        force = np.array([[w[2], w[3]] for w in wrenches], float)
        order = np.argsort(ws, kind='stable')
        ws, force = ws[order], force[order]
        good = np.isfinite(force).all(axis=1)
        w_t, w = (ws[good] - t0) * 1e-9, force[good]
    return JointRecording(
        t=(stamps - t0) * 1e-9,
        position=pos,
        # ignored: no rates is possible here; find_impacts refuses such a recording
        velocity=vel if np.isfinite(vel).all() else None,  # type: ignore[arg-type]
        effort=eff,
        wrench_t=w_t,
        wrench=w,
        joints=list(joints),
        source=source,
        t0_ns=t0,
        notes=notes,
    )
