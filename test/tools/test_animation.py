"""``impact-arm animate``: a GIF of the recorded arm, its frames checked."""

import numpy as np
import pytest
import yaml
from PIL import Image, ImageSequence

from impact_arm.physics.scene import scene_from_text
from impact_arm.physics.simulate import run
from impact_arm.io.offline_mcap import OfflineRecorder
from impact_arm.tools import analysis
from impact_arm.tools.animation import (
    DEFAULT_CONTACT_FRAMES,
    AnimationError,
    _contacts,
    animate,
    contact_forces,
    frame_times,
)
from impact_arm.tools.cli import main
from scenes import paper_dict


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp('anim') / 'run.mcap'
    data = paper_dict()
    data['cycles'] = 1
    scene = scene_from_text(yaml.safe_dump(data))  # with its text: the file keeps the scene
    rec = OfflineRecorder(path, scene)
    result = None
    try:
        result = run(scene, observer=rec)
    finally:
        rec.close(result)
    return path


def test_frame_times_are_real_time_and_slowed_near_impacts():
    t = frame_times(0.0, 1.0, [0.5], fps=10, slow=5, window=0.1)
    steps = np.diff(t)
    assert steps[0] == pytest.approx(0.1) and steps[-1] == pytest.approx(0.1)
    near = np.abs(t[:-1] - 0.5) <= 0.1
    assert steps[near] == pytest.approx(0.02) and near.sum() >= 9


def test_gif_has_one_frame_per_frame_time_showing_the_moving_arm(recording, tmp_path):
    out = tmp_path / 'arm.gif'
    assert main(['animate', str(recording), '--out', str(out), '--fps', '40']) == 0
    run_ = analysis.load(str(recording), progress=lambda _: None)
    contacts = [(c.start, c.end - c.start) for c in _contacts(run_)]
    assert len(contacts) == len(run_.impacts) == 1
    expected = frame_times(
        run_.t[0],
        run_.t[-1],
        [i.t_contact for i in run_.impacts],
        fps=40,
        contacts=contacts,
        contact_frames=DEFAULT_CONTACT_FRAMES,
    )
    image = Image.open(out)
    assert image.size == (400, 400) and image.n_frames == len(expected) > 25
    frames = [np.asarray(f.convert('RGB'), dtype=int) for f in ImageSequence.Iterator(image)]
    blue = [np.count_nonzero((f[..., 2] > 150) & (f[..., 0] < 80)) for f in frames]
    assert min(blue) > 100  # every frame draws the arm (tab:blue)
    assert np.abs(frames[0] - frames[len(frames) // 2]).sum() > 0  # and it moves


def test_the_contact_force_is_drawn_at_the_impact(recording, tmp_path):
    run_ = analysis.load(str(recording), progress=lambda _: None)
    forces = contact_forces(str(recording))
    assert forces is not None and forces[1][:, 1].max() > 0
    out = tmp_path / 'arm.gif'
    animate(run_, str(out), forces, fps=10)
    orange = [
        np.count_nonzero(
            (f[..., 0] > 200) & (f[..., 1] > 100) & (f[..., 1] < 160) & (f[..., 2] < 60)
        )
        for f in (
            np.asarray(g.convert('RGB'), dtype=int) for g in ImageSequence.Iterator(Image.open(out))
        )
    ]
    assert sum(o > 20 for o in orange) >= 1


def orange_pixels(frame):
    f = np.asarray(frame.convert('RGB'), dtype=int)
    return np.count_nonzero(
        (f[..., 0] > 200) & (f[..., 1] > 100) & (f[..., 1] < 160) & (f[..., 2] < 60)
    )


def test_each_impact_is_shown_in_slow_motion_with_its_force_to_scale(recording, tmp_path):
    """Frames evenly through the contact, the arrow drawn from the trace's force: longest
    near the peak force, shorter at separation (the force falls to zero), and the lengths in
    proportion to the force (one scale for the whole animation)."""
    run_ = analysis.load(str(recording), progress=lambda _: None)
    (contact,) = _contacts(run_)
    times = frame_times(0.0, 0.0, [], contacts=[(contact.start, 1e-4)], contact_frames=5)
    assert times[0] == 0 and times[1:] == pytest.approx(contact.start + np.linspace(0, 1e-4, 5))
    out = tmp_path / 'arm.gif'
    # no real-time frames in the way: one frame a second, then the contact's 30
    animate(run_, str(out), None, fps=1, slow=1, window=0, contact_frames=30)
    image = Image.open(out)
    frames = []
    for k in range(image.n_frames):
        image.seek(k)
        frames.append(image.copy())
    expected = frame_times(
        run_.t[0],
        run_.t[-1],
        [],
        fps=1,
        slow=1,
        window=0,
        contacts=[(contact.start, contact.end - contact.start)],
        contact_frames=30,
    )
    assert len(frames) == len(expected)
    inside = [k for k, t in enumerate(expected) if contact.start <= t <= contact.end]
    assert len(inside) == 30
    force = np.array([np.hypot(*contact.at(expected[k])[0]) for k in inside])
    scale_bar = orange_pixels(frames[0])  # before the impact: no arrow, the scale bar only
    assert scale_bar > 0
    orange = np.array([orange_pixels(frames[k]) - scale_bar for k in inside])
    peak = int(np.argmax(force))
    assert orange[peak] > 3 * orange[-2] > 0  # near separation the force is small
    assert orange[0] <= 5  # at first contact no force yet (a pixel of the tip may count)
    # to scale: the arrow's pixels grow with the force (thick line: about linearly)
    strong = force > 0.2 * force.max()
    ratio = orange[strong] / force[strong]
    assert np.ptp(ratio) < 0.5 * np.mean(ratio)


def test_refuses_an_unknown_format(recording, tmp_path):
    run_ = analysis.load(str(recording), progress=lambda _: None)
    with pytest.raises(AnimationError, match='.gif or .mp4'):
        animate(run_, str(tmp_path / 'arm.avi'))


def test_analyze_animates_only_when_asked(recording, tmp_path):
    """analyze writes animation.gif with --animation, after the report; not by default."""
    plain, animated = tmp_path / 'plain', tmp_path / 'animated'
    assert main(['analyze', str(recording), '--out', str(plain), '--laws', '']) == 0
    assert (plain / 'report.md').is_file() and not (plain / 'animation.gif').exists()
    argv = ['analyze', str(recording), '--out', str(animated), '--laws', '', '--animation']
    assert main(argv) == 0
    gif = Image.open(animated / 'animation.gif')
    assert gif.n_frames > DEFAULT_CONTACT_FRAMES  # real-time frames and the contact's own
