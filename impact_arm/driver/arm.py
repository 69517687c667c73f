"""The simulated arm as its driver sees it, free of ROS: torque commands in; sampled joint
states, period-averaged contact wrenches and impact reports out.

The simulator node is a thin shell around ``SimulatedArm``: it decides *when* to call
``step`` (wall clock or lockstep) and turns what comes back into messages. Joint space here is
the driver's: relative encoder angles (joint1 = q1, joint2 = q2 - q1), joint torques T01, T12.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from ..physics.limits import LimitWatch
from ..physics.control import q_law
from ..physics.errors import ImpactArmError
from ..physics.impact import Impact
from ..physics.integrator import PRESETS, IntegratorOptions, PhaseIntegrator
from ..physics.metrics import ImpactBuilder
from ..physics.periods import advance_period
from ..physics.model import ArmModel
from ..physics.scene import Scene
from .sensors import Sensors


# Each joint's brake torque limit [N m]: ten times the article arm's largest static gravity
# torque (~20 N m at joint 1, stretched out horizontally), so it holds the arm anywhere and
# stops a swinging one within a few degrees.
DEFAULT_BRAKE_TORQUE = 200.0


class CommandError(ImpactArmError):
    """A torque command that must not be applied (wrong length, non-finite values)."""


@dataclass
class Tick:
    """What the arm's sensors show at the end of one period."""

    t: float  # simulated time [s]
    position: list  # joint angles [rad] (relative, encoder convention)
    velocity: list  # joint rates [rad/s]
    effort: list  # joint torques acting now [N m] (0 while actuators are off)
    wrench: tuple  # (tangential, normal) contact force averaged over the period [N]
    # [(record, trace rows)] of the impacts completed this period
    impacts: list[tuple[Impact, list]] = field(default_factory=list)
    force_peak: float = 0.0  # the largest normal contact force in the period [N]
    plates: tuple = ()  # (z, ż) of each mounted surface's plate (ArmModel.plate_states)


class SimulatedArm:
    """One arm, one clock: ``step()`` advances exactly one period of ``1 / rate`` seconds.

    Time is counted in whole periods (t = k / rate) so that a long run never drifts from the
    schedule by accumulated rounding."""

    def __init__(
        self,
        scene: Scene,
        rate: float,
        *,
        preset: str | None = None,
        max_effort: float = math.inf,
        trace: bool = True,
        brake_torque: float = DEFAULT_BRAKE_TORQUE,
    ):
        if not rate > 0:
            raise ValueError(f'rate = {rate}: must be > 0 Hz')
        preset = preset or scene.integrator.preset
        if preset not in PRESETS:
            raise ValueError(f'preset = {preset!r}: choose one of {", ".join(PRESETS)}')
        self.scene = scene
        self.model = ArmModel(scene)
        self.n = self.model.n
        self.rate = float(rate)
        self.max_effort = max_effort
        # the wire is in the robot's joint coordinates (its URDF's zero and sign)
        self.coordinates = scene.joint_coordinates
        # how the driver reports the state (the scene's sensors section; ideal by default)
        self.sensors = Sensors(scene.sensors, self.rate, self.n)
        self._reading: tuple | None = None  # (period, state bytes, reading) of the last one
        self.brake_torque = float(brake_torque)
        # the brake holds with the scene controller's own stiffness: gains known to be
        # stable at the control rate, under the same zero-order hold
        self._brake_gains = (
            np.asarray(scene.controller.kp, float),
            np.asarray(scene.controller.kd, float),
        )
        self._brake_at = None  # absolute link angles the brake holds
        spec = scene.integrator
        # the scene's own tolerances apply with its own preset
        self._options = IntegratorOptions.of_scene(spec, None if preset == spec.preset else preset)
        self._trace = trace
        self.reset()

    def reset(self) -> None:
        """Back to the scene's initial state at t = 0, zero torque, no impact in progress."""
        self.integrator = PhaseIntegrator(
            self.model, options=self._options, control='held', trace=self._trace
        )
        self.builder = ImpactBuilder(self.model)
        self.periods = 0
        self.command = [0.0] * self.n  # the torque being held (after clipping)
        self.sensors.reset()
        self._reading = None
        # the periods the published joint states spend beyond the robot's limits
        self.limits = LimitWatch(self.scene)

    def warm_up(self) -> None:
        """Load every compiled function the stepping path may call (numba loads them from its
        cache on first use: ~0.5 s in all), so that the first period, or the first impact,
        of a real-time run does not pay for it."""
        from ..physics.model import kinetic_energy_split

        scratch = PhaseIntegrator(
            self.model, self.integrator.state.copy(), preset='fast', control='held'
        )
        scratch.advance(scratch.state.t + 1.0 / self.rate)
        # a whole impact on a scratch copy, released without torque (under gravity the arm
        # falls onto its surface within a second): every Python path an impact takes
        builder = ImpactBuilder(self.model)
        for event in scratch.advance(scratch.state.t + 2.0):
            record = builder.feed(event)
            if record is not None:
                json.dumps(record.to_dict())  # as the report sends it
                break
        n, y = self.n, scratch.state.y
        scratch.torque()
        self._brake_torques(y[:n].copy(), y[n : 2 * n].copy(), y[:n].copy())
        scratch.contact_forces(y[:n], y[n : 2 * n])
        kinetic_energy_split(self.model, y[:n], y[n : 2 * n])
        self.model.tip(y[:n], y[n : 2 * n])
        self.model.gravity_forces(y[:n])

    # ----------------------------------------------------------------------- commands
    def check_command(self, values: Iterable[float]) -> list[float]:
        """The command as floats, or CommandError saying why it is refused."""
        values = list(values)
        if len(values) != self.n:
            raise CommandError(
                f'command has {len(values)} values, expected {self.n} (one torque per joint)'
            )
        out = [float(v) for v in values]
        bad = [i for i, v in enumerate(out) if not math.isfinite(v)]
        if bad:
            raise CommandError(f'command value(s) {out} not finite (index {bad})')
        # a subnormal torque (< 2.2e-308 N m) is no controller's output but the mark of a
        # message cut short and zero-padded on the way: its last bytes were zeroed
        tiny = [i for i, v in enumerate(out) if v and abs(v) < sys.float_info.min]
        if tiny:
            raise CommandError(
                f'command value(s) {out} subnormal (index {tiny}): a corrupted or truncated message'
            )
        return out

    @property
    def max_effort(self) -> float:
        """The driver's own torque limit [N m]: each joint's drive clips at its own limit
        (the scene's ``joints[i].max_effort``, else the URDF's), and at this where lower."""
        return self._max_effort

    @max_effort.setter
    def max_effort(self, limit: float) -> None:
        self._max_effort = float(limit)
        self.effort_limits = [min(self._max_effort, j) for j in self.scene.effort_limits]

    def clips(self, values: Iterable[float]) -> bool:
        """Whether a command exceeds any joint's limit."""
        return any(abs(v) > limit for v, limit in zip(values, self.effort_limits))

    def apply(self, values: Iterable[float]) -> None:
        """Hold ``values`` (the robot's joint efforts, N m) from now on, each clipped to its
        joint's effort limit."""
        self.apply_checked(self.check_command(values))

    def apply_checked(self, tau: list[float]) -> None:
        """``apply`` for torques ``check_command`` has already passed (a driver checks each
        command once, when it arrives, and applies it at its next period)."""
        clipped = [min(max(v, -limit), limit) for v, limit in zip(tau, self.effort_limits)]
        self._hold(self.coordinates.model_efforts(clipped))

    def release(self) -> None:
        """Zero torque (watchdog expired, controller gone)."""
        self._hold([0.0] * self.n)

    def engage_brake(self) -> None:
        """Hold the joints where they are now, from this period on (``brake``)."""
        self._brake_at = self.integrator.state.y[: self.n].copy()

    def brake(self) -> list[float]:
        """Apply the brake for the next period and return its joint torques: a stiff hold of
        the angles ``engage_brake`` saw (the scene controller's PD gains plus gravity
        compensation, recomputed each period from the state), each joint's torque limited to
        ±``brake_torque``, as a real brake slips beyond its rated torque."""
        y = self.integrator.state.y
        n = self.n
        tau = self._brake_torques(y[:n].copy(), y[n : 2 * n].copy(), self._brake_at)
        limit = self.brake_torque
        tau = [min(max(v, -limit), limit) for v in tau]
        self._hold(tau)
        return tau

    def _brake_torques(self, q, qd, target) -> list:
        out = np.zeros(self.n)
        q_law(
            q, qd, target, *self._brake_gains, np.asarray(self.model.gravity_forces(q), float), out
        )
        return out.tolist()

    def _hold(self, tau):
        if tau != self.command:
            self.command = tau
            self.integrator.set_held_torque(tau)

    # ----------------------------------------------------------------------------- time
    @property
    def t(self) -> float:
        return self.integrator.state.t

    def hold_still(self) -> None:
        """A braked period: simulated time advances one period and the arm stays where it is
        (no physics runs; whatever command was held stays held)."""
        self.periods += 1
        y, n = self.integrator.state.y, self.n
        self.integrator.set_state(self.periods / self.rate, y[:n].copy(), y[n : 2 * n].copy())

    def step(self) -> Tick:
        """Advance one period under the held command; raises SimulationError when the physics
        leaves its validity (the state stays at the last good point)."""
        impacts, (jt, jn) = advance_period(
            self.integrator, self.builder, (self.periods + 1) / self.rate
        )
        self.periods += 1
        tick = self.sample(wrench=(jt * self.rate, jn * self.rate), impacts=impacts)
        tick.force_peak = self.integrator.take_peak()
        self.limits.add(tick.position, tick.velocity)
        return tick

    def sample(
        self, wrench: tuple[float, float] = (0.0, 0.0), impacts: Iterable[tuple[Impact, list]] = ()
    ) -> Tick:
        """The sensors' view of the current state (``driver/sensors.py``: one reading per
        period; asked again in the same period, they repeat it, as a driver republishing its
        last sample does)."""
        st = self.integrator.state
        n = self.n
        q, qd = st.y[:n].tolist(), st.y[n : 2 * n].tolist()
        tau = self.integrator.torque()
        effort = list(tau) if tau is not None else [0.0] * n
        plates = self.model.plate_states(st.y)
        coordinates = self.coordinates
        effort = coordinates.efforts(effort)
        if self.sensors.ideal:
            return Tick(
                st.t,
                coordinates.positions(q),
                coordinates.rates(qd),
                effort,
                tuple(wrench),
                list(impacts),
                plates=plates,
            )
        key = (self.periods, st.y.tobytes())
        if self._reading is None or self._reading[:2] != key:
            reading = self.sensors.read(
                coordinates.positions(q), coordinates.rates(qd), effort, wrench
            )
            self._reading = (*key, reading)
        r = self._reading[2]
        return Tick(st.t, r.position, r.velocity, r.effort, r.wrench, list(impacts), plates=plates)
