"""``impact-arm animate FILE.mcap``: the arm, the surface and the contact force, frame by frame.

For people without a 3D viewer. Frames are spaced 1/fps of simulated time (real time),
``slow`` times closer within ``window`` seconds of each impact, and each impact itself (which
lasts ~0.1 ms) gets ``contact_frames`` frames of its own: slow motion through the contact,
with the force of the impact's trace (``/impact_trace``: offline recordings) at that instant.
Each frame shows the recorded joint state nearest its time. The force arrow is drawn to scale
(a scale bar says how many kN a length is): inside an impact the traced force, elsewhere the
strongest /contact_wrench value since the previous frame (a period average), so no contact is
missed between frames.

The axes, the surface and the scale bar are drawn once by matplotlib; each frame draws the
arm, the tip and the arrow onto a copy of that picture with Pillow (which matplotlib brings):
seconds for a whole run, where redrawing every frame with matplotlib took minutes. Writes a GIF
(Pillow) or an MP4 (needs ffmpeg).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..contract import CONTACT_WRENCH
from ..physics.errors import ImpactArmError

if TYPE_CHECKING:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.transforms import Transform

    from .run_data import Run

DEFAULT_FPS = 20.0
DEFAULT_SLOW = 10.0  # frames this much closer near impacts
DEFAULT_WINDOW = 0.03  # s either side of an impact's contact time
DEFAULT_CONTACT_FRAMES = 12  # frames through each impact (slow motion)
PIXELS, DPI = 400, 80  # frame size: PIXELS square at DPI (5 inches)
ARROW_SHARE = 0.45  # the strongest force is drawn this fraction of the reach long
BLUE, RED, ORANGE, GREY = (31, 119, 180), (214, 39, 40), (255, 127, 14), (80, 80, 80)


class AnimationError(ImpactArmError):
    """The animation cannot be made (no scene in the file, bad option, missing writer)."""


def frame_times(
    t0: float,
    t1: float,
    impact_times: Iterable[float],
    fps: float = DEFAULT_FPS,
    slow: float = DEFAULT_SLOW,
    window: float = DEFAULT_WINDOW,
    contacts: Iterable[tuple[float, float]] = (),
    contact_frames: int = 0,
) -> np.ndarray:
    """Simulated times of the frames from ``t0`` to ``t1``: 1/fps apart, 1/(fps·slow) apart
    within ``window`` of an impact time, and ``contact_frames`` evenly through each contact
    ``(t_contact, duration)`` of ``contacts`` (from its start to its end)."""
    impacts = np.sort(np.asarray(list(impact_times), float))
    out, t, step = [], float(t0), 1.0 / fps
    while t <= t1 + 1e-12:
        out.append(t)
        near = impacts.size and np.min(np.abs(impacts - t)) <= window
        t += step / slow if near else step
    for start, duration in contacts if contact_frames > 0 else ():
        out.extend(start + duration * np.linspace(0.0, 1.0, contact_frames))
    return np.unique(np.asarray(out, float))


def contact_forces(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """(times [s], (N, 2) tangential and normal force) of /contact_wrench, or None."""
    from ..io.mcap_ros2 import iter_raw, topics_info
    from ..io.wire import wrench_stamped_fields

    if CONTACT_WRENCH not in topics_info(path):
        return None
    t, f = [], []
    for m in iter_raw(path, [CONTACT_WRENCH]):
        sec, nanosec, force = wrench_stamped_fields(m.data)
        t.append(sec + 1e-9 * nanosec)
        f.append(force[:2])
    order = np.argsort(t, kind='stable')
    return np.asarray(t)[order], np.asarray(f, float).reshape(-1, 2)[order]


class _Contact:
    """One impact's traced force (tangential F_f, normal F_n) and indentation over time."""

    def __init__(self, index, columns, rows):
        col = {name: rows[:, i] for i, name in enumerate(columns)}
        self.index = index
        self.t = col['t']
        self.start, self.end = float(self.t[0]), float(self.t[-1])
        self.force = np.stack([col['F_f'], col['F_n']], axis=1)
        self.delta = col['delta']

    def at(self, t: float) -> tuple[np.ndarray, float]:
        """(tangential, normal) force [N] and indentation [m] at ``t``, linear between points;
        zero before the first point (the contact itself, δ = 0)."""
        if t < self.t[0]:
            return np.zeros(2), 0.0
        ft = [np.interp(t, self.t, self.force[:, k]) for k in (0, 1)]
        return np.asarray(ft), float(np.interp(t, self.t, self.delta))


def _contacts(run):
    """The traced impacts of ``run`` (``_Contact``), starting at each one's contact time."""
    out = []
    for k, (columns, rows) in enumerate(run.traces):
        if len(rows) < 2 or not {'t', 'F_n', 'F_f', 'delta'} <= set(columns):
            continue
        contact = _Contact(k + 1, columns, np.asarray(rows, float))
        if k < len(run.impacts):  # the trace's first point is a step end, not the contact
            contact.start = min(contact.start, float(run.impacts[k].t_contact))
        out.append(contact)
    return out


def _nice_force(value: float) -> float:
    """A round force [N] near ``value``/2 for the scale bar: 1, 2 or 5 times a power of ten."""
    if not value > 0:
        return 1000.0
    exponent = math.floor(math.log10(value / 2))
    for mantissa in (5, 2, 1):
        if mantissa * 10**exponent <= value / 2:
            return mantissa * 10**exponent
    return 10**exponent


def _kn(force: float) -> str:
    return f'{force / 1e3:g} kN'


def animate(
    run: Run,
    out_path: str,
    forces: tuple[np.ndarray, np.ndarray] | None = None,
    fps: float = DEFAULT_FPS,
    slow: float = DEFAULT_SLOW,
    window: float = DEFAULT_WINDOW,
    progress: Callable[[str], Any] | None = None,
    contact_frames: int = DEFAULT_CONTACT_FRAMES,
) -> int:
    """Write the animation of ``run`` (analysis.Run, with its scene) to ``out_path`` (.gif or
    .mp4); ``forces`` as ``contact_forces`` returns. Returns the number of frames."""
    if run.scene is None:
        raise AnimationError(f'{run.label}: the recording holds no scene (link lengths)')
    if not (fps > 0 and slow >= 1 and window >= 0 and contact_frames >= 0):
        raise AnimationError(
            f'fps = {fps}, slow = {slow}, window = {window}, contact_frames = '
            f'{contact_frames}: need fps > 0, slow >= 1, window >= 0, contact_frames >= 0'
        )
    ext = os.path.splitext(out_path)[1].lower()
    if ext not in ('.gif', '.mp4'):
        raise AnimationError(f'--out {out_path}: must end in .gif or .mp4')
    if ext == '.mp4':
        from matplotlib import animation as mpl_animation

        if not mpl_animation.FFMpegWriter.isAvailable():
            raise AnimationError(
                f'--out {out_path}: MP4 needs ffmpeg, which is not installed; write a .gif instead'
            )
    scene, lengths = run.scene, np.asarray(run.scene.lengths, float)
    if len(lengths) != run.q.shape[1]:
        raise AnimationError(
            f'{run.label}: {run.q.shape[1]} joints recorded, the stored scene '
            f'has {len(lengths)} links'
        )
    contacts = _contacts(run)
    times = frame_times(
        run.t[0],
        run.t[-1],
        [i.t_contact for i in run.impacts],
        fps,
        slow,
        window,
        [(c.start, c.end - c.start) for c in contacts],
        contact_frames,
    )
    reach = float(lengths.sum())
    strongest = max(
        [float(np.max(np.hypot(*c.force.T))) for c in contacts]
        + ([float(np.max(np.hypot(*forces[1].T)))] if forces is not None and len(forces[0]) else [])
        + [0.0]
    )
    per_newton = ARROW_SHARE * reach / strongest if strongest > 0 else 0.0
    background, to_pixels = _background(scene, reach, per_newton, _nice_force(strongest))
    tip_radius = max(
        abs(
            to_pixels(np.array([[scene.tip_radius, 0.0]]))[0, 0] - to_pixels(np.zeros((1, 2)))[0, 0]
        ),
        3.0,
    )
    frames = []
    previous = -math.inf
    for k, t in enumerate(times):
        frames.append(
            _frame(
                background,
                to_pixels,
                run,
                lengths,
                t,
                previous,
                forces,
                contacts,
                per_newton,
                tip_radius,
            )
        )
        previous = t
        if progress and k % 100 == 0:
            progress(f'  animation frame {k}/{len(times)}')
    _write(frames, out_path, ext, fps)
    return len(times)


def _background(scene, reach, per_newton, bar_force):
    """The picture every frame starts from (axes, surfaces, force scale bar) as a Pillow
    image, and the map from data coordinates [m] to its pixels."""
    import matplotlib

    matplotlib.use('Agg', force=True)
    import matplotlib.pyplot as plt
    from PIL import Image

    fig, ax = plt.subplots(figsize=(PIXELS / DPI, PIXELS / DPI), dpi=DPI)
    ax.set_xlim(-1.1 * reach, 1.1 * reach)
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    fig.subplots_adjust(left=0.16, right=0.96, bottom=0.12, top=0.88)
    for s in scene.surfaces:
        ax.axhline(s.height, color='0.5', lw=3)
    if per_newton > 0:
        length = bar_force * per_newton
        x0, y0 = -1.0 * reach, -1.0 * reach
        ax.plot([x0, x0 + length], [y0, y0], color='tab:orange', lw=2)
        ax.text(x0, y0 + 0.04 * reach, f'force scale: {_kn(bar_force)}', fontsize=7)
    fig.canvas.draw()
    height = fig.canvas.get_width_height()[1]
    transform = cast('Transform', ax.transData.frozen())  # a transform's frozen copy
    canvas = cast('FigureCanvasAgg', fig.canvas)  # the Agg backend chosen above
    image = Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)

    def to_pixels(xy: Any) -> np.ndarray:
        display = transform.transform(np.asarray(xy, float))
        return np.stack([display[:, 0], height - display[:, 1]], axis=1)

    return image, to_pixels


def _frame(background, to_pixels, run, lengths, t, previous, forces, contacts, per_newton, radius):
    from PIL import ImageDraw

    i = min(int(np.searchsorted(run.t, t)), len(run.t) - 1)
    if i and abs(run.t[i - 1] - t) <= abs(run.t[i] - t):
        i -= 1
    q = run.q[i]
    x = np.concatenate([[0.0], np.cumsum(lengths * np.cos(q))])
    y = np.concatenate([[0.0], np.cumsum(lengths * np.sin(q))])
    if run.scene.general_links:  # the tip B: the contact point on the last link
        along, across = run.scene.contact_point
        c, s = math.cos(q[-1]), math.sin(q[-1])
        x[-1], y[-1] = x[-2] + along * c - across * s, y[-2] + along * s + across * c
    image = background.copy()
    draw = ImageDraw.Draw(image)
    points = to_pixels(np.stack([x, y], axis=1))
    draw.line([tuple(p) for p in points], fill=BLUE, width=4)
    for px, py in points[:-1]:
        draw.ellipse([px - 3, py - 3, px + 3, py + 3], fill=BLUE)
    tx, ty = points[-1]
    draw.ellipse([tx - radius, ty - radius, tx + radius, ty + radius], fill=RED)
    force, title = None, f't = {t:.3f} s'
    inside = next((c for c in contacts if c.start <= t <= c.end), None)
    if inside is not None:
        force, delta = inside.at(t)
        newtons = round(float(np.hypot(*force)), -1)
        title = (
            f't = {t:.6f} s   impact {inside.index}, {1e6 * (t - inside.start):.1f} us '
            f'after contact (slow motion)\nindentation {1e6 * delta:.0f} um,  '
            f'force {_kn(newtons)}'
        )
    elif forces is not None:
        ft, f = forces
        sel = (ft > previous) & (ft <= t)
        if sel.any():
            mags = np.hypot(f[sel, 0], f[sel, 1])
            force = f[sel][int(np.argmax(mags))]
    if force is not None and per_newton > 0 and np.hypot(*force) > 0:
        end = to_pixels(np.array([[x[-1] + per_newton * force[0], y[-1] + per_newton * force[1]]]))[
            0
        ]
        _arrow(draw, (tx, ty), tuple(end))
    draw.multiline_text((70, 8), title, fill=GREY, spacing=2)
    return image


def _arrow(draw, start, end):
    """A line from ``start`` to ``end`` (pixels) with a head at ``end``."""
    draw.line([start, end], fill=ORANGE, width=3)
    dx, dy = end[0] - start[0], end[1] - start[1]
    length = math.hypot(dx, dy)
    if length < 1:
        return
    ux, uy = dx / length, dy / length
    size = min(10.0, 0.5 * length)
    left = (end[0] - size * ux + 0.5 * size * uy, end[1] - size * uy - 0.5 * size * ux)
    right = (end[0] - size * ux - 0.5 * size * uy, end[1] - size * uy + 0.5 * size * ux)
    draw.polygon([end, left, right], fill=ORANGE)


def _write(frames, out_path, ext, fps):
    try:
        if ext == '.gif':
            first = frames[0].quantize(colors=64)
            rest = [f.quantize(palette=first) for f in frames[1:]]
            first.save(
                out_path,
                save_all=True,
                append_images=rest,
                duration=int(round(1000 / fps)),
                loop=0,
                optimize=False,
            )
        else:
            _write_mp4(frames, out_path, fps)
    except OSError as e:
        raise AnimationError(f'--out {out_path}: cannot write ({e.strerror or e})') from None


def _write_mp4(frames, out_path, fps):
    import matplotlib

    matplotlib.use('Agg', force=True)
    import matplotlib.pyplot as plt
    from matplotlib import animation

    fig = plt.figure(figsize=(PIXELS / DPI, PIXELS / DPI), dpi=DPI)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.axis('off')
    shown = ax.imshow(np.asarray(frames[0]))
    writer = animation.FFMpegWriter(fps=fps)
    try:
        with writer.saving(fig, out_path, DPI):
            for frame in frames:
                shown.set_data(np.asarray(frame))
                writer.grab_frame()
    finally:
        plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('file', help='MCAP recording (live or simulate --mcap)')
    parser.add_argument(
        '--out', metavar='FILE', help='GIF or MP4 to write (default: runs/<file name>.gif)'
    )
    parser.add_argument(
        '--fps',
        type=float,
        default=DEFAULT_FPS,
        help=f'frames per second of simulated time (default {DEFAULT_FPS:g})',
    )
    parser.add_argument(
        '--slow',
        type=float,
        default=DEFAULT_SLOW,
        help=f'slow-motion factor near impacts (default {DEFAULT_SLOW:g}; '
        f'1 = real time throughout)',
    )
    parser.add_argument(
        '--window',
        type=float,
        default=DEFAULT_WINDOW,
        metavar='S',
        help=f'seconds either side of an impact shown slowed (default {DEFAULT_WINDOW:g})',
    )
    parser.add_argument(
        '--contact-frames',
        type=int,
        default=DEFAULT_CONTACT_FRAMES,
        metavar='N',
        help=f'frames through each impact, from its /impact_trace (default '
        f'{DEFAULT_CONTACT_FRAMES}; 0: none)',
    )


def cli(args: argparse.Namespace) -> int:
    from .run_data import load

    out = args.out or os.path.join(
        'runs', os.path.splitext(os.path.basename(args.file))[0] + '.gif'
    )
    if os.path.dirname(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)
    from .progress import Progress

    line = Progress(prefix='animate: ')

    def say(text: str) -> None:
        line.show(text, log=True)

    run = load(args.file, progress=say)
    frames = animate(
        run,
        out,
        contact_forces(args.file),
        args.fps,
        args.slow,
        args.window,
        progress=say,
        contact_frames=args.contact_frames,
    )
    line.end()
    print(f'wrote {out} ({frames} frames)')
    return 0
