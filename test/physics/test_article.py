"""The article's scene: first impact against docs/model.md's reading, limit cycle, CLI JSON."""

import json

import pytest

from impact_arm.physics.scene import load_scene
from impact_arm.physics.simulate import run
from scenes import ARTICLE_FIRST_IMPACT


@pytest.fixture(scope='module')
def paper_run():
    return run(load_scene('paper'))


def test_first_impact_reproduces_the_article_within_one_percent(paper_run):
    first = paper_run.impacts[0]
    for key, expected in ARTICLE_FIRST_IMPACT.items():
        values = getattr(first, key) if isinstance(expected, list) else [getattr(first, key)]
        targets = expected if isinstance(expected, list) else [expected]
        for got, want in zip(values, targets):
            assert got == pytest.approx(want, rel=0.01), (key, got, want)
    assert first.t_contact == pytest.approx(0.2403, abs=5e-4)
    assert first.q_contact_deg == pytest.approx([-48.7, -14.4], abs=0.1)


def test_phase_durations_match_model_md(paper_run):
    elastic, plastic, restitution = paper_run.impacts[0].phase_durations
    assert elastic == pytest.approx(1e-6, rel=0.1)
    assert plastic == pytest.approx(99e-6, rel=0.03)
    assert restitution == pytest.approx(46e-6, rel=0.03)


def test_fifteen_cycles_settle_into_a_limit_cycle(paper_run):
    impacts = paper_run.impacts
    assert len(impacts) == 15
    settled = paper_run.settled_after
    assert settled is not None and settled <= 6, settled
    last, before = impacts[-1], impacts[-2]
    assert last.v_before == pytest.approx(before.v_before, rel=1e-6)
    for impact in impacts:  # physically consistent every time
        assert 0 < impact.delta_r < impact.delta_m
        assert impact.T_after[-1] < impact.T_before[-1]  # contact never adds energy


def test_cli_json_has_exactly_the_documented_structure(tmp_path):
    from impact_arm.tools.cli import main

    out = tmp_path / 'paper.json'
    assert main(['simulate', '--scene', 'paper', '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data) == {'impacts', 'run'}
    assert set(data['impacts'][0]) == {
        'index',
        't_contact',
        'q_contact_deg',
        'joints_contact_deg',
        'duration',
        'delta_m',
        'delta_r',
        'F_max',
        'v_before',
        'v_after',
        'cor_kinematic',
        'T_before',
        'T_after',
        'cor_energetic',
        'phase_durations',
        'q_max_compression_deg',
        'q_separation_deg',
    }
    assert set(data['run']) == {
        'impacts',
        't_end',
        'period_last',
        'q1_range_deg',
        'q2_range_deg',
        'vx_range',
        'vy_range',
        'rhs_evaluations',
        'wall_time',
        'chatter',
        'limits',
    }
    assert data['run']['chatter'] == [] and data['run']['limits'] == []
    assert data['run']['impacts'] == 15 == len(data['impacts'])


def test_sampled_control_stays_close_to_continuous_control(paper_run):
    sampled = run(load_scene('paper'), control_rate=1000.0)
    assert len(sampled.impacts) == 15
    a, b = sampled.impacts[0], paper_run.impacts[0]
    assert a.delta_m == pytest.approx(b.delta_m, rel=0.03)
    assert a.v_after[1] == pytest.approx(b.v_after[1], rel=0.03)
