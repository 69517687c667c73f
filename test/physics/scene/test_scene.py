"""Scene validation: bad scenes are refused with messages naming key, value and range."""

import math

import pytest

from impact_arm.physics.errors import SceneError
from impact_arm.physics.scene import load_scene, parse_scene, scene_from_text

from scenes import PAPER, paper_dict


def test_paper_scene_loads_in_si_units():
    scene = load_scene('paper')
    assert scene.n_links == 2
    assert scene.q0 == pytest.approx((math.radians(60), math.radians(45)))
    assert scene.surfaces[0].height == -1.0
    assert scene.arm_material.E == 210e9
    assert scene.cycles == 15


def refused(data, *fragments):
    with pytest.raises(SceneError) as info:
        parse_scene(data, origin='t.yaml')
    message = str(info.value)
    for fragment in fragments:
        assert fragment in message, message
    return message


def test_missing_key_is_named():
    data = paper_dict()
    del data['tip_radius']
    refused(data, 'tip_radius', 'missing')


def test_negative_mass_names_key_value_and_range():
    data = paper_dict()
    data['links'][1]['mass'] = -1.0
    refused(data, 'links[1].mass', '-1', '>= 1e-06', 'kg')


def test_poisson_ratio_of_half_or_more_is_refused():
    data = paper_dict()
    data['materials']['steel']['nu'] = 0.5
    refused(data, 'materials.steel.nu', '0.5', '< 0.5')


def test_unknown_contact_law_lists_the_choices():
    data = paper_dict()
    data['surfaces'][0]['law'] = 'plastic'
    refused(data, 'surfaces[0].law', 'plastic', 'elastoplastic', 'hertz')


def test_non_numeric_value_is_refused():
    data = paper_dict()
    data['controller']['kp'] = [600, 'lots']
    refused(data, 'controller.kp[1]', 'not a number')


def test_unknown_key_is_refused_so_typos_never_pass():
    data = paper_dict()
    data['controler'] = data['controller']
    refused(data, 'controler', 'not a known key')


def test_nan_is_refused():
    data = paper_dict()
    data['gravity'] = float('nan')
    refused(data, 'gravity', 'not finite')


def test_vector_length_must_match_links():
    data = paper_dict()
    data['initial']['q_deg'] = [60.0]
    refused(data, 'initial.q_deg', 'one per link')


def test_exponent_without_sign_reads_as_number():
    text = open(PAPER, encoding='utf-8').read()
    assert scene_from_text(text.replace('210.0e9', '210e9')).arm_material.E == 210e9


def test_unreadable_file_is_a_scene_error():
    with pytest.raises(SceneError, match='cannot be read'):
        load_scene('/nonexistent/scene.yaml')


def test_a_misspelled_scene_name_lists_the_installed_scenes():
    with pytest.raises(
        SceneError,
        match=r"scene 'papr': cannot be read: .*installed scenes: "
        r'paper\b',
    ) as refused:
        load_scene('papr')
    assert 'simulator' not in str(refused.value)  # node parameter files are not scenes


def test_cli_reports_bad_scene_without_traceback(tmp_path, capsys):
    from impact_arm.tools.cli import main

    bad = tmp_path / 'bad.yaml'
    bad.write_text(open(PAPER, encoding='utf-8').read().replace('mass: 1.0}', 'mass: -2.0}', 1))
    assert main(['simulate', '--scene', str(bad)]) == 2
    err = capsys.readouterr().err
    assert 'links[0].mass' in err and 'Traceback' not in err


def test_shipped_three_link_example_strikes_the_floor_through_its_cycles():
    """config/three_link.yaml, the example of an arm other than the article's: its
    controller completes every cycle, each with an impact on the floor."""
    from impact_arm.physics.simulate import StopReason, run

    scene = load_scene('three_link')
    assert scene.n_links == 3 and [round(x, 3) for x in scene.lengths] == [0.7, 0.7, 0.6]
    result = run(scene, control_rate=1000.0, keep_samples=False)
    assert result.stop_reason == StopReason.CYCLES_COMPLETED, result.stop_detail
    assert len(result.impacts) >= scene.cycles
