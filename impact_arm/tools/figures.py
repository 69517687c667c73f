"""Figures like the article's Figures 3–11 (matplotlib, Agg backend, no display needed).

Every figure is ``FIGURE_INCHES`` in size, saved without tight cropping, as PNG (``FIGURE_SIZE``
pixels at the default ``DPI``; ``Style.dpi`` scales the pixels, not the layout), SVG or PDF
(``Style.format``). ``draw_all`` returns [(file name, caption)] of what it drew; a
figure whose data the recording lacks (no scene for Figures 3 and 7, neither ``/impact_trace``
nor a re-integrable ``/impact_report`` for 8–11) is left out, and ``analyze`` says why.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..physics.contact import ContactConstants
    from ..physics.replay import ElasticCurve
    from .analysis.impacts import ImpactPoints
    from .run_data import Run

DPI = 100
FIGURE_INCHES = (9.0, 5.5)
FIGURE_SIZE = (int(FIGURE_INCHES[0] * DPI), int(FIGURE_INCHES[1] * DPI))  # pixels
FORMATS = ('png', 'svg', 'pdf')


@dataclass(frozen=True)
class Style:
    """How the figures are written: file format (``FORMATS``) and the dpi of raster output."""

    format: str = 'png'
    dpi: float = DPI

    def __post_init__(self):
        if self.format not in FORMATS:
            raise ValueError(f'figure format {self.format!r}: choose one of {", ".join(FORMATS)}')
        if not 50 <= self.dpi <= 1200:
            raise ValueError(f'figure dpi = {self.dpi:g}: must be in [50, 1200]')


PHASE_NAMES = {1: 'elastic compression', 2: 'elasto-plastic compression', 3: 'restitution'}

PANEL = 'abcdefghijklmnopqrstuvwxyz'  # the panels' letters


def _plt():
    import matplotlib

    matplotlib.use('Agg', force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out, name, style=Style()):
    path = os.path.join(out, name)
    tmp = path + '.tmp.' + style.format
    # no creation date in vector files: the same run gives the same file
    metadata = {'CreationDate': None} if style.format == 'pdf' else None
    if style.format == 'svg':
        metadata = {'Date': None}
    fig.savefig(tmp, dpi=style.dpi, format=style.format, metadata=metadata)
    _plt().close(fig)
    os.replace(tmp, path)
    return path


def _layout(fig):
    """Fixed margins (tight_layout measures every text and costs seconds per figure)."""
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.12, top=0.92, wspace=0.3, hspace=0.35)


def _deg(a):
    return np.degrees(a)


def fig3_controllers(runs: Sequence[Run], out: str) -> Figure:
    """The article's Figure 3: step responses of the control laws (no impact), each link in
    its panel, the target dotted, a zoom on the approach to the target where PD's offset and
    PID's overshoot show, and each law's numbers under its panel."""
    from .step_responses import step_metrics

    targets = runs[0].target
    assert targets is not None, 'step responses (step_response) carry their target'
    plt = _plt()
    fig, axes = plt.subplots(1, runs[0].q.shape[1], figsize=FIGURE_INCHES)
    notes_size = 7 if len(axes) <= 2 else 5  # each law's numbers fit under a narrower panel
    styles = {'q': ('tab:blue', '-'), 'pd': ('tab:orange', '--'), 'pid': ('tab:green', '-.')}
    for k, ax in enumerate(axes):
        target = math.degrees(targets[k])
        inset = ax.inset_axes([0.45, 0.42, 0.52, 0.5])
        lines = []
        for run in runs:
            color, style = styles.get(run.law, (None, '-'))
            for a in (ax, inset):
                a.plot(
                    run.t,
                    _deg(run.q[:, k]),
                    style,
                    color=color,
                    lw=1.2,
                    label=run.label if (a is ax and k == 0) else None,
                )
            m = step_metrics(run)[k]
            settle = (
                f'within 0.1° from {m["settle_s"]:.2f} s'
                if math.isfinite(m['settle_s'])
                else 'never within 0.1°'
            )
            lines.append(
                (
                    f'{run.law.upper() if run.law != "q" else "Q"}: '
                    f'{m["overshoot_deg"]:.2f}° past target, end error '
                    f'{round(m["final_error_deg"], 2) + 0.0:+.2f}°, {settle}',
                    color,
                )
            )
        for a in (ax, inset):
            a.axhline(
                target, color='k', lw=0.8, ls=':', label='target' if (a is ax and k == 0) else None
            )
        inset.set_xlim(runs[0].t[-1] * 0.15, runs[0].t[-1])
        inset.set_ylim(target - 2.5, target + 2.5)
        inset.set_title('zoom: ±2.5° about the target', fontsize=7)
        inset.tick_params(labelsize=6)
        inset.grid(alpha=0.3)
        ax.set_xlabel('t [s]')
        ax.set_ylabel(f'q{k + 1} [deg]')
        ax.set_title(f'({PANEL[k]}) response of link {k + 1} (target {target:g}°)', fontsize=9)
        ax.grid(alpha=0.3)
        for i, (text, color) in enumerate(lines):
            ax.text(
                0.0,
                -0.19 - 0.065 * i,
                text,
                transform=ax.transAxes,
                fontsize=notes_size,
                color=color,
            )
    fig.legend(
        loc='upper center',
        ncol=len(runs) + 1,
        fontsize=8,
        bbox_to_anchor=(0.5, 0.99),
        frameon=False,
    )
    fig.text(
        0.5,
        0.915,
        'Step responses without impact (surface removed): from '
        f'({", ".join(f"{a:.0f}°" for a in _deg(runs[0].q[0]))}) to '
        'the down target',
        ha='center',
        fontsize=9,
    )
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.3, top=0.85, wspace=0.3)
    return fig


def fig_recordings(runs: Sequence[Run], out: str) -> Figure:
    """Link angles of several recordings (``analyze --compare``), over the time all cover."""
    plt = _plt()
    fig, axes = plt.subplots(1, min(r.q.shape[1] for r in runs), figsize=FIGURE_INCHES)
    t_end = min(r.t[-1] - r.t[0] for r in runs) if len(runs) > 1 else math.inf
    for run in runs:
        label = run.label + (f' (law {run.law})' if run.law and 'law' not in run.label else '')
        t = run.t - run.t[0]
        keep = t <= t_end
        for k, ax in enumerate(axes):
            ax.plot(t[keep], _deg(run.q[keep, k]), label=label, lw=1)
    for k, ax in enumerate(axes):
        ax.set_xlabel("t since the recording's start [s]")
        ax.set_ylabel(f'q{k + 1} [deg]')
        ax.set_title(f'({PANEL[k]}) link {k + 1}', fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    _layout(fig)
    return fig


def _time_series(t, series, ylabels, titles):
    """One panel per series over t, one above the other: (a), (b), ..."""
    plt = _plt()
    fig, axes = plt.subplots(len(series), 1, figsize=FIGURE_INCHES, sharex=True, squeeze=False)
    axes = axes[:, 0]
    for ax, y, ylabel, title in zip(axes, series, ylabels, titles):
        ax.plot(t, y, lw=0.8)
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel('t [s]')
    _layout(fig)
    return fig


def fig4_link_angles(run: Run, out: str) -> Figure:
    """Every link's angle: the article's two panels, one more per further link. A URDF arm
    whose joint angles are not the model's link angles is drawn in its own joint angles,
    as its driver reports them, under its joint names."""
    links = range(run.q.shape[1])
    scene = run.scene
    if scene is not None and not scene.joint_coordinates.is_identity:
        theta = np.array([scene.joint_coordinates.positions(q) for q in run.q])
        names = scene.joint_names
        return _time_series(
            run.t,
            [_deg(theta[:, k]) for k in links],
            [f'{names[k]} [deg]' for k in links],
            [f'({PANEL[k]}) {names[k]}(t)' for k in links],
        )
    return _time_series(
        run.t,
        [_deg(run.q[:, k]) for k in links],
        [f'q{k + 1} [deg]' for k in links],
        [f'({PANEL[k]}) angle q{k + 1}(t)' for k in links],
    )


def angle_pair(k: int) -> tuple[int, int]:
    """The two link angles link ``k``'s rate is drawn against (0-based): the article's q1, q2
    for links 1 and 2, the link's own angle and its inner neighbour's beyond them."""
    return (0, 1) if k < 2 else (k - 1, k)


def fig5_phase_portraits(run: Run, out: str) -> Figure:
    """One 3-D phase portrait per link: its rate against two link angles (``angle_pair``),
    the article's (q1, q2, q̇1) and (q1, q2, q̇2) for two links. Angles and rates in one unit
    system: degrees and degrees per second (as Figure 4)."""
    plt = _plt()
    fig = plt.figure(figsize=FIGURE_INCHES)
    n = run.q.shape[1]
    small = {} if n <= 2 else {'fontsize': 8}  # three panels or more share the width
    for k in range(n):
        a, b = angle_pair(k)
        ax = fig.add_subplot(1, n, k + 1, projection='3d')
        ax.plot(_deg(run.q[:, a]), _deg(run.q[:, b]), _deg(run.qd[:, k]), lw=0.6)
        ax.set_xlabel(f'q{a + 1} [deg]', **small)
        ax.set_ylabel(f'q{b + 1} [deg]', **small)
        ax.set_zlabel(f'q̇{k + 1} [deg/s]', **small)
        ax.set_title(f'({PANEL[k]}) q{a + 1}, q{b + 1}, q̇{k + 1}', fontsize=9)
        if n > 2:
            from matplotlib.ticker import MaxNLocator

            ax.tick_params(labelsize=7)
            for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
                axis.set_major_locator(MaxNLocator(4))
            ax.set_box_aspect(None, zoom=0.8)  # room for the rate's axis label
    fig.subplots_adjust(left=0.02, right=0.95 if n <= 2 else 0.97, wspace=0.15)
    return fig


DIRECTIONS = {-1.0: 'falling', 1.0: 'rising'}


def fig6_poincare(run: Run, sections: dict[int, np.ndarray], out: str) -> Figure:
    """One panel per section (q̇k = 0 for every link k, one row each) and direction of the
    crossing (falling, rising), drawn in the two link angles of Figure 5's portrait of that
    link (``angle_pair``: q1, q2 for the article's two links): the crossings of one
    direction gather about one point of the limit cycle, and the other direction's lie far
    away, so each cluster gets axes scaled to itself. Successive crossings are joined (the
    way the motion settles), the last one starred. ``sections``: {k: rows of
    ``analysis.poincare``}."""
    plt = _plt()
    n = len(sections)
    fig, axes = plt.subplots(n, 2, figsize=FIGURE_INCHES, squeeze=False)
    norm = plt.Normalize(0, max([len(rows) - 1 for rows in sections.values()] + [1]))
    mappable = None
    for k in range(n):
        rows = sections[k]
        a, b = angle_pair(k)
        for j, (direction, name) in enumerate(DIRECTIONS.items()):
            ax = axes[k, j]
            order = np.nonzero(rows[:, -1] == direction)[0] if len(rows) else np.zeros(0, int)
            if len(order):
                x, y = _deg(rows[order, 1 + a]), _deg(rows[order, 1 + b])
                ax.plot(x, y, '-', color='0.75', lw=0.6, zorder=0)
                mappable = ax.scatter(x, y, c=order, cmap='viridis', norm=norm, s=16)
                ax.plot(x[-1:], y[-1:], '*', color='tab:red', ms=10, mfc='none', mew=1.0)
                ax.margins(0.15)
                if len(order) >= 6:  # the settled half, about the last point
                    half = len(order) // 2
                    dx, dy = x[half:] - x[-1], y[half:] - y[-1]
                    inset = ax.inset_axes([0.58, 0.5, 0.4, 0.38])
                    inset.plot(dx, dy, '-', color='0.75', lw=0.6, zorder=0)
                    inset.scatter(dx, dy, c=order[half:], cmap='viridis', norm=norm, s=10)
                    inset.plot([0], [0], '*', color='tab:red', ms=8, mfc='none')
                    inset.margins(0.25)
                    inset.ticklabel_format(useOffset=False, style='plain')
                    spread = max(np.ptp(dx), np.ptp(dy))
                    _style_inset(inset, '', f'Δq{a + 1} from the star [deg]', f'Δq{b + 1} [deg]')
                    inset.text(
                        0.03,
                        0.97,
                        f'last {len(dx)}: within {spread:.2g}°',
                        transform=inset.transAxes,
                        fontsize=6,
                        va='top',
                    )
            ax.set_title(
                f'({PANEL[2 * k + j]}) q̇{k + 1} = 0, {name}: {len(order)} crossings', fontsize=8
            )
            ax.set_xlabel(f'q{a + 1} [deg]', fontsize=8)
            ax.set_ylabel(f'q{b + 1} [deg]', fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    # the article's two rows keep their spacing; more rows share the height
    fig.subplots_adjust(
        left=0.08, right=0.86, bottom=0.1, top=0.93, wspace=0.3, hspace=0.55 if n <= 2 else 0.8
    )
    if mappable is not None:
        bar = fig.colorbar(mappable, ax=list(axes.ravel()), fraction=0.03, pad=0.02)
        bar.set_label('crossing number (star: the last)')
    return fig


def fig7_tip_velocity(run: Run, v_tip: np.ndarray, out: str) -> Figure:
    return _time_series(
        run.t,
        [v_tip[:, k] for k in (0, 1)],
        [f'v{"xy"[k]} [m/s]' for k in (0, 1)],
        [f'({"ab"[k]}) tip velocity along {"xy"[k]}' for k in (0, 1)],
    )


PHASE_COLORS = {1: 'tab:green', 2: 'tab:orange', 3: 'tab:blue'}


def _trace(impact):
    """Columns by name of an impact's points (``impact``: (columns, rows, record, note)) and
    their times in µs since contact."""
    columns, rows = impact[0], impact[1]
    col = {name: rows[:, i] for i, name in enumerate(columns)}
    return col, (col['t'] - impact[2].t_contact) * 1e6


def _by_phase(ax, tus, y, phase, scale=1.0, x=None, legend=True, last_is_end=True, curves=None):
    """One colour per contact phase, every point drawn; each phase's line starts at the
    previous phase's last point (the switch, located exactly), so the curve has no gap, and
    the switches are marked. ``curves``: {phase: (x, y)} drawn as that phase's line instead of
    the segments between its points (the elastic phase from the integrator's dense output:
    its points are a step or two apart)."""
    x = tus if x is None else x
    curves = curves or {}
    for p, name in PHASE_NAMES.items():
        idx = np.nonzero(phase == p)[0]
        if not len(idx):
            continue
        if idx[0] > 0:
            idx = np.concatenate([[idx[0] - 1], idx])
        if p in curves:
            cx, cy = curves[p]
            ax.plot(cx, np.asarray(cy) * scale, '-', lw=1, color=PHASE_COLORS[p])
            ax.plot(
                x[idx],
                y[idx] * scale,
                '.',
                ms=3,
                color=PHASE_COLORS[p],
                label=name + ' (line: dense output)' if legend else None,
            )
            continue
        ax.plot(
            x[idx],
            y[idx] * scale,
            '.-',
            ms=3,
            lw=1,
            color=PHASE_COLORS[p],
            label=name if legend else None,
        )
    switches = np.nonzero(np.diff(phase) != 0)[0]
    ends_parts = [np.asarray([0]), switches]
    if last_is_end:
        ends_parts.append(np.asarray([len(phase) - 1]))
    ends = np.concatenate(ends_parts).astype(int)
    ax.plot(
        x[ends],
        y[ends] * scale,
        'o',
        mfc='none',
        mec='k',
        ms=6,
        mew=0.9,
        label='contact, phase switches, separation' if legend else None,
    )


def _note(ax, impact):
    """Where the impact's points come from, when not from /impact_trace: in the figure's
    bottom-left corner, below the axis labels."""
    if impact[3]:
        ax.figure.text(0.005, 0.004, impact[3], ha='left', va='bottom', fontsize=7, color='0.35')


def _elastic(elastic, impact, x='t'):
    """{1: (x, y)} of the elastic phase's dense curve (``physics.replay.ElasticCurve``): x in µs
    since contact (or the indentation, ``x='delta'``, in µm); y in the trace's own unit
    (the caller scales)."""
    if elastic is None:
        return None
    xs = (elastic.t - impact[2].t_contact) * 1e6 if x == 't' else elastic.delta * 1e6
    return xs, elastic


def fig8_indentation(impact: ImpactPoints, out: str, elastic: ElasticCurve | None = None) -> Figure:
    from ..physics.contact import YIELD_ONSET_FACTOR

    plt = _plt()
    col, tus = _trace(impact)
    k = impact[2].index
    fig, ax = plt.subplots(figsize=FIGURE_INCHES)
    dense = _elastic(elastic, impact)
    curves = {1: (dense[0], elastic.delta)} if dense and elastic is not None else None
    _by_phase(ax, tus, col['delta'], col['phase'], 1e6, curves=curves)
    ax.set_xlabel('t since contact [µs]')
    ax.set_ylabel('indentation δ [µm]')
    ax.set_title(
        f'Indentation during impact {k}: δm = {impact[2].delta_m * 1e6:.1f} µm, '
        f'δr = {impact[2].delta_r * 1e6:.1f} µm'
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper left')
    in_elastic = np.nonzero(col['phase'] == 1)[0]
    if len(in_elastic):  # zoom on the short elastic phase, as the article does
        last = min(in_elastic[-1] + 3, len(tus) - 1)
        inset = ax.inset_axes([0.6, 0.1, 0.35, 0.4])
        _by_phase(
            inset,
            tus[: last + 1],
            col['delta'][: last + 1],
            col['phase'][: last + 1],
            1e6,
            legend=False,
            last_is_end=False,
            curves=curves,
        )
        t_yield, d_yield = tus[in_elastic[-1]], col['delta'][in_elastic[-1]] * 1e6
        if np.any(col['phase'] == 2):  # it yielded: Hertz hands over at 1.9 δc
            d_c = d_yield / YIELD_ONSET_FACTOR
            inset.axhline(d_yield, color='k', ls=':', lw=0.8)
            inset.axhline(d_c, color='tab:red', ls='--', lw=0.8)
            inset.annotate(
                f'Hertz → Jackson–Green:\nδ = 1.9 δc = {d_yield:.2f} µm at {t_yield:.2f} µs',
                (t_yield, d_yield),
                xytext=(0.03, 0.8),
                textcoords='axes fraction',
                fontsize=6,
                arrowprops=dict(arrowstyle='->', lw=0.6),
            )
            inset.text(
                0.03 * t_yield,
                d_c,
                f'onset of yield: δc = {d_c:.2f} µm',
                fontsize=6,
                color='tab:red',
                va='bottom',
            )
        inset.set_xlim(-0.02 * t_yield, 1.5 * t_yield)
        inset.set_ylim(0, 1.6 * d_yield)
        _style_inset(inset, 'zoom: elastic compression (Hertz)', 't [µs]', 'δ [µm]')
    _note(ax, impact)
    _layout(fig)
    return fig


def fig9_impact_velocity(impact: ImpactPoints, out: str) -> Figure:
    plt = _plt()
    col, tus = _trace(impact)
    k = impact[2].index
    fig, axes = plt.subplots(1, 2, figsize=FIGURE_INCHES)
    for i, (ax, name) in enumerate(zip(axes, ('v_x', 'v_y'))):
        _by_phase(ax, tus, col[name], col['phase'], legend=i == 1)
        ax.set_xlabel('t since contact [µs]')
        ax.set_ylabel(f'{name} [m/s]')
        ax.set_title(
            f'({"ab"[i]}) {("tangential", "normal")[i]} tip velocity, impact {k}: '
            f'{col[name][0]:.2f} → {col[name][-1]:.2f} m/s',
            fontsize=9,
        )
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, loc='lower right')
    _note(axes[0], impact)
    _layout(fig)
    return fig


def fig10_contact_force(
    impact: ImpactPoints, out: str, elastic: ElasticCurve | None = None
) -> Figure:
    plt = _plt()
    col, tus = _trace(impact)
    k = impact[2].index
    fig, ax = plt.subplots(figsize=FIGURE_INCHES)
    dense = _elastic(elastic, impact)
    curves = {1: (dense[0], elastic.force)} if dense and elastic is not None else None
    _by_phase(ax, tus, col['F_n'], col['phase'], 1e-3, curves=curves)
    if np.any(col['F_f'] != 0):
        ax.plot(tus, col['F_f'] * 1e-3, 'k--', lw=0.8, label='friction force F_f')
    ax.set_xlabel('t since contact [µs]')
    ax.set_ylabel('contact force: normal F_n, friction F_f [kN]')
    ax.set_title(f'Contact force during impact {k} (F_max = {impact[2].F_max * 1e-3:.2f} kN)')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper left')
    in_elastic = np.nonzero(col['phase'] == 1)[0]
    if len(in_elastic) and np.any(col['phase'] == 2):  # zoom on the elastic phase (Hertz)
        last = min(in_elastic[-1] + 3, len(tus) - 1)
        inset = ax.inset_axes([0.42, 0.3, 0.28, 0.36])  # between F_f and the peak
        _by_phase(
            inset,
            tus[: last + 1],
            col['F_n'][: last + 1],
            col['phase'][: last + 1],
            1e-3,
            legend=False,
            last_is_end=False,
            curves=curves,
        )
        t_yield, f_yield = tus[in_elastic[-1]], col['F_n'][in_elastic[-1]] * 1e-3
        inset.set_xlim(-0.02 * t_yield, 1.5 * t_yield)
        inset.set_ylim(0, 1.6 * f_yield)
        _style_inset(inset, 'zoom: elastic compression (Hertz, F ∝ δ^1.5)', 't [µs]', 'F_n [kN]')
    _note(ax, impact)
    _layout(fig)
    return fig


def fig_force_indentation(
    impact: ImpactPoints,
    constants: ContactConstants | None,
    out: str,
    elastic: ElasticCurve | None = None,
) -> Figure:
    """Normal force against indentation: the points of the impact on the model's three laws
    (Hertz to 1.9 δc, Jackson–Green to δm, restitution from δm down to δr)."""
    from ..physics.contact import (
        hertz_force,
        jackson_green_force,
        residual_indentation,
        restitution_force,
        restitution_radius,
    )

    plt = _plt()
    col, _ = _trace(impact)
    record = impact[2]
    k = record.index
    fig, ax = plt.subplots(figsize=FIGURE_INCHES)
    delta = col['delta'] * 1e6
    inset = ax.inset_axes([0.08, 0.45, 0.32, 0.4])
    if constants is not None:
        c = constants
        dm = record.delta_m
        dy = min(c.delta_yield, dm)
        d1 = np.linspace(0, dy, 200)
        d2 = np.linspace(dy, dm, 400)
        dr = residual_indentation(dm, c)
        pm = jackson_green_force(dm, c) if dm > c.delta_yield else hertz_force(dm, c.E, c.R)
        rr = restitution_radius(dm, dr, pm, c.E)
        d3 = np.linspace(dr, dm, 400)
        curves = [
            (d1, [hertz_force(d, c.E, c.R) for d in d1], 'Hertz (elastic)'),
            (d2, [jackson_green_force(d, c) for d in d2], 'Jackson–Green'),
            (d3, [restitution_force(d, dr, c.E, rr) for d in d3], 'restitution law'),
        ]
        for a in (ax, inset):
            for i, (d, force, _name) in enumerate(curves):
                a.plot(
                    d * 1e6,
                    np.asarray(force) * 1e-3,
                    color='0.6',
                    lw=2.5,
                    alpha=0.6,
                    zorder=0,
                    label="the model's laws: Hertz, Jackson–Green, restitution"
                    if a is ax and i == 0
                    else None,
                )
            a.plot(
                d1[-1:] * 1e6,
                [hertz_force(dy, c.E, c.R) * 1e-3],
                'x',
                color='k',
                ms=5,
                label='1.9 δc (Hertz → Jackson–Green)' if a is ax else None,
            )
    elastic_curves = {1: (elastic.delta * 1e6, elastic.force)} if elastic is not None else None
    _by_phase(ax, delta, col['F_n'], col['phase'], 1e-3, x=delta, curves=elastic_curves)
    _by_phase(
        inset,
        delta,
        col['F_n'],
        col['phase'],
        1e-3,
        x=delta,
        legend=False,
        last_is_end=False,
        curves=elastic_curves,
    )
    ax.set_xlabel('indentation δ [µm]')
    ax.set_ylabel('normal force F_n [kN]')
    ax.set_title(
        f'Force against indentation, impact {k} (not in the article): loading, '
        f'unloading to δr = {record.delta_r * 1e6:.1f} µm',
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='lower left', bbox_to_anchor=(0.3, 0.02))
    edge = max(4 * float(np.max(delta[col['phase'] == 1], initial=1.0)), 5.0)
    inset.set_xlim(0, edge)
    near = col['F_n'][delta <= edge]
    inset.set_ylim(0, max(float(np.max(near, initial=0)) * 1.3e-3, 1e-3))
    _style_inset(inset, 'zoom: start of loading', 'δ [µm]', 'F_n [kN]')
    _note(ax, impact)
    _layout(fig)
    return fig


def fig11_kinetic_energy(impact: ImpactPoints, out: str) -> Figure:
    plt = _plt()
    col, tus = _trace(impact)
    links = sorted(
        (c for c in col if c.startswith('T') and c[1:].isdigit()), key=lambda c: int(c[1:])
    )
    series = [(f'link {c[1:]}', col[c]) for c in links]
    series.append(('total', np.sum([col[c] for c in links], axis=0)))
    fig, axes = plt.subplots(1, len(series), figsize=FIGURE_INCHES)
    axes = np.atleast_1d(axes)
    for i, (ax, (name, y)) in enumerate(zip(axes, series)):
        _by_phase(ax, tus, y, col['phase'], legend=i == 0)
        ax.set_xlabel('t since contact [µs]')
        ax.set_ylabel('kinetic energy T [J]')
        ratio = math.sqrt(y[-1] / y[0]) if y[0] > 0 and y[-1] >= 0 else math.nan
        ax.set_title(
            f'({"abcdefgh"[i]}) {name}: {y[0]:.2f} → {y[-1]:.2f} J, e = {ratio:.3f}', fontsize=8
        )
        ax.grid(alpha=0.3)
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc='upper center',
        ncol=4,
        fontsize=7,
        bbox_to_anchor=(0.5, 1.0),
    )
    _note(axes[0], impact)
    fig.subplots_adjust(left=0.08, right=0.97, bottom=0.13, top=0.86, wspace=0.4)
    return fig


IMPACT_FIGURES = (
    'fig8_indentation',
    'fig9_impact_velocity',
    'fig10_contact_force',
    'fig10b_force_indentation',
    'fig11_kinetic_energy',
)
CAPTIONS = {
    'fig3_controllers': 'Fig. 3: step responses of the Q controller, PD and PID without '
    'impact, (a) link 1, (b) link 2',
    'fig3b_recordings': 'Link angles of the compared recordings',
    'fig4_link_angles': 'Fig. 4: link angles q1(t), q2(t)',
    'fig5_phase_portraits': 'Fig. 5: phase portraits, one per link: (q1, q2, q̇1), '
    '(q1, q2, q̇2), and (qk-1, qk, q̇k) for a further link k; degrees and degrees per second',
    'fig6_poincare': 'Fig. 6: Poincaré maps at q̇k = 0, one row per link k, in the angles of '
    "that link's phase portrait, one panel per direction of the crossing (each scaled to its "
    'points)',
    'fig7_tip_velocity': 'Fig. 7: tip velocity vx(t), vy(t)',
    'fig8_indentation': 'Fig. 8: indentation during the impact, elastic phase zoomed',
    'fig9_impact_velocity': 'Fig. 9: tangential and normal tip velocity during the impact',
    'fig10_contact_force': 'Fig. 10: contact force during the impact',
    'fig10b_force_indentation': 'Force against indentation on the three contact laws '
    '(not in the article)',
    'fig11_kinetic_energy': 'Fig. 11: kinetic energies during the impact',
}


def draw_all(
    run: Run,
    steps: Sequence[Run],
    sections: dict[int, np.ndarray],
    v_tip: np.ndarray | None,
    impact: ImpactPoints | None,
    out: str,
    progress: Callable[[str], Any] | None = None,
    recordings: Sequence[Run] = (),
    constants: ContactConstants | None = None,
    style: Style | None = None,
    elastic: ElasticCurve | None = None,
) -> list[tuple[str, str]]:
    """Draw every figure the data allows into ``out``; returns [(file name, caption)].
    ``steps``: the step-response runs of Figure 3 (none: no Figure 3); ``impact``: (columns,
    rows, record, note) of the impact for Figures 8–11, or None; ``recordings``: more
    recordings to compare with ``run``; ``constants``: the impacted surface's contact
    constants (the model's curves in the force–indentation plot); ``style``: format and dpi
    (default: PNG at ``DPI``); ``elastic``: the impact's elastic phase on a fine grid
    (``physics.replay.ElasticCurve``), drawn as the line of that phase in Figures 8 and 10."""
    style = style or Style()
    jobs = []
    if steps:
        jobs.append(('fig3_controllers', lambda: fig3_controllers(steps, out)))
    if recordings:
        jobs.append(('fig3b_recordings', lambda: fig_recordings([run] + list(recordings), out)))
    jobs += [
        ('fig4_link_angles', lambda: fig4_link_angles(run, out)),
        ('fig5_phase_portraits', lambda: fig5_phase_portraits(run, out)),
        ('fig6_poincare', lambda: fig6_poincare(run, sections, out)),
    ]
    if v_tip is not None:
        jobs.append(('fig7_tip_velocity', lambda: fig7_tip_velocity(run, v_tip, out)))
    if impact is not None:
        jobs += [
            ('fig8_indentation', lambda: fig8_indentation(impact, out, elastic)),
            ('fig9_impact_velocity', lambda: fig9_impact_velocity(impact, out)),
            ('fig10_contact_force', lambda: fig10_contact_force(impact, out, elastic)),
            (
                'fig10b_force_indentation',
                lambda: fig_force_indentation(impact, constants, out, elastic),
            ),
            ('fig11_kinetic_energy', lambda: fig11_kinetic_energy(impact, out)),
        ]
    made = []
    for i, (stem, draw) in enumerate(jobs):
        name = f'{stem}.{style.format}'
        if progress:
            progress(f'figure {i + 1}/{len(jobs)}: {name}')
        _save(draw(), out, name, style)
        caption = CAPTIONS[stem]
        if stem in IMPACT_FIGURES:
            assert impact is not None  # the impact's figures are drawn only with one
            caption += f' (impact {impact[2].index}' + (f'; {impact[3]})' if impact[3] else ')')
        made.append((name, caption))
    return made


def _style_inset(inset, title, xlabel, ylabel):
    """A zoomed inset's small print: title, axis labels with units, ticks, grid."""
    inset.set_title(title, fontsize=7)
    inset.set_xlabel(xlabel, fontsize=6)
    inset.set_ylabel(ylabel, fontsize=6)
    inset.tick_params(labelsize=6)
    inset.grid(alpha=0.3)
