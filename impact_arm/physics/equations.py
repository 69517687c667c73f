"""Equations of motion of a planar chain of links, derived with sympy and compiled once.

Generalized coordinates are the *absolute* link angles q_i (from +x). Lagrange's equations
d/dt(dT/dq̇) - dT/dq = Q give  M(q) q̈ = Q - b(q, q̇)  with b the velocity-product terms.
Gravity enters through its generalized forces Q_g = Σ G_j · ∂r_Cj/∂q_i (docs/model.md), never
through a hand-typed formula.

The derivation keeps lengths, masses and g as symbols (for general links also the centres of
mass, inertias and contact point: ``GEOMETRY``), so one derivation serves every scene with the
same number of links (gravity, contact and friction are values: g, the surface table's rows
and μ); a scene of uniform rods gets the rods' equations,
exactly as before general links existed; sympy is slow to import and to
differentiate, so the generated Python source is cached on disk (``cache_dir()``) keyed by a
hash of what it was generated from. A warm start imports no sympy at all.

Why the kernel is generated text rather than an ordinary module: each scene shape gets its
own module whose header makes N, NM and the layout's offsets module-level constants, which
numba compiles as constants (loops of known length); and numba caches compiled functions per
source file, so one file per shape gives each shape its own cache entry, which a shared
module with runtime flags could not. The kernel's source is ``kernel/`` (split by concern;
``kernel/injected.py`` declares what this generator injects).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import hashlib
import importlib.util
import os
import re
import sys
import tempfile
import types

GENERATOR_VERSION = '7'


def jit_options() -> str:
    from . import jit

    return f'numba {jit.AVAILABLE}, {sorted(jit.LEAF_OPTIONS.items())}'


def cache_dir() -> str:
    base = os.environ.get('IMPACT_ARM_CACHE') or os.path.join(
        os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache'),
        'impact_arm',
    )
    return base


# the kernel's form of mass_and_rhs (``kernel/injected.py``) for the symbolic derivation
MASS_INTO_WRAPPER = """

@jit_leaf
def mass_and_rhs_into(q, qd, Qx, L, m, g, S, out):
    values = mass_and_rhs(q, qd, Qx, L, m, g)
    for i in range(len(q) * len(q)):
        S[i] = values[i]
    for i in range(len(q)):
        out[i] = values[len(q) * len(q) + i]
"""


def _derive_source(n: int, general: bool = False) -> str:
    """Generate Python source for the chain's numeric functions (runs sympy).

    ``general``: links with any centre of mass (along and across the link), any inertia
    about it and the contact point anywhere on the last link, read from the geometry block
    (``GEOMETRY``); otherwise uniform rods struck at the last link's end, whose block holds
    the lengths alone."""
    import sympy as sp

    q = sp.symbols(f'q0:{n}')
    qd = sp.symbols(f'qd0:{n}')
    L = sp.symbols(f'L0:{n}', positive=True)
    if general:
        com_x = sp.symbols(f'cx0:{n}', real=True)  # centre of mass along link i
        com_y = sp.symbols(f'cy0:{n}', real=True)  # ... and across it (towards e_i⊥)
        inertias = sp.symbols(f'Jc0:{n}', positive=True)  # about the centre of mass
        tip_x, tip_y = sp.symbols('tx ty', real=True)  # contact point on the last link
        geometry = tuple(L) + com_x + com_y + inertias + (tip_x, tip_y)
    else:
        geometry = tuple(L)
    m = sp.symbols(f'm0:{n}', positive=True)
    g = sp.Symbol('g')
    Qx = sp.symbols(f'Qx0:{n}')  # non-gravity generalized forces (joint torques, contact)

    def e(i: int) -> Any:
        return sp.Matrix([sp.cos(q[i]), sp.sin(q[i])])

    def across(i: int) -> Any:  # e_i turned by +90°
        return sp.Matrix([-sp.sin(q[i]), sp.cos(q[i])])

    def dt(expr: Any) -> Any:  # total time derivative along the motion
        return sum(sp.diff(expr, q[i]) * qd[i] for i in range(n))

    joints = [sp.zeros(2, 1)]
    for i in range(n):
        joints.append(joints[-1] + L[i] * e(i))
    if general:
        centres = [joints[i] + com_x[i] * e(i) + com_y[i] * across(i) for i in range(n)]
        tip = joints[n - 1] + tip_x * e(n - 1) + tip_y * across(n - 1)
    else:
        centres = [joints[i] + L[i] / 2 * e(i) for i in range(n)]
        tip = joints[-1]

    link_T = []
    for i in range(n):
        v = centres[i].applyfunc(dt)
        # about the centre: given, or a uniform rod's
        inertia = inertias[i] if general else m[i] * L[i] ** 2 / 12
        link_T.append(
            sp.Rational(1, 2) * inertia * qd[i] ** 2 + sp.Rational(1, 2) * m[i] * (v.T * v)[0]
        )
    link_T = [sp.trigsimp(sp.expand(t)) for t in link_T]
    T = sum(link_T)
    qg = [sum((-m[j] * g) * sp.diff(centres[j][1], q[i]) for j in range(n)) for i in range(n)]
    V = sum(m[j] * g * centres[j][1] for j in range(n))

    M = sp.Matrix(n, n, lambda i, j: sp.diff(T, qd[i], qd[j]))
    p = [sp.diff(T, qd[i]) for i in range(n)]
    b = [dt(p[i]) - sp.diff(T, q[i]) for i in range(n)]  # d/dt(dT/dq̇) without the q̈ part
    rhs = sp.Matrix([Qx[i] + qg[i] - b[i] for i in range(n)])
    M = M.applyfunc(sp.simplify)
    if n <= (GENERAL_SYMBOLIC_ACCEL if general else 3):
        qdd = list(M.LUsolve(rhs))
        solve_numerically = False
    else:  # symbolic inverses grow too fast; solve M x = rhs numerically at run time
        qdd = None
        solve_numerically = True

    tip_v = tip.applyfunc(dt)
    qdd_s = sp.symbols(f'qdd0:{n}')
    tip_a = tip_v.applyfunc(lambda e: dt(e) + sum(sp.diff(e, qd[i]) * qdd_s[i] for i in range(n)))
    jac = [[sp.diff(tip[k], q[i]) for i in range(n)] for k in range(2)]

    def function(
        name: str, args: Sequence[str], outputs: Sequence[Any], unpacks: Sequence[tuple]
    ) -> str:
        reps, reduced = sp.cse(outputs, optimizations='basic')
        lines = ['@jit_leaf', f'def {name}({", ".join(args)}):']
        for symbols, source in unpacks:
            lines += [f'    {sym} = {source}[{i}]' for i, sym in enumerate(symbols)]
        lines += [f'    {s} = {sp.pycode(x, fully_qualified_modules=False)}' for s, x in reps]
        body = ', '.join(sp.pycode(x, fully_qualified_modules=False) for x in reduced)
        lines.append(f'    return ({body},)')
        return '\n'.join(lines)

    params = [(geometry, 'L'), (m, 'm')]
    state = [(q, 'q'), (qd, 'qd')]
    funcs = []
    if not solve_numerically:
        funcs.append(
            # ignored [arg-type]: qdd is set whenever the system is solved symbolically
            function('accel', ['q', 'qd', 'Qx', 'L', 'm', 'g'], qdd, state + params + [(Qx, 'Qx')])  # type: ignore[arg-type]
        )
    funcs.append(
        function(
            'mass_and_rhs',
            ['q', 'qd', 'Qx', 'L', 'm', 'g'],
            list(M) + list(rhs),
            state + params + [(Qx, 'Qx')],
        )
    )
    funcs.append(
        function(
            'tip', ['q', 'qd', 'L'], [tip[0], tip[1], tip_v[0], tip_v[1]], state + [(geometry, 'L')]
        )
    )
    funcs.append(
        function(
            'tip_acceleration',
            ['q', 'qd', 'qdd', 'L'],
            [tip_a[0], tip_a[1]],
            state + [(qdd_s, 'qdd'), (geometry, 'L')],
        )
    )
    funcs.append(function('tip_jacobian', ['q', 'L'], jac[0] + jac[1], [(q, 'q'), (geometry, 'L')]))
    funcs.append(function('gravity_forces', ['q', 'L', 'm', 'g'], qg, [(q, 'q')] + params))
    funcs.append(function('link_energies', ['q', 'qd', 'L', 'm'], link_T, state + params))
    funcs.append(function('potential', ['q', 'L', 'm', 'g'], [V], [(q, 'q')] + params))
    funcs.append(f'HAS_ACCEL = {not solve_numerically}')
    return '\n\n\n'.join(funcs) + '\n'


# Up to this many links the equations come from the symbolic derivation above (which then
# also gives q̈ in closed form); beyond it from the chain's closed form below
# (``_chain_source``): the symbolic expansion grows steeply with n (4 links: 5 s, 5 links:
# 5-10 s, 8 links: ~1 min) while the closed form is written in milliseconds.
SYMBOLIC_LINKS = 3


def _source_head(name: str, args: Sequence[str]) -> list[str]:
    """The first lines of a generated chain function (a jit leaf)."""
    return ['@jit_leaf', f'def {name}({", ".join(args)}):']


def _source_trig(lines: list[str], n: int) -> None:
    """c{i}, s{i}: the cosine and sine of each link's absolute angle."""
    for i in range(n):
        lines.append(f'    c{i} = cos(q[{i}])')
        lines.append(f'    s{i} = sin(q[{i}])')


def _source_tail_masses(lines: list[str], n: int) -> None:
    """S{k}: the mass of links k .. n-1 (S{n} = 0)."""
    lines.append(f'    S{n} = 0.0')
    for k in reversed(range(n)):
        lines.append(f'    S{k} = S{k + 1} + m[{k}]')


def _chain_source(n: int) -> str:
    """The same functions as ``_derive_source`` for a planar chain of uniform rods, written
    from the chain's closed form instead of a symbolic expansion.

    With absolute angles, link k's centre moves with ∂c_k/∂q_i = a_ik e_i⊥ (a_ik = L_i for
    i < k, L_k / 2 for i = k, 0 beyond), so T = ½ Σ_ij C_ij cos(q_i - q_j) q̇_i q̇_j with
    C_ij = L_i L_j (m_j / 2 + S_{j+1}) for i < j (S_k: the mass of links k, k+1, ...) and
    C_ii = L_i² (m_i / 3 + S_{i+1}) (the rod's own inertia m L² / 12 included). Lagrange's
    equations then give M_ij = C_ij cos(q_i - q_j) and the velocity terms
    b_i = Σ_j C_ij sin(q_i - q_j) q̇_j²; gravity's generalized force is
    Q_g,i = -g L_i cos q_i (m_i / 2 + S_{i+1}). Checked against the symbolic derivation for
    2-4 links (test_equations.py)."""
    r = range(n)

    def coefficient(i: int, j: int) -> str:
        if i == j:
            return f'L[{i}] * L[{i}] * (m[{i}] / 3.0 + S{i + 1})'
        a, b = min(i, j), max(i, j)
        return f'L[{a}] * L[{b}] * (0.5 * m[{b}] + S{b + 1})'

    funcs = []
    lines = _source_head('mass_and_rhs', ['q', 'qd', 'Qx', 'L', 'm', 'g'])
    _source_trig(lines, n)
    _source_tail_masses(lines, n)
    for i in r:
        for j in range(i, n):
            lines.append(f'    C{i}_{j} = {coefficient(i, j)}')
    for i in r:
        for j in range(i + 1, n):
            lines.append(f'    M{i}_{j} = C{i}_{j} * (c{i} * c{j} + s{i} * s{j})')
            lines.append(f'    sn{i}_{j} = s{i} * c{j} - c{i} * s{j}')  # sin(q_i - q_j)
    for i in r:
        terms = []
        for j in r:
            if j == i:
                continue
            lo, hi = min(i, j), max(i, j)
            sign = '' if i < j else '-'
            terms.append(f'{sign}C{lo}_{hi} * sn{lo}_{hi} * qd[{j}] * qd[{j}]')
        b = ' + '.join(terms).replace('+ -', '- ') or '0.0'
        grav = f' - g * L[{i}] * c{i} * (0.5 * m[{i}] + S{i + 1})'
        lines.append(f'    r{i} = Qx[{i}]{grav} - ({b})')
    entries = []
    for i in r:
        for j in r:
            entries.append(f'C{i}_{i}' if i == j else f'M{min(i, j)}_{max(i, j)}')
    entries += [f'r{i}' for i in r]
    lines.append(f'    return ({", ".join(entries)},)')
    funcs.append('\n'.join(lines))
    # the kernel's form: loops, not straight-line code (n² named values cost numba seconds
    # to type and lower: 6 s at 12 links)
    gravity_term = ' - g * L[j] * cos(q[j]) * (0.5 * m[j] + tail)'
    funcs.append(f"""@jit_leaf
def mass_and_rhs_into(q, qd, Qx, L, m, g, S, out):
    n = q.shape[0]
    tail = 0.0                  # mass of the links beyond link j
    for j in range(n - 1, -1, -1):
        out[j] = Qx[j]{gravity_term}
        S[j * n + j] = L[j] * L[j] * (m[j] / 3.0 + tail)
        for i in range(j):      # the upper triangle holds C_ij until the second pass
            S[i * n + j] = L[i] * L[j] * (0.5 * m[j] + tail)
        tail += m[j]
    for j in range(n):
        for i in range(j):
            c = S[i * n + j]
            d = q[i] - q[j]
            sn = c * sin(d)
            out[i] -= sn * qd[j] * qd[j]
            out[j] += sn * qd[i] * qd[i]
            S[i * n + j] = c * cos(d)
            S[j * n + i] = S[i * n + j]""")
    lines = _source_head('tip', ['q', 'qd', 'L'])
    _source_trig(lines, n)
    lines.append(
        '    return ('
        + ' + '.join(f'L[{i}] * c{i}' for i in r)
        + ', '
        + ' + '.join(f'L[{i}] * s{i}' for i in r)
        + ', '
        + ' + '.join(f'-L[{i}] * s{i} * qd[{i}]' for i in r)
        + ', '
        + ' + '.join(f'L[{i}] * c{i} * qd[{i}]' for i in r)
        + ',)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('tip_acceleration', ['q', 'qd', 'qdd', 'L'])
    _source_trig(lines, n)
    lines.append(
        '    return ('
        + ' + '.join(f'L[{i}] * (-s{i} * qdd[{i}] - c{i} * qd[{i}] * qd[{i}])' for i in r)
        + ', '
        + ' + '.join(f'L[{i}] * (c{i} * qdd[{i}] - s{i} * qd[{i}] * qd[{i}])' for i in r)
        + ',)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('tip_jacobian', ['q', 'L'])
    _source_trig(lines, n)
    lines.append(
        '    return ('
        + ', '.join([f'-L[{i}] * s{i}' for i in r] + [f'L[{i}] * c{i}' for i in r])
        + ',)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('gravity_forces', ['q', 'L', 'm', 'g'])
    _source_tail_masses(lines, n)
    lines.append(
        '    return ('
        + ', '.join(f'-g * L[{i}] * cos(q[{i}]) * (0.5 * m[{i}] + S{i + 1})' for i in r)
        + ',)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('link_energies', ['q', 'qd', 'L', 'm'])
    _source_trig(lines, n)
    # centre velocity of link k: the joint's velocity (sum over the links before it) plus
    # half of its own link's
    lines.append('    jx = 0.0')
    lines.append('    jy = 0.0')
    for k in r:
        lines.append(f'    vx = jx - 0.5 * L[{k}] * s{k} * qd[{k}]')
        lines.append(f'    vy = jy + 0.5 * L[{k}] * c{k} * qd[{k}]')
        lines.append(
            f'    T{k} = 0.5 * m[{k}] * (vx * vx + vy * vy) '
            f'+ m[{k}] * L[{k}] * L[{k}] / 24.0 * qd[{k}] * qd[{k}]'
        )
        lines.append(f'    jx = jx - L[{k}] * s{k} * qd[{k}]')
        lines.append(f'    jy = jy + L[{k}] * c{k} * qd[{k}]')
    lines.append('    return (' + ', '.join(f'T{k}' for k in r) + ',)')
    funcs.append('\n'.join(lines))

    lines = _source_head('potential', ['q', 'L', 'm', 'g'])
    lines.append('    y = 0.0')
    lines.append('    V = 0.0')
    for k in r:
        lines.append(f'    V += m[{k}] * g * (y + 0.5 * L[{k}] * sin(q[{k}]))')
        lines.append(f'    y += L[{k}] * sin(q[{k}])')
    lines.append('    return (V,)')
    funcs.append('\n'.join(lines))
    funcs.append('HAS_ACCEL = False')
    return '\n\n\n'.join(funcs) + '\n'


# General links: the closed-form q̈ of the symbolic derivation up to this many links (its
# expressions grow faster with the centre-of-mass offsets than with rods'); beyond, and in
# every long chain, M q̈ = rhs is solved numerically.
GENERAL_SYMBOLIC_ACCEL = 2

# The geometry block of general links (``layout.geometry_size``), in the order the
# generated functions read it: lengths L_i (joint i to joint i+1), centre of mass of each
# link along (cx_i) and across (cy_i) it from its joint, inertia about the centre of mass
# (Jc_i), then the contact point on the last link along (tx) and across (ty) it.
GEOMETRY = ('L', 'cx', 'cy', 'Jc', 'tip')


def _general_chain_source(n: int) -> str:
    """``_chain_source`` for general links (``GEOMETRY``): any centre of mass, inertia and
    contact point on the last link.

    Link k's centre is c_k = Σ_(i<k) L_i e_i + cx_k e_k + cy_k e_k⊥ (e⊥: e turned by +90°), so
    ∂c_k/∂q_i = L_i e_i⊥ for i < k and cx_k e_k⊥ − cy_k e_k for i = k. With S_k the mass of
    links k, k+1, ... the kinetic energy ½ Σ M_ij q̇_i q̇_j has
    M_ii = Jc_i + m_i (cx_i² + cy_i²) + L_i² S_(i+1) and, for i < j,
    M_ij = A_ij cos(q_i − q_j) + B_ij sin(q_i − q_j), A_ij = L_i (L_j S_(j+1) + m_j cx_j),
    B_ij = L_i m_j cy_j. Each M_ij depends on q_i − q_j alone, so Lagrange's velocity terms
    are b_i = Σ_(j>i) σ_ij q̇_j² − Σ_(j<i) σ_ji q̇_j² with σ_ij = A_ij sin(q_i − q_j) −
    B_ij cos(q_i − q_j); gravity's generalized force is
    Q_g,i = −g (L_i cos q_i S_(i+1) + m_i (cx_i cos q_i − cy_i sin q_i)). A rod (cx = L/2,
    cy = 0, Jc = m L²/12) gives ``_chain_source``'s coefficients. Checked against the
    symbolic derivation for 2-4 links and against Pinocchio (test_equations.py,
    test_urdf_arm.py)."""
    r = range(n)
    last = n - 1

    def cx(i: int) -> str:
        return f'L[{n + i}]'

    def cy(i: int) -> str:
        return f'L[{2 * n + i}]'

    def jc(i: int) -> str:
        return f'L[{3 * n + i}]'

    tx, ty = f'L[{4 * n}]', f'L[{4 * n + 1}]'

    def gravity_force(i: int) -> str:
        return f'-g * (L[{i}] * c{i} * S{i + 1} + m[{i}] * ({cx(i)} * c{i} - {cy(i)} * s{i}))'

    def rotated_tip(lines: list[str]) -> None:
        # the contact point relative to the last joint, in the plane's axes
        lines.append(f'    px = {tx} * c{last} - {ty} * s{last}')
        lines.append(f'    py = {tx} * s{last} + {ty} * c{last}')

    funcs = []
    lines = _source_head('mass_and_rhs', ['q', 'qd', 'Qx', 'L', 'm', 'g'])
    _source_trig(lines, n)
    _source_tail_masses(lines, n)
    for i in r:
        lines.append(
            f'    M{i}_{i} = {jc(i)} + m[{i}] * ({cx(i)} * {cx(i)} + {cy(i)} * {cy(i)})'
            f' + L[{i}] * L[{i}] * S{i + 1}'
        )
        for j in range(i + 1, n):
            lines.append(f'    A{i}_{j} = L[{i}] * (L[{j}] * S{j + 1} + m[{j}] * {cx(j)})')
            lines.append(f'    B{i}_{j} = L[{i}] * m[{j}] * {cy(j)}')
            lines.append(f'    cd{i}_{j} = c{i} * c{j} + s{i} * s{j}')  # cos(q_i - q_j)
            lines.append(f'    sd{i}_{j} = s{i} * c{j} - c{i} * s{j}')  # sin(q_i - q_j)
            lines.append(f'    M{i}_{j} = A{i}_{j} * cd{i}_{j} + B{i}_{j} * sd{i}_{j}')
            lines.append(f'    g{i}_{j} = A{i}_{j} * sd{i}_{j} - B{i}_{j} * cd{i}_{j}')
    for i in r:
        terms = [f'g{i}_{j} * qd[{j}] * qd[{j}]' for j in range(i + 1, n)]
        terms += [f'-g{j}_{i} * qd[{j}] * qd[{j}]' for j in range(i)]
        b = ' + '.join(terms).replace('+ -', '- ') or '0.0'
        grav = f' + ({gravity_force(i)})'
        lines.append(f'    r{i} = Qx[{i}]{grav} - ({b})')
    entries = [f'M{min(i, j)}_{max(i, j)}' for i in r for j in r] + [f'r{i}' for i in r]
    lines.append(f'    return ({", ".join(entries)},)')
    funcs.append('\n'.join(lines))
    gravity_term = (
        f' - g * (L[j] * cos(q[j]) * tail + m[j] * (L[{n} + j] * cos(q[j])'
        f' - L[{2 * n} + j] * sin(q[j])))'
    )
    funcs.append(f"""@jit_leaf
def mass_and_rhs_into(q, qd, Qx, L, m, g, S, out):
    n = q.shape[0]
    tail = 0.0                  # mass of the links beyond link j
    for j in range(n - 1, -1, -1):
        cx = L[n + j]
        cy = L[2 * n + j]
        out[j] = Qx[j]{gravity_term}
        S[j * n + j] = L[3 * n + j] + m[j] * (cx * cx + cy * cy) + L[j] * L[j] * tail
        for i in range(j):      # A_ij above the diagonal, B_ij below, until the second pass
            S[i * n + j] = L[i] * (L[j] * tail + m[j] * cx)
            S[j * n + i] = L[i] * m[j] * cy
        tail += m[j]
    for j in range(n):
        for i in range(j):
            a = S[i * n + j]
            b = S[j * n + i]
            d = q[i] - q[j]
            cd = cos(d)
            sd = sin(d)
            sigma = a * sd - b * cd
            out[i] -= sigma * qd[j] * qd[j]
            out[j] += sigma * qd[i] * qd[i]
            S[i * n + j] = a * cd + b * sd
            S[j * n + i] = S[i * n + j]""")

    def joint_sum(term: str) -> str:
        return ' + '.join([term.format(i=i) for i in range(last)] or ['0.0'])

    lines = _source_head('tip', ['q', 'qd', 'L'])
    _source_trig(lines, n)
    rotated_tip(lines)
    lines.append(
        '    return ('
        + f'{joint_sum("L[{i}] * c{i}")} + px, '
        + f'{joint_sum("L[{i}] * s{i}")} + py, '
        + f'{joint_sum("-L[{i}] * s{i} * qd[{i}]")} - py * qd[{last}], '
        + f'{joint_sum("L[{i}] * c{i} * qd[{i}]")} + px * qd[{last}],)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('tip_acceleration', ['q', 'qd', 'qdd', 'L'])
    _source_trig(lines, n)
    rotated_tip(lines)
    w = f'qd[{last}] * qd[{last}]'
    lines.append(
        '    return ('
        + joint_sum('L[{i}] * (-s{i} * qdd[{i}] - c{i} * qd[{i}] * qd[{i}])')
        + f' - py * qdd[{last}] - px * {w}, '
        + joint_sum('L[{i}] * (c{i} * qdd[{i}] - s{i} * qd[{i}] * qd[{i}])')
        + f' + px * qdd[{last}] - py * {w},)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('tip_jacobian', ['q', 'L'])
    _source_trig(lines, n)
    rotated_tip(lines)
    lines.append(
        '    return ('
        + ', '.join(
            [f'-L[{i}] * s{i}' for i in range(last)]
            + ['-py']
            + [f'L[{i}] * c{i}' for i in range(last)]
            + ['px']
        )
        + ',)'
    )
    funcs.append('\n'.join(lines))

    lines = _source_head('gravity_forces', ['q', 'L', 'm', 'g'])
    _source_trig(lines, n)
    _source_tail_masses(lines, n)
    lines.append('    return (' + ', '.join(gravity_force(i) for i in r) + ',)')
    funcs.append('\n'.join(lines))

    def centre(lines: list[str], k: int) -> None:
        # link k's centre relative to its joint, in the plane's axes
        lines.append(f'    ux = {cx(k)} * c{k} - {cy(k)} * s{k}')
        lines.append(f'    uy = {cx(k)} * s{k} + {cy(k)} * c{k}')

    lines = _source_head('link_energies', ['q', 'qd', 'L', 'm'])
    _source_trig(lines, n)
    lines.append('    jx = 0.0')  # velocity of link k's joint
    lines.append('    jy = 0.0')
    for k in r:
        centre(lines, k)
        lines.append(f'    vx = jx - uy * qd[{k}]')
        lines.append(f'    vy = jy + ux * qd[{k}]')
        lines.append(
            f'    T{k} = 0.5 * m[{k}] * (vx * vx + vy * vy) + 0.5 * {jc(k)} * qd[{k}] * qd[{k}]'
        )
        lines.append(f'    jx = jx - L[{k}] * s{k} * qd[{k}]')
        lines.append(f'    jy = jy + L[{k}] * c{k} * qd[{k}]')
    lines.append('    return (' + ', '.join(f'T{k}' for k in r) + ',)')
    funcs.append('\n'.join(lines))

    lines = _source_head('potential', ['q', 'L', 'm', 'g'])
    _source_trig(lines, n)
    lines.append('    y = 0.0')
    lines.append('    V = 0.0')
    for k in r:
        centre(lines, k)
        lines.append(f'    V += m[{k}] * g * (y + uy)')
        lines.append(f'    y += L[{k}] * s{k}')
    lines.append('    return (V,)')
    funcs.append('\n'.join(lines))
    funcs.append('HAS_ACCEL = False')
    return '\n\n\n'.join(funcs) + '\n'


def _module_header(n, general=False, n_mount=0):
    """Constants the kernel template reads as compile-time constants."""
    from .layout import shape_offsets

    offsets = shape_offsets(n, general, n_mount)
    links = ', general links' if general else ''
    lines = [
        f'# generated by impact_arm.physics.equations v{GENERATOR_VERSION}: n={n}{links}'
        + (f', mounted surfaces={n_mount}.' if n_mount else '.'),
        '# Do not edit: delete the file to regenerate it.',
        f'# compiled with {jit_options()}',
        'import math',
        'from math import sin, cos, sqrt',
        'import numpy as np',
        # a long chain: the kernel's helpers are compiled once and called instead of
        # inlined at every call site (numba's inlining copies and re-types their code
        # each time: a 30 s cold start, growing with the links)
        'from impact_arm.physics.jit import jit, jit_leaf'
        if n <= SYMBOLIC_LINKS
        else 'from impact_arm.physics.jit import jit, jit as jit_leaf  # called, not inlined',
        'from impact_arm.physics.layout import *  # noqa: F401,F403',
        'from impact_arm.physics.contact import friction_force, phase_normal_force',
        'from impact_arm.physics.contact_phases import max_compression, phase_events',
        'from impact_arm.physics.dormand_prince import (dormand_prince_step, error_norm,',
        '                                D12, D13, D14, D32, D33, D34, D42, D43, D44,',
        '                                D52, D53, D54, D62, D63, D64, D72, D73, D74)',
        'from impact_arm.physics.control import add_joint_torques, pid_error, pid_law, q_law',
        'from impact_arm.physics.roots import event_tolerance, locate_crossing',
        f'N = {n}',
    ]
    lines += [f'NM = {n_mount}', f'HAS_MOUNT = {n_mount > 0}']
    lines += [f'{k} = {v}' for k, v in offsets.items()]
    return '\n'.join(lines) + '\n\n\n'


def _derivation(n, general=False):
    """The sympy part (slow), cached on its own: it does not depend on the scene's features.
    Beyond ``SYMBOLIC_LINKS`` the chain's closed form, which needs no cache. Gravity is
    always in it: g is a value (P_G), and g = 0 multiplies its terms away."""
    if n > SYMBOLIC_LINKS:
        return _general_chain_source(n) if general else _chain_source(n)
    shape = f'{GENERATOR_VERSION}-{n}-True' + ('-general' if general else '')
    key = hashlib.sha256(shape.encode()).hexdigest()[:16]
    path = os.path.join(cache_dir(), f'derivation_{n}_{key}.py.txt')
    if os.path.exists(path):
        with open(path, encoding='utf-8') as f:
            text = f.read()
        if text:
            return text + MASS_INTO_WRAPPER
    from .jit import compile_ended, compile_started

    compile_started()  # sympy: part of the one-time cost the tools announce
    try:
        text = _derive_source(n, general)
    finally:
        compile_ended()
    _write_atomically(path, text)
    return text + MASS_INTO_WRAPPER


def _write_atomically(path, text):
    """Write then rename: parallel processes (tests, nodes) never read half a file."""
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix='.tmp')
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write(text)
        os.replace(tmp, path)
        return True
    except OSError:
        return False


_LOADED: dict[
    tuple, types.ModuleType
] = {}  # (shape, cache directory) -> module: a study builds a model per run


def load_equations(n: int, general: bool = False, n_mount: int = 0) -> types.ModuleType:
    """The compiled module for one scene shape: generated equations + the integrator kernel.
    ``general``: links other than uniform rods struck at the end (``GEOMETRY``).

    Derives (sympy) and writes it on first use; later processes import the cached file, and
    numba's own cache (next to it) spares them the compilation too. Within a process a shape
    is looked up once (reading and hashing the sources costs 0.17 ms, a study's run ~2 ms)."""
    key = (n, general, n_mount, cache_dir())
    if key not in _LOADED:
        _LOADED[key] = _load_equations(n, general, n_mount)
    return _LOADED[key]


_IMPORTED_MODULE = re.compile(r'^from impact_arm\.physics\.(\w+) import', re.MULTILINE)


def kernel_key(source: str, package_dir: str | None = None) -> str:
    """The cache name's hash of a kernel module: its own text, the Python version and the text
    of every project module its header imports. numba inlines those modules' functions (the
    contact laws, the control laws, the event bracket) into the compiled kernel and its cache
    looks only at the kernel's own file: without them an edited contact law would run the old
    compiled one. ``package_dir``: where those modules are read (default: this package)."""
    digest = hashlib.sha256(f'{source}{sys.version_info[:2]}'.encode())
    here = package_dir or os.path.dirname(os.path.abspath(__file__))
    for module in sorted(set(_IMPORTED_MODULE.findall(source))):
        with open(os.path.join(here, module + '.py'), 'rb') as f:
            digest.update(f.read())
    return digest.hexdigest()[:16]


def _load_equations(n, general, n_mount=0):
    from .kernel import template_source

    template = template_source()
    source = _module_header(n, general, n_mount) + _derivation(n, general) + '\n\n' + template
    name = f'impact_arm_kernel_{n}_{kernel_key(source)}'
    if name in sys.modules:
        return sys.modules[name]
    path = os.path.join(cache_dir(), name + '.py')
    if not os.path.exists(path) and not _write_atomically(path, source):
        path = os.path.join(tempfile.mkdtemp(prefix='impact_arm_'), name + '.py')
        _write_atomically(path, source)  # read-only home: a private temporary copy
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]  # a .py path has a spec
    sys.modules[name] = module
    spec.loader.exec_module(module)  # type: ignore[union-attr]  # ... and a loader
    return module
