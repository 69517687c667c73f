"""The strikes every peer is tuned on, and their outcome in the package's own model.

A strike is the whole arm arriving at the surface with its joints unpowered (the article's
contact: gravity and the joints' own friction act, the motors do not), in the posture of
the scene's limit-cycle impact (its last impact), at a speed ratio s of that impact's tip
speed:

- oblique: the limit-cycle joint rates times s (the tip's velocity keeps its direction);
- normal: the joint rates of least norm that give the tip a velocity straight down, of the
  limit-cycle tip speed times s.

The outcome is read where each model's contact ends (our separation event; the peers' last
step with a contact force): the kinematic coefficient of restitution -v_y,after/v_y,before,
the contact's duration, its peak normal force and the tip's tangential velocity after it."""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass

import numpy as np

from ..physics.errors import SimulationError
from ..physics.impact import Impact
from ..physics.integrator import IntegratorOptions, PhaseIntegrator
from ..physics.metrics import ImpactBuilder
from ..physics.model import ArmModel
from ..physics.periods import feed_events
from ..physics.scene import Scene
from ..physics.simulate import run

SPEED_RATIOS = (0.5, 0.75, 1.0, 1.25, 1.5)  # of the limit-cycle impact speed
# our strike starts this long before the contact, so the contact is located as in a run
LEAD_TIME = 1e-7  # [s]


class StrikeKind(enum.Enum):
    NORMAL = 'normal'
    OBLIQUE = 'oblique'


@dataclass(frozen=True)
class Strike:
    kind: StrikeKind
    speed_ratio: float  # of the limit-cycle impact's tip speed
    q: tuple[float, ...]  # absolute link angles at contact [rad]
    qd: tuple[float, ...]  # absolute link rates [rad/s]
    joints: tuple[float, ...]  # the robot's joint angles at contact [rad]
    joint_rates: tuple[float, ...]  # the robot's joint rates [rad/s]
    v_before: tuple[float, float]  # tip velocity (x, y) at contact [m/s]
    surface: int  # index of the struck surface

    @property
    def label(self) -> str:
        return f'{self.kind.value} {self.speed_ratio:g}x'

    @property
    def speed(self) -> float:
        return math.hypot(*self.v_before)


@dataclass(frozen=True)
class Outcome:
    cor: float  # -v_y,after / v_y,before
    duration: float  # [s]
    F_max: float  # peak normal force [N]
    v_t_after: float  # tip velocity along the surface after the contact [m/s]
    separated: bool = True  # False: the tip had not left the surface when the run ended
    # a peer's outcomes at the phases of its time step this one is the mean of (``phases``);
    # empty for ours (continuous time) and for one phase
    phases: tuple[Outcome, ...] = ()


def rigid(scene: Scene) -> Scene:
    """The scene with its surfaces rigidly mounted: the peers are tuned on the contact
    alone (a mount is a body of its own, not a contact parameter)."""
    return dataclasses.replace(
        scene, surfaces=tuple(dataclasses.replace(s, mount=None) for s in scene.surfaces)
    )


def limit_cycle_impact(scene: Scene) -> Impact:
    """The impact record the scene's run settles on (its last impact)."""
    result = run(scene, samples=False)
    if not result.impacts:
        raise SimulationError(
            f'scene {scene.name!r}: no impact in its run ({result.stopped}); '
            'an export needs the impact it settles on'
        )
    return result.impacts[-1]


def contact_rates(model: ArmModel, record: Impact) -> np.ndarray:
    """The absolute link rates at an impact's contact: J⁻¹ v for two links; for more, the
    rates that give the record's tip velocity and every link's kinetic energy."""
    n = model.n
    q = np.radians(np.asarray(record.q_contact_deg, float))
    v = np.asarray(record.v_before, float)
    jacobian = np.asarray(model.tip_jacobian(q), float).reshape(2, n)
    if n == 2:
        return np.linalg.solve(jacobian, v)
    from scipy.optimize import least_squares

    energies = np.asarray(record.T_before[:n], float)
    scale_v, scale_t = max(float(np.hypot(*v)), 1e-9), max(float(np.sum(energies)), 1e-12)

    def misfit(qd: np.ndarray) -> np.ndarray:
        return np.concatenate(
            [(jacobian @ qd - v) / scale_v, (model.link_energies(q, qd) - energies) / scale_t]
        )

    fit = least_squares(misfit, np.linalg.pinv(jacobian) @ v, method='lm', xtol=1e-15)
    if not float(np.max(np.abs(fit.fun))) < 1e-8:
        raise SimulationError(
            'the limit-cycle impact: no joint rates give its tip velocity and link energies'
        )
    return np.asarray(fit.x, float)


def strikes(
    scene: Scene, ratios: tuple[float, ...] = SPEED_RATIOS, record: Impact | None = None
) -> list[Strike]:
    """The normal and oblique strikes at each speed ratio, from the limit-cycle impact."""
    for ratio in ratios:
        if not 0.0 < ratio <= 10.0:
            raise ValueError(f'speed ratio {ratio}: must be in (0, 10]')
    model = ArmModel(scene)
    record = record if record is not None else limit_cycle_impact(scene)
    n = model.n
    q = np.radians(np.asarray(record.q_contact_deg, float))
    qd_cycle = contact_rates(model, record)
    jacobian = np.asarray(model.tip_jacobian(q), float).reshape(2, n)
    speed = float(np.hypot(*record.v_before))
    qd_normal = np.linalg.pinv(jacobian) @ np.array([0.0, -speed])
    coordinates = scene.joint_coordinates
    out = []
    for kind, rates in ((StrikeKind.NORMAL, qd_normal), (StrikeKind.OBLIQUE, qd_cycle)):
        for ratio in ratios:
            qd = ratio * rates
            out.append(
                Strike(
                    kind,
                    float(ratio),
                    tuple(float(x) for x in q),
                    tuple(float(x) for x in qd),
                    tuple(float(x) for x in coordinates.positions(q)),
                    tuple(float(x) for x in coordinates.rates(qd)),
                    (float(jacobian[0] @ qd), float(jacobian[1] @ qd)),
                    0,  # the first surface: an impact record names none
                )
            )
    return out


def our_outcome(scene: Scene, strike: Strike) -> Outcome:
    """The strike in the package's model (the scene's contact laws, rigid surfaces)."""
    model = ArmModel(rigid(scene))
    n = model.n
    q, qd = np.asarray(strike.q), np.asarray(strike.qd)
    state = model.initial_state()
    state.y[:n], state.y[n : 2 * n] = q - qd * LEAD_TIME, qd
    state.mode = 'up'  # the controller is off (held zero torque); no down/up switch matters
    integ = PhaseIntegrator(
        model,
        state,
        control='held',
        options=IntegratorOptions.of_scene(scene.integrator, preset='balanced'),
    )
    builder = ImpactBuilder(model)
    t_end = 0.05  # far longer than any contact of a stiff surface
    while state.t < t_end:
        done = feed_events(integ, builder, integ.advance(t_end, stop_at_event=True))
        if done:
            record = done[0][0]
            return Outcome(
                float(record.cor_kinematic),
                float(record.duration),
                float(record.F_max),
                float(record.v_after[0]),
            )
    raise SimulationError(f'strike {strike.label}: the contact did not end within {t_end} s')
