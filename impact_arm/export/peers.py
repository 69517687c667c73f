"""The simulators the arm is exported to, and what each cannot represent of our contact."""

from __future__ import annotations

import enum
import importlib.util

from ..physics.errors import ImpactArmError


class Peer(enum.Enum):
    MUJOCO = 'mujoco'
    DRAKE = 'drake'
    GAZEBO = 'gazebo'


class PeerMissing(ImpactArmError):
    """The peer's Python package is not installed (the export runs the peer to tune it)."""


# the module each peer is run through, and its PyPI package (Gazebo is not run: a model here)
PACKAGES = {Peer.MUJOCO: ('mujoco', 'mujoco'), Peer.DRAKE: ('pydrake', 'drake')}


def require(peer: Peer) -> None:
    """Raise PeerMissing, with the pip command, when ``peer``'s package is not installed."""
    if peer not in PACKAGES:
        return
    module, package = PACKAGES[peer]
    if importlib.util.find_spec(module) is None:
        raise PeerMissing(
            f'--to {peer.value}: the export runs {peer.value} to tune its contact, and the '
            f'{package} package is not installed: pip install {package} '
            f"(or pip install 'impact_arm[export]' for both peers)"
        )


# in words, for the report: what stays of our contact model however the peer is tuned
LIMITS = {
    Peer.MUJOCO: (
        "MuJoCo's contact is a soft constraint whose reference acceleration is a linear "
        'spring-damper in the penetration (solref), scaled by an impedance that rises with '
        'depth (solimp). Its coefficient of restitution is set by the damping ratio and does '
        'not fall with the impact speed as ours does (yield makes our rebound weaker the '
        'harder the strike); the force grows about linearly with the speed where ours grows '
        'more slowly (Jackson-Green yield caps the pressure); the residual dent is not kept. '
        'Friction is a soft elliptic cone, not our tanh-smoothed Coulomb law.'
    ),
    Peer.DRAKE: (
        "Drake's point contact is Hunt-Crossley, f = k x (1 + d ẋ), with a linear spring: "
        'its restitution falls with the impact speed (the dissipation term grows with it), '
        'which follows our trend in kind but not in measure, and its force is linear in the '
        'penetration where ours is Hertz (x^1.5) and then elasto-plastic. The residual dent '
        "is not kept. Drake's SDF joints have viscous damping and rotor inertia but no "
        "Coulomb friction: the scene's joint friction is written and ignored by Drake."
    ),
    Peer.GAZEBO: (
        "Gazebo's ODE contact is a spring-damper (kp, kd as ERP and CFM) with a "
        'velocity-level bounce: the rebound is a fixed fraction of the approach speed, '
        'imposed within a step, so the coefficient of restitution cannot fall with speed '
        'and the duration and peak force follow the spring, not the rebound. These numbers '
        "come from a model of ODE's contact written here, not from Gazebo, which was not "
        'run: check them in Gazebo before relying on them. SDF has no armature.'
    ),
}
