"""Checks across keys: each bounds what the model or the numerics can do (docs/scene.md,
"Physical ranges"), and the sections whose keys depend on one another."""

from __future__ import annotations

import math
from collections.abc import Sequence

from .arm import _ArmLinks
from .schema import SceneChecker
from .types import JointSpec, RateReading, SensorSpec, reduced_modulus

MAX_YIELD_STRAIN = 0.1  # S_y / E* beyond which the Jackson-Green law is meaningless
MAX_LENGTH_RATIO = 1e3  # longest / shortest link
MAX_MASS_RATIO = 1e4  # heaviest / lightest link
MIN_CONTACT_TIME = 1e-6  # s, Hertz contact duration at 1 m/s
MAX_LOOP_RATE = 1e5  # 1/s, the control loop's fastest eigenvalue (kd/I, sqrt(kp/I))
# a link's inertia about its joint, at least, in m L^2 (a rod has 1/3): below it the link
# turns almost freely about its joint and the mass matrix is near singular
MIN_JOINT_INERTIA = 1e-6
MAX_COM_DISTANCE = 10.0  # a link's centre of mass from its joint, at most, in link lengths


def _joint_inertias(check: SceneChecker, links: _ArmLinks) -> list[float]:
    """Each link's inertia about its joint, refused when too small; a rod's m L² / 3."""
    out = []
    for k, (length, mass, (cx, cy), inertia) in enumerate(
        zip(links.lengths, links.masses, links.com, links.inertias)
    ):
        rod = (cx, cy) == (length / 2, 0.0) and inertia == mass * length * length / 12
        where = (
            f'links[{k}]' if links.key == 'links' else f"{links.key} link '{links.link_names[k]}'"
        )
        if math.hypot(cx, cy) > MAX_COM_DISTANCE * length:
            check.fail(
                f'{where}.com_x' if links.key == 'links' else f'{where} centre of mass',
                f'= ({cx:g}, {cy:g}) m is out of range: must lie within '
                f'{MAX_COM_DISTANCE:g} link lengths ({MAX_COM_DISTANCE * length:g} m) of the '
                f"link's joint (a link's mass lies on or near the link)",
            )
        about_joint = mass * length**2 / 3 if rod else inertia + mass * (cx * cx + cy * cy)
        if about_joint < MIN_JOINT_INERTIA * mass * length**2:
            check.fail(
                f'{where}.inertia' if links.key == 'links' else f'{where} inertia',
                f'= {inertia:g} with the centre of mass at ({cx:g}, {cy:g}) m: the inertia '
                f'about the joint, {about_joint:.3g} kg m^2, is out of range: must be >= '
                f'{MIN_JOINT_INERTIA:g} m L^2 = {MIN_JOINT_INERTIA * mass * length**2:.3g} '
                f'(the link would turn almost freely: mass matrix near singular)',
            )
        out.append(about_joint)
    return out


def _joint_values(check: SceneChecker, links: _ArmLinks, entries: Sequence[dict]) -> tuple:
    """The arm's joints (names and limits from ``links``) with the values the scene's
    ``joints`` states: one entry per link, or none."""
    from dataclasses import replace

    if not entries:
        return links.joints
    n = len(links.lengths)
    if len(entries) != n:
        check.fail('joints', f'has {len(entries)} entries: must have one per link ({n}) or none')
    return tuple(
        replace(joint, **{k: v for k, v in entry.items() if v is not None})
        for joint, entry in zip(links.joints, entries)
    )


def _check_joints(check: SceneChecker, links: _ArmLinks, joints: Sequence[JointSpec]) -> None:
    """Joint friction and armature within what the numerics can follow."""
    for k, joint in enumerate(joints):
        cx, cy = links.com[k]
        own = links.inertias[k]  # the link about its centre of mass
        inertia = own + links.masses[k] * (cx * cx + cy * cy) + joint.armature
        # near ω = 0 smoothed Coulomb friction is a damper of slope friction / friction_v_d
        for key, value, rate in (
            ('damping', joint.damping, joint.damping / inertia),
            ('friction', joint.friction, joint.friction / joint.friction_v_d / inertia),
        ):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'joints[{k}].{key}',
                    f'= {value:g} is out of range: gives a decay rate of {rate:.3g} 1/s '
                    f'on link {k + 1} (inertia {inertia:.3g} kg m^2'
                    + (f', friction_v_d {joint.friction_v_d:g} rad/s' if key == 'friction' else '')
                    + f'); must be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: '
                    f'beyond the run budget)',
                )
        if joint.armature > MAX_MASS_RATIO * own:
            check.fail(
                f'joints[{k}].armature',
                f'= {joint.armature:g} is out of range: must be <= {MAX_MASS_RATIO:g} times '
                f"link {k + 1}'s own inertia ({MAX_MASS_RATIO * own:.3g} kg m^2: the mass "
                f'matrix becomes too ill-conditioned to solve)',
            )


def _check_physics(check, raw, links, surfaces, arm):
    """Ranges that involve several keys: each bounds what the model or the numerics can do."""
    lengths, masses = links.lengths, links.masses
    joint_inertias = _joint_inertias(check, links)
    if max(lengths) / min(lengths) > MAX_LENGTH_RATIO:
        check.fail(
            links.key,
            f'= lengths {min(lengths):g} .. {max(lengths):g} m: ratio '
            f'{max(lengths) / min(lengths):.3g} is out of range: must be <= '
            f'{MAX_LENGTH_RATIO:g} (the absolute tolerances, in m and rad, cannot suit '
            f'both ends of the arm)',
        )
    if max(masses) / min(masses) > MAX_MASS_RATIO:
        check.fail(
            links.key,
            f'= masses {min(masses):g} .. {max(masses):g} kg: ratio '
            f'{max(masses) / min(masses):.3g} is out of range: must be <= '
            f'{MAX_MASS_RATIO:g} (the mass matrix becomes too ill-conditioned to solve)',
        )
    if links.tip_radius > min(lengths):
        check.fail(
            'tip_radius' if links.key == 'links' else 'arm.contact.radius',
            f'= {links.tip_radius:g} is out of range: must be <= the '
            f'shortest link ({min(lengths):g} m): the tip is a sphere on a slender rod',
        )
    # Hertz contact duration of the lightest link's mass striking at 1 m/s:
    # t_c = 2.87 (m^2 / (R E*^2 v))^(1/5); the contact phases need steps well below it
    for i, sfc in enumerate(surfaces):
        if sfc.law == 'none':
            continue
        e_red = reduced_modulus(arm, sfc.material)
        t_c = 2.87 * (min(masses) ** 2 / (links.tip_radius * e_red**2)) ** 0.2
        if t_c < MIN_CONTACT_TIME:
            check.fail(
                f'surfaces[{i}].material',
                f'= {raw["surfaces"][i]["material"]!r}: contact lasts ~{t_c:.2g} s '
                f'(Hertz, lightest link at 1 m/s), out of range: must be >= '
                f'{MIN_CONTACT_TIME:g} s (stiffness E* = {e_red:.3g} Pa against link '
                f'masses down to {min(masses):g} kg: steps would fall under the '
                f'resolution of t)',
            )
    for i, sfc in enumerate(surfaces):
        if sfc.mount is None or sfc.law == 'none':
            continue
        mount = sfc.mount
        omega = math.sqrt(mount.stiffness / mount.mass)
        for key, rate in (('stiffness', omega), ('damping_ratio', 2 * mount.damping_ratio * omega)):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'surfaces[{i}].mount.{key}',
                    f'= {getattr(mount, key):g} is out of range: gives the plate a rate of '
                    f'{rate:.3g} 1/s (mass {mount.mass:g} kg, stiffness {mount.stiffness:g} '
                    f'N/m); must be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: beyond '
                    f'the run budget)',
                )
        e_red = reduced_modulus(arm, sfc.material)
        t_c = 2.87 * (mount.mass**2 / (links.tip_radius * e_red**2)) ** 0.2
        if t_c < MIN_CONTACT_TIME:
            check.fail(
                f'surfaces[{i}].mount.mass',
                f'= {mount.mass:g} is out of range: the tip would bounce off the plate in '
                f'~{t_c:.2g} s (Hertz at 1 m/s); must be >= {MIN_CONTACT_TIME:g} s: steps '
                f'would fall under the resolution of t',
            )
    c = raw['controller']
    for k, inertia in enumerate(joint_inertias):
        for key, rate in (
            ('kd', c['kd'][k] / inertia if k < len(c['kd']) else 0.0),
            ('kp', math.sqrt(c['kp'][k] / inertia) if k < len(c['kp']) else 0.0),
        ):
            if rate > MAX_LOOP_RATE:
                check.fail(
                    f'controller.{key}[{k}]',
                    f'= {c[key][k]:g} is out of range: gives a closed-loop rate of '
                    f'{rate:.3g} 1/s on link {k + 1} (inertia {inertia:.3g} kg m^2); must '
                    f'be <= {MAX_LOOP_RATE:g} 1/s (explicit steps of ~10 us: beyond the run budget)',
                )
    if 0 < c['rate'] < 1:
        check.fail(
            'controller.rate',
            f'= {c["rate"]:g} is out of range: must be 0 '
            f'(continuous) or >= 1 (Hz): a slower sampled controller holds one torque '
            f'for more than a second',
        )


def _sensor_spec(check: SceneChecker, raw: dict) -> SensorSpec:
    """The checked ``sensors`` section; a key that the chosen rate reading would ignore is
    refused rather than silently dropped."""
    if not raw:  # the section left out: ideal sensors
        return SensorSpec()
    rate = RateReading(raw['rate'])
    if raw['rate_noise'] and rate is not RateReading.EXACT:
        check.fail(
            'sensors.rate_noise',
            f'= {raw["rate_noise"]:g} applies to rate: exact only; rate: {rate.value} '
            f'derives the rates from the published positions and carries their noise',
        )
    if rate is RateReading.FILTERED and raw['rate_cutoff'] is None:
        check.fail('sensors.rate_cutoff', 'is missing: rate: filtered needs a cut-off (Hz)')
    if rate is not RateReading.FILTERED and raw['rate_cutoff'] is not None:
        check.fail(
            'sensors.rate_cutoff',
            f'= {raw["rate_cutoff"]:g} applies to rate: filtered only (rate is {rate.value})',
        )
    return SensorSpec(**{**raw, 'rate': rate})
