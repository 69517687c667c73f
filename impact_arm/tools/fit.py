"""``impact-arm fit``: scene parameters from a recording of an arm, with a report.

    impact-arm fit runs/arm.mcap --scene config/paper.yaml \\
        --param surfaces[0].mu=0.05:1 --param materials.steel.S_y=2e8:5e9

The method lives in calibration/fit/ (docs/fit.md) and the Python API over it is
``impact_arm.fit`` (docs/api.md); this module is the command: it reads the recording, diagnoses
it, runs the fit with a progress line and writes the JSON, the fitted scene, report.md and the
figures. ``fit_recording(...)`` does all that from Python and returns the ``FitResult``.
"""

from __future__ import annotations

import argparse
import functools
import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from ..physics.errors import ImpactArmError
from .fit_figures import FigureData, ImpactPanel, draw_figures

if TYPE_CHECKING:
    from ..api.fitting import Bounds
    from ..api.scenes import SceneLike
    from ..calibration.diagnose import Corrections
    from ..calibration.diagnose.findings import Diagnosis
    from ..calibration.fit import FitOptions, FitResult, Prediction
    from ..calibration.identify import ImpactWindow, JointRecording


def parse_param(text: str) -> tuple[str, tuple[float, float] | tuple[float, float, float]]:
    """'KEY=LO:HI' -> (key, (lo, hi)), 'KEY=LO:HI@START' -> (key, (lo, hi, start)); a
    one-line error naming the argument."""
    key, eq, rest = text.partition('=')
    rng, at, start = rest.partition('@')
    lo, colon, hi = rng.partition(':')
    try:
        if not (key and eq and colon) or (at and not start):
            raise ValueError
        bounds = (float(lo), float(hi), float(start)) if at else (float(lo), float(hi))
        return key.strip(), bounds
    except ValueError:
        raise ImpactArmError(
            f'--param {text!r}: expected KEY=LO:HI or KEY=LO:HI@START, e.g. '
            f'surfaces[0].mu=0.05:1 or surfaces[0].mu=0.05:1@0.5'
        ) from None


def scene_of(
    recording: str | os.PathLike[str], scene: SceneLike | None = None
) -> tuple[SceneLike, str]:
    """The scene to read ``recording`` with: ``scene`` when given (path or installed name),
    else the one the recording stores (the recorder and ``simulate --mcap`` store it), else
    the article's. Returns (scene for ``Study``, its name for the user)."""
    if scene:
        return scene, str(scene)
    from ..io.recording import recorded_scene

    stored = recorded_scene(recording)
    if stored is None:
        return 'paper', 'paper (the recording stores no scene)'
    return stored, f'{stored.name!r}, stored in the recording'


def default_out(recording: str | os.PathLike[str]) -> str:
    name = os.path.basename(os.path.normpath(os.fspath(recording)))
    return os.path.join('runs', f'fit_{os.path.splitext(name)[0]}')


def fit_recording(
    recording: str | os.PathLike[str],
    scene: SceneLike | None,
    params: Mapping[str, Bounds],
    *,
    joints: Sequence[str] | None = None,
    states_topic: str | None = None,
    wrench_topic: str | None = None,
    out: str | Literal[False] | None = None,
    json_path: str | None = None,
    options: FitOptions | None = None,
    progress: Callable[..., Any] | None = None,
    say: Callable[[str], Any] = print,
    corrections: Corrections | None = None,
) -> FitResult:
    """Read ``recording``, diagnose it (``calibration/diagnose/``: findings said and
    reported; only the ``corrections`` asked for are applied), fit ``params`` ({key: (lo,
    hi)}) of ``scene`` and write ``out``/fitted.yaml, fit.json, report.md and the PNGs
    (``out`` None: the default runs/fit_<name>/; False: write nothing). Returns the
    ``FitResult``."""
    from ..api import fit, read_recording, write_fitted_scene
    from ..contract import JOINT_STATES
    from ..calibration.diagnose import Corrections, correct, diagnose
    from ..calibration.study import Study
    from ..physics.model import ArmModel
    from .side_process import SideProcess

    scene, scene_name = scene_of(recording, scene)
    base = Study(scene).scene()
    conflict = (corrections or Corrections()).shift_conflict(base.sensors, params)
    if conflict:  # refused before the recording is read: the efforts would be shifted twice
        raise ImpactArmError(conflict)

    def read() -> JointRecording:
        return read_recording(
            recording,
            base,
            joints=joints,
            states_topic=states_topic or JOINT_STATES,
            wrench_topic=wrench_topic,
        )

    # a second process reads the recording while this one imports the optimiser, then
    # imports matplotlib while this one fits, and draws the figures (the diagnosis stays
    # here: on a first run the model it needs compiles, which one notice tells)
    side = SideProcess.start(read) if out is not False else None
    try:
        if side is not None:
            import scipy.optimize  # noqa: F401  # the fit's, imported while the side reads

        rec = read() if side is None else side.first_result()
        diagnosis = diagnose(rec, ArmModel(base))
        rec = correct(rec, corrections or Corrections(), diagnosis)
        for line in diagnosis.lines():
            say(line)
        result = fit(rec, scene, params, options=options, progress=progress)
        reads_no_effort = not result.timing.reads_efforts
        if corrections is not None and corrections.effort_latency and reads_no_effort:
            # the option was applied, but this reading replays no recorded effort
            result.warnings.append(
                f'--effort-latency {corrections.effort_latency:g} moved the efforts, but the fit '
                "read them as the scene's own controller (the reading that best predicts the free "
                'flight after the impacts), which replays none of them: the latency acts only on '
                'which samples count as taken in a contact'
            )
        if out is False:
            return result
        out = out or default_out(recording)
        os.makedirs(out, exist_ok=True)
        data = figure_data(result)
        if side is not None:
            side.submit(data, out)  # drawn there while the rest is written here
        fitted = os.path.join(out, 'fitted.yaml')
        write_fitted_scene(scene, result.scene_overrides, fitted, recording)
        result.scene_path = os.path.abspath(fitted)
        from .cli import write_json

        for path in filter(None, [os.path.join(out, 'fit.json'), json_path]):
            write_json(path, {**result.to_json(), 'diagnosis': diagnosis.to_json()})
            say(f'wrote {path}')
        say(f'wrote {fitted}')
        for path in side.figures() if side is not None else draw_figures(data, out):
            say(f'wrote {path}')
        report = os.path.join(out, 'report.md')
        with open(report, 'w', encoding='utf-8') as f:
            f.write(report_text(result, recording, scene_name, diagnosis))
        say(f'wrote {report}')
        return result
    finally:
        if side is not None:
            side.close()


def _fmt(v: object) -> str:
    return f'{v:.5g}' if isinstance(v, float) and math.isfinite(v) else str(v)


def report_text(
    result: FitResult,
    recording: str | os.PathLike[str],
    scene: str,
    diagnosis: Diagnosis | None = None,
) -> str:
    lines = [
        f'# Fit of {os.fspath(recording)}',
        '',
        f'Scene: `{scene}` → fitted scene `{result.scene_path}`',
        '',
        f'**Verdict: {result.verdict}**',
        '',
        *[f'- {w}' for w in result.warnings],
        *([''] if result.warnings else []),
        (
            f'{result.impacts_used} impacts used; '
            f'{"joint rates and wrench impulse" if result.used_wrench else "joint rates only"}; '
            f'χ² = {result.chi2:.4g} over {result.dof} degrees of freedom '
            f'(χ²/dof = {result.chi2 / result.dof:.3g}); residual rms {result.residual_rms:.3g} '
            f'rad/s against a noise rms of {result.noise_rms:.3g} rad/s; '
            f'{result.evaluations} model evaluations in {result.wall_time:.2f} s.'
        ),
        '',
        '| parameter | start | fitted | 95 % interval | identified |',
        '|---|---:|---:|---|---|',
    ]
    for key, p in result.parameters.items():
        ident = 'yes' if p.identifiable else f'no ({p.why or "correlated"})'
        digits = p.digits()
        lines.append(
            f'| `{key}` | {_fmt(p.start)} | {p.value:.{digits}g} | '
            f'[{p.ci95[0]:.{digits}g}, {p.ci95[1]:.{digits}g}] | {ident}'
            + (' (at a bound)' if p.at_bound else '')
            + ' |'
        )
    if result.output_tests:
        lines += [
            '',
            '| output | recorded below fitted | sign test p | mean [σ] | trend with speed [s.e.] |',
            '|---|---:|---:|---:|---:|',
        ]
        for t in result.output_tests:
            trend = f'{t.trend_t:+.2f}' if math.isfinite(t.trend_t) else 'one speed'
            lines.append(
                f'| {t.output} | {t.below} of {t.count} | {t.sign_p:.2g} | {t.mean:+.2f} '
                f'| {trend} |'
            )
    if result.dependences:
        lines += [
            '',
            'What the fitted values depend on (first order, per 1 % of each fixed parameter; '
            'tolerance: how well that parameter must be known for its error to stay within '
            "one standard deviation of the fitted value's):",
            '',
            '| fitted | fixed | change per 1 % (or per the amount given) | tolerance |',
            '|---|---|---:|---:|',
        ]
        for d in result.dependences:
            change = d.change_text(signed=True)
            per = '' if d.unit == '%' else f' per {d.step:g} {d.unit}'
            lines.append(
                f'| `{d.fitted}` | `{d.fixed}` | {change}{per} | {d.tolerance:.2g} {d.unit} |'
            )
    if result.cannot_tell_apart:
        lines += [
            '',
            'The data cannot tell apart: '
            + '; '.join(' and '.join(f'`{k}`' for k in pair) for pair in result.cannot_tell_apart)
            + ' (|correlation| > 0.95): fix one of them in the scene and fit the other.',
        ]
    if result.correlations:
        lines += [
            '',
            'Correlations: ' + ', '.join(f'{k}: {_fmt(v)}' for k, v in result.correlations.items()),
        ]
    noise = result.noise
    lines += [
        '',
        f'Noise estimated from the free flight: positions '
        f'{", ".join(_fmt(x) for x in noise["position"])} rad, rates '
        f'{", ".join(_fmt(x) for x in noise["velocity"])} rad/s, efforts '
        f'{", ".join(_fmt(x) for x in noise["effort"])} N m'
        + (f', wrench {", ".join(_fmt(x) for x in noise["wrench"])} N' if 'wrench' in noise else '')
        + '.',
        f'Effort timing used between samples: {result.timing}.',
        '',
        (
            '| # | t [s] | impact speed [m/s] | CoR recorded | CoR fitted | '
            'rate residual [rad/s] | whitened rms |'
        ),
        '|---:|---:|---:|---:|---:|---|---:|',
    ]
    for k, row in enumerate(result.per_impact):
        if row.get('error'):
            lines.append(
                f'| {k + 1} | {row["t"]:.4f} | {row["impact_speed"]:.4g} | | | {row["error"]} | |'
            )
            continue
        res = np.array(row['residual_rates'][0])
        wr = float(np.sqrt(np.mean(np.square(row['whitened']))))
        lines.append(
            f'| {k + 1} | {row["t"]:.4f} | {row["impact_speed"]:.4g} | '
            f'{row["cor_recorded"]:.4f} | {row["cor_fitted"]:.4f} | '
            f'{", ".join(f"{x:+.2e}" for x in res)} | {wr:.2f} |'
        )
    lines += [
        '',
        '![joint rates and wrench around the impacts](impacts.png)',
        '',
        '![CoR against impact speed](cor.png)',
        '',
    ]
    if result.notes:
        lines += ['Notes:', ''] + [f'- {x}' for x in result.notes] + ['']
    if diagnosis is not None:
        lines += diagnosis.markdown()
    return '\n'.join(lines)


def _ms_from(origin: float, t: npt.ArrayLike) -> np.ndarray:
    return (np.asarray(t) - origin) * 1e3


def fitted_period_forces(
    path: np.ndarray, ts: npt.ArrayLike, period: float, n: int, lag: float = 0.0
) -> tuple[np.ndarray, ...]:
    """The fitted contact force averaged over each period ending at ``ts`` (a wrench's
    stamps), (tangential, normal), from a prediction's ``path`` rows: t, the ``n`` joint rates,
    then the cumulative impulse (tangential, normal): the impulse gained over the period over
    its length, as a driver's period-averaged wrench reports it. ``lag`` [s]: the wrench is
    published that much late (the scene's wrench latency less its state latency), so the
    period a stamp reports ends that much earlier in the replay."""
    ends = np.asarray(ts, float) - lag
    out = []
    for col in (1 + n, 2 + n):
        gained = np.interp(ends, path[:, 0], path[:, col]) - np.interp(
            ends - period, path[:, 0], path[:, col]
        )
        out.append(gained / period)
    return tuple(out)


def impact_replay(
    result: FitResult, win: ImpactWindow
) -> tuple[Prediction, tuple[np.ndarray, ...] | None]:
    """The fitted scene's replay of one impact for the figures, with its path at 80 instants
    and, with a recorded wrench, at the ends of the periods its stamps report (moved back by
    the wrench's delay, fitted or stated), and those stamps' fitted period-averaged forces:
    (prediction, (stamps, tangential, normal) or None)."""
    from ..calibration.fit import predict_impact
    from ..calibration.fit.efforts import wrench_shift

    rec = result.recording
    assert rec is not None and result.model is not None, (
        "a fit's result holds its recording and model"
    )
    extra = list(np.linspace(win.t_a, win.post_t[-1], 80))
    stamps = period = None
    lag = wrench_shift(result.model)  # a wrench published late shows the impact that late
    if rec.wrench is not None:
        assert rec.wrench_t is not None, 'a recorded wrench has its stamps'
        ends = rec.wrench_t - lag
        stamps = rec.wrench_t[(ends > win.t_a) & (ends <= win.post_t[-1])]
        period = float(np.median(np.diff(rec.wrench_t)))
        # the path at each period's end and start: the fitted period averages are then
        # differences of exact cumulative impulses
        ends = stamps - lag
        extra += list(ends) + list(ends[ends - period > win.t_a] - period)
    pred = predict_impact(result.model, win, result.timing, dense=extra)
    if stamps is None or period is None or pred.error or not len(pred.path):
        return pred, None
    return pred, (stamps, *fitted_period_forces(pred.path, stamps, period, rec.n, lag))


def figure_data(result: FitResult) -> FigureData:
    """The arrays of impacts.png (recorded vs fitted rates and wrench around up to 4 impacts)
    and cor.png, from the fit's result."""
    rec = result.recording
    assert rec is not None, "a fit's result holds its recording"
    wins = [w for w, p in zip(result.windows, result.predictions) if not p.error][:4]
    data = FigureData(list(rec.joints), 2 if rec.wrench is not None else 1)
    for w in wins:
        dt = w.t_b - w.t_a
        pred, fitted_wrench = impact_replay(result, w)
        lo, hi = w.t_a - 6 * dt, w.post_t[-1] + 3 * dt
        sel = (rec.t >= lo) & (rec.t <= hi)
        t_ms = functools.partial(_ms_from, w.t_c)
        recorded = [(t_ms(rec.t[sel]), rec.velocity[sel, j]) for j in range(rec.n)]
        fitted = (
            []
            if pred.error
            else [(t_ms(pred.path[:, 0]), pred.path[:, 1 + j]) for j in range(rec.n)]
        )
        wrench = forces = None
        if data.rows == 2:
            assert rec.wrench is not None and rec.wrench_t is not None, 'rows == 2: a wrench'
            wsel = (rec.wrench_t >= lo) & (rec.wrench_t <= hi)
            wrench = (t_ms(rec.wrench_t[wsel]), rec.wrench[wsel, 1], rec.wrench[wsel, 0])
            if fitted_wrench is not None:
                ts, tangential, normal = fitted_wrench
                forces = (t_ms(ts), tangential, normal)
        data.panels.append(ImpactPanel(w.t_c, recorded, fitted, wrench, forces))
    good = [r for r in result.per_impact if not r.get('error')]
    data.speeds = [r['impact_speed'] for r in good]
    data.cor_recorded = [r['cor_recorded'] for r in good]
    data.cor_fitted = [r['cor_fitted'] for r in good]
    data.cor_start = [r['cor_start'] for r in good]
    return data


def write_figures(result: FitResult, out: str) -> list[str]:
    """impacts.png (recorded vs fitted rates and wrench around up to 4 impacts) and cor.png."""
    return draw_figures(figure_data(result), out)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from .recording_diagnosis import add_correction_arguments
    from .recording_options import add_recording_arguments

    parser.add_argument('recording', help='rosbag2 folder (metadata.yaml + MCAP) or MCAP file')
    parser.add_argument(
        '--scene',
        default=None,
        help='scene file or installed name: the fixed rest and the start (default: the '
        'scene the recording stores, else paper)',
    )
    parser.add_argument(
        '--param',
        action='append',
        default=[],
        metavar='KEY=LO:HI[@START]',
        help='a scene key path to fit within bounds (repeat), e.g. '
        "surfaces[0].mu=0.05:1, materials.steel.S_y=2e8:5e9; '@START' starts the search "
        "there instead of at the scene's value, e.g. surfaces[0].mu=0.05:1@0.5",
    )
    add_recording_arguments(
        parser, without_wrench='; without it the fit uses the joint states alone'
    )
    parser.add_argument(
        '--no-wrench',
        action='store_true',
        help='ignore a recorded wrench: fit from the joint states alone',
    )
    parser.add_argument(
        '--leave-out',
        action='append',
        type=float,
        default=[],
        metavar='T',
        help='leave the impact at time T [s from the first sample] out of the fit (repeat); '
        'an outlier impact is named and refitted without in any case',
    )
    add_correction_arguments(parser)
    parser.add_argument('--json', default=None, metavar='OUT', help='also write the JSON here')
    parser.add_argument(
        '--out',
        default=None,
        metavar='DIR',
        help='output folder (default runs/fit_<recording name>/)',
    )


def cli(args: argparse.Namespace) -> int:
    from ..calibration.fit import FitOptions
    from .recording_diagnosis import corrections_from
    from .cli import writable_output
    from .progress import Progress

    params = dict(parse_param(p) for p in args.param)
    if not params:
        raise ImpactArmError('--param: give at least one KEY=LO:HI to fit')
    if args.json:
        args.json = writable_output(args.json, '--json')
    joints = [j.strip() for j in args.joints.split(',')] if args.joints else None
    corrections = corrections_from(args)
    line = Progress(prefix='  ')

    def progress(text: str, done: float | None = None, total: float | None = None) -> None:
        line.total = total
        line.show(text, done=done, log=done is None or bool(total and done == total))

    try:
        result = fit_recording(
            args.recording,
            args.scene,
            params,
            joints=joints,
            states_topic=args.states_topic,
            wrench_topic=args.wrench_topic,
            out=args.out,
            json_path=args.json,
            options=FitOptions(use_wrench=not args.no_wrench, leave_out=tuple(args.leave_out)),
            progress=progress,
            corrections=corrections,
        )
    finally:
        line.end()
    for key, p in result.parameters.items():
        print(
            f'{key} = {p.interval_text()}'
            + ('' if p.identifiable else '  NOT identified by these data')
        )
    for warning in result.warnings:
        print(f'warning: {warning}')
    if result.cannot_tell_apart:
        print('cannot tell apart: ' + '; '.join(' ~ '.join(p) for p in result.cannot_tell_apart))
    print(
        f'{result.impacts_used} impacts, residual rms {result.residual_rms:.3g} rad/s, '
        f'noise rms {result.noise_rms:.3g} rad/s: {result.verdict}'
    )
    return 0 if result.fits else 1
