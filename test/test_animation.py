"""``impact-arm animate``: a GIF of the recorded arm, its frames checked."""

import numpy as np
import pytest
import yaml
from PIL import Image, ImageSequence

from impact_arm.physics.scene import scene_from_text
from impact_arm.physics.simulate import run
from impact_arm.io.offline_mcap import OfflineRecorder
from impact_arm.tools import analysis
from impact_arm.tools.animation import AnimationError, animate, contact_forces, frame_times
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
    expected = frame_times(run_.t[0], run_.t[-1], [i['t_contact'] for i in run_.impacts], fps=40)
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


def test_refuses_an_unknown_format(recording, tmp_path):
    run_ = analysis.load(str(recording), progress=lambda _: None)
    with pytest.raises(AnimationError, match='.gif or .mp4'):
        animate(run_, str(tmp_path / 'arm.avi'))
