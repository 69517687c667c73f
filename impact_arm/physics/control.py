"""Control laws (article §2.3, docs/model.md) and the down/up cycle logic, free of ROS.

Torques are joint torques τ_i acting from link i-1 on link i (τ_1 = T01, τ_2 = T12). With the
absolute-angle coordinates of the model they enter Lagrange's equations as
Q_i = τ_i - τ_{i+1} (article eq. 6).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import math
from dataclasses import dataclass, field

import numpy as np

from ..contract import ANTIWINDUP_STRATEGIES, AntiWindup, ControlLaw, CycleMode, PidSpace
from .jit import jit_leaf as jit

if TYPE_CHECKING:
    from .model import ArmModel
    from .scene import ControllerSpec


@jit
def add_joint_torques(tau: np.ndarray, generalized: np.ndarray) -> None:
    """Q_i += τ_i - τ_{i+1}: joint i's torque acts on link i and reacts on link i-1."""
    n = tau.shape[0]
    for i in range(n):
        generalized[i] += tau[i] - (tau[i + 1] if i + 1 < n else 0.0)


@jit
def q_law(
    q: np.ndarray,
    qd: np.ndarray,
    target: np.ndarray,
    kp: np.ndarray,
    kd: np.ndarray,
    gravity_forces: np.ndarray,
    out: np.ndarray,
) -> None:
    """Article eq. 9 generalised to n links: PD on the absolute angles plus exact gravity
    compensation. τ_i = -Kd_i q̇_i - Kp_i (q_i - q_if) - Σ_{j≥i} Q_jg, so that after the
    mapping Q_i = τ_i - τ_{i+1} the gravity generalized forces cancel exactly."""
    tail = 0.0
    for i in range(q.shape[0] - 1, -1, -1):
        tail += gravity_forces[i]
        out[i] = -kd[i] * qd[i] - kp[i] * (q[i] - target[i]) - tail


@jit
def pid_error(
    q: np.ndarray,
    qd: np.ndarray,
    target: np.ndarray,
    joint_space: bool,
    error: np.ndarray,
    rate: np.ndarray,
) -> None:
    """Error and its rate in the angles the PID acts on: absolute link angles (article
    eq. 10 as docs/model.md reads it) or relative joint angles (encoder angles)."""
    for i in range(q.shape[0]):
        if joint_space and i > 0:
            error[i] = (q[i] - q[i - 1]) - (target[i] - target[i - 1])
            rate[i] = qd[i] - qd[i - 1]
        else:
            error[i] = q[i] - target[i]
            rate[i] = qd[i]


@jit
def pid_law(
    error: np.ndarray,
    rate: np.ndarray,
    integral: np.ndarray,
    kp: np.ndarray,
    kd: np.ndarray,
    ki: np.ndarray,
    out: np.ndarray,
) -> None:
    """τ_i = -Kd_i ė_i - Kp_i e_i - Ki_i ∫e_i (article eq. 10; PD when Ki = 0)."""
    for i in range(error.shape[0]):
        out[i] = -kd[i] * rate[i] - kp[i] * error[i] - ki[i] * integral[i]


@dataclass
class PidIntegrator:
    """Discrete integral state and output limits of the PID, as control_toolbox names them:
    ``i_clamp_*`` clamp the integral term (strategy 'legacy'), ``u_clamp_*`` the output; with
    'conditional_integration' a joint's integral is frozen while its output is at a limit
    (so it never winds up against a saturated actuator); 'none' integrates regardless."""

    n: int
    i_clamp_max: float = math.inf
    i_clamp_min: float = -math.inf
    antiwindup: AntiWindup | str = AntiWindup.NONE
    u_clamp_max: float = math.inf
    u_clamp_min: float = -math.inf
    value: list = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.antiwindup not in ANTIWINDUP_STRATEGIES:
            raise ValueError(
                f"antiwindup_strategy = '{self.antiwindup}': choose one of "
                f'{", ".join(ANTIWINDUP_STRATEGIES)}'
            )
        self.antiwindup = AntiWindup(self.antiwindup)  # parsed once: compared as a member
        if not self.u_clamp_min <= self.u_clamp_max:
            raise ValueError(
                f'u_clamp_min = {self.u_clamp_min:g} > u_clamp_max = {self.u_clamp_max:g}'
            )
        self.reset()

    def saturated(self, output: Iterable[float]) -> list[bool]:
        """Per joint: is this output at (or beyond) a limit?"""
        return [not self.u_clamp_min < u < self.u_clamp_max for u in output]

    def clamp(self, output: np.ndarray) -> None:
        """Limit ``output`` (a float array) to [u_clamp_min, u_clamp_max] in place."""
        np.clip(output, self.u_clamp_min, self.u_clamp_max, out=output)

    def reset(self) -> None:
        self.value = [0.0] * self.n

    def update(
        self,
        error: Sequence[float] | np.ndarray,
        dt: float,
        ki: Sequence[float],
        saturated: Sequence[bool] | None = None,
    ) -> None:
        for i in range(self.n):
            if self.antiwindup is AntiWindup.CONDITIONAL_INTEGRATION and saturated and saturated[i]:
                continue  # hold the integral while the actuator is at its limit
            self.value[i] += error[i] * dt
            if self.antiwindup is AntiWindup.LEGACY and ki[i] > 0:
                # clamp the integral *term* ki·∫e to [i_clamp_min, i_clamp_max]
                term = min(max(ki[i] * self.value[i], self.i_clamp_min), self.i_clamp_max)
                self.value[i] = term / ki[i]


class CycleController:
    """The down/up striking cycle as a sampled controller sees it (ROS node, offline ZOH).

    It knows only what a real model-based controller knows: the arm's kinematics and gravity
    terms (``model``), the sampled joint state and, if available, the contact force. Down→up on
    impact (normal force above ``force_threshold``, or the tip's vertical velocity reversing
    within ``reversal_band`` of the surface); up→down when the tip reaches ``switch_height``.
    """

    def __init__(
        self,
        model: ArmModel,
        law: ControlLaw | str,
        kp: Sequence[float],
        kd: Sequence[float],
        ki: Sequence[float],
        down_target: Sequence[float],
        up_target: Sequence[float],
        switch_height: float,
        surface_height: float | None,
        space: PidSpace | str = PidSpace.ABSOLUTE,
        force_threshold: float = 1.0,
        reversal_band: float = 0.01,
        integrator: PidIntegrator | None = None,
    ):
        self.model = model
        self.law = law  # (parsed by the property: compared as a member below)
        self.kp, self.kd, self.ki = kp, kd, ki  # (float lists: the properties convert)
        self.targets = {CycleMode.DOWN: list(down_target), CycleMode.UP: list(up_target)}
        self.switch_height = switch_height
        self.surface_height = surface_height
        self.space = space
        self.force_threshold = force_threshold
        self.reversal_band = reversal_band
        self.integral = integrator or PidIntegrator(len(kp))
        self.mode = CycleMode.DOWN
        self.switches = 0
        # an impact the prediction met before the samples show it (``anticipate_impact``)
        self.impact_ahead = False
        self.anticipated = 0  # down-to-up switches made so, ahead of the sampled impact
        self._last_t: float | None = None
        self._last_vy: float | None = None
        # the compiled kinematics take arrays: the sample is copied into these each call
        # (numpy's conversion of a list allocates, which costs more than the kinematics)
        self._q = np.zeros(model.n)
        self._qd = np.zeros(model.n)

    @classmethod
    def for_scene(cls, model: ArmModel, spec: ControllerSpec) -> CycleController:
        """The controller a scene's ``controller`` section (``spec``) describes, switching on
        its lowest surface (offline runs and tests; the node builds its own from parameters)."""
        return cls(
            model,
            spec.law,
            spec.kp,
            spec.kd,
            spec.ki,
            spec.down_target,
            spec.up_target,
            spec.switch_height,
            min((s.height for s in model.surfaces), default=None),
            space=spec.space,
        )

    def rearm(self, restart: bool = False) -> None:
        """Forget the previous sample (its time, tip velocity, integral), as after a reset:
        for a stamp that went backwards or jumped far ahead. ``restart`` also starts the cycle
        again from its down half (time went back: the arm was reset)."""
        self._last_t = None
        self._last_vy = None
        self.impact_ahead = False
        self.integral.reset()
        if restart:
            self.mode = CycleMode.DOWN

    @property
    def law(self) -> ControlLaw:
        """The control law (set as a member or its text: a parameter changed at run time)."""
        return self._law

    @law.setter
    def law(self, law: ControlLaw | str) -> None:
        self._law = ControlLaw(law)

    @property
    def kp(self) -> list[float]:
        """Proportional gains, one per joint (set as any numbers: kept as floats, the
        compiled laws' type, so that the float path of ``torque`` computes the same bits)."""
        return self._kp

    @kp.setter
    def kp(self, gains: Sequence[float]) -> None:
        self._kp = [float(k) for k in gains]

    @property
    def kd(self) -> list[float]:
        """Derivative gains (as ``kp``)."""
        return self._kd

    @kd.setter
    def kd(self, gains: Sequence[float]) -> None:
        self._kd = [float(k) for k in gains]

    @property
    def ki(self) -> list[float]:
        """Integral gains (as ``kp``)."""
        return self._ki

    @ki.setter
    def ki(self, gains: Sequence[float]) -> None:
        self._ki = [float(k) for k in gains]

    @property
    def space(self) -> PidSpace:
        """The angles the PID/PD acts on (set as a member or its text)."""
        return self._space

    @space.setter
    def space(self, space: PidSpace | str) -> None:
        self._space = PidSpace(space)

    @property
    def mode(self) -> CycleMode:
        """The cycle's half now (set as a member or its text)."""
        return self._mode

    @mode.setter
    def mode(self, mode: CycleMode | str) -> None:
        self._mode = CycleMode(mode)

    def _switch(self, mode):
        self.mode = mode
        self.switches += 1
        self.integral.reset()

    def anticipate_impact(
        self,
        q: Sequence[float],
        qd: Sequence[float],
        sensed: tuple[Sequence[float], Sequence[float]],
        normal_force: float | None = None,
        lead: float = 0.0,
    ) -> tuple[list[float], list[float]]:
        """The state to act on in place of the predicted one (``q``, ``qd``) when an impact
        lies between the sample (``sensed``, with its ``normal_force``) and the state the
        command will meet: (``q``, ``qd``) themselves when none does.

        The prediction is free motion: it carries the tip through the surface at its
        approach speed, where the arm will be in contact, its tip held at the surface. So
        when the predicted tip is below the surface and moving into it (in the down half, or
        after an impact anticipated so that the samples do not show it yet), the state comes
        back with the tip at the surface and its approach stopped (``stopped_at_surface``):
        the arm at the depth of the compression, as a sample inside the contact would show
        it. And the cycle switches to its up half now, so that the command meets the impact
        in it, as a sample in contact would have switched it with no latency; commands left
        in the down half would push the tip into the surface for as long as the latency
        lasts and lengthen the cycle about as much.

        ``lead`` [s]: how long before the predicted state the tip must have reached the
        surface (depth over approach speed) for the cycle to switch: as much as the command
        may act earlier than predicted, so that it meets the impact begun, never the
        approach before it (an up command through the whole compression drove the tip
        deeper, offline: up to 9 %)."""
        if self.surface_height is None:
            return list(q), list(qd)
        if self.impact_ahead:
            # the samples reach the impact: the wrench, or the tip no longer approaching
            vy_seen = self._tip(*sensed)[3]
            if (normal_force is not None and normal_force > self.force_threshold) or vy_seen >= 0:
                self.impact_ahead = False
        _, y_tip, _, vy_tip = self._tip(q, qd)
        if not (y_tip < self.surface_height and vy_tip < 0):
            return list(q), list(qd)
        if self.mode is CycleMode.DOWN:
            if self.surface_height - y_tip < -vy_tip * lead:
                return list(q), list(qd)
            self._switch(CycleMode.UP)
            self.impact_ahead = True
            self.anticipated += 1
        elif not self.impact_ahead:
            return list(q), list(qd)
        return stopped_at_surface(self.model, q, qd, self.surface_height - y_tip)

    def update(
        self,
        t: float,
        q: Sequence[float] | np.ndarray,
        qd: Sequence[float] | np.ndarray,
        normal_force: float | None = None,
        sensed: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> list[float]:
        """Torques for the sample at time t (the caller holds them until the next sample).

        ``sensed``: the sampled (q, qd) when ``q``, ``qd`` are a prediction of the state the
        torques will meet. The impact is then judged on the sample: the prediction's free
        motion goes through the surface, so a tip reversal it shows comes periods after the
        one the sample shows (with no wrench, four periods of latency struck twice)."""
        _, y_tip, _, vy_tip = self._tip(q, qd)
        y_seen, vy_seen = y_tip, vy_tip
        if sensed is not None:
            _, y_seen, _, vy_seen = self._tip(*sensed)
        if self.mode is CycleMode.DOWN and self.surface_height is not None:
            hit = normal_force is not None and normal_force > self.force_threshold
            reversed_near = (
                self._last_vy is not None
                and self._last_vy < 0 <= vy_seen
                and y_seen < self.surface_height + self.reversal_band
            )
            if hit or reversed_near:
                self._switch(CycleMode.UP)
        elif self.mode is CycleMode.UP and y_tip >= self.switch_height:
            self._switch(CycleMode.DOWN)
        self._last_vy = vy_seen
        dt = 0.0 if self._last_t is None else t - self._last_t
        self._last_t = t
        return self.torque(q, qd, dt)

    def _state_arrays(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(``q``, ``qd``) in the reused arrays: what ``np.asarray(q, float)`` gives."""
        bq, bqd = self._q, self._qd
        for i in range(bq.shape[0]):
            bq[i] = q[i]
            bqd[i] = qd[i]
        return bq, bqd

    def _tip(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray
    ) -> tuple[float, float, float, float]:
        """``model.tip(q, qd)`` without its arrays' allocation."""
        m = self.model
        return m.eq.tip(*self._state_arrays(q, qd), m.geometry)

    def torque(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray, dt: float = 0.0
    ) -> list[float]:
        """The law's joint torques at (``q``, ``qd``); ``dt``: the time since the previous
        sample, over which the PID integrates."""
        if self.law is ControlLaw.Q:
            return self._q_torque(q, qd)
        return self.torque_arrays(q, qd, dt)

    def _q_torque(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray
    ) -> list[float]:
        """``q_law`` on floats, its operations in its order (the same bits): for the two or
        three joints of an arm, numpy's conversions and the compiled call's dispatch cost
        several times its arithmetic. Only gravity comes from the compiled model."""
        m = self.model
        bq = self._state_arrays(q, qd)[0]
        gravity = m.eq.gravity_forces(bq, m.geometry, m.m, m.g)
        target, kp, kd = self.targets[self.mode], self._kp, self._kd
        n = len(kp)
        out = [0.0] * n
        tail = 0.0
        for i in range(n - 1, -1, -1):
            tail += gravity[i]
            out[i] = -kd[i] * float(qd[i]) - kp[i] * (float(q[i]) - float(target[i])) - tail
        return out

    def q_law_terms(self) -> tuple[list[float], list[float], list[float]] | None:
        """(target, kp, kd) of the 'q' law as it acts now (this half of the cycle): what a
        compiled caller needs to evaluate ``torque`` itself; None for the other laws."""
        if self.law is not ControlLaw.Q:
            return None
        return self.targets[self.mode], self._kp, self._kd

    def torque_arrays(
        self, q: Sequence[float] | np.ndarray, qd: Sequence[float] | np.ndarray, dt: float = 0.0
    ) -> list[float]:
        """``torque`` through numpy arrays and the compiled laws: every law (the reference
        ``torque``'s float path for the 'q' law is tested against)."""
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        n = q.shape[0]
        out = np.zeros(n)
        target = np.asarray(self.targets[self.mode], dtype=float)
        if self.law is ControlLaw.NONE:
            return out.tolist()
        if self.law is ControlLaw.Q:
            q_law(
                q,
                qd,
                target,
                np.asarray(self.kp, float),
                np.asarray(self.kd, float),
                np.asarray(self.model.gravity_forces(q), float),
                out,
            )
            return out.tolist()
        error, rate = np.zeros(n), np.zeros(n)
        pid_error(q, qd, target, self.space is PidSpace.JOINT, error, rate)
        ki = self.ki if self.law is ControlLaw.PID else [0.0] * n
        gains = np.asarray(self.kp, float), np.asarray(self.kd, float), np.asarray(ki, float)
        if self.law is ControlLaw.PID and dt > 0:
            saturated = None
            if self.integral.antiwindup is AntiWindup.CONDITIONAL_INTEGRATION:
                # the output the actuator gets before this sample's integration
                pid_law(error, rate, np.asarray(self.integral.value, float), *gains, out)
                saturated = self.integral.saturated(out)
            self.integral.update(error, dt, ki, saturated)
        pid_law(error, rate, np.asarray(self.integral.value, float), *gains, out)
        self.integral.clamp(out)
        return out.tolist()


def stopped_at_surface(
    model: ArmModel, q: Sequence[float], qd: Sequence[float], depth: float
) -> tuple[list[float], list[float]]:
    """The state (``q``, ``qd``) of an arm whose tip is ``depth`` below a horizontal surface,
    moved to the surface and stopped there: a perfectly plastic, frictionless impulse at
    the tip, qd - (J qd) / (J M⁻¹ Jᵀ) M⁻¹ Jᵀ (of all rates that stop the tip vertically,
    the nearest to ``qd`` in the kinetic-energy metric), and the angles moved by
    depth / (J M⁻¹ Jᵀ) M⁻¹ Jᵀ, the same direction raising the tip by ``depth`` to first
    order. J: the tip's vertical row of the Jacobian, M: the mass matrix, at ``q``.
    Unchanged where the arm cannot move its tip vertically."""
    q_arr = np.asarray(q, float)
    qd_arr = np.asarray(qd, float)
    n = model.n
    row = np.asarray(model.tip_jacobian(q_arr), float)[n : 2 * n]
    direction = np.linalg.solve(model.mass_matrix(q_arr), row)  # M⁻¹ Jᵀ
    effective = float(row @ direction)  # 1 / (the tip's effective mass, vertically)
    if not effective > 0:
        return [float(v) for v in q_arr], [float(v) for v in qd_arr]
    q_out = q_arr + (depth / effective) * direction
    qd_out = qd_arr - (float(row @ qd_arr) / effective) * direction
    return [float(v) for v in q_out], [float(v) for v in qd_out]
