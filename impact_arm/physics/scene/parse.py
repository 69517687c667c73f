"""Scene data (parsed YAML) to the frozen ``Scene``: the schema, the arm, the checks."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

from ...contract import ControlLaw, IntegratorPreset, JointCoordinates, PidSpace, StepMethod
from .arm import _arm_links
from .checks import MAX_YIELD_STRAIN, _check_joints, _check_physics, _joint_values, _sensor_spec
from .schema import REQUIRED, SCHEMA, SceneChecker
from .types import (
    ContactLaw,
    ControllerSpec,
    IntegratorSpec,
    Material,
    Mount,
    Scene,
    Surface,
    reduced_modulus,
)


def parse_scene(
    data: Any,
    origin: str = '<scene>',
    text: str = '',
    path: str = '',
    *,
    checked: dict | None = None,
) -> Scene:
    """Validate a scene already parsed from YAML and build the frozen ``Scene``.

    ``checked``: for many variants of one scene's data that share their unchanged parts
    and are never changed in place (a study's runs, ``study.apply_overrides``), a dict
    kept between the calls: a shared part already checked is not checked again. The
    checks across keys always run; a variant is refused exactly as without it."""
    check = SceneChecker(origin, checked)
    raw = check.leaf('', data, ('dict', SCHEMA, '', REQUIRED))
    links = _arm_links(check, raw, path)
    n = len(links.lengths)

    def vector(path: str, values: Sequence | None, default: Any = None) -> tuple:
        if values is None:
            return tuple(default for _ in range(n))
        if len(values) != n:
            check.fail(path, f'has {len(values)} entries: must have one per link ({n})')
        return tuple(values)

    # A URDF arm's angles are the robot's joint angles (its zero and sign); the scene's rods
    # give absolute link angles. Inside, everything is absolute.
    robot_coordinates = links.key != 'links'
    coordinates = JointCoordinates(
        tuple(j.sign for j in links.joints), tuple(j.offset for j in links.joints)
    )

    def angles(path: str, degrees: Sequence) -> tuple:
        values = [math.radians(v) for v in vector(path, degrees)]
        return tuple(coordinates.absolute(values) if robot_coordinates else values)

    materials = {k: Material(**v) for k, v in raw['materials'].items()}

    def material(path: str, name: str) -> Material:
        if name not in materials:
            check.fail(path, f"= {name!r} names no entry of 'materials' ({', '.join(materials)})")
        return materials[name]

    arm = material('arm_material', raw['arm_material'])
    surfaces = tuple(
        Surface(
            height=s['height'],
            law=ContactLaw(s['law']),
            mu=s['mu'],
            v_d=s['v_d'],
            material=material(f'surfaces[{i}].material', s['material']),
            mount=Mount(**s['mount']) if s['mount'] is not None else None,
        )
        for i, s in enumerate(raw['surfaces'])
    )
    heights = [s.height for s in surfaces]
    if len(set(heights)) != len(heights):
        check.fail('surfaces', f'= heights {heights}: two surfaces at the same height')

    c = raw['controller']
    controller = ControllerSpec(
        law=ControlLaw(c['law']),
        space=PidSpace(c['space']),
        kp=vector('controller.kp', c['kp']),
        kd=vector('controller.kd', c['kd']),
        ki=vector('controller.ki', c['ki'], 0.0),
        down_target=angles('controller.down_target_deg', c['down_target_deg']),
        up_target=angles('controller.up_target_deg', c['up_target_deg']),
        switch_height=c['switch_height'],
        rate=c['rate'],
        allow_unstable=c['allow_unstable'],
    )
    if controller.law == 'pid' and not any(controller.ki):
        check.fail('controller.ki', '= all zero with law pid: use law pd, or give integral gains')

    q0 = angles('initial.q_deg', raw['initial']['q_deg'])
    qd0 = vector('initial.qd', raw['initial']['qd'], 0.0)
    if robot_coordinates:
        qd0 = tuple(coordinates.absolute_rates(qd0))
    reach = sum(links.lengths[:-1]) + math.hypot(*links.tip_point)
    for i, s in enumerate(surfaces):
        if s.law != 'none' and abs(s.height) >= reach:
            check.fail(
                f'surfaces[{i}].height',
                f'= {s.height:g} is out of reach: must satisfy |height| < {reach:g} (m)',
            )
    for i, s in enumerate(surfaces):
        if s.law != 'elastoplastic':
            continue
        # the Jackson-Green fit (B = 0.14 exp(23 S_y/E)) holds for metals-like yield strains;
        # far beyond it B overflows and the force law means nothing
        strain = min(arm.S_y, s.material.S_y) / reduced_modulus(arm, s.material)
        if strain > MAX_YIELD_STRAIN:
            check.fail(
                f'surfaces[{i}].material',
                f'= {raw["surfaces"][i]["material"]!r}: yield strain S_y/E* = '
                f'{strain:.3g} is out of range: must be <= {MAX_YIELD_STRAIN:g} for the '
                f'elasto-plastic (Jackson-Green) law; use law hertz, or a consistent '
                f'E and S_y',
            )
    joints = _joint_values(check, links, raw['joints'])
    _check_physics(check, raw, links, surfaces, arm)
    _check_joints(check, links, joints)
    integ = IntegratorSpec(**raw['integrator'])
    integ = dataclasses.replace(
        integ, preset=IntegratorPreset(integ.preset), method=StepMethod(integ.method)
    )
    sensors = _sensor_spec(check, raw['sensors'])
    scene = Scene(
        name=raw['name'],
        lengths=links.lengths,
        masses=links.masses,
        gravity=raw['gravity'] * links.gravity_scale,
        tip_radius=links.tip_radius,
        arm_material=arm,
        surfaces=surfaces,
        actuators_during_contact=raw['actuators_during_contact'],
        controller=controller,
        q0=q0,
        qd0=qd0,
        cycles=raw['cycles'],
        t_max=raw['t_max'],
        publish_rate=raw['publish_rate'],
        integrator=integ,
        com=links.com,
        inertias=links.inertias,
        tip_point=links.tip_point,
        joints=joints,
        link_names=links.link_names,
        urdf_path=links.urdf_path,
        locked_joints=links.locked,
        plane=links.plane,
        notes=links.notes,
        joint_limits=raw['joint_limits'],
        urdf_text=links.urdf_text,
        sensors=sensors,
        source_text=text,
        source_path=path,
    )
    _check_stability(origin, scene)
    return scene


def _check_stability(origin: str, scene: Scene) -> None:
    """A sampled law unstable at the scene's own rate is refused (or warned, with
    ``controller.allow_unstable``): its commands would chatter (``physics/stability.py``)."""
    c = scene.controller
    if not c.rate or c.law == 'none':
        return
    from ..stability import check_stability

    check_stability(scene, origin=origin)  # named as the other refusals name it
