"""``impact-arm analyze FILE.mcap``: the command line."""

from __future__ import annotations

import argparse
import os

from ...contract import FEEDBACK_LAWS
from ..run_data import AnalysisError, chatter, load
from ..step_responses import STEP_LAWS, step_response
from .impacts import elastic_curve, impact_points, rates_before
from .report import no_impact_figures, no_impact_reason, write_outputs
from .sections import limit_cycle_text, impact_table, limit_cycle


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('file', help='MCAP recording (live or simulate --mcap)')
    parser.add_argument(
        '--out', metavar='DIR', help='output directory (default: runs/<file name>_analysis)'
    )
    parser.add_argument(
        '--compare',
        nargs='+',
        default=[],
        metavar='FILE',
        help='more recordings (e.g. other controller laws): their link angles '
        "beside this one's (fig3b_recordings.png)",
    )
    parser.add_argument(
        '--laws',
        default=None,
        metavar='LAWS',
        help='the control laws of Figure 3, comma separated (default q,pd,pid; pid '
        'left out when the scene has no integral gains; empty: no Figure 3): step '
        "responses of the file's scene without its surface, simulated offline",
    )
    parser.add_argument(
        '--compare-time',
        type=float,
        default=5.0,
        metavar='S',
        help='simulated seconds of each step response (default 5, (0, 60])',
    )
    parser.add_argument(
        '--impact',
        type=int,
        default=1,
        metavar='K',
        help='impact shown in Figures 8-11 (default 1, the first); from '
        '/impact_trace, or re-integrated from /impact_report in a live '
        'recording',
    )
    parser.add_argument(
        '--animation',
        action='store_true',
        help='also write animation.gif (slow, about a minute; impact-arm animate makes it alone)',
    )
    parser.add_argument(
        '--no-animation',
        action='store_true',
        help='no animation.gif: the default since --animation (accepted for older scripts)',
    )
    figure_options(parser)


def figure_options(parser: argparse.ArgumentParser) -> None:
    """--format and --dpi, shared with the commands that draw figures."""
    from ..figures import DPI, FORMATS

    parser.add_argument(
        '--format',
        default='png',
        choices=FORMATS,
        help='file format of the figures (default png; svg and pdf are vector graphics)',
    )
    parser.add_argument(
        '--dpi',
        type=float,
        default=DPI,
        metavar='N',
        help=f'resolution of png figures in dots per inch (default {DPI}, [50, 1200]); '
        f'sets the size in pixels, not the layout',
    )


def cli(args: argparse.Namespace) -> int:
    from .. import figures
    from ..progress import Progress

    line = Progress(prefix='analyze: ')

    def say(text: str) -> None:
        line.show(text, log=True)

    out = args.out or os.path.join(
        'runs', os.path.splitext(os.path.basename(args.file))[0] + '_analysis'
    )
    if not 0 < args.compare_time <= 60:
        raise AnalysisError(f'--compare-time = {args.compare_time}: must be in (0, 60] s')
    if not 50 <= args.dpi <= 1200:
        raise AnalysisError(f'--dpi = {args.dpi:g}: must be in [50, 1200]')
    given = ','.join(STEP_LAWS) if args.laws is None else args.laws
    laws = [w.strip() for w in given.split(',') if w.strip()]
    for law in laws:
        if law not in FEEDBACK_LAWS:
            raise AnalysisError(f'--laws: {law!r} is not one of {", ".join(FEEDBACK_LAWS)}')
    run = load(args.file, progress=say)
    if run.traces and not 1 <= args.impact <= len(run.traces):
        raise AnalysisError(
            f'--impact = {args.impact}: must be in [1, {len(run.traces)}] '
            f'(the impacts with a trace in {args.file})'
        )
    if not run.traces and run.impacts and not 1 <= args.impact <= len(run.impacts):
        raise AnalysisError(
            f'--impact = {args.impact}: must be in [1, {len(run.impacts)}] '
            f'(the impacts reported in {args.file})'
        )
    others = [load(f, progress=say) for f in args.compare]
    # the table first: it needs nothing but the file, the figures take seconds
    table = impact_table(run.impacts)
    lc = limit_cycle(run.impacts)
    line.end()
    if run.impacts:
        print(f'impact table ({len(run.impacts)} impacts):')
        print(table)
    else:
        print(f'no impacts in {args.file}: {no_impact_reason(run)}')
    print(limit_cycle_text(lc), flush=True)
    for found in chatter(run):
        print(f'CHATTER: {found.text()}: the law is unstable at its rate', flush=True)
    if run.scene is not None:
        from ...physics.limits import limit_excursions

        for excursion in limit_excursions(run.scene, run.q, run.qd):
            print(f'LIMIT: {excursion.text()}', flush=True)
    missing = []
    steps = []
    if laws and run.scene is None:
        missing.append(
            f'Figure 3 not drawn: {args.file} stores no scene to simulate the step responses of'
        )
    elif laws and run.scene is not None:
        if args.laws is None and not any(run.scene.controller.ki):
            # the default asks for every law the scene can run; asked for by name, pid is refused
            laws = [law for law in laws if law != 'pid']
            missing.append('Figure 3 without PID: the scene has no integral gains (controller.ki)')
        steps = [step_response(run.scene, law, args.compare_time, say) for law in laws]
    impact, constants = impact_points(run, args.impact, say)
    if impact is None:
        missing.append(no_impact_figures(run, args.file))
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise AnalysisError(f'--out {out}: cannot create ({e.strerror})') from None
    written = write_outputs(
        run,
        steps,
        out,
        impact,
        figures,
        progress=say,
        recordings=others,
        constants=constants,
        missing=missing,
        style=figures.Style(args.format, args.dpi),
        elastic=elastic_curve(
            run.scene, impact[2], guess=rates_before(run, float(impact[2].t_contact))
        )
        if impact is not None
        else None,
    )
    line.end()
    if impact is not None and impact[3]:
        print(f'Figures 8-11: impact {args.impact} {impact[3]}')
    for line_ in missing:
        print(line_)
    print(
        f'wrote {os.path.join(out, "report.md")} ({len(written["figures"])} figures: '
        + ', '.join(name for name, _ in written['figures'])
        + ')',
        flush=True,
    )
    if args.animation and run.scene is not None:
        from ..animation import animate, contact_forces

        gif = os.path.join(out, 'animation.gif')
        say(f'animating to {gif}')
        frames = animate(run, gif, contact_forces(args.file), progress=say)
        line.end()
        print(f'animation: {gif} ({frames} frames)')
    elif args.animation:
        print(f'animation not drawn: {args.file} stores no scene (link lengths)')
    return 0
