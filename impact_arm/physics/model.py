"""The immutable model of a scene and the small mutable state that evolves on it.

Like MuJoCo's mjModel / mjData: ``ArmModel`` is built once from a ``Scene`` (geometry, masses,
contact constants, compiled equations) and never changes during a run; ``ArmState`` holds what
does (time, coordinates, velocities, integral states, contact phase, the current impact's
δm/δr and the dent each surface keeps until the tip has left it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from . import layout
from .contact import CONTACT_LAW_CODES, ContactConstants, contact_constants
from .equations import load_equations
from .scene.types import Mount, Scene

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


class Phase(IntEnum):
    FREE = 0
    ELASTIC = 1  # Hertz compression
    ELASTOPLASTIC = 2  # Jackson-Green compression
    RESTITUTION = 3  # elastic unloading about the residual dent


@dataclass(frozen=True)
class SurfaceModel:
    index: int
    height: float
    law: str
    mu: float
    v_d: float
    constants: ContactConstants
    mount: Mount | None = None  # None: rigid
    mount_state: int = -1  # index of the plate's z in the state (ż follows), -1: rigid


class ArmModel:
    """Everything about the arm and its world that stays fixed during a run."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.n = scene.n_links
        self.L = np.array(scene.lengths, dtype=float)
        self.m = np.array(scene.masses, dtype=float)
        # the generated functions' link geometry (equations.GEOMETRY): the lengths for rods
        self.general = scene.general_links
        self.geometry = (
            np.concatenate(
                [
                    self.L,
                    [c[0] for c in scene.link_com],
                    [c[1] for c in scene.link_com],
                    scene.link_inertias,
                    scene.contact_point,
                ]
            )
            if self.general
            else self.L
        )
        self.g = scene.gravity
        joints = scene.joint_specs
        self.damping = np.array([j.damping for j in joints], dtype=float)
        self.friction = np.array([j.friction for j in joints], dtype=float)
        self.friction_v_d = np.array([j.friction_v_d for j in joints], dtype=float)
        self.armature = np.array([j.armature for j in joints], dtype=float)
        ctrl = scene.controller
        # integral states exist only if a PID is evaluated continuously in the right-hand side
        self.n_integral = self.n if (ctrl.law == 'pid' and ctrl.rate == 0) else 0
        struck = [s for s in scene.surfaces if s.law != 'none']
        # each mounted surface's plate adds z, ż to the state, after the integrals
        mount_states, k = [], 2 * self.n + self.n_integral
        for surface in struck:
            mount_states.append(k if surface.mount is not None else -1)
            k += 2 if surface.mount is not None else 0
        self.n_mount = len([surface for surface in struck if surface.mount is not None])
        self.surfaces = tuple(
            SurfaceModel(
                i,
                s.height,
                s.law,
                s.mu,
                s.v_d,
                contact_constants(scene.arm_material, s.material, scene.tip_radius),
                s.mount,
                mount_states[i],
            )
            for i, s in enumerate(struck)
        )
        self.size = 2 * self.n + self.n_integral + 2 * self.n_mount
        # The compiled module depends on the arm's shape alone: gravity, contact and friction
        # are values (g, the surface table's rows, μ), so g = 0, no surface or μ = 0 run on
        # the same kernel as the article's scene.
        self.eq = load_equations(self.n, general=self.general, n_mount=self.n_mount)
        self.surface_table = np.zeros((max(1, len(self.surfaces)), layout.S_SIZE))
        for s in self.surfaces:
            c = s.constants
            self.surface_table[s.index] = (
                s.height,
                CONTACT_LAW_CODES[s.law],
                s.mu,
                s.v_d,
                c.E,
                c.R,
                c.S_y,
                c.C_j,
                c.delta_c,
                c.P_c,
                c.B,
                s.mount_state,
                s.mount.mass if s.mount else 0.0,
                s.mount.stiffness if s.mount else 0.0,
                s.mount.damping if s.mount else 0.0,
            )
        if not self.surfaces:
            self.surface_table = self.surface_table[:0]

    @property
    def mounted(self) -> tuple[SurfaceModel, ...]:
        """The surfaces on a compliant mount, in surface order."""
        return tuple(s for s in self.surfaces if s.mount is not None)

    def plate_states(self, y: Sequence[float] | np.ndarray) -> tuple[float, ...]:
        """(z, ż) of each mounted surface's plate from a state ``y``, flat, in surface
        order; () for a rigid scene."""
        if not self.n_mount:
            return ()
        return tuple(float(y[s.mount_state + k]) for s in self.mounted for k in (0, 1))

    # --- kinematics and energies (thin wrappers over the generated functions) ---
    def tip(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """(x_B, y_B, ẋ_B, ẏ_B) of the tip centre B."""
        return self.eq.tip(np.asarray(q, float), np.asarray(qd, float), self.geometry)

    def tip_jacobian(self, q: ArrayLike) -> np.ndarray:
        """(∂x_B/∂q, ∂y_B/∂q) flattened: first n entries x, next n entries y."""
        return self.eq.tip_jacobian(np.asarray(q, float), self.geometry)

    def gravity_forces(self, q: ArrayLike) -> np.ndarray:
        return self.eq.gravity_forces(np.asarray(q, float), self.geometry, self.m, self.g)

    def link_energies(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """Kinetic energy of each link, its joint's rotor (armature) included."""
        qd = np.asarray(qd, float)
        links = np.asarray(self.eq.link_energies(np.asarray(q, float), qd, self.geometry, self.m))
        return links + self.rotor_energies(qd) if self.armature.any() else links

    def joint_rates(self, qd: ArrayLike) -> np.ndarray:
        """ω_i = q̇_i - q̇_(i-1): each joint's relative rate (q̇_0 = 0)."""
        qd = np.asarray(qd, float)
        return np.diff(qd, prepend=0.0)

    def rotor_energies(self, qd: ArrayLike) -> np.ndarray:
        """½ J_i ω_i²: the kinetic energy of each joint's rotor."""
        return 0.5 * self.armature * self.joint_rates(qd) ** 2

    def joint_friction_torques(self, qd: ArrayLike) -> np.ndarray:
        """τ_i = -(d_i ω_i + f_i tanh(ω_i / v_i)): what each joint's bearing applies."""
        omega = self.joint_rates(qd)
        return -(self.damping * omega + self.friction * np.tanh(omega / self.friction_v_d))

    def potential_energy(self, q: ArrayLike) -> float:
        return self.eq.potential(np.asarray(q, float), self.geometry, self.m, self.g)[0]

    def mass_matrix(self, q: ArrayLike) -> np.ndarray:
        n = self.n
        values = self.eq.mass_and_rhs(
            np.asarray(q, float), np.zeros(n), np.zeros(n), self.geometry, self.m, self.g
        )
        M = np.array(values[: n * n]).reshape(n, n)
        T = np.eye(n) - np.eye(n, k=-1)  # ω = T q̇
        return M + T.T @ np.diag(self.armature) @ T

    def free_forces(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """Q_g − b(q, q̇): gravity's generalized forces less the velocity terms, the
        right-hand side of M q̈ = Q_x + Q_g − b without other forces."""
        n = self.n
        values = self.eq.mass_and_rhs(
            np.asarray(q, float), np.asarray(qd, float), np.zeros(n), self.geometry, self.m, self.g
        )
        return np.array(values[n * n :])

    def parameters(
        self,
        rtol: float,
        atol: float,
        max_step: float,
        contact_rtol: float | None = None,
        contact_atol: float | None = None,
    ) -> np.ndarray:
        """The flat parameter array of the kernel (layout: P_* in the generated module).
        Contact phases use ``contact_rtol`` / ``contact_atol`` (default: rtol / atol)."""
        eq, n, c = self.eq, self.n, self.scene.controller
        P = np.zeros(eq.P_SIZE)
        P[eq.P_L : eq.P_L + eq.NL] = self.geometry
        P[eq.P_M : eq.P_M + n] = self.m
        P[eq.P_G] = self.g
        P[eq.P_KP : eq.P_KP + n] = c.kp
        P[eq.P_KD : eq.P_KD + n] = c.kd
        P[eq.P_KI : eq.P_KI + n] = c.ki if c.law == 'pid' else 0.0
        P[eq.P_TDOWN : eq.P_TDOWN + n] = c.down_target
        P[eq.P_TUP : eq.P_TUP + n] = c.up_target
        P[eq.P_SWITCH] = c.switch_height
        P[eq.P_RTOL], P[eq.P_ATOL], P[eq.P_MAXSTEP] = rtol, atol, max_step
        P[eq.P_CRTOL] = rtol if contact_rtol is None else contact_rtol
        P[eq.P_CATOL] = atol if contact_atol is None else contact_atol
        P[eq.P_DAMP : eq.P_DAMP + n] = self.damping
        P[eq.P_FRIC : eq.P_FRIC + n] = self.friction
        P[eq.P_FVD : eq.P_FVD + n] = self.friction_v_d
        P[eq.P_ARM : eq.P_ARM + n] = self.armature
        P[eq.P_JFRIC_ON] = 1.0 if self.damping.any() or self.friction.any() else 0.0
        P[eq.P_ARM_ON] = 1.0 if self.armature.any() else 0.0
        return P

    def initial_state(self) -> 'ArmState':
        s = self.scene
        y = np.zeros(self.size)
        y[: self.n] = s.q0
        y[self.n : 2 * self.n] = s.qd0
        return ArmState(0.0, y, [surf.height for surf in self.surfaces], self.n)


class ArmState:
    """What changes during a run. ``y`` = [q (n), q̇ (n), ∫e (n if continuous PID), then z, ż
    of each mounted surface's plate (``SurfaceModel.mount_state``)]; the
    contact phase machine lives in the flat array ``c`` the kernel reads (layout.C_*)."""

    def __init__(self, t: float, y: ArrayLike, levels: ArrayLike, n: int):
        self.t = float(t)
        self.y = np.asarray(y, dtype=float)
        self.levels = np.array(levels, dtype=float)  # contact height per surface (dent memory)
        self.c = np.zeros(layout.C_SIZE)
        self.c[layout.C_SURF] = -1
        self.held = np.zeros(n)  # zero-order-hold torque (sampled control)

    # ignored [misc]: a helper run in the class body (deleted after it), not a method
    def _field(index: int, kind: Callable[[float], Any] = float, doc: str = '') -> Any:  # type: ignore[misc]
        def get(self: ArmState) -> Any:
            return kind(self.c[index])

        def put(self: ArmState, value: float) -> None:
            self.c[index] = float(value)

        return property(get, put, doc=doc)

    phase = _field(layout.C_PHASE, lambda v: Phase(int(v)))
    surface = _field(layout.C_SURF, int, 'index into model.surfaces while in contact')
    delta_r = _field(layout.C_DR)
    R_r = _field(layout.C_RR)
    delta_m = _field(layout.C_DM)
    P_m = _field(layout.C_PM)
    del _field

    @property
    def mode(self) -> str:
        """Cycle half of the continuous controller: 'down' or 'up'."""
        return 'up' if self.c[layout.C_MODE] > 0.5 else 'down'

    @mode.setter
    def mode(self, value: str) -> None:
        self.c[layout.C_MODE] = 1.0 if value == 'up' else 0.0

    @property
    def held_torque(self) -> tuple[float, ...]:
        return tuple(self.held.tolist())

    @held_torque.setter
    def held_torque(self, tau: ArrayLike) -> None:
        self.held[:] = tau

    def copy(self) -> 'ArmState':
        other = ArmState(self.t, self.y.copy(), self.levels.copy(), self.held.shape[0])
        other.c[:] = self.c
        other.held[:] = self.held
        return other


def kinetic_energy_split(model: ArmModel, q: ArrayLike, qd: ArrayLike) -> list[float]:
    """[T1, T2, ..., T] with T the total."""
    parts = list(model.link_energies(q, qd))
    return parts + [math.fsum(parts)]
