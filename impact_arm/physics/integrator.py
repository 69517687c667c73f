"""The stepped phase integrator: adaptive Dormand-Prince 5(4) that stops exactly at every
switch of the contact phase machine and restarts with the next phase's force law. With
``method='rosenbrock'`` the free flight takes linearly implicit Rosenbrock 4(3) steps instead
(it is stiff under the article's controller); ``contact_rtol`` gives contact phases their own
tolerance.

free --contact--> elastic --δ=1.9δc--> elasto-plastic --δ̇=0--> restitution --δ=δr--> free
(elastic --δ̇=0--> restitution for gentle impacts or a Hertz-only surface)

Contact is decided by this machine, never by the sign of y_B - h: after separation the tip sits
δr below h while it rises. Every switch is located by root-finding on *real* Runge-Kutta steps
from the start of the step that crossed it (not on an interpolant), so the state at a switch is
as accurate as any step end. Shaped like scipy's OdeSolver: ``advance(t_end)`` plays the part
of repeated ``step()`` calls and returns the events it crossed.

The stepping loop and the phase machine's transitions are the compiled kernel in
``physics/kernel/`` (appended to each scene shape's generated module): an impact's four
switches cost no return to Python. This wrapper turns the kernel's event log into ``Event``s.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import math
from dataclasses import dataclass, field

import numpy as np

from ..contract import INTEGRATOR_METHODS, INTEGRATOR_PRESETS
from . import layout
from .errors import RunBudgetError, SimulationError
from .kinds import EventKind
from .model import ArmModel, ArmState, Phase

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from .scene import IntegratorSpec

# name: (rtol, atol). atol is absolute on angles [rad], rates [rad/s] and integral states.
# (the contract's INTEGRATOR_PRESETS, in that order: reference, accurate, balanced, fast)
PRESETS = dict(
    zip(INTEGRATOR_PRESETS, ((1e-12, 1e-14), (1e-10, 1e-12), (1e-8, 1e-10), (1e-5, 1e-8)))
)
# A preset's own contact-phase rtol, where it differs from its rtol. At rtol 1e-5 the free
# flight is bound by stability, not accuracy, and the impacts' error came from the contact
# phases (δm, e 2-3e-5 over the 15 impacts, the motion 1e-6): 3e-7 there costs 3 % more
# evaluations for 2e-6 (bench tradeoff), which puts `fast` on the speed/accuracy front.
PRESET_CONTACT_RTOL = {'fast': 3e-7}

# step methods: 'dopri5' everywhere, or 'rosenbrock' (linearly implicit 4(3)) in free flight,
# where the controller's damping makes the motion stiff, and Dormand-Prince in contact
METHODS = dict(zip(INTEGRATOR_METHODS, (layout.METHOD_DOPRI5, layout.METHOD_ROSENBROCK)))


@dataclass(frozen=True)
class IntegratorOptions:
    """How a ``PhaseIntegrator`` steps, as one record: a preset's tolerances or the caller's
    ``rtol``/``atol``, the contact phases' ``contact_rtol`` (None: the preset's, else rtol),
    the largest step [s] (None: unbounded) and the step method."""

    preset: str = 'balanced'
    rtol: float | None = None
    atol: float | None = None
    max_step: float | None = None
    method: str = 'dopri5'
    contact_rtol: float | None = None

    @classmethod
    def of_scene(
        cls,
        spec: IntegratorSpec,
        preset: str | None = None,
        rtol: float | None = None,
        atol: float | None = None,
        contact_rtol: float | None = None,
    ) -> IntegratorOptions:
        """The options of a scene's ``integrator`` section: its own settings, unless the
        caller names a preset (then the preset's tolerances, not the scene's
        rtol/atol/contact_rtol overrides) or tolerances of its own. The scene's step method
        and max_step always apply."""
        scene_tolerances = preset is None and rtol is None and atol is None
        return cls(
            preset=preset or spec.preset,
            rtol=rtol if rtol is not None else spec.rtol if scene_tolerances else None,
            atol=atol if atol is not None else spec.atol if scene_tolerances else None,
            contact_rtol=contact_rtol
            if contact_rtol is not None
            else spec.contact_rtol
            if scene_tolerances
            else None,
            max_step=spec.max_step,
            method=spec.method,
        )

    def free_rtol(self) -> float:
        """The free flight's relative tolerance these options give."""
        return self.rtol if self.rtol is not None else PRESETS[self.preset][0]


@dataclass
class Event:
    kind: EventKind  # contact | yield | max_compression | separation | switch
    t: float
    surface: int
    y: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass
class Stats:
    rhs_evaluations: int = 0
    steps: int = 0
    rejected: int = 0
    events: int = 0


TRACE_CAPACITY = 4096
OUTPUT_CAPACITY = 4096  # output rows per kernel call (advance splits longer spans)
EVENT_LOG_CAPACITY = 64  # events one kernel call crosses before Python reads them
# A kernel call returns after this many steps (tens of ms), so Ctrl-C and the run budget are
# honoured while it integrates. The budget allows a burst plus a mean step of 5 us: the
# article's scene takes ~6 000 steps per simulated second at the reference preset.
STEPS_PER_CALL = 20_000
MIN_STEP_BUDGET = 500_000
STEPS_PER_SIMULATED_SECOND = 200_000
_KINDS = {
    layout.EV_SWITCH: EventKind.SWITCH,
    layout.EV_YIELD: EventKind.YIELD,
    layout.EV_MAX: EventKind.MAX_COMPRESSION,
    layout.EV_SEP: EventKind.SEPARATION,
}
KIND_BITS: dict[str, int] = {
    EventKind.CONTACT: layout.KIND_BIT_CONTACT,
    **{kind: 1 << (1 + slot) for slot, kind in _KINDS.items()},
}
ALL_KINDS_MASK = sum(KIND_BITS.values())
_LAWS = {
    'held': layout.LAW_HELD,
    'q': layout.LAW_Q,
    'pid': layout.LAW_PID,
    'pd': layout.LAW_PID,
    'none': layout.LAW_NONE,
}


def _numba_type(value):
    """numba's type of a kernel argument, built directly: ``numba.typeof`` of an array imports
    numpy.ma (13 ms of a fresh process) to rule out masked arrays."""
    from numba import types

    if isinstance(value, np.ndarray):
        dtype = types.int64 if value.dtype == np.int64 else types.float64
        return types.Array(dtype, value.ndim, 'C')
    return types.float64


def scratch_arrays(model: ArmModel) -> tuple[np.ndarray, ...]:
    """The kernel's working arrays (``kernel/loop.py``, ``advance``), made once per
    integrator: y1, f1, err, work, y_root, f_tmp (the state's size each), the stages K, the
    right-hand side's scratch W, three rows of event values, the Rosenbrock Jacobian and its
    factors JW, y_prev, and the contact-frequency scratch."""
    size, n = model.size, model.n
    events = model.surface_table.shape[0] + 4
    vectors = [np.zeros(size) for _ in range(6)]
    return (
        *vectors,
        np.zeros((5, size)),
        np.zeros(model.eq.SCRATCH),
        np.zeros(events),
        np.zeros(events),
        np.zeros(events),
        np.zeros((2 * size + 2, size)),
        np.zeros(size),
        np.zeros(4 * n + n * n),
    )


class PhaseIntegrator:
    """Advances an ``ArmState`` on an ``ArmModel`` across contact phase switches.

    control='continuous' evaluates the scene's control law inside the right-hand side and
    switches its target at located events (the article's set-up); control='held' applies
    the torque given to ``set_held_torque`` as a zero-order hold, as a real driver does between
    commands.
    The stepping itself runs in the compiled kernel of the model's generated module.
    """

    def __init__(
        self,
        model: ArmModel,
        state: ArmState | None = None,
        *,
        options: IntegratorOptions | None = None,
        control='continuous',
        trace=False,
        preset=None,
        rtol=None,
        atol=None,
        max_step=None,
        method=None,
        contact_rtol=None,
    ):
        separate = (preset, rtol, atol, max_step, method, contact_rtol)
        if options is not None and any(v is not None for v in separate):
            raise TypeError('PhaseIntegrator: give options or the separate settings, not both')
        if options is None:  # (the separate settings: tests and benchmarks name one or two)
            options = IntegratorOptions(
                preset or 'balanced', rtol, atol, max_step, method or 'dopri5', contact_rtol
            )
        preset, rtol, atol = options.preset, options.rtol, options.atol
        max_step, method, contact_rtol = options.max_step, options.method, options.contact_rtol
        self.options = options
        if preset not in PRESETS:
            raise ValueError(f'integrator preset {preset!r}: choose one of {", ".join(PRESETS)}')
        if control not in ('continuous', 'held'):
            raise ValueError(f"control = {control!r}: choose 'continuous' or 'held'")
        if method not in METHODS:
            raise ValueError(f'integrator method {method!r}: choose one of {", ".join(METHODS)}')
        self.method = method
        self.model = model
        self.state = state or model.initial_state()
        self.rtol, self.atol = PRESETS[preset]
        if contact_rtol is None and rtol is None and atol is None:
            contact_rtol = PRESET_CONTACT_RTOL.get(preset)  # the preset's, as a whole
        self.rtol = rtol if rtol is not None else self.rtol
        self.atol = atol if atol is not None else self.atol
        self.max_step = max_step if max_step is not None else math.inf
        self.control = control
        self.trace: list | None = [] if trace else None
        spec = model.scene.controller
        # Contact phases may need a tighter tolerance than free flight: the indentation
        # (0.1-1 mm) is a difference of tip coordinates of order L, so the relative tolerance
        # on the joint state that suits the motion is loose for δ. The contact atol keeps the
        # preset's atol/rtol ratio.
        if contact_rtol is not None and not 1e-14 <= contact_rtol <= 0.1:
            raise ValueError(f'contact_rtol = {contact_rtol:g}: allowed 1e-14 ... 0.1')
        self.contact_rtol = contact_rtol if contact_rtol is not None else self.rtol
        self.contact_atol = self.atol * self.contact_rtol / self.rtol
        self._P = model.parameters(
            self.rtol, self.atol, self.max_step, self.contact_rtol, self.contact_atol
        )
        self._I = np.array(
            [
                _LAWS['held' if control == 'held' else spec.law],
                1 if spec.space == 'joint' else 0,
                1 if model.scene.actuators_during_contact else 0,
                1 if trace else 0,
                METHODS[method],
            ],
            dtype=np.int64,
        )
        self._stats = np.zeros(3, dtype=np.int64)  # rhs evaluations, steps, rejected
        self._T = np.zeros(3)  # t, next step size (0: choose), f stale flag
        self._f = np.zeros(model.size)
        self._f_valid = False
        self._h = 0.0
        # without a trace the kernel writes no row (I_TRACE is 0) but checks the buffer's
        # length after each contact step: one row will do, not 4096 (290 kB zeroed for
        # each run of a study)
        self._trace_buffer = np.zeros((TRACE_CAPACITY if trace else 1, model.eq.TR_SIZE))
        self._trace_count = np.zeros(1, dtype=np.int64)
        self._ev = np.zeros(4, dtype=np.int64)  # layout.EV_*: slot, logged, stop mask, steps
        self._ev[layout.EV_STEPS] = STEPS_PER_CALL
        self._evlog = np.zeros((EVENT_LOG_CAPACITY, layout.E_Y + model.size))
        self._W = np.zeros(model.eq.SCRATCH)
        self._scratch = scratch_arrays(model)
        self._O = np.zeros(3)  # next output index k, period dt (0: off), rows
        self._out = np.zeros((1, self.output_width))
        self._output: list[np.ndarray] = []
        self._output_sink: Callable[[np.ndarray], Any] | None = None
        self.events = 0
        self.load_time = self._load_kernel()

    def _kernel_args(self, t_end: float, O: np.ndarray) -> tuple:
        """The arguments of the kernel's ``advance``, in its order: one place for the call
        and for its compilation ahead of time."""
        st = self.state
        return (
            self._T,
            t_end,
            st.y,
            self._f,
            self._P,
            self._I,
            self.model.surface_table,
            st.c,
            st.levels,
            st.held,
            self._stats,
            self._trace_buffer,
            self._trace_count,
            self._ev,
            self._evlog,
            O,
            self._out,
            *self._scratch,
        )

    def _load_kernel(self):
        """Load the compiled kernel (from numba's cache, or compile it) before the first
        step, so that timings of the integration do not include it; returns the seconds it
        took in this process (0 once loaded). Without numba: 0."""
        from . import jit

        eq = self.model.eq
        if not jit.AVAILABLE or eq.advance.overloads:
            return 0.0
        import time

        t0 = time.perf_counter()
        args = self._kernel_args(0.0, self._O)
        eq.advance.compile(tuple(_numba_type(a) for a in args))
        return time.perf_counter() - t0

    # --- output on a time grid, from each step's continuous extension -------------------
    @property
    def output_width(self) -> int:
        """Columns of an output row (layout R_*): t, the state, contact impulse (tangential,
        normal) since the previous row, the torque acting (n), actuators acting (1/0), tip
        velocity (2)."""
        return self.model.eq.R_SIZE

    def start_output(
        self, dt: float, next_index: int, sink: Callable[[np.ndarray], Any] | None = None
    ) -> None:
        """Record the state at the times k dt, k >= next_index, as the integration passes them:
        steps are not shortened to land on them in free flight (the step's continuous
        extension gives the state: Dormand-Prince's quartic, or a cubic Hermite after a
        Rosenbrock step); contact steps do end on them, so each row's impulse is exact.

        ``sink(rows)`` is handed the rows after each kernel call (at most OUTPUT_CAPACITY,
        valid during the call only) instead of collecting them for ``take_output``: memory
        stays bounded however many rows an ``advance`` passes."""
        if not dt > 0:
            raise ValueError(f'output period {dt}: must be > 0')
        if len(self._out) != OUTPUT_CAPACITY:
            self._out = np.zeros((OUTPUT_CAPACITY, self.output_width))
        self._O[layout.O_NEXT], self._O[layout.O_DT], self._O[layout.O_ROWS] = next_index, dt, 0.0
        self._output = []
        self._output_sink = sink

    def take_output(self) -> np.ndarray:
        """The output rows recorded since the last call (one row per grid time, in order)."""
        rows = np.concatenate(self._output) if self._output else np.zeros((0, self.output_width))
        self._output = []
        return rows

    def _drain_output(self):
        count = int(self._O[layout.O_ROWS])
        if count:
            self._O[layout.O_ROWS] = 0.0
            if self._output_sink is not None:
                self._output_sink(self._out[:count])
            else:
                self._output.append(self._out[:count].copy())

    @property
    def stats(self) -> Stats:
        s = self._stats
        return Stats(
            int(s[layout.ST_RHS]), int(s[layout.ST_STEPS]), int(s[layout.ST_REJECTED]), self.events
        )

    # --- evaluation helpers (Python side; the kernel has its own compiled copies) ---------
    def rhs(self, t: float, y: ArrayLike) -> np.ndarray:
        out = np.zeros(self.model.size)
        st = self.state
        self.model.eq.rhs(
            t,
            np.asarray(y, float),
            out,
            self._P,
            self._I,
            self.model.surface_table,
            st.c,
            st.levels,
            st.held,
            self._stats,
            self._W,
        )
        return out

    def contact_forces(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """(δ, F_n, F_f, ẋ_B, ẏ_B) for the current contact phase."""
        y = np.concatenate([np.asarray(q, float), np.asarray(qd, float)])
        st = self.state
        return self.model.eq.contact_forces(y, self._P, self.model.surface_table, st.c, st.levels)

    def torque(self) -> tuple[float, ...] | None:
        """Joint torques acting at the current state, or None when the actuators are off."""
        st = self.state
        tau = np.zeros(self.model.n)
        acting = self.model.eq.control_torque(
            st.y,
            self._P,
            self._I,
            st.c,
            st.held,
            tau,
            np.zeros(self.model.n),
            np.zeros(self.model.n),
        )
        return tuple(tau.tolist()) if acting else None

    def contact_force_now(self) -> tuple[float, float]:
        """(F_tangential, F_normal) acting at the current state (zero in free motion)."""
        st = self.state
        if st.phase == Phase.FREE:
            return 0.0, 0.0
        n = self.model.n
        _, fn, ff, _, _ = self.contact_forces(st.y[:n], st.y[n : 2 * n])
        return ff, fn

    def take_impulse(self) -> tuple[float, float]:
        """Contact impulse (tangential, normal) [N s] accumulated since the last call."""
        c = self.state.c
        out = (float(c[layout.C_JT]), float(c[layout.C_JN]))
        c[layout.C_JT] = c[layout.C_JN] = 0.0
        return out

    def take_peak(self) -> float:
        """Peak normal contact force [N] since the last call, at the contact points the
        integration computed (every step end in contact, including maximum compression: an
        event, so a step end); the next span starts from the force acting now."""
        c = self.state.c
        out = float(c[layout.C_PERIOD_PEAK])
        c[layout.C_PERIOD_PEAK] = c[layout.C_IMP_FN] if c[layout.C_PHASE] != layout.FREE else 0.0
        return out

    def set_held_torque(self, tau: ArrayLike) -> None:
        """Hold the joint torques ``tau`` from now on (``control='held'``: a new command).
        The derivative cached at the current state is dropped, since it held the old torque."""
        self.state.held_torque = tau
        self._f_valid = False

    def set_state(self, t: float, q: ArrayLike, qd: ArrayLike) -> None:
        """Place the arm at absolute angles ``q`` and rates ``qd`` at time ``t`` (the contact
        phase and any integral states are kept). The cached derivative is dropped and the
        next step size chosen afresh."""
        n = self.model.n
        st = self.state
        st.t = float(t)
        st.y[:n] = q
        st.y[n : 2 * n] = qd
        self._f_valid = False
        self._h = 0.0  # 0: the kernel chooses the first step

    # --- phase machine (compiled: the kernel applies it without returning) -----------------
    def _kind(self, slot):
        n_surf = len(self.model.surfaces)
        return EventKind.CONTACT if slot < n_surf else _KINDS[slot - n_surf]

    @staticmethod
    def _info(kind, values):
        """The event's numbers by name (``values``: the log's four info floats)."""
        if kind == 'max_compression':
            return dict(zip(('delta_m', 'P_m', 'delta_r', 'R_r'), values))
        if kind == 'separation':
            return dict(zip(('F_max', 'delta_m', 'delta_r'), values))
        return {}

    def _apply_event(self, slot):
        """Switch the phase machine at event ``slot`` with the state where it is now (for
        integrations that locate events themselves: the scipy baselines); returns
        (kind, surface, info). The kernel applies the same compiled ``apply_event``."""
        st = self.state
        surface = slot if slot < len(self.model.surfaces) else st.surface
        values = np.zeros(4)
        if not self.model.eq.apply_event(
            slot, st.t, st.y, self._P, self._I, self.model.surface_table, st.c, st.levels, values
        ):
            self._raise(layout.ERR_RESIDUAL)
        kind = self._kind(slot)
        return kind, surface, self._info(kind, values.tolist())

    def _drain_events(self, events):
        count = int(self._ev[layout.EV_COUNT])
        if not count:
            return
        block = self._evlog[:count].copy()  # each event's state: a row of this copy
        heads = block[:, : layout.E_Y].tolist()  # slot, surface, t, info as Python numbers
        for head, y in zip(heads, block[:, layout.E_Y :]):
            kind = self._kind(int(head[layout.E_SLOT]))
            events.append(
                Event(
                    kind,
                    head[layout.E_T],
                    int(head[layout.E_SURF]),
                    y,
                    self._info(kind, head[layout.E_INFO :]),
                )
            )
        self.events += count
        self._ev[layout.EV_COUNT] = 0

    # --- public API ---------------------------------------------------------------------------
    def advance(self, t_end: float, stop_at_event: bool | Iterable[str] = False) -> list[Event]:
        """Integrate to ``t_end`` (exactly), crossing and reporting every phase switch.

        ``stop_at_event`` returns right after the first event (True) or the first event of
        one of the kinds named (e.g. ``('switch',)``: the others are crossed inside the
        compiled loop); with a contact trace, a separation stops too, so that the trace rows
        read at an impact's end are that impact's."""
        st = self.state
        model = self.model
        events: list[Event] = []
        t_end = float(t_end)
        O = self._O
        if not stop_at_event:
            mask = 0
        elif stop_at_event is True:
            mask = ALL_KINDS_MASK
        else:
            unknown = set(stop_at_event) - set(KIND_BITS)
            if unknown:
                raise ValueError(
                    f'stop_at_event: unknown event kind(s) {sorted(unknown)}; '
                    f'choose from {", ".join(KIND_BITS)}'
                )
            mask = sum(KIND_BITS[kind] for kind in set(stop_at_event))
        if mask and self.trace is not None:
            mask |= KIND_BITS['separation']
        self._ev[layout.EV_MASK] = mask
        while True:
            self._T[layout.T_TIME], self._T[layout.T_STEP] = st.t, self._h
            self._T[layout.T_STALE] = 0.0 if self._f_valid else 1.0
            # with output on, no kernel call may pass more grid times than the buffer holds
            k, dt = O[layout.O_NEXT], O[layout.O_DT]
            t_call = min(t_end, (k + OUTPUT_CAPACITY - 1) * dt) if dt > 0 else t_end
            status = model.eq.advance(*self._kernel_args(t_call, O))
            st.t, self._h = float(self._T[layout.T_TIME]), float(self._T[layout.T_STEP])
            self._f_valid = self._T[layout.T_STALE] == 0.0
            self._drain_events(events)
            self._drain_trace()
            self._drain_output()
            if status == layout.DONE:
                if t_call < t_end:
                    continue
                return events
            if status == layout.EVENT:
                return events
            if status in (layout.TRACE_FULL, layout.EVENT_LOG_FULL):
                continue
            if status == layout.STEP_BUDGET:
                self._check_budget()
                continue
            self._raise(status)

    def _check_budget(self):
        """Stop a run whose steps outgrow what any meaningful scene needs per simulated second
        (a hang otherwise: the kernel would step for hours)."""
        steps = int(self._stats[layout.ST_STEPS] + self._stats[layout.ST_REJECTED])
        allowed = MIN_STEP_BUDGET + STEPS_PER_SIMULATED_SECOND * self.state.t
        if steps > allowed:
            raise RunBudgetError(
                f'run budget exceeded: {steps} steps by t = {self.state.t:.6g} s (allowed '
                f'{MIN_STEP_BUDGET:g} + {STEPS_PER_SIMULATED_SECOND:g} per simulated second; '
                f'h = {self._h:.3g} s): the scene is too stiff or too small for its tolerances',
                t=self.state.t,
                state=self.state.y.copy(),
            )

    def _raise(self, status):
        st = self.state
        if status == layout.OUTPUT_FULL:  # advance() splits its calls so this cannot be
            raise RuntimeError('internal error: the output buffer overflowed')
        if status == layout.ERR_RESIDUAL:
            surf = self.model.surfaces[st.surface]
            delta, ratio = st.delta_m, st.delta_m / surf.constants.delta_c
            raise SimulationError(
                f'residual indentation fit gives delta_r = {st.delta_r:.4g} m >= delta_m = '
                f'{delta:.4g} m at t = {st.t:.9g} s: delta_m / delta_c = {ratio:.3g} is '
                f"beyond the fit's range (delta_r < delta_m needs delta_m / delta_c < "
                f'~9.8e3); the material is far too stiff for its yield strength',
                t=st.t,
                state=st.y.copy(),
            )
        if status == layout.ERR_PENETRATION:
            radius = self.model.surfaces[st.surface].constants.R
            raise SimulationError(
                f'penetration exceeds the tip radius {radius:g} m at t = {st.t:.9g} s: the '
                f'contact model is outside its validity (impact too fast or material too soft)',
                t=st.t,
                state=st.y.copy(),
            )
        what = 'non-finite state' if status == layout.ERR_NONFINITE else 'step size underflow'
        raise SimulationError(
            f'{what} at t = {st.t:.9g} s in phase {st.phase.name} (h = {self._h:.3g} s): the '
            f'model is too stiff for rtol = {self.rtol:g} or its state left the finite numbers',
            t=st.t,
            state=st.y.copy(),
        )

    def _drain_trace(self):
        count = int(self._trace_count[0])
        if count and self.trace is not None:
            rows = self._trace_buffer[:count]
            self.trace.extend(tuple(r) for r in rows.tolist())
        self._trace_count[0] = 0
