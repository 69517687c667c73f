"""A recording reduced to arrays (``Run``) for the analysis, the animation and the figures:
``load`` reads /joint_states (relative joint angles to absolute link angles), /impact_report,
/impact_trace and the scene stored in the file; ``chatter`` finds the joints whose commands
chattered. No rclpy: CDR is decoded by ``rosbags``' typestore."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..contract import IMPACT_REPORT, IMPACT_TRACE, JOINT_STATES, to_absolute
from ..physics.errors import ImpactArmError
from ..physics.impact import Impact, impact_from_json

if TYPE_CHECKING:
    from ..physics.scene import Scene


class AnalysisError(ImpactArmError):
    """The recording cannot be analysed (missing file, topic or data)."""


@dataclass
class Run:
    """One recording (or an offline run) reduced to arrays. Angles in rad, SI units."""

    label: str
    t: np.ndarray  # joint state times [s] (header stamps)
    q: np.ndarray  # (N, n) absolute link angles
    qd: np.ndarray  # (N, n) absolute link rates
    impacts: list[Impact] = field(default_factory=list)  # the /impact_report records
    traces: list = field(default_factory=list)  # [(columns, (rows, cols) array)]
    scene: Scene | None = None
    metadata: dict = field(default_factory=dict)
    law: str = ''
    topics: tuple = ()  # the topics the file holds (with or without messages)
    effort: np.ndarray | None = None  # (N, n) the joint states' efforts [N m]; None: not all
    joint_names: tuple = ()  # of the first joint state
    target: np.ndarray | None = None  # a step response's target link angles [rad]


def _quiet(text: str) -> None:
    pass


def _scene_joints(
    scene: Scene, names: Sequence[str], position: np.ndarray, velocity: np.ndarray
) -> tuple[np.ndarray | list[float], np.ndarray | list[float]]:
    """The positions and velocities of ``scene``'s moving joints in a joint state: picked
    by name when the message names them all, else its first ``scene.n_links`` entries."""
    n = scene.n_links
    names = list(names)
    wanted = list(scene.joint_names)
    if names[:n] == wanted or not all(j in names for j in wanted):
        return position[:n], velocity[:n]
    index = [names.index(j) for j in wanted]
    return (
        [position[k] for k in index],
        [velocity[k] for k in index] if len(velocity) == len(names) else velocity[:0],
    )


def load(path: str | os.PathLike[str], progress: Callable[[str], Any] = _quiet) -> Run:
    """Read a recording. ``progress(text)`` is told what is being read."""
    from ..io.mcap_ros2 import iter_raw, read_metadata, topics_info, unreadable_reason
    from ..io.msgdefs import typestore

    deserialize_cdr = typestore().deserialize_cdr
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise AnalysisError(f'{path}: no such file')
    try:
        info = topics_info(path)
        metadata = read_metadata(path)
    except Exception as e:  # noqa: BLE001 - any reader failure: not an MCAP file we can use
        raise AnalysisError(f'{path}: {unreadable_reason(path, e)}') from None
    if JOINT_STATES not in info:
        raise AnalysisError(f'{path}: no /joint_states recorded (topics: {sorted(info)})')
    total = sum(i.message_count for i in info.values()) or 1
    progress(f'reading {path} ({total} messages)')
    t, pos, vel, effort = [], [], [], []
    impacts: list[Impact] = []
    traces: list[tuple[list, np.ndarray]] = []  # (columns, (rows, cols) array)
    names: tuple = ()
    scene = _scene(metadata)
    # the wire holds the robot's joint angles; the analysis the model's absolute ones
    coordinates = scene.joint_coordinates if scene is not None else None
    wanted = [JOINT_STATES, IMPACT_REPORT, IMPACT_TRACE]
    for k, m in enumerate(iter_raw(path, [w for w in wanted if w in info])):
        if k and k % 20000 == 0:
            progress(f'  {100 * k // total} %')
        msg = deserialize_cdr(m.data, m.type_name)
        if m.topic == JOINT_STATES:
            t.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            position, velocity = msg.position, msg.velocity
            if scene is not None:
                # the scene's joints by name (a URDF arm's locked joints follow them), else
                # the first n_links entries
                position, velocity = _scene_joints(scene, msg.name, position, velocity)
            if coordinates is None:
                pos.append(to_absolute(position))
                vel.append(to_absolute(velocity) if len(velocity) else [math.nan] * len(position))
            else:
                pos.append(coordinates.absolute(position))
                vel.append(
                    coordinates.absolute_rates(velocity)
                    if len(velocity)
                    else [math.nan] * len(position)
                )
            if len(msg.effort) == len(msg.position):
                effort.append(list(msg.effort))
            names = names or tuple(msg.name)
        elif m.topic == IMPACT_REPORT:
            try:
                impacts.append(impact_from_json(msg.data))
            except ImpactArmError as e:
                raise AnalysisError(
                    f'{path}: /impact_report message {len(impacts) + 1}: {e}'
                ) from None
        else:
            dims = msg.layout.dim
            if len(dims) != 2:
                raise AnalysisError(
                    f'{path}: {IMPACT_TRACE} message {len(traces) + 1} has '
                    f'{len(dims)} dimensions, expected 2'
                )
            columns = dims[1].label.split(',')
            data = np.asarray(msg.data, float)[msg.layout.data_offset :]
            traces.append((columns, data.reshape(dims[0].size, dims[1].size)))
    if not t:
        raise AnalysisError(f'{path}: /joint_states has no messages')
    # stamp order, never file order: a recorder that stalled writes what it received late
    # after newer messages (impact reports by their contact time, joint states by stamp)
    impacts.sort(key=lambda record: _number(record.t_contact))
    order = np.argsort(t, kind='stable')
    law = scene.controller.law if scene is not None else ''
    return Run(
        os.path.basename(path),
        np.asarray(t)[order],
        np.asarray(pos, float)[order],
        np.asarray(vel, float)[order],
        impacts,
        traces,
        scene,
        metadata,
        law,
        tuple(sorted(info)),
        np.asarray(effort, float)[order] if len(effort) == len(t) else None,
        names,
    )


def chatter(run: Run) -> list:
    """The joints whose reported efforts (the held commands) alternated in sign every period
    and grew (``physics.stability.ChatterWatch``): a sampled law unstable at its rate."""
    from ..physics.stability import find_chatter

    if run.effort is None or not len(run.effort):
        return []
    n = run.effort.shape[1]
    names = run.joint_names if len(run.joint_names) == n else [f'joint{k + 1}' for k in range(n)]
    return find_chatter(run.t, run.effort, names)


def _number(value: Any) -> float:  # a JSON value
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.inf


def _scene(metadata: dict[str, dict[str, str]]) -> Scene | None:
    text = metadata.get('scene', {}).get('yaml')
    if not text:
        return None
    from ..physics.scene import scene_from_text

    try:
        # a file the scene names (an older recording's arm.urdf) is found beside the scene
        # file the recording was made from
        return scene_from_text(
            text,
            origin='scene stored in the recording',
            path=metadata.get('scene', {}).get('path') or '',
        )
    except ImpactArmError:
        return None
