"""The stepped phase integrator kernel, as template text split by concern.

``equations.load_equations`` builds one module per scene shape: a header of compile-time
constants (``N``, ``NM``, ``HAS_MOUNT``, the layout's offsets), the
sympy-generated equations (``tip``, ``tip_jacobian``, ``gravity_forces``, ``link_energies``,
``accel`` or ``mass_and_rhs``), then the parts below, in ``PARTS`` order, each from its
``MARKER`` line on. What stands above a part's marker (imports from ``layout``, from the
``injected`` stub and from sibling parts) is there so linters and editors can follow the
template; the generator drops it. The parts are written in the numba-compatible subset of
Python: compiled with numba when it is available, interpreted otherwise. Module-level
constants are compile-time constants for numba; what a parameter value can switch off
(gravity, surfaces, friction) is a value, so every scene of one arm shape shares a kernel.

The kernel: Dormand-Prince 5(4) with error control (or, in free flight when I_METHOD asks
for it, a linearly implicit Rosenbrock 4(3) step: the controller makes the free flight
stiff); every step is checked for sign changes of the phase's event functions, and a crossing
is located by root-finding on real steps from the step start (Newton inside an Illinois
bracket), so the state at a switch is as accurate as any step end. The kernel applies each
switch itself (``apply_event``) and logs it for the Python wrapper, which asks it to return
only after the kinds of event it needs to act on.

- ``rhs``: the right-hand side (equations of motion, contact forces, control torque)
- ``steps``: the Dormand-Prince step (``physics/dormand_prince.py``) and the Rosenbrock step,
  starting step
- ``events``: event functions (``physics/contact_phases.py``) and their location
  (``physics/roots.py``)
- ``phases``: the phase machine (apply_event) and the contact bookkeeping per point

The Dormand-Prince step, the event location, the phase machine's events and switches and the
contact force dispatch (``physics/contact.py``) are plain modules the free body's kernel
(``bodies/kernel.py``) uses too; the generated module's header imports them.
- ``output``: dense output and the rows on the output grid
- ``loop``: the stepping loop and ``advance``, the entry point
- ``predict``: the controller's prediction of the free motion over its commands in flight
"""

import os

__all__ = ['MARKER', 'PARTS', 'template_source']

PARTS = ('rhs', 'steps', 'events', 'phases', 'output', 'loop', 'predict')
MARKER = '# --- template: equations.py copies what follows into the generated module ---\n'


def template_source() -> str:
    """The parts' template text, concatenated in ``PARTS`` order."""
    texts = []
    for name in PARTS:
        with open(os.path.join(os.path.dirname(__file__), name + '.py'), encoding='utf-8') as f:
            text = f.read()
        head, marker, body = text.partition(MARKER)
        if not marker:
            raise RuntimeError(f'kernel part {name}.py has no template marker')
        texts.append(f'# ----- kernel part: {name}\n{body.strip()}\n')
    return '\n\n'.join(texts)
