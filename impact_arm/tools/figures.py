"""PNG figures like the article's Figures 3–11 (matplotlib, Agg backend, no display needed).

Every figure is ``FIGURE_SIZE`` pixels (width, height): a fixed size in inches at a fixed dpi,
saved without tight cropping. ``draw_all`` returns [(file name, caption)] of what it drew; a
figure whose data the recording lacks (no scene for Figure 7, no ``/impact_trace`` for 8–11) is
left out.
"""
from __future__ import annotations

import math
import os

import numpy as np

DPI = 100
FIGURE_INCHES = (9.0, 5.5)
FIGURE_SIZE = (int(FIGURE_INCHES[0] * DPI), int(FIGURE_INCHES[1] * DPI))  # pixels
PHASE_NAMES = {1: 'elastic compression', 2: 'elasto-plastic compression', 3: 'restitution'}


def _plt():
    import matplotlib
    matplotlib.use('Agg', force=True)
    import matplotlib.pyplot as plt
    return plt


def _save(fig, out, name):
    path = os.path.join(out, name)
    tmp = path + '.tmp.png'
    fig.savefig(tmp, dpi=DPI)
    _plt().close(fig)
    os.replace(tmp, path)
    return path


def _layout(fig):
    """Fixed margins (tight_layout measures every text and costs seconds per figure)."""
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.1, top=0.92, wspace=0.3, hspace=0.35)


def _deg(a):
    return np.degrees(a)


def fig3_controllers(runs, out):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=FIGURE_INCHES)
    # compared over the time all runs cover (relative to each run's start)
    t_end = min(r.t[-1] - r.t[0] for r in runs) if len(runs) > 1 else math.inf
    for run in runs:
        label = run.label + (f' (law {run.law})' if run.law and 'law' not in run.label else '')
        t = run.t - run.t[0]
        keep = t <= t_end
        for k, ax in enumerate(axes):
            ax.plot(t[keep], _deg(run.q[keep, k]), label=label, lw=1)
    for k, ax in enumerate(axes):
        ax.set_xlabel('t [s]')
        ax.set_ylabel(f'q{k + 1} [deg]')
        ax.set_title(f'({"ab"[k]}) response of link {k + 1}')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    _layout(fig)
    return fig


def _two_time_series(t, series, ylabels, titles):
    """Two panels over t, one above the other: (a) and (b)."""
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=FIGURE_INCHES, sharex=True)
    for ax, y, ylabel, title in zip(axes, series, ylabels, titles):
        ax.plot(t, y, lw=0.8)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel('t [s]')
    _layout(fig)
    return fig


def fig4_link_angles(run, out):
    return _two_time_series(run.t, [_deg(run.q[:, k]) for k in (0, 1)],
                            [f'q{k + 1} [deg]' for k in (0, 1)],
                            [f'({"ab"[k]}) angle q{k + 1}(t)' for k in (0, 1)])


def fig5_phase_portraits(run, out):
    plt = _plt()
    fig = plt.figure(figsize=FIGURE_INCHES)
    for k in (0, 1):
        ax = fig.add_subplot(1, 2, k + 1, projection='3d')
        ax.plot(_deg(run.q[:, 0]), _deg(run.q[:, 1]), run.qd[:, k], lw=0.6)
        ax.set_xlabel('q1 [deg]')
        ax.set_ylabel('q2 [deg]')
        ax.set_zlabel(f'q̇{k + 1} [rad/s]')
        ax.set_title(f'({"ab"[k]}) q1, q2, q̇{k + 1}', fontsize=9)
    fig.subplots_adjust(left=0.02, right=0.95, wspace=0.15)
    return fig


def fig6_poincare(run, sections, out):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=FIGURE_INCHES)
    for k, ax in enumerate(axes):
        rows = sections[k]
        if len(rows):
            order = np.arange(len(rows))
            sc = ax.scatter(_deg(rows[:, 1]), _deg(rows[:, 2]), c=order, cmap='viridis', s=18)
            fig.colorbar(sc, ax=ax, label='crossing number')
        ax.set_xlabel('q1 [deg]')
        ax.set_ylabel('q2 [deg]')
        ax.set_title(f'({"ab"[k]}) q1, q2 at q̇{k + 1} = 0 ({len(rows)} crossings)', fontsize=9)
        ax.grid(alpha=0.3)
    _layout(fig)
    return fig


def fig7_tip_velocity(run, v_tip, out):
    return _two_time_series(run.t, [v_tip[:, k] for k in (0, 1)],
                            [f'v{"xy"[k]} [m/s]' for k in (0, 1)],
                            [f'({"ab"[k]}) tip velocity along {"xy"[k]}' for k in (0, 1)])


def _trace(run, k):
    columns, rows = run.traces[k - 1]
    col = {name: rows[:, i] for i, name in enumerate(columns)}
    t0 = col['t'][0]
    return col, (col['t'] - t0) * 1e6  # µs since contact


def _by_phase(ax, tus, y, phase, scale=1.0):
    for p, name in PHASE_NAMES.items():
        mask = phase == p
        if np.any(mask):
            ax.plot(tus[mask], y[mask] * scale, '.-', ms=2, lw=1, label=name)


def fig8_indentation(run, k, out):
    plt = _plt()
    col, tus = _trace(run, k)
    fig, ax = plt.subplots(figsize=FIGURE_INCHES)
    _by_phase(ax, tus, col['delta'], col['phase'], 1e6)
    ax.set_xlabel('t since contact [µs]')
    ax.set_ylabel('δ [µm]')
    ax.set_title(f'indentation during impact {k}')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    elastic = col['phase'] == 1
    if np.count_nonzero(elastic) > 1:  # zoom on the short elastic phase, as the article does
        inset = ax.inset_axes([0.62, 0.1, 0.33, 0.33])
        inset.plot(tus[elastic], col['delta'][elastic] * 1e6, '.-', ms=2, lw=1)
        inset.set_title('elastic phase', fontsize=7)
        inset.tick_params(labelsize=6)
    _layout(fig)
    return fig


def fig9_impact_velocity(run, k, out):
    plt = _plt()
    col, tus = _trace(run, k)
    fig, axes = plt.subplots(1, 2, figsize=FIGURE_INCHES)
    for i, (ax, name) in enumerate(zip(axes, ('v_x', 'v_y'))):
        _by_phase(ax, tus, col[name], col['phase'])
        ax.set_xlabel('t since contact [µs]')
        ax.set_ylabel(f'{name} [m/s]')
        ax.set_title(f'({"ab"[i]}) {("tangential", "normal")[i]} tip velocity, impact {k}',
                     fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    _layout(fig)
    return fig


def fig10_contact_force(run, k, out):
    plt = _plt()
    col, tus = _trace(run, k)
    fig, ax = plt.subplots(figsize=FIGURE_INCHES)
    _by_phase(ax, tus, col['F_n'], col['phase'], 1e-3)
    if np.any(col['F_f'] != 0):
        ax.plot(tus, col['F_f'] * 1e-3, 'k--', lw=0.8, label='friction force')
    ax.set_xlabel('t since contact [µs]')
    ax.set_ylabel('F [kN]')
    ax.set_title(f'contact force during impact {k} (F_max = {np.max(col["F_n"]):.4g} N)')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _layout(fig)
    return fig


def fig11_kinetic_energy(run, k, out):
    plt = _plt()
    col, tus = _trace(run, k)
    links = sorted((c for c in col if c.startswith('T') and c[1:].isdigit()),
                   key=lambda c: int(c[1:]))
    series = [(f'link {c[1:]}', col[c]) for c in links]
    series.append(('total', np.sum([col[c] for c in links], axis=0)))
    fig, axes = plt.subplots(1, len(series), figsize=FIGURE_INCHES)
    for i, (ax, (name, y)) in enumerate(zip(np.atleast_1d(axes), series)):
        _by_phase(ax, tus, y, col['phase'])
        ax.set_xlabel('t since contact [µs]')
        ax.set_ylabel('T [J]')
        ratio = math.sqrt(y[-1] / y[0]) if y[0] > 0 and y[-1] >= 0 else math.nan
        ax.set_title(f'({"abcdefgh"[i]}) {name}: {y[0]:.3g} → {y[-1]:.3g} J, '
                     f'e = {ratio:.3f}', fontsize=8)
        ax.grid(alpha=0.3)
    _layout(fig)
    return fig


IMPACT_FIGURES = ('fig8_indentation.png', 'fig9_impact_velocity.png', 'fig10_contact_force.png',
                  'fig11_kinetic_energy.png')
CAPTIONS = {
    'fig3_controllers.png': 'Fig. 3: controller comparison, (a) link 1, (b) link 2',
    'fig4_link_angles.png': 'Fig. 4: link angles q1(t), q2(t)',
    'fig5_phase_portraits.png': 'Fig. 5: phase portraits (q1, q2, q̇1) and (q1, q2, q̇2)',
    'fig6_poincare.png': 'Fig. 6: Poincaré maps, q1 and q2 at q̇1 = 0 and at q̇2 = 0',
    'fig7_tip_velocity.png': 'Fig. 7: tip velocity vx(t), vy(t)',
    'fig8_indentation.png': 'Fig. 8: indentation during the impact',
    'fig9_impact_velocity.png': 'Fig. 9: tangential and normal tip velocity during the impact',
    'fig10_contact_force.png': 'Fig. 10: contact force during the impact',
    'fig11_kinetic_energy.png': 'Fig. 11: kinetic energies during the impact',
}


def draw_all(run, others, sections, v_tip, impact_k, out, progress=None):
    """Draw every figure the data allows into ``out``; returns [(file name, caption)]."""
    jobs = [('fig3_controllers.png', lambda: fig3_controllers([run] + list(others), out)),
            ('fig4_link_angles.png', lambda: fig4_link_angles(run, out)),
            ('fig5_phase_portraits.png', lambda: fig5_phase_portraits(run, out)),
            ('fig6_poincare.png', lambda: fig6_poincare(run, sections, out))]
    if v_tip is not None:
        jobs.append(('fig7_tip_velocity.png', lambda: fig7_tip_velocity(run, v_tip, out)))
    if run.traces:
        jobs += [('fig8_indentation.png', lambda: fig8_indentation(run, impact_k, out)),
                 ('fig9_impact_velocity.png', lambda: fig9_impact_velocity(run, impact_k, out)),
                 ('fig10_contact_force.png', lambda: fig10_contact_force(run, impact_k, out)),
                 ('fig11_kinetic_energy.png', lambda: fig11_kinetic_energy(run, impact_k, out))]
    made = []
    for i, (name, draw) in enumerate(jobs):
        if progress:
            progress(f'figure {i + 1}/{len(jobs)}: {name}')
        _save(draw(), out, name)
        caption = CAPTIONS[name]
        if name in IMPACT_FIGURES:
            caption += f' (impact {impact_k})'
        made.append((name, caption))
    return made
