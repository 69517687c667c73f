"""``impact-arm analyze`` on the offline article run: the impact table of ``simulate`` exactly,
the limit cycle, Poincaré sections, every figure (opened and measured) and the report."""

import json
import math
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from impact_arm.tools.analysis import limit_cycle, poincare
from impact_arm.tools.figures import FIGURE_SIZE
from repo_paths import CONFIG
from scenes import impact_at


FIGURES = [
    'fig3_controllers.png',
    'fig4_link_angles.png',
    'fig5_phase_portraits.png',
    'fig6_poincare.png',
    'fig7_tip_velocity.png',
    'fig8_indentation.png',
    'fig9_impact_velocity.png',
    'fig10_contact_force.png',
    'fig10b_force_indentation.png',
    'fig11_kinetic_energy.png',
]


def cli(*argv, cwd):
    return subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', *map(str, argv)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


@pytest.fixture(scope='module')
def article(tmp_path_factory):
    d = tmp_path_factory.mktemp('article')
    sim = cli(
        'simulate',
        '--scene',
        'paper',
        '--mcap',
        d / 'paper.mcap',
        '--json',
        d / 'paper.json',
        cwd=d,
    )
    assert sim.returncode == 0, sim.stderr
    ana = cli('analyze', d / 'paper.mcap', '--out', d / 'out', cwd=d)
    assert ana.returncode == 0, ana.stderr
    return d, sim, ana


def test_impact_table_is_exactly_the_simulated_one(article):
    d, sim, ana = article
    with open(d / 'paper.json', encoding='utf-8') as f:
        simulated = json.load(f)
    with open(d / 'out' / 'impacts.json', encoding='utf-8') as f:
        analysed = json.load(f)
    assert len(simulated['impacts']) == 15
    assert analysed['impacts'] == simulated['impacts']  # every field, every digit
    # the printed table: the same rows as simulate prints
    rows = sim.stdout.split('\n\n')[0].strip('\n')
    assert rows in ana.stdout
    with open(d / 'out' / 'impact_table.txt', encoding='utf-8') as f:
        assert f.read().strip('\n') == rows
    # the animation is a step of its own (impact-arm animate, or analyze --animation)
    assert not (d / 'out' / 'animation.gif').exists()


def test_limit_cycle_and_poincare_sections(article):
    d, sim, ana = article
    assert 'limit cycle reached after 5 impacts' in sim.stdout
    assert 'limit cycle reached after 5 impacts' in ana.stdout
    with open(d / 'paper.json', encoding='utf-8') as f:
        run = json.load(f)['run']
    assert f'period {run["period_last"]:.5f} s' in ana.stdout
    for k in (1, 2):
        rows = np.loadtxt(d / 'out' / f'poincare_qd{k}_zero.csv', delimiter=',', skiprows=1)
        assert rows.ndim == 2 and rows.shape[1] == 4 and len(rows) >= 2 * 15 - 2
        assert np.all(np.isfinite(rows)) and np.all(np.diff(rows[:, 0]) > 0)
        # on the limit cycle the sections repeat: the last crossings of each direction agree
        # (to the 1 kHz sampling: a crossing through an impact is interpolated across it)
        for direction in (-1, 1):
            last = rows[rows[:, 3] == direction][-3:, 1:3]
            assert np.ptp(last, axis=0) == pytest.approx([0, 0], abs=0.5)
            first = rows[rows[:, 3] == direction][0, 1:3]
            assert np.max(np.abs(first - last[-1])) > 1.0  # ... and differ from the start
        lo, hi = run['q1_range_deg']
        assert lo - 1 <= rows[:, 1].min() and rows[:, 1].max() <= hi + 1


def png_size(path):
    with open(path, 'rb') as f:
        head = f.read(24)
    assert head[:8] == b'\x89PNG\r\n\x1a\n' and head[12:16] == b'IHDR'
    return struct.unpack('>II', head[16:24])


def test_every_figure_is_written_non_empty_and_of_the_stated_size(article):
    import matplotlib.image as mpimg

    d, _, ana = article
    for name in FIGURES:
        path = d / 'out' / name
        assert png_size(path) == FIGURE_SIZE, name
        pixels = mpimg.imread(path)
        assert pixels.shape[:2] == (FIGURE_SIZE[1], FIGURE_SIZE[0])
        # not blank: a good share of pixels differ from the background colour
        background = pixels[0, 0]
        drawn = np.any(np.abs(pixels - background) > 0.05, axis=-1).mean()
        assert 0.01 < drawn < 0.9, (name, drawn)
        assert f'({name})' in open(d / 'out' / 'report.md', encoding='utf-8').read()
    assert 'figure 10/10' in ana.stderr  # progress is shown


def test_report_states_table_cycle_and_sections(article):
    d, _, _ = article
    text = (d / 'out' / 'report.md').read_text(encoding='utf-8')
    for needle in (
        '# Analysis of paper.mcap',
        '## Impacts',
        '## Limit cycle',
        'limit cycle reached after 5 impacts',
        '## Poincaré sections',
        'poincare_qd1_zero.csv',
        'scene paper, law q',
        '(offline run, impact-arm simulate --mcap)',
    ):
        assert needle in text, needle
    assert '(offline, offline)' not in text


def test_poincare_crossings_of_a_known_signal():
    t = np.linspace(0, 2, 2001)
    q = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)], axis=1)
    qd = np.stack([2 * np.pi * np.cos(2 * np.pi * t), -2 * np.pi * np.sin(2 * np.pi * t)], 1)
    rows = poincare(t, q, qd, 0)  # q̇1 = 0 at t = 0.25, 0.75, 1.25, 1.75
    assert rows[:, 0] == pytest.approx([0.25, 0.75, 1.25, 1.75], abs=1e-6)
    assert rows[:, 1] == pytest.approx([1, -1, 1, -1], abs=1e-5)
    assert list(rows[:, 3]) == [-1, 1, -1, 1]
    qd[5, 0] = math.nan  # a non-finite sample makes no crossing, and is not hidden elsewhere
    assert len(poincare(t, q, qd, 0)) == 4


def test_limit_cycle_of_records():
    impacts = [
        impact_at([1.0, 2.0 + (i < 3)], index=i + 1, t_contact=0.4 * i, v_before=(0.0, -1.0))
        for i in range(8)
    ]
    lc = limit_cycle(impacts)
    assert lc['settled_after'] == 4 and lc['period'] == pytest.approx(0.4)
    assert lc['impacts_per_cycle'] == 1


def test_a_limit_cycle_of_two_strikes_per_cycle_is_found_with_its_period():
    """A strike and a light re-strike 2 ms later each cycle of 0.47 s (the three-link arm):
    no impact repeats its predecessor, every one repeats the one two before it."""
    from impact_arm.physics.metrics import limit_cycle as find, settle_index

    impacts = []
    for k in range(7):
        for first in (True, False):
            settling = 2.0 * 0.5**k  # the first cycles approach the limit cycle
            impacts.append(
                impact_at(
                    [-49.0 + settling, -22.0 if first else -22.5],
                    index=len(impacts) + 1,
                    t_contact=0.47 * k + (0.0 if first else 0.002),
                    v_before=(-3.3, -4.9) if first else (-1.2, -0.4),
                )
            )
    assert settle_index(impacts) is None  # not every impact repeats its predecessor
    cycle = find(impacts)
    assert cycle is not None and cycle.impacts_per_cycle == 2
    # the 6th cycle (impacts 11, 12) repeats in the 7th within 1e-3 of 49 degrees; the 5th
    # differs from the 6th by 0.0625 degrees
    assert cycle.settled_after == 11
    assert cycle.period(impacts) == pytest.approx(0.47)
    lc = limit_cycle(impacts)
    assert lc['impacts_per_cycle'] == 2 and lc['period'] == pytest.approx(0.47)
    assert lc['period_last'] == pytest.approx(0.002)
    # one repetition seen is not a cycle: the last two cycles only, and the 4th impact on
    assert find(impacts[-3:]) is None and find(impacts[-4:]).settled_after == 1


def small_recording(path):
    """Joint states only: no scene, no impacts, no traces (a bare live recording)."""
    from sensor_msgs.msg import JointState

    from impact_arm.io.mcap_ros2 import Ros2McapWriter

    with Ros2McapWriter(path) as w:
        for i in range(400):
            t = i * 0.005
            m = JointState(
                name=['joint1', 'joint2'],
                position=[math.sin(4 * t), 0.5 * math.cos(4 * t) - math.sin(4 * t)],
                velocity=[4 * math.cos(4 * t), -2 * math.sin(4 * t) - 4 * math.cos(4 * t)],
            )
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(i * 5_000_000, 10**9)
            w.write_message('/joint_states', m, i * 5_000_000)
    return path


def test_what_the_data_allows_compare_and_errors(article, tmp_path):
    d, _, _ = article
    small = small_recording(tmp_path / 'small.mcap')
    ok = cli(
        'analyze',
        small,
        '--out',
        tmp_path / 'cmp',
        '--compare',
        small,
        '--no-animation',
        '--dpi',
        50,
        cwd=tmp_path,
    )
    assert ok.returncode == 0, ok.stderr
    made = sorted(p.name for p in (tmp_path / 'cmp').glob('*.png'))
    # --dpi sets the pixels, not the layout: half the default's on each side
    assert png_size(tmp_path / 'cmp' / 'fig4_link_angles.png') == tuple(n // 2 for n in FIGURE_SIZE)
    assert 'no impacts in' in ok.stdout and 'no /impact_report topic' in ok.stdout
    # no scene: no Figs. 3 and 7; no traces and no reports: no Figs. 8-11; each said why
    assert made == sorted(['fig3b_recordings.png'] + FIGURES[1:4])
    assert 'Figure 3 not drawn' in ok.stdout and 'stores no scene' in ok.stdout
    assert 'Figures 8-11 not drawn' in ok.stdout and 'no /impact_report' in ok.stdout
    assert 'impact-arm simulate --scene SCENE --mcap FILE' in ok.stdout
    report = (tmp_path / 'cmp' / 'report.md').read_text(encoding='utf-8')
    assert 'Recordings compared (fig3b_recordings.png): small.mcap, small.mcap' in report
    assert 'Figures 8-11 not drawn' in report
    assert '0 impact reports' in report and 'no impacts recorded' in report
    rows = np.loadtxt(tmp_path / 'cmp' / 'poincare_qd1_zero.csv', delimiter=',', skiprows=1)
    # q̇1 = 4 cos 4t crosses zero at t = π/8, 3π/8, 5π/8 within 2 s, where q1 = ±1 rad and
    # the absolute q2 = joint1 + joint2 = 0.5 cos 4t = 0
    assert rows[:, 0] == pytest.approx([math.pi / 8, 3 * math.pi / 8, 5 * math.pi / 8], abs=1e-3)
    assert rows[:, 1] == pytest.approx([57.2958, -57.2958, 57.2958], abs=0.01)
    assert rows[:, 2] == pytest.approx([0, 0, 0], abs=0.01)
    for argv, needle in (
        ([tmp_path / 'none.mcap'], 'no such file'),
        ([d / 'paper.mcap', '--impact', 16], '--impact = 16: must be in [1, 15]'),
        ([d / 'paper.mcap', '--laws', 'lqr'], "--laws: 'lqr' is not one of"),
        ([d / 'paper.json'], 'paper.json: not an MCAP file'),
        ([small, '--dpi', 10], '--dpi = 10: must be in [50, 1200]'),
    ):
        bad = cli('analyze', *argv, cwd=tmp_path)
        assert bad.returncode == 2 and needle in bad.stderr, bad.stderr
        assert 'Traceback' not in bad.stderr


def without_trace(src, dst):
    """A copy of an offline recording without /impact_trace: what a live recording holds
    (the simulator node publishes no trace)."""
    from impact_arm.io.mcap_ros2 import Ros2McapWriter, iter_raw, read_metadata, topics_info

    info = topics_info(src)
    with Ros2McapWriter(dst) as w:
        for topic, ti in info.items():
            if topic != '/impact_trace':
                w.add_topic(topic, ti.type_name, ti.qos or None)
        for m in iter_raw(src):
            if m.topic != '/impact_trace':
                w.write(m.topic, m.data, m.log_time_ns)
        for name, data in read_metadata(src).items():
            if name != 'rosbag2':  # the writer writes its own
                w.add_metadata(name, data)
    return dst


def test_an_impact_traced_but_not_reported_is_drawn_from_its_trace(article, tmp_path):
    """An impact with its /impact_trace and no /impact_report: the record of Figures 8-11 is
    read off the trace (its number, δm, δr and F_max, the time and state at its first
    point), with no contact angles, so nothing integrates it again."""
    import dataclasses

    import matplotlib

    matplotlib.use('Agg')
    from impact_arm.tools import analysis, figures

    d, _, _ = article
    recorded = analysis.load(d / 'paper.mcap')
    unreported = dataclasses.replace(recorded, impacts=[])
    impact, constants = analysis.impact_points(unreported, 2)
    assert impact is not None and constants is None  # no report: no contact posture
    columns, rows, record, note = impact
    reported = recorded.impacts[1]
    assert record.index == 2 and note == '' and record.q_contact_deg == ()
    assert record.delta_m == pytest.approx(reported.delta_m, rel=1e-12)
    assert record.F_max == pytest.approx(reported.F_max, rel=1e-12)
    assert record.t_contact == pytest.approx(reported.t_contact, abs=1e-5)
    assert math.isnan(record.duration) and math.isnan(record.cor_kinematic)
    assert analysis.elastic_curve(unreported.scene, record) is None
    assert 'impact 2: δm = ' in figures.fig8_indentation(impact, tmp_path).axes[0].get_title()


def test_a_live_recording_gets_figures_8_to_11_from_its_impact_reports(article, tmp_path):
    """No /impact_trace: impact 2 is integrated again from its reported contact state; its
    points are the offline trace's (the same impact, actuators off during contact)."""
    from impact_arm.tools import analysis

    d, _, _ = article
    live = without_trace(d / 'paper.mcap', tmp_path / 'live.mcap')
    ana = cli(
        'analyze',
        live,
        '--out',
        tmp_path / 'out',
        '--impact',
        2,
        '--laws',
        '',
        '--no-animation',
        cwd=tmp_path,
    )
    assert ana.returncode == 0, ana.stderr
    for name in FIGURES[5:]:
        assert png_size(tmp_path / 'out' / name) == FIGURE_SIZE, name
    assert 'impact 2 re-integrated from /impact_report' in ana.stdout
    assert not (tmp_path / 'out' / 'fig3_controllers.png').exists()  # --laws ''
    recorded = analysis.load(d / 'paper.mcap')
    again = analysis.load(live)
    assert not again.traces
    (columns, rows, record, note), _ = analysis.impact_points(again, 2)
    (_, trace_rows, _, trace_note), _ = analysis.impact_points(recorded, 2)
    assert note and not trace_note
    assert rows.shape == trace_rows.shape
    delta, force = columns.index('delta'), columns.index('F_n')
    assert np.max(rows[:, delta]) == pytest.approx(record.delta_m, rel=1e-5)
    assert rows[:, delta] == pytest.approx(trace_rows[:, delta], rel=1e-4, abs=1e-9)
    assert rows[:, force] == pytest.approx(trace_rows[:, force], rel=1e-4, abs=1e-3)
    # the points start at contact and every phase switch is among them
    assert rows[0, delta] == 0 and rows[0, 0] == record.t_contact
    phase = rows[:, columns.index('phase')]
    assert list(np.unique(phase)) == [1, 2, 3]
    t_us = (rows[:, 0] - record.t_contact) * 1e6
    switches = t_us[np.nonzero(np.diff(phase))[0]]
    elastic, plastic, _ = np.array(record.phase_durations) * 1e6
    assert switches == pytest.approx([elastic, elastic + plastic], abs=1e-6)
    # maximum compression is a point: v_y = 0 there, no jump to the next phase's points
    v_y = rows[:, columns.index('v_y')]
    assert abs(v_y[np.nonzero(np.diff(phase))[0][1]]) < 1e-3


def test_figure_3_data_are_the_articles_comparison_of_the_control_laws():
    """Step responses without impact (the surface taken away): PD settles short of the
    target by exactly gravity / Kp, PID overshoots, the Q controller overshoots by nothing
    worth the name and settles within 0.1° sooner than PID on both links."""
    from impact_arm.physics.scene import load_scene
    from impact_arm.tools.analysis import step_response

    scene = load_scene('paper')
    runs = {law: step_response(scene, law, t_max=5.0) for law in ('q', 'pd', 'pid')}
    target = np.array(scene.controller.down_target)
    assert not any(r.impacts for r in runs.values())
    step = np.degrees(runs['q'].q[0] - target)  # the step (from 60°, 45°), deg

    def past_target(run, k):  # degrees beyond the target, in the step's direction
        return max(0.0, float(-np.min(np.degrees(run.q[:, k] - target[k]) * np.sign(step[k]))))

    def settled_at(run, k, band=0.1):  # time from which |error| stays within band degrees
        out = np.nonzero(np.abs(np.degrees(run.q[:, k] - target[k])) > band)[0]
        return run.t[out[-1] + 1] if out[-1] + 1 < len(run.t) else math.inf

    # PD: at rest, K_p e balances gravity: e2 = Q2g / Kp2, e1 = (Q1g + Q2g) / Kp1, with
    # Q1g = -(m1/2 + m2) g L1 cos q1, Q2g = -m2 g L2/2 cos q2 at the resting angles
    q1, q2 = runs['pd'].q[-1]
    (m1, m2), (L1, L2), g = scene.masses, scene.lengths, scene.gravity
    Q1g, Q2g = -(m1 / 2 + m2) * g * L1 * math.cos(q1), -m2 * g * L2 / 2 * math.cos(q2)
    kp = scene.controller.kp
    expected = np.degrees([(Q1g + Q2g) / kp[0], Q2g / kp[1]])
    error = np.degrees(runs['pd'].q[-1] - target)
    assert error == pytest.approx(expected, rel=0.02)
    assert np.all(np.abs(error) > 0.25)  # PD does not reach the target
    for k in (0, 1):
        assert settled_at(runs['pd'], k) == math.inf
        # PID: overshoot, by more than 5 % of the step on link 1
        assert past_target(runs['pid'], k) > 0.05 * abs(step[k])
        # Q: no overshoot worth the name (< 0.05 % of the step), no offset, faster
        assert past_target(runs['q'], k) < 5e-4 * abs(step[k])
        assert abs(np.degrees(runs['q'].q[-1, k] - target[k])) < 0.01
        assert settled_at(runs['q'], k) < settled_at(runs['pid'], k)


def test_the_table_comes_first_and_figures_as_pdf(article, tmp_path):
    """The impact table is printed before the first figure is drawn; --format pdf writes
    every figure as a PDF (and the report links them)."""
    d, _, _ = article
    out = tmp_path / 'pdf'
    ana = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'analyze', str(d / 'paper.mcap')]
        + ['--out', str(out), '--laws', 'pd', '--format', 'pdf'],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    assert ana.returncode == 0, ana.stdout
    text = ana.stdout
    assert text.index('impact table (15 impacts)') < text.index('limit cycle reached')
    assert text.index('limit cycle reached') < text.index('figure 1/10')
    assert text.index('figure 1/10') < text.index('wrote ')
    names = [name.replace('.png', '.pdf') for name in FIGURES]
    for name in names:
        assert (out / name).read_bytes()[:5] == b'%PDF-', name
    assert not list(out.glob('*.png'))
    report = (out / 'report.md').read_text(encoding='utf-8')
    assert all(f'({name})' in report for name in names)


def test_a_recording_in_which_the_arm_struck_nothing_says_so(tmp_path):
    """/impact_report recorded, without a message: 'no impacts', and why, not a hint to
    record the trace."""
    from impact_arm.io.mcap_ros2 import Ros2McapWriter, iter_raw, topics_info

    src = small_recording(tmp_path / 'small.mcap')
    path = tmp_path / 'quiet.mcap'
    with Ros2McapWriter(path) as w:
        for topic, ti in topics_info(src).items():
            w.add_topic(topic, ti.type_name, ti.qos or None)
        w.add_topic('/impact_report', 'std_msgs/msg/String')
        for m in iter_raw(src):
            w.write(m.topic, m.data, m.log_time_ns)
    ana = cli('analyze', path, '--out', tmp_path / 'out', '--laws', '', cwd=tmp_path)
    assert ana.returncode == 0, ana.stderr
    assert f'no impacts in {path}: the arm struck no surface' in ana.stdout
    assert 'has no impact to show' in ana.stdout
    assert 'impact-arm simulate --scene SCENE' not in ana.stdout


def test_the_elastic_phase_is_drawn_from_a_fine_grid_of_the_integrators_output(article):
    """Impact 1's elastic phase, which its trace holds as one step (contact to 1.9 δc), on
    80 grid points: it starts with the normal velocity before impact as its rate (δ̇ = -v_y,
    nothing else moves the tip into the surface at first), ends on 1.9 δc of the scene's
    constants after the reported elastic duration, and its force follows Hertz in time."""
    from impact_arm.physics.contact import YIELD_ONSET_FACTOR
    from impact_arm.physics.model import ArmModel
    from impact_arm.tools import analysis

    d, _, _ = article
    run = analysis.load(d / 'paper.mcap')
    record = run.impacts[0]
    curve = analysis.elastic_curve(run.scene, record)
    assert curve is not None and curve.end == 'yield' and len(curve.t) >= 80
    columns, rows = run.traces[0]
    phase = rows[:, columns.index('phase')]
    assert np.count_nonzero(phase == 1) <= 2  # what the trace alone would draw: a segment
    assert curve.t[-1] - curve.t[0] == pytest.approx(record.phase_durations[0], rel=1e-6)
    c = ArmModel(run.scene).surfaces[0].constants
    assert curve.delta[-1] == pytest.approx(YIELD_ONSET_FACTOR * c.delta_c, rel=1e-6)
    rate = np.diff(curve.delta) / np.diff(curve.t)
    assert rate[0] == pytest.approx(-record.v_before[1], rel=1e-4)
    # at a nearly constant rate δ ∝ t, so F ∝ t^1.5: half way in time the force is
    # 0.5^1.5 = 0.354 of the end's, where the straight segment between the two step ends
    # would give 0.5
    middle = np.interp(0.5 * (curve.t[0] + curve.t[-1]), curve.t, curve.force)
    assert middle / curve.force[-1] == pytest.approx(0.5**1.5, rel=0.02)
    # Hertz (eq. 11): F = 4/3 E* sqrt(R) δ^(3/2)
    assert curve.force == pytest.approx(4 / 3 * c.E * math.sqrt(c.R) * curve.delta**1.5)


def test_an_empty_or_truncated_file_is_named_with_what_is_wrong(article, tmp_path):
    """One line naming the file and the fault, from every command that reads recordings."""
    d, _, _ = article
    whole = (d / 'paper.mcap').read_bytes()
    empty, cut = tmp_path / 'empty.mcap', tmp_path / 'cut.mcap'
    empty.write_bytes(b'')
    cut.write_bytes(whole[: len(whole) // 3])  # a recorder killed mid-write, unrecovered
    for path, fault in (
        (empty, 'empty file (0 bytes)'),
        (cut, f'truncated MCAP file: {len(whole) // 3} bytes ending without the MCAP footer'),
    ):
        for argv in (
            ['analyze', path],
            ['animate', path],
            ['fit', path, '--param', 'surfaces[0].mu=0.05:1'],
            ['replay', path],
        ):
            bad = cli(*argv, cwd=tmp_path)
            lines = bad.stderr.strip().splitlines()
            assert bad.returncode == 2 and len(lines) == 1, bad.stderr
            assert path.name in lines[0] and fault in lines[0], lines[0]


@pytest.fixture(scope='module')
def three_link(tmp_path_factory):
    """A live-like recording of the three-link arm (config/three_link.yaml): its offline
    recording without /impact_trace, as the simulator node records none."""
    d = tmp_path_factory.mktemp('three_link')
    scene = os.path.join(CONFIG, 'three_link.yaml')
    sim = cli('simulate', '--scene', scene, '--mcap', d / 'offline.mcap', cwd=d)
    assert sim.returncode == 0, sim.stderr
    return d, without_trace(d / 'offline.mcap', d / 'live.mcap')


def test_a_three_link_live_recording_gets_every_links_figures(three_link):
    """Figures 5, 6 and 8-11 of a live three-link recording: Figure 5 one portrait per link
    (the article's (q1, q2, q̇1), (q1, q2, q̇2), then (q2, q3, q̇3)), Figure 6 one row of
    sections per link, the impact integrated again from its report (the rates at contact
    from its tip velocity and link energies) with all three links' energies, and its points
    those of the offline trace of the same impact."""
    import matplotlib

    matplotlib.use('Agg')
    from impact_arm.tools import analysis, figures

    d, live = three_link
    ana = cli('analyze', live, '--out', d / 'out', '--laws', '', '--no-animation', cwd=d)
    assert ana.returncode == 0, ana.stderr
    assert 'impact 1 re-integrated from /impact_report' in ana.stdout
    for name in FIGURES[2:4] + FIGURES[5:]:
        assert png_size(d / 'out' / name) == FIGURE_SIZE, name
    rows = np.loadtxt(d / 'out' / 'poincare_qd3_zero.csv', delimiter=',', skiprows=1)
    assert rows.shape[1] == 5 and len(rows) >= 5  # t, q1, q2, q3, direction

    run = analysis.load(live)
    deg = np.degrees
    portraits = [ax for ax in figures.fig5_phase_portraits(run, d).axes]
    assert len(portraits) == 3
    for k, (ax, (a, b)) in enumerate(zip(portraits, [(0, 1), (0, 1), (1, 2)])):
        (line,) = ax.get_lines()
        x, y, z = line.get_data_3d()
        assert np.array_equal(x, deg(run.q[:, a])) and np.array_equal(y, deg(run.q[:, b]))
        assert np.array_equal(z, deg(run.qd[:, k])), k
    sections = {k: analysis.poincare(run.t, run.q, run.qd, k) for k in range(3)}
    maps = figures.fig6_poincare(run, sections, d)
    for k in range(3):
        rows = sections[k]
        assert rows.shape[1] == 5 and np.all(np.abs(np.interp(rows[:, 0], run.t, run.qd[:, k])) < 1)
        a, b = figures.angle_pair(k)
        for j, direction in enumerate((-1.0, 1.0)):
            ax = maps.axes[2 * k + j]
            assert ax.get_xlabel() == f'q{a + 1} [deg]' and ax.get_title().startswith(
                f'({"abcdef"[2 * k + j]}) q̇{k + 1} = 0'
            )
            points = ax.collections[0].get_offsets()
            mine = rows[rows[:, -1] == direction]
            assert np.allclose(points, deg(mine[:, [1 + a, 1 + b]]))

    (columns, points, record, note), _ = analysis.impact_points(run, 1)
    (_, trace_rows, _, trace_note), _ = analysis.impact_points(analysis.load(d / 'offline.mcap'), 1)
    assert note and not trace_note
    assert [c for c in columns if c.startswith('T')] == ['T1', 'T2', 'T3']
    assert points.shape == trace_rows.shape
    # the same points where the steps agree: the offline run also stops its steps at each
    # sample instant (1 ms), which the re-integration does not know of, so the few steps
    # around an instant inside the impact fall elsewhere
    same = np.abs(points[:, 0] - trace_rows[:, 0]) < 1e-9
    assert same.mean() > 0.8
    assert points[same] == pytest.approx(trace_rows[same], rel=1e-4, abs=1e-6)
    energies = figures.fig11_kinetic_energy((columns, points, record, note), d)
    assert [ax.get_title().split(':')[0] for ax in energies.axes] == [
        '(a) link 1',
        '(b) link 2',
        '(c) link 3',
        '(d) total',
    ]
    for i, ax in enumerate(energies.axes[:3]):
        drawn = np.concatenate([line.get_ydata() for line in ax.get_lines()])
        assert set(drawn) <= set(points[:, columns.index(f'T{i + 1}')])
