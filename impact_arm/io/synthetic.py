"""Recordings with known parameters, for the tests and ``bench fit``: the simulator runs a
scene variant, its samples become what a driver would publish (relative joint angles, rates,
efforts, period-averaged wrench) with sensor noise, lost samples and a clock offset, and can
be written as a single MCAP file (our writer) or a rosbag2 folder (the rosbags library's).

The scene's ``sensors`` section (encoder counts, noise, rate readings, latencies) is applied
by the simulated driver's own sensor chain (``driver/sensors.py``), e.g. ``overrides=
{'sensors.rate': 'difference', 'sensors.effort_latency': 0.002}``: a recording "like a real
arm's". With that section the ``noise`` argument defaults to none (the section says it)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import os

import numpy as np

from ..contract import CONTACT_WRENCH, JOINT_STATES, SURFACE_MOUNTS, to_joint_space
from ..calibration.identify import JointRecording
from ..driver.sensors import sensed_series
from .recording import to_model

REALISTIC_NOISE = {'position': 2e-5, 'velocity': 2e-3, 'effort': 0.05, 'wrench': 2.0}


def synthetic_recording(
    scene: Any = 'paper',
    overrides: dict | None = None,
    *,
    cycles: int | None = None,
    publish_rate: float = 1000.0,
    noise: dict | None = None,
    drop: float = 0.0,
    jitter: float = 0.0,
    clock_offset: float = 0.0,
    seed: int = 0,
    wrench: bool = True,
    control_rate: float | None = None,
    plates: bool = True,
) -> JointRecording:
    """Simulate ``scene`` with ``overrides`` and sample it as a driver would: through the
    scene's ``sensors`` section, then adding Gaussian ``noise`` (per signal, see
    REALISTIC_NOISE; none by default when the scene has a sensors section), dropping a
    fraction ``drop`` of the samples, jittering the stamps by ``jitter`` seconds (uniform:
    the values stay those of the regular periods) and offsetting the clock. A scene with
    mounted surfaces also gives their plates' states (as /surface_mounts), unless ``plates``
    is False (a real arm's recording rarely has them)."""
    from ..physics.simulate import run
    from ..calibration.study import Study

    over = dict(overrides or {})
    if cycles is not None:
        over['cycles'] = cycles
    sc = Study(scene).scene(over)
    result = run(sc, publish_rate=publish_rate, control_rate=control_rate)
    if result.error:
        raise RuntimeError(f'synthetic run stopped: {result.error}')
    rng = np.random.default_rng(seed)
    s = result.samples
    t = np.array([x.t for x in s])
    # the model's relative angles (a JointRecording's, as read_recording gives them)
    q = np.array([to_joint_space(x.q) for x in s])
    qd = np.array([to_joint_space(x.qd) for x in s])
    tau = np.array([x.tau for x in s], float)
    w = np.array([x.wrench for x in s], float)
    if not sc.sensors.ideal:
        q, qd, tau, w = sensed_series(sc.sensors, publish_rate, q, qd, tau, w)
    noise = _default_noise(sc, noise)
    q, qd, tau, w = (
        _noisy(x, noise.get(name, 0.0), rng)
        for x, name in ((q, 'position'), (qd, 'velocity'), (tau, 'effort'), (w, 'wrench'))
    )
    keep = rng.random(len(t)) >= drop
    stamps = t + clock_offset + (rng.uniform(-jitter, jitter, len(t)) if jitter else 0.0)
    w_keep = rng.random(len(t)) >= drop
    rec = JointRecording(
        t=stamps[keep] - stamps[keep][0],
        position=q[keep],
        velocity=qd[keep],
        effort=tau[keep],
        joints=list(sc.joint_names),
        source=f'synthetic {scene}',
        t0_ns=round(stamps[keep][0] * 1e9),
    )
    if wrench:
        rec.wrench_t = stamps[w_keep] - stamps[keep][0]
        rec.wrench = w[w_keep]
    if plates and s and s[0].plates:
        # the mounted surfaces' plates, as the simulator publishes them (/surface_mounts)
        rec.plates_t = rec.t.copy()
        rec.plates = np.array([x.plates for x in s], float)[keep]
    # the impacts simulated, for the tests that compare a fit with them (not a field: a
    # recording read from a file has no truth)
    rec.truth = result.impacts  # type: ignore[attr-defined]
    return rec


def _default_noise(scene, noise):
    if noise is not None:
        return noise
    return REALISTIC_NOISE if scene.sensors.ideal else {}


def _noisy(x, sigma, rng):
    return x + rng.normal(0.0, sigma, x.shape) if sigma else x


def _messages(rec: JointRecording):
    """(topic, stamp ns, kind, fields) of the recording in time order."""
    out = []
    for k in range(len(rec.t)):
        ns = rec.t0_ns + round(rec.t[k] * 1e9)
        out.append((ns, 'js', k))
    if rec.wrench is not None and rec.wrench_t is not None:
        for k in range(len(rec.wrench_t)):
            out.append((rec.t0_ns + round(rec.wrench_t[k] * 1e9), 'w', k))
    if rec.plates is not None and rec.plates_t is not None:
        for k in range(len(rec.plates_t)):
            out.append((rec.t0_ns + round(rec.plates_t[k] * 1e9), 'p', k))
    out.sort(key=lambda x: x[0])
    return out


def write_rosbag2(
    rec: JointRecording,
    folder: str | os.PathLike,
    joints: Sequence[str] | None = None,
    states_topic: str = JOINT_STATES,
    wrench_topic: str = CONTACT_WRENCH,
    extra_joint: bool = True,
    frame: str = 'surface',
) -> None:
    """A rosbag2 folder (metadata.yaml + MCAP) written by the rosbags library, not by us; the
    joint states carry an extra joint first (as a real arm's driver may: a gripper)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    JS = store.types['sensor_msgs/msg/JointState']
    WS = store.types['geometry_msgs/msg/WrenchStamped']
    W = store.types['geometry_msgs/msg/Wrench']
    V = store.types['geometry_msgs/msg/Vector3']
    H = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    names = list(joints or rec.joints)
    if extra_joint:
        names = ['gripper'] + names
    with Writer(os.fspath(folder), version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        cjs = writer.add_connection(states_topic, JS.__msgtype__, typestore=store)
        cw = (
            writer.add_connection(wrench_topic, WS.__msgtype__, typestore=store)
            if rec.wrench is not None
            else None
        )
        cp = (
            writer.add_connection(SURFACE_MOUNTS, JS.__msgtype__, typestore=store)
            if rec.plates is not None
            else None
        )
        for ns, kind, k in _messages(rec):
            stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            if kind == 'js':
                pad = [0.0] if extra_joint else []
                msg = JS(
                    header=H(stamp=stamp, frame_id=''),
                    name=names,
                    position=np.array(pad + rec.position[k].tolist()),
                    velocity=np.array(pad + rec.velocity[k].tolist()),
                    effort=np.array(pad + rec.effort[k].tolist()),
                )
                writer.write(cjs, ns, store.serialize_cdr(msg, JS.__msgtype__))
            elif kind == 'p':
                # _messages lists plates and wrenches only for a recording that has them
                assert cp is not None and rec.plates is not None
                plate = rec.plates[k]
                msg = JS(
                    header=H(stamp=stamp, frame_id=''),
                    name=[f'surface{i + 1}' for i in range(len(plate) // 2)],
                    position=np.array(plate[0::2], float),
                    velocity=np.array(plate[1::2], float),
                    effort=np.zeros(0),
                )
                writer.write(cp, ns, store.serialize_cdr(msg, JS.__msgtype__))
            else:
                assert cw is not None and rec.wrench is not None
                fx, fy = rec.wrench[k]
                msg = WS(
                    header=H(stamp=stamp, frame_id=frame),
                    wrench=W(
                        force=V(x=float(fx), y=float(fy), z=0.0), torque=V(x=0.0, y=0.0, z=0.0)
                    ),
                )
                writer.write(cw, ns, store.serialize_cdr(msg, WS.__msgtype__))


def driver_recording(
    scene: Any = 'paper',
    overrides: dict | None = None,
    *,
    rate: float = 1000.0,
    cycles: int = 6,
    noise: dict | None = None,
    seed: int = 0,
    t_max: float | None = None,
) -> JointRecording:
    """What the simulator node publishes (``SimulatedArm``: each period's effort is the
    command held over the period that ends at the stamp; the scene's ``sensors`` section
    applied) under the scene's controller sampled at ``rate`` — the reading of efforts of a
    ros2_control driver. The controller sees what is published, as over the topics."""
    from ..physics.control import CycleController
    from ..physics.cycle_count import CycleCount
    from ..driver.arm import SimulatedArm
    from ..calibration.study import Study

    sc = Study(scene).scene(dict(overrides or {}))
    arm = SimulatedArm(sc, rate)
    ctrl = CycleController.for_scene(arm.model, sc.controller)
    rng = np.random.default_rng(seed)
    rows, count, t_end = [], CycleCount(cycles), t_max or sc.t_max
    tick = arm.sample()
    while count.completed < cycles and tick.t < t_end:
        before = ctrl.mode
        coordinates = arm.coordinates  # the wire's: the robot's joint coordinates
        arm.apply(
            coordinates.efforts(
                ctrl.update(
                    tick.t,
                    coordinates.absolute(tick.position),
                    coordinates.absolute_rates(tick.velocity),
                    normal_force=tick.wrench[1],
                )
            )
        )
        count.turn(before, ctrl.mode, tick.t)
        tick = arm.step()
        rows.append((tick.t, tick.position, tick.velocity, tick.effort, tick.wrench))
    noise = _default_noise(sc, noise)
    t = np.array([r[0] for r in rows])
    q, qd, tau, w = (np.array([r[k] for r in rows], float) for k in range(1, 5))
    q, qd, tau, w = (
        _noisy(x, noise.get(name, 0.0), rng)
        for x, name in ((q, 'position'), (qd, 'velocity'), (tau, 'effort'), (w, 'wrench'))
    )
    rec = JointRecording(
        t=t - t[0],
        position=q,
        velocity=qd,
        effort=tau,
        wrench_t=t - t[0],
        wrench=w,
        joints=list(sc.joint_names),
        source=f'driver {scene}',
        t0_ns=round(t[0] * 1e9),
    )
    if not sc.joint_coordinates.is_identity:
        to_model(rec, sc.joint_coordinates)  # as read_recording gives a recording
    return rec
