"""The stepped phase integrator: adaptive Dormand-Prince 5(4) that stops exactly at every
switch of the contact phase machine and restarts with the next phase's force law.

free --contact--> elastic --δ=1.9δc--> elasto-plastic --δ̇=0--> restitution --δ=δr--> free
(elastic --δ̇=0--> restitution for gentle impacts or a Hertz-only surface)

Contact is decided by this machine, never by the sign of y_B - h: after separation the tip sits
δr below h while it rises. Every switch is located by root-finding on *real* Runge-Kutta steps
from the start of the step that crossed it (not on an interpolant), so the state at a switch is
as accurate as any step end. Shaped like scipy's OdeSolver: ``advance(t_end)`` plays the part
of repeated ``step()`` calls and returns the events it crossed; ``sample(t)`` is dense output
over the last step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from . import control as ctl
from .contact import (friction_force, hertz_force, jackson_green_force, residual_indentation,
                      restitution_force, restitution_radius)
from .errors import SimulationError
from .model import ArmModel, ArmState, Phase

# name: (rtol, atol). atol is absolute on angles [rad], rates [rad/s] and integral states.
PRESETS = {
    'reference': (1e-12, 1e-14),
    'accurate': (1e-10, 1e-12),
    'balanced': (1e-8, 1e-10),
    'fast': (1e-5, 1e-8),
}

# Dormand-Prince 5(4) tableau (FSAL): the 5th-order solution propagates, the 4th-order one
# only estimates the error.
_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0)
_A = ((),
      (1 / 5,),
      (3 / 40, 9 / 40),
      (44 / 45, -56 / 15, 32 / 9),
      (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
      (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656))
_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)
_B4 = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)
_E = tuple(b - b4 for b, b4 in zip(_B + (0.0,), _B4))


@dataclass
class Event:
    kind: str            # contact | yield | max_compression | separation | switch | sample
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


class PhaseIntegrator:
    """Advances an ``ArmState`` on an ``ArmModel`` across contact phase switches.

    control='continuous' evaluates the scene's control law inside the right-hand side and
    switches its target at located events (the article's set-up); control='held' applies
    ``state.held_torque`` as a zero-order hold, as a real driver does between commands.
    """

    def __init__(self, model: ArmModel, state: ArmState | None = None, *, preset='balanced',
                 rtol=None, atol=None, max_step=None, control='continuous', trace=False):
        if preset not in PRESETS:
            raise ValueError(f'integrator preset {preset!r}: choose one of {", ".join(PRESETS)}')
        if control not in ('continuous', 'held'):
            raise ValueError(f"control = {control!r}: choose 'continuous' or 'held'")
        self.model = model
        self.state = state or model.initial_state()
        self.rtol, self.atol = PRESETS[preset]
        self.rtol = rtol if rtol is not None else self.rtol
        self.atol = atol if atol is not None else self.atol
        self.max_step = max_step if max_step is not None else math.inf
        self.control = control
        self.stats = Stats()
        self.trace = [] if trace else None
        spec = model.scene.controller
        self._law = spec.law if control == 'continuous' else 'held'
        self._targets = {'down': spec.down_target, 'up': spec.up_target}
        self._kp, self._kd = spec.kp, spec.kd
        self._ki = spec.ki if spec.law == 'pid' else (0.0,) * model.n
        self._actuators_in_contact = model.scene.actuators_during_contact
        self._h = None
        self._f = None
        self._last_step = None   # (t0, h, y0, f0, y1, f1) for dense output
        self._peak_force = 0.0
        self._impulse = [0.0, 0.0]          # ∫(F_f, F_n) dt since the last take_impulse()
        self._impulse_prev = (0.0, 0.0, 0.0)
        self._configure_events()

    # --- right-hand side ------------------------------------------------------------------
    def contact_forces(self, q, qd):
        """(δ, F_n, F_f, x_B, y_B, ẋ_B, ẏ_B) for the current contact phase."""
        st = self.state
        surf = self.model.surfaces[st.surface]
        c = surf.constants
        x, y_tip, vx, vy = self.model.tip(q, qd)
        delta = st.levels[st.surface] - y_tip
        if st.phase == Phase.ELASTIC:
            fn = hertz_force(delta, c.E, c.R)
        elif st.phase == Phase.ELASTOPLASTIC:
            fn = jackson_green_force(delta, c)
        else:
            fn = restitution_force(delta, st.delta_r, c.E, st.R_r)
        ff = friction_force(fn, vx, surf.mu, surf.v_d) if surf.mu > 0 else 0.0
        return delta, fn, ff, x, y_tip, vx, vy

    def torque(self, t, q, qd, y):
        """Joint torques acting now, or None when the actuators are off."""
        st = self.state
        if st.phase != Phase.FREE and not self._actuators_in_contact:
            return None
        if self._law == 'held':
            return st.held_torque
        if self._law == 'none':
            return None
        target = self._targets[st.mode]
        if self._law == 'q':
            return ctl.q_law(q, qd, target, self._kp, self._kd, self.model.gravity_forces(q))
        n = self.model.n
        error, rate = ctl.pid_error(q, qd, target, self.model.scene.controller.space)
        integral = y[2 * n:] if self.model.n_integral else (0.0,) * n
        return ctl.pid_law(error, rate, integral, self._kp, self._kd, self._ki)

    def rhs(self, t, y):
        self.stats.rhs_evaluations += 1
        model = self.model
        n = model.n
        q = y[:n].tolist()
        qd = y[n:2 * n].tolist()
        generalized = [0.0] * n
        if self.state.phase != Phase.FREE:
            _, fn, ff, *_ = self.contact_forces(q, qd)
            jac = model.tip_jacobian(q)
            for i in range(n):
                generalized[i] += jac[i] * ff + jac[n + i] * fn
        tau = self.torque(t, q, qd, y)
        if tau is not None:
            for i, value in enumerate(ctl.torques_to_generalized(tau)):
                generalized[i] += value
        out = np.empty(model.size)
        out[:n] = qd
        out[n:2 * n] = model.accelerations(q, qd, generalized)
        if model.n_integral:
            # the integral runs only while the controller acts (it is off during contact)
            if tau is None:
                out[2 * n:] = 0.0
            else:
                out[2 * n:] = ctl.pid_error(q, qd, self._targets[self.state.mode],
                                            model.scene.controller.space)[0]
        return out

    # --- one Dormand-Prince step --------------------------------------------------------------
    def _rk_step(self, t, y, f0, h):
        k = [f0]
        for i in range(1, 6):
            a = _A[i]
            yi = y + h * sum(a[j] * k[j] for j in range(i) if a[j])
            k.append(self.rhs(t + _C[i] * h, yi))
        y1 = y + h * sum(_B[j] * k[j] for j in range(6) if _B[j])
        f1 = self.rhs(t + h, y1)
        k.append(f1)
        err = h * sum(_E[j] * k[j] for j in range(7) if _E[j])
        return y1, f1, err

    def _error_norm(self, err, y0, y1):
        scale = self.atol + self.rtol * np.maximum(np.abs(y0), np.abs(y1))
        return math.sqrt(float(np.mean((err / scale) ** 2)))

    def _initial_step(self, t, y, f0):
        """Hairer's starting step: the phase just entered may be far stiffer than the last."""
        scale = self.atol + self.rtol * np.abs(y)
        d0 = math.sqrt(float(np.mean((y / scale) ** 2)))
        d1 = math.sqrt(float(np.mean((f0 / scale) ** 2)))
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        f1 = self.rhs(t + h0, y + h0 * f0)
        d2 = math.sqrt(float(np.mean(((f1 - f0) / scale) ** 2))) / h0
        h1 = (max(1e-6, h0 * 1e-3) if max(d1, d2) <= 1e-15
              else (0.01 / max(d1, d2)) ** (1 / 5))
        return min(100 * h0, h1, self.max_step)

    # --- events ---------------------------------------------------------------------------
    def _configure_events(self):
        """The event functions of the current phase; each fires when it rises through zero."""
        st = self.state
        if st.phase == Phase.FREE:
            kinds = [('contact', s.index) for s in self.model.surfaces]
            if self._law not in ('held', 'none') and st.mode == 'up':
                kinds.append(('switch', -1))
        elif st.phase == Phase.ELASTIC:
            law = self.model.surfaces[st.surface].law
            kinds = ([('yield', st.surface)] if law == 'elastoplastic' else []) + \
                [('max_compression', st.surface)]
        elif st.phase == Phase.ELASTOPLASTIC:
            kinds = [('max_compression', st.surface)]
        else:
            kinds = [('separation', st.surface)]
        self._event_kinds = kinds

    def _event_values(self, y):
        n = self.model.n
        q, qd = y[:n].tolist(), y[n:2 * n].tolist()
        _, y_tip, _, vy = self.model.tip(q, qd)
        st = self.state
        values = []
        for kind, s in self._event_kinds:
            if kind == 'contact':
                values.append(st.levels[s] - y_tip)
            elif kind == 'switch':
                values.append(y_tip - self.model.scene.controller.switch_height)
            elif kind == 'yield':
                values.append(st.levels[s] - y_tip - self.model.surfaces[s].constants.delta_yield)
            elif kind == 'max_compression':
                values.append(vy)      # δ̇ = -ẏ_B changes sign from + to -
            else:  # separation: δ falls through δr
                values.append(st.delta_r - (st.levels[s] - y_tip))
        return values

    def _apply_event(self, kind, s):
        """Switch the phase machine; returns information the event reports."""
        st = self.state
        n = self.model.n
        q, qd = st.y[:n].tolist(), st.y[n:2 * n].tolist()
        info = {}
        if kind == 'contact':
            st.phase, st.surface = Phase.ELASTIC, s
            self._peak_force = 0.0
            self._impulse_prev = (st.t, 0.0, 0.0)
            if self._law not in ('held', 'none') and st.mode == 'down':
                self._set_mode('up')
        elif kind == 'yield':
            st.phase = Phase.ELASTOPLASTIC
        elif kind == 'max_compression':
            delta, fn, *_ = self.contact_forces(q, qd)
            c = self.model.surfaces[s].constants
            st.delta_m, st.P_m = delta, fn
            st.delta_r = (residual_indentation(delta, c)
                          if self.model.surfaces[s].law == 'elastoplastic' else 0.0)
            st.R_r = restitution_radius(delta, st.delta_r, fn, c.E)
            self._peak_force = max(self._peak_force, fn)
            st.phase = Phase.RESTITUTION
            info = {'delta_m': delta, 'P_m': fn, 'delta_r': st.delta_r, 'R_r': st.R_r}
        elif kind == 'separation':
            # keep the dent: a re-strike before the tip leaves it meets the dent's floor
            st.levels[s] = st.levels[s] - st.delta_r
            st.phase, st.surface = Phase.FREE, -1
            info = {'F_max': self._peak_force, 'delta_m': st.delta_m, 'delta_r': st.delta_r}
        elif kind == 'switch':
            self._set_mode('down')
        self._configure_events()
        return info

    def _set_mode(self, mode):
        self.state.mode = mode
        if self.model.n_integral:
            self.state.y[2 * self.model.n:] = 0.0  # integral states reset when the target switches

    def _locate(self, t, y, f0, h, index, g1):
        """Earliest s in (0, h] where event ``index`` crosses zero, on real RK steps."""
        def g_at(s):
            y_s, _, _ = self._rk_step(t, y, f0, s)
            return self._event_values(y_s)[index]
        g0 = self._g0[index]
        if g1 == 0.0:
            return h
        tol = max(h * 1e-12, 1e-18)
        return brentq(g_at, 0.0, h, xtol=tol, rtol=4 * np.finfo(float).eps) if g0 < 0 else 0.0

    # --- public API -------------------------------------------------------------------------
    def reset_derivative(self):
        """Call after changing the state or held torque from outside (new command)."""
        self._f = None

    def advance(self, t_end, stop_at_event=False):
        """Integrate to ``t_end`` (exactly), crossing and reporting every phase switch.

        With ``stop_at_event`` it returns right after the first event instead."""
        st = self.state
        events = []
        if self._f is None:
            self._f = self.rhs(st.t, st.y)
        self._g0 = self._event_values(st.y)
        if self._h is None:
            self._h = self._initial_step(st.t, st.y, self._f)
        while st.t < t_end:
            remaining = t_end - st.t
            if remaining <= 4 * np.finfo(float).eps * max(1.0, abs(t_end)):
                st.t = t_end
                break
            h = min(self._h, self.max_step)
            clipped = h >= remaining
            if clipped:
                h = remaining
            t0, y0, f0 = st.t, st.y, self._f
            y1, f1, err = self._rk_step(t0, y0, f0, h)
            norm = self._error_norm(err, y0, y1) if np.all(np.isfinite(y1)) else math.inf
            if not norm <= 1.0:
                self.stats.rejected += 1
                self._h = h * (0.2 if not math.isfinite(norm) else max(0.2, 0.9 * norm ** -0.2))
                if self._h < 1e-15 * max(1.0, abs(t0)):
                    raise SimulationError(
                        f'step size underflow at t = {t0:.9g} s in phase {st.phase.name} '
                        f'(h = {self._h:.3g} s): the state is non-finite or the model too stiff '
                        f'for rtol = {self.rtol:g}', t=t0, state=y0.copy())
                continue
            self.stats.steps += 1
            factor = min(5.0, max(0.2, 0.9 * norm ** -0.2)) if norm > 0 else 5.0
            self._h = min(self._h, h * factor) if clipped else h * factor
            g1 = self._event_values(y1)
            crossed = [i for i, (a, b) in enumerate(zip(self._g0, g1)) if a < 0 <= b]
            if crossed:
                s_root, index = min((self._locate(t0, y0, f0, h, i, g1[i]), i) for i in crossed)
                y_root = self._rk_step(t0, y0, f0, s_root)[0] if s_root < h else y1
                st.t, st.y = t0 + s_root, y_root
                self._record(st.t, st.y)
                kind, surface = self._event_kinds[index]
                info = self._apply_event(kind, surface)
                self.stats.events += 1
                events.append(Event(kind, st.t, surface, st.y.copy(), info))
                self._f = self.rhs(st.t, st.y)
                self._g0 = self._event_values(st.y)
                self._h = self._initial_step(st.t, st.y, self._f) if kind != 'switch' else self._h
                self._last_step = None
                self._check_state()
                if stop_at_event:
                    return events
                continue
            self._last_step = (t0, h, y0, f0, y1, f1)
            st.t, st.y, self._f, self._g0 = t0 + h, y1, f1, g1
            if clipped:
                st.t = t_end  # land exactly, whatever the rounding of t0 + h
            self._after_step()
        return events

    def _after_step(self):
        st = self.state
        if st.phase != Phase.FREE:
            self._record(st.t, st.y)
            self._check_state()
        elif any(level != s.height for level, s in zip(st.levels, self.model.surfaces)):
            # the dent is forgotten once the tip has risen above the surface again
            n = self.model.n
            y_tip = self.model.tip(st.y[:n].tolist(), st.y[n:2 * n].tolist())[1]
            for i, s in enumerate(self.model.surfaces):
                if y_tip > s.height:
                    st.levels[i] = s.height
            self._g0 = self._event_values(st.y)

    def _check_state(self):
        st = self.state
        if not np.all(np.isfinite(st.y)):
            raise SimulationError(f'non-finite state at t = {st.t:.9g} s', t=st.t, state=st.y)
        if st.phase != Phase.FREE:
            n = self.model.n
            delta = st.levels[st.surface] - self.model.tip(st.y[:n].tolist(),
                                                           st.y[n:2 * n].tolist())[1]
            radius = self.model.surfaces[st.surface].constants.R
            if delta > radius:
                raise SimulationError(
                    f'penetration {delta:.4g} m exceeds the tip radius {radius:g} m at '
                    f't = {st.t:.9g} s: the contact model is outside its validity (impact '
                    f'too fast or material too soft)', t=st.t, state=st.y.copy())

    def _record(self, t, y):
        st = self.state
        if st.phase == Phase.FREE:
            return
        n = self.model.n
        q, qd = y[:n].tolist(), y[n:2 * n].tolist()
        delta, fn, ff, x, y_tip, vx, vy = self.contact_forces(q, qd)
        self._peak_force = max(self._peak_force, fn)
        # trapezoidal impulse over accepted points (steps inside contact are microseconds)
        t_prev, ff_prev, fn_prev = self._impulse_prev
        self._impulse[0] += 0.5 * (ff + ff_prev) * (t - t_prev)
        self._impulse[1] += 0.5 * (fn + fn_prev) * (t - t_prev)
        self._impulse_prev = (t, ff, fn)
        if self.trace is not None:
            energies = self.model.link_energies(q, qd)
            self.trace.append((t, int(st.phase), delta, fn, ff, vx, vy, *energies))

    def take_impulse(self):
        """Contact impulse (tangential, normal) [N s] accumulated since the last call."""
        out = tuple(self._impulse)
        self._impulse = [0.0, 0.0]
        return out

    def contact_force_now(self):
        """(F_tangential, F_normal) acting at the current state (zero in free motion)."""
        st = self.state
        if st.phase == Phase.FREE:
            return 0.0, 0.0
        n = self.model.n
        _, fn, ff, *_ = self.contact_forces(st.y[:n].tolist(), st.y[n:2 * n].tolist())
        return ff, fn

    def sample(self, t):
        """Dense output inside the last accepted step (cubic Hermite on y and f)."""
        if self._last_step is None:
            return self.state.y.copy()
        t0, h, y0, f0, y1, f1 = self._last_step
        s = (t - t0) / h
        h00, h10 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s
        h01, h11 = -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
        return h00 * y0 + h10 * h * f0 + h01 * y1 + h11 * h * f1
