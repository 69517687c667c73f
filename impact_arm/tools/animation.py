"""``impact-arm animate FILE.mcap``: the arm, the surface and the contact force, frame by frame.

For people without a 3D viewer. Frames are spaced 1/fps of simulated time (real time), and
``slow`` times closer within ``window`` seconds of each impact, where the interesting part
lasts milliseconds. Each frame shows the recorded joint state nearest its time; the contact
force is the strongest /contact_wrench value since the previous frame, drawn from the tip with
the same saturating length as the 3D markers (io/scene_visuals.py), so no contact is missed
between frames. Writes a GIF (pillow, which matplotlib brings) or an MP4 (needs ffmpeg).
"""

from __future__ import annotations

import math
import os

import numpy as np

from ..contract import CONTACT_WRENCH
from ..physics.errors import ImpactArmError

DEFAULT_FPS = 20.0
DEFAULT_SLOW = 10.0  # frames this much closer near impacts
DEFAULT_WINDOW = 0.03  # s either side of an impact's contact time


class AnimationError(ImpactArmError):
    """The animation cannot be made (no scene in the file, bad option, missing writer)."""


def frame_times(
    t0: float,
    t1: float,
    impact_times,
    fps: float = DEFAULT_FPS,
    slow: float = DEFAULT_SLOW,
    window: float = DEFAULT_WINDOW,
) -> np.ndarray:
    """Simulated times of the frames from ``t0`` to ``t1``: 1/fps apart, 1/(fps·slow) apart
    within ``window`` of an impact time."""
    impacts = np.sort(np.asarray(list(impact_times), float))
    out, t, step = [], float(t0), 1.0 / fps
    while t <= t1 + 1e-12:
        out.append(t)
        near = impacts.size and np.min(np.abs(impacts - t)) <= window
        t += step / slow if near else step
    return np.asarray(out)


def contact_forces(path):
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


def animate(
    run,
    out_path,
    forces=None,
    fps: float = DEFAULT_FPS,
    slow: float = DEFAULT_SLOW,
    window: float = DEFAULT_WINDOW,
    progress=None,
) -> int:
    """Write the animation of ``run`` (analysis.Run, with its scene) to ``out_path`` (.gif or
    .mp4); ``forces`` as ``contact_forces`` returns. Returns the number of frames."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib import animation

    from ..io.scene_visuals import arrow_length

    if run.scene is None:
        raise AnimationError(f'{run.label}: the recording holds no scene (link lengths)')
    if not (fps > 0 and slow >= 1 and window >= 0):
        raise AnimationError(
            f'fps = {fps}, slow = {slow}, window = {window}: need fps > 0, slow >= 1, window >= 0'
        )
    ext = os.path.splitext(out_path)[1].lower()
    if ext not in ('.gif', '.mp4'):
        raise AnimationError(f'--out {out_path}: must end in .gif or .mp4')
    scene, lengths = run.scene, np.asarray(run.scene.lengths, float)
    if len(lengths) != run.q.shape[1]:
        raise AnimationError(
            f'{run.label}: {run.q.shape[1]} joints recorded, the stored scene '
            f'has {len(lengths)} links'
        )
    times = frame_times(
        run.t[0], run.t[-1], [i['t_contact'] for i in run.impacts], fps, slow, window
    )
    reach = float(lengths.sum())
    fig, ax = plt.subplots(figsize=(5, 5), dpi=80)
    ax.set_xlim(-1.1 * reach, 1.1 * reach)
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    for s in scene.surfaces:
        ax.axhline(s.height, color='0.5', lw=3)
    (arm,) = ax.plot([], [], '-o', lw=3, color='tab:blue', ms=4)
    tip = plt.Circle((0, 0), max(scene.tip_radius, 0.01 * reach), color='tab:red')
    ax.add_patch(tip)
    (arrow,) = ax.plot([], [], '-', lw=2, color='tab:orange')
    title = ax.set_title('')
    previous = [-math.inf]

    def draw(k):
        t = times[k]
        i = min(np.searchsorted(run.t, t), len(run.t) - 1)
        if i and abs(run.t[i - 1] - t) <= abs(run.t[i] - t):
            i -= 1
        q = run.q[i]
        x = np.concatenate([[0.0], np.cumsum(lengths * np.cos(q))])
        y = np.concatenate([[0.0], np.cumsum(lengths * np.sin(q))])
        if scene.general_links:  # the tip B: the contact point on the last link
            along, across = scene.contact_point
            c, s = math.cos(q[-1]), math.sin(q[-1])
            x[-1], y[-1] = x[-2] + along * c - across * s, y[-2] + along * s + across * c
        arm.set_data(x, y)
        tip.center = (x[-1], y[-1])
        arrow.set_data([], [])
        if forces is not None:
            ft, f = forces
            sel = (ft > previous[0]) & (ft <= t)
            if sel.any():
                mags = np.hypot(f[sel, 0], f[sel, 1])
                j = int(np.argmax(mags))
                if mags[j] > 0:
                    length = arrow_length(mags[j], reach)
                    arrow.set_data(
                        [x[-1], x[-1] + length * f[sel][j, 0] / mags[j]],
                        [y[-1], y[-1] + length * f[sel][j, 1] / mags[j]],
                    )
        previous[0] = t
        title.set_text(f't = {t:.3f} s')
        if progress and k % 100 == 0:
            progress(f'  animation frame {k}/{len(times)}')
        return arm, tip, arrow, title

    anim = animation.FuncAnimation(fig, draw, frames=len(times), blit=False)
    if ext == '.gif':
        writer = animation.PillowWriter(fps=fps)
    else:
        if not animation.FFMpegWriter.isAvailable():
            plt.close(fig)
            raise AnimationError(
                f'--out {out_path}: MP4 needs ffmpeg, which is not installed; write a .gif instead'
            )
        writer = animation.FFMpegWriter(fps=fps)
    try:
        anim.save(out_path, writer=writer)
    except OSError as e:
        raise AnimationError(f'--out {out_path}: cannot write ({e.strerror})') from None
    finally:
        plt.close(fig)
    return len(times)


def add_arguments(parser):
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


def cli(args) -> int:
    from .analysis import load

    out = args.out or os.path.join(
        'runs', os.path.splitext(os.path.basename(args.file))[0] + '.gif'
    )
    if os.path.dirname(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)
    from .progress import Progress

    line = Progress(prefix='animate: ')

    def say(text):
        line.show(text, log=True)

    run = load(args.file, progress=say)
    frames = animate(
        run, out, contact_forces(args.file), args.fps, args.slow, args.window, progress=say
    )
    line.end()
    print(f'wrote {out} ({frames} frames)')
    return 0
