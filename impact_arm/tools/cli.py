"""``impact-arm``: the user command (every sub-command: ``impact-arm --help``).

Each sub-command lives in its own small function; errors meant for the user (bad scene, bad
argument, a run that had to stop) are printed as one line on stderr with exit status 2 or 1,
never as a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
import warnings
from collections.abc import Iterator, Sequence
from typing import TYPE_CHECKING, NoReturn, TextIO

STARTED = time.perf_counter()  # this module's import: the fallback for the command's start
NOTICE: list[CompileNotice] = []  # the command's CompileNotice (how long it compiled)

# (the clock above starts before the package's own imports: they count in the command's time)
from ..contract import INTEGRATOR_PRESETS  # noqa: E402
from ..physics.errors import ImpactArmError, UnstableControlWarning  # noqa: E402
from .progress import CompileNotice, Progress  # noqa: E402

if TYPE_CHECKING:
    from ..physics.scene import Scene
    from ..physics.simulate import RunResult

DEFAULT_SCENE = 'paper'


def _positive(value: str) -> float:
    number = float(value)
    if not number > 0:
        raise argparse.ArgumentTypeError(f'{value} must be > 0')
    return number


def _non_negative(value: str) -> float:
    number = float(value)
    if not number >= 0:
        raise argparse.ArgumentTypeError(f'{value} must be >= 0')
    return number


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..physics.scene import load_scene
    from ..physics.simulate import format_table, run

    scene = load_scene(args.scene)
    for note in scene.notes:
        print(f'impact-arm simulate: note: {note}', file=sys.stderr)
    from ..physics import jit

    if not jit.AVAILABLE:
        print(
            f'impact-arm simulate: warning: interpreted kernel ({jit.UNAVAILABLE}), about '
            f'100x slower. Fix: {jit.FIX}',
            file=sys.stderr,
        )
    # refused now, not after a long run whose results would then be lost
    args.json = args.json and writable_output(args.json, '--json')
    args.mcap = args.mcap and writable_output(args.mcap, '--mcap')
    load_s = _load_kernel(scene)
    if args.no_samples:
        return _simulate_without_samples(scene, args, load_s)
    _check_run_size(scene, args)
    observer = None
    if args.mcap:
        from ..io.offline_mcap import OfflineRecorder

        observer = OfflineRecorder(
            args.mcap,
            scene,
            control_rate=args.control_rate,
            preset=args.preset,
            tf_rate=args.tf_rate,
        )

    line = Progress(prefix='  ', keep=True)

    def progress(cycle: int, cycles: int, impacts: int, t: float) -> None:
        line.total = cycles
        line.show(
            f'cycle {min(cycle + 1, cycles)}/{cycles}  impacts {impacts}  t = {t:.3f} s', done=cycle
        )

    result = None
    try:
        # streamed: the samples go to the MCAP file as they come, none is kept
        result = run(
            scene,
            control_rate=args.control_rate,
            preset=args.preset,
            observer=observer,
            progress=progress,
            keep_samples=False,
        )
    finally:
        if observer is not None:
            observer.close(result)  # with the result: its summary is stored in the file
        line.end()
    print(format_table(result))
    print(
        _timing(
            result,
            load_s,
            f'integration, {round(result.t_end * scene.publish_rate)} '
            f'samples' + (', MCAP writing' if args.mcap else ''),
        )
    )
    if args.json:
        write_json(args.json, result.to_json())
        print(f'wrote {args.json}')
    if args.mcap:
        from ..io.viewer_layout import write_layout_beside

        try:  # made for this arm and the file's topics (every joint, the plates)
            layout = write_layout_beside(args.mcap, scene)
        except OSError as exc:  # the run and its file stand without it
            layout = f'not written ({exc})'
        print(f'wrote {args.mcap}; its viewer layout {layout}')
    return 1 if result.error else 0


# A sampled run's cost grows with publish_rate x t_max: measured on a 2-core VM, ~3 us and
# (with --mcap) ~120 bytes of compressed MCAP per sample. Beyond this many samples (~30 s,
# ~1.2 GB; counted up to t_max, which the scene's cycles may end sooner) `simulate` says what
# the run may cost and runs it only with --yes.
RUN_SIZE_LIMIT = 1e7
SECONDS_PER_SAMPLE, MCAP_BYTES_PER_SAMPLE = 3e-6, 120


def _check_run_size(scene: Scene, args: argparse.Namespace) -> None:
    samples = scene.publish_rate * scene.t_max
    if samples <= RUN_SIZE_LIMIT / 10:
        return
    estimate = (
        f'publish_rate {scene.publish_rate:g} Hz x t_max {scene.t_max:g} s = '
        f'{samples:.3g} samples: up to about {samples * SECONDS_PER_SAMPLE:.0f} s'
        + (f' and {samples * MCAP_BYTES_PER_SAMPLE / 1e9:.1f} GB of MCAP' if args.mcap else '')
    )
    if samples > RUN_SIZE_LIMIT and not args.yes:
        raise ImpactArmError(
            f'{estimate}; more than {RUN_SIZE_LIMIT:.0e} samples run only '
            f'with --yes (or lower publish_rate or t_max)'
        )
    print(f'impact-arm simulate: {estimate}', file=sys.stderr)


def cmd_urdf(args: argparse.Namespace) -> int:
    from ..physics.scene import load_scene
    from ..io.urdf import robot_description

    sys.stdout.write(robot_description(load_scene(args.scene), rod_radius=args.rod_radius))
    return 0


def _load_kernel(scene: Scene) -> float:
    """Load (or compile, announced) the scene's kernel before the run is timed: the first
    call in a process reads numba's cache (~0.1-0.3 s), which is start-up, not integration.
    Returns the seconds it took."""
    from ..driver.arm import SimulatedArm

    t0 = time.perf_counter()
    SimulatedArm(scene, scene.publish_rate, trace=False).warm_up()
    return time.perf_counter() - t0


def whole_command_seconds() -> float:
    """Seconds since the process started, interpreter start-up and imports included (what a
    user waits for): from the process's start time in /proc (10 ms resolution); where there
    is no /proc, since this module was imported."""
    since_import = time.perf_counter() - STARTED
    try:
        with open('/proc/self/stat', encoding='ascii') as f:
            # field 22, counted after the command name (which may hold spaces), in clock ticks
            started = int(f.read().rsplit(')', 1)[1].split()[19]) / os.sysconf('SC_CLK_TCK')
        with open('/proc/uptime', encoding='ascii') as f:
            now = float(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return since_import
    return max(now - started, since_import)


def _timing(result: RunResult, load_s: float, what: str) -> str:
    """What the printed times include, in one line."""
    total = whole_command_seconds()
    compiled = NOTICE[-1].total if NOTICE else 0.0
    loading = (
        'compiling the kernel (first use of this scene shape)'
        if compiled > 1.0
        else 'loading the compiled kernel'
    )
    return (
        f'timing: {result.t_end:.3f} s simulated in {result.wall_time * 1e3:.1f} ms wall '
        f'({what}); before that {load_s:.2f} s {loading}; '
        f'{total:.2f} s for the whole command with start-up. Repeated warm runs: '
        f'impact-arm bench speed'
    )


def _simulate_without_samples(scene: Scene, args: argparse.Namespace, load_s: float = 0.0) -> int:
    from ..physics.simulate import format_table, run

    rate = scene.controller.rate if args.control_rate is None else args.control_rate
    if rate or args.mcap:
        what = '--mcap' if args.mcap else f'a sampled controller ({rate:g} Hz)'
        raise ImpactArmError(
            f'--no-samples runs from event to event with continuous control: '
            f'{what} needs the sampled run (drop --no-samples'
            + (', or pass --control-rate 0)' if rate else ')')
        )
    result = run(scene, samples=False, preset=args.preset)
    print(format_table(result))
    print(_timing(result, load_s, 'integration only, no samples'))
    if args.json:
        write_json(args.json, result.to_json())
        print(f'wrote {args.json}')
    return 1 if result.error else 0


def writable_output(path: str, flag: str) -> str:
    """The file to write for ``flag``, checked before any work: its directory must exist and
    be writable (none is created), and it must be absent, a regular file, or a symlink to one
    (then its target is written and the link kept). Directories, FIFOs and devices are refused.
    The one exception to "none is created": ``runs/``, where every command's outputs go by
    default, is made when its parent exists (a fresh clone has none)."""
    target = os.path.realpath(path)
    runs = os.path.dirname(target)
    if (
        os.path.basename(runs) == 'runs'
        and not os.path.exists(runs)
        and os.path.isdir(os.path.dirname(runs))
    ):
        os.makedirs(runs, exist_ok=True)
    if os.path.isdir(target):
        raise ImpactArmError(f'{flag} {path}: is a directory')
    if os.path.exists(target) and not os.path.isfile(target):
        raise ImpactArmError(
            f'{flag} {path}: not a regular file (a FIFO or device is not replaced)'
        )
    directory = os.path.dirname(target)
    if not os.path.isdir(directory):
        raise ImpactArmError(
            f'{flag} {path}: {directory} '
            + ('is not a directory' if os.path.exists(directory) else 'does not exist')
        )
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ImpactArmError(f'{flag} {path}: directory {directory} is not writable')
    if os.path.exists(target) and not os.access(target, os.W_OK):
        raise ImpactArmError(f'{flag} {path}: file is not writable')
    if target != os.path.abspath(path):
        print(f'{flag}: {path} is a symlink: writing its target {target}, the link is kept')
    return target


def finite_or_null(value: object) -> object:
    """JSON has no NaN or infinity: such a number is written as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    return value


def write_json(path: str, data: object) -> None:
    """Written to a temporary file next to ``path`` and renamed over it: a reader never sees
    half a file, and a failure leaves no temporary file behind."""
    import tempfile

    fd, tmp = tempfile.mkstemp(
        dir=os.path.dirname(path), prefix='.' + os.path.basename(path), suffix='.tmp'
    )
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)  # as open() would create it, not mkstemp's 0600
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            json.dump(finite_or_null(data), f, indent=1, allow_nan=False)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def build_parser(selected: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='impact-arm',
        description='impact_arm from the command line: '
        + ', '.join(['simulate', 'urdf', *COMMANDS])
        + ". 'impact-arm COMMAND --help' gives a command's options.",
    )
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')

    p = sub.add_parser('simulate', help='integrate a scene offline (no ROS graph needed)')
    p.add_argument('--scene', default=DEFAULT_SCENE, help='scene file or installed scene name')
    p.add_argument(
        '--control-rate',
        type=_non_negative,
        default=None,
        metavar='HZ',
        help='sample the controller at HZ with zero-order hold (0: continuous, '
        "as the article; default: the scene's controller.rate)",
    )
    p.add_argument(
        '--preset',
        default=None,
        choices=INTEGRATOR_PRESETS,
        help="integrator preset (default: the scene's)",
    )
    p.add_argument('--json', metavar='FILE', help='write impacts and run summary as JSON')
    p.add_argument('--mcap', metavar='FILE', help='record the run to MCAP (ROS 2 topics)')
    p.add_argument(
        '--tf-rate',
        type=_positive,
        default=100.0,
        metavar='HZ',
        help='rate of /tf and /impact_markers in the MCAP file (default 100)',
    )
    p.add_argument(
        '--yes',
        action='store_true',
        help=f'run even past {RUN_SIZE_LIMIT:.0e} samples (publish_rate x t_max)',
    )
    p.add_argument(
        '--no-samples',
        action='store_true',
        help='impacts only: integrate from event to event without sampling or '
        'tracing (the fast path of studies; continuous control)',
    )
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser('urdf', help="print the scene's robot description (URDF)")
    p.add_argument('--scene', default=DEFAULT_SCENE, help='scene file or installed scene name')
    p.add_argument(
        '--rod-radius',
        type=float,
        default=0.0,
        metavar='M',
        help='radius the rods are drawn with [m] (default 0: 1 %% of the shortest link)',
    )
    p.set_defaults(func=cmd_urdf)

    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text)
        if name == selected:
            _attach(p, module)
    return parser


# Sub-commands implemented in their own modules: ``add_arguments(parser)`` and
# ``cli(args) -> int``. Only the selected one is imported, so `simulate` never loads rclpy.
COMMANDS = {
    'run': (
        'impact_arm.tools.runner',
        'start simulator, controller and recorder over DDS; record to MCAP',
    ),
    'replay': (
        'impact_arm.nodes.replay',
        'republish a recorded MCAP file with its original timing',
    ),
    'analyze': (
        'impact_arm.tools.analysis',
        'impact table, limit cycle, Poincare sections and figures',
    ),
    'sweep': (
        'impact_arm.tools.sweep',
        'many runs of a scene (grid/list/random/LHS) to Parquet; sweep plot',
    ),
    'animate': (
        'impact_arm.tools.animation',
        'draw the arm, the surface and the contact force into a GIF or MP4',
    ),
    'study': (
        'impact_arm.tools.contact_study',
        'shipped studies: contact (the contact laws against published results)',
    ),
    'fit': (
        'impact_arm.tools.fit',
        'fit scene parameters (E, S_y, mu, ...) to the impacts of a recording',
    ),
    'compare': (
        'impact_arm.tools.compare',
        'compare the impacts of two recordings, or of a recording and a scene',
    ),
    'body': (
        'impact_arm.tools.body',
        'run a free-body scene (a rigid body whose corners strike surfaces)',
    ),
    'kernel': (
        'impact_arm.tools.kernel',
        "kernel dump: print the generated kernel module of a scene's shape",
    ),
    'export': (
        'impact_arm.tools.export',
        'the arm and its contact for MuJoCo, Drake or Gazebo, tuned by running them',
    ),
    'layout': (
        'impact_arm.tools.layout_command',
        'the Foxglove/Lichtblick layout made for a recording or a scene (every joint, plates)',
    ),
    'bench': (
        'impact_arm.tools.bench_command',
        "benchmarks from the repository's bench/ folder: speed, tradeoff, stress, "
        'rates, fit, peers, ... (docs/benchmarks.md)',
    ),
}


def _attach(parser: argparse.ArgumentParser, module: str) -> None:
    import importlib

    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith('impact_arm'):
            parser.set_defaults(func=lambda args: _missing(parser.prog))
            return
        raise
    mod.add_arguments(parser)
    parser.set_defaults(func=mod.cli)


def _missing(prog: str) -> NoReturn:
    raise ImpactArmError(f'{prog} is not available in this version')


@contextlib.contextmanager
def _warnings(args: argparse.Namespace) -> Iterator[None]:
    """The core's warnings meant for the user (an unstable law the scene allows) as one line
    on stderr, like the errors; other warnings as Python shows them."""
    shown = warnings.showwarning

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        if issubclass(category, UnstableControlWarning):
            print(f'impact-arm {args.command}: warning: {message}', file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.simplefilter('always', UnstableControlWarning)
        warnings.showwarning = show
        yield


def main(argv: Sequence[str] | None = None) -> int:
    # every sub-command that touches DDS keeps discovery on this machine unless the user
    # chose otherwise
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    argv = sys.argv[1:] if argv is None else list(argv)
    selected = next((a for a in argv if not a.startswith('-')), None)
    args = build_parser(selected).parse_args(argv)
    try:
        with CompileNotice(prefix=f'impact-arm {args.command}: ') as notice, _warnings(args):
            NOTICE.append(notice)
            return args.func(args)
    except ImpactArmError as exc:
        print(f'impact-arm {args.command}: error: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'impact-arm {args.command}: interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
