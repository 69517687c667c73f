"""The immutable model of a scene and the small mutable state that evolves on it.

Like MuJoCo's mjModel / mjData: ``ArmModel`` is built once from a ``Scene`` (geometry, masses,
contact constants, compiled equations) and never changes during a run; ``ArmState`` holds what
does (time, coordinates, velocities, integral states, contact phase, the current impact's
δm/δr and the dent each surface keeps until the tip has left it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from .contact import ContactConstants, contact_constants
from .equations import load_equations
from .scene import Scene


class Phase(IntEnum):
    FREE = 0
    ELASTIC = 1          # Hertz compression
    ELASTOPLASTIC = 2    # Jackson-Green compression
    RESTITUTION = 3      # elastic unloading about the residual dent


@dataclass(frozen=True)
class SurfaceModel:
    index: int
    height: float
    law: str
    mu: float
    v_d: float
    constants: ContactConstants


class ArmModel:
    """Everything about the arm and its world that stays fixed during a run."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.n = scene.n_links
        self.L = tuple(scene.lengths)
        self.m = tuple(scene.masses)
        self.g = scene.gravity
        self.surfaces = tuple(
            SurfaceModel(i, s.height, s.law, s.mu, s.v_d,
                         contact_constants(scene.arm_material, s.material, scene.tip_radius))
            for i, s in enumerate(scene.surfaces) if s.law != 'none')
        # Model only what the scene needs: the generated code has no gravity terms for g = 0.
        self.eq = load_equations(self.n, gravity=self.g != 0.0)
        ctrl = scene.controller
        # integral states exist only if a PID is evaluated continuously in the right-hand side
        self.n_integral = self.n if (ctrl.law == 'pid' and ctrl.rate == 0) else 0
        self.size = 2 * self.n + self.n_integral

    # --- kinematics and energies (thin wrappers over the generated functions) ---
    def tip(self, q, qd):
        """(x_B, y_B, ẋ_B, ẏ_B) of the tip centre B."""
        return self.eq.tip(q, qd, self.L)

    def tip_jacobian(self, q):
        """(∂x_B/∂q, ∂y_B/∂q) flattened: first n entries x, next n entries y."""
        return self.eq.tip_jacobian(q, self.L)

    def gravity_forces(self, q):
        return self.eq.gravity_forces(q, self.L, self.m, self.g)

    def link_energies(self, q, qd):
        return self.eq.link_energies(q, qd, self.L, self.m)

    def potential_energy(self, q):
        return self.eq.potential(q, self.L, self.m, self.g)[0]

    def accelerations(self, q, qd, Qx):
        if hasattr(self.eq, 'accel'):
            return self.eq.accel(q, qd, Qx, self.L, self.m, self.g)
        values = self.eq.mass_and_rhs(q, qd, Qx, self.L, self.m, self.g)
        n = self.n
        M = np.array(values[:n * n]).reshape(n, n)
        return tuple(np.linalg.solve(M, np.array(values[n * n:])))

    def initial_state(self) -> 'ArmState':
        s = self.scene
        y = np.zeros(self.size)
        y[:self.n] = s.q0
        y[self.n:2 * self.n] = s.qd0
        return ArmState(t=0.0, y=y, levels=[surf.height for surf in self.surfaces])


@dataclass
class ArmState:
    """What changes during a run. ``y`` = [q (n), q̇ (n), ∫e (n if continuous PID)]."""
    t: float
    y: np.ndarray
    phase: Phase = Phase.FREE
    surface: int = -1                 # index into model.surfaces while in contact
    levels: list = field(default_factory=list)  # contact height per surface (dent memory)
    delta_m: float = 0.0
    P_m: float = 0.0
    delta_r: float = 0.0
    R_r: float = 0.0
    mode: str = 'down'                # cycle phase of the continuous controller
    held_torque: tuple | None = None  # zero-order-hold torque (sampled control)

    def copy(self) -> 'ArmState':
        other = ArmState(**{k: getattr(self, k) for k in self.__dataclass_fields__})
        other.y = self.y.copy()
        other.levels = list(self.levels)
        return other


def kinetic_energy_split(model: ArmModel, q, qd):
    """[T1, T2, ..., T] with T the total."""
    parts = list(model.link_energies(q, qd))
    return parts + [math.fsum(parts)]
