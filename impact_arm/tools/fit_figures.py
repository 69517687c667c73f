"""The fit's figures, drawn from plain arrays: impacts.png (recorded against fitted joint rates
and wrench around up to four impacts) and cor.png (the coefficient of restitution against the
impact speed). ``FigureData`` holds no model, so the fit's side process (side_process.py), which
has imported only matplotlib, draws them; ``fit.figure_data`` computes them from a result."""

from __future__ import annotations

import os
from dataclasses import dataclass, field


@dataclass
class ImpactPanel:
    """What one column of impacts.png shows, as plain arrays (times in ms from the contact):
    no model in it, so a process that has only matplotlib can draw it."""

    t_c: float  # the contact's time [s], for the title
    recorded: list  # per joint: (t, rate) of the recorded samples around the impact
    fitted: list  # per joint: (t, rate) of the fitted scene's replay ([] when it failed)
    wrench: tuple | None  # (t, normal, tangential) of the recorded wrench, or None
    forces: tuple | None  # (t, tangential, normal): the fitted period averages, or None


@dataclass
class FigureData:
    """Everything write_figures draws, computed from a ``FitResult`` (the replays with dense
    output are made here), picklable."""

    joints: list
    rows: int  # 2 with a recorded wrench
    panels: list = field(default_factory=list)  # ImpactPanel per drawn impact (up to 4)
    speeds: list = field(default_factory=list)  # per replayed impact, for cor.png
    cor_recorded: list = field(default_factory=list)
    cor_fitted: list = field(default_factory=list)
    cor_start: list = field(default_factory=list)


def draw_figures(data: FigureData, out: str) -> list[str]:
    """Draw ``data`` into impacts.png and cor.png in ``out``; their paths."""
    from matplotlib import rc_context

    # titles at the axes' top, not placed above the axes' decorations there (they have none:
    # the same pixels) by laying every tick label out once more
    with rc_context({'axes.titley': 1.0}):
        return _draw(data, out)


def _draw(data: FigureData, out: str) -> list[str]:
    # the object API with the Agg canvas, not pyplot: no backend machinery to import in the
    # fresh process a fit runs in
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    made = []
    rows, columns = data.rows, max(len(data.panels), 1)
    fig = Figure(figsize=(4.2 * columns, 3.4 * rows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, columns, squeeze=False)
    colors = ['tab:blue', 'tab:orange', 'tab:green', 'tab:red']
    for c, panel in enumerate(data.panels):
        ax = axes[0][c]
        for j, joint in enumerate(data.joints):
            ax.plot(*panel.recorded[j], 'o', ms=3, color=colors[j % 4], label=f'{joint} recorded')
            if panel.fitted:
                ax.plot(*panel.fitted[j], '-', color=colors[j % 4], lw=1, label=f'{joint} fitted')
        ax.set_xlabel('time from contact [ms]')
        ax.set_ylabel('joint rate [rad/s]')
        ax.set_title(f'impact at t = {panel.t_c:.3f} s', fontsize=9)
        if c == 0:
            ax.legend(fontsize=7)
        if rows == 2:
            ax = axes[1][c]
            t, normal, tangential = panel.wrench
            ax.plot(t, normal, 's', ms=3, color='k', label='normal recorded')
            ax.plot(t, tangential, '^', ms=3, color='tab:gray', label='tangential recorded')
            if panel.forces is not None:
                t, *forces = panel.forces
                for (name, mark, color), values in zip(
                    (('tangential', '+', 'tab:purple'), ('normal', 'x', 'tab:red')), forces
                ):
                    ax.plot(t, values, mark, ms=9, color=color, label=f'{name} fitted')
            ax.set_xlabel('time from contact [ms]')
            ax.set_ylabel('period-averaged force [N]')
            if c == 0:
                ax.legend(fontsize=7)
    fig.suptitle('Recorded and fitted around the impacts', fontsize=10)
    # fixed margins: tight_layout lays every label out again, the costliest step of the fit's
    # outputs in a fresh process
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.1, top=0.9, wspace=0.3, hspace=0.35)
    path = os.path.join(out, 'impacts.png')
    fig.savefig(path, dpi=110)
    made.append(path)

    fig = Figure(figsize=(5.5, 4))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot(data.speeds, data.cor_recorded, 'o', label='recorded')
    ax.plot(data.speeds, data.cor_fitted, 'x', ms=8, label='fitted scene')
    ax.plot(data.speeds, data.cor_start, '+', ms=8, color='tab:gray', label='starting scene')
    ax.set_xlabel('impact speed (tip, normal) [m/s]')
    ax.set_ylabel('kinematic coefficient of restitution [-]')
    ax.set_title('CoR against impact speed', fontsize=10)
    ax.legend(fontsize=8)
    fig.subplots_adjust(left=0.14, right=0.97, bottom=0.13, top=0.92)
    path = os.path.join(out, 'cor.png')
    fig.savefig(path, dpi=110)
    made.append(path)
    return made
