"""Studies: overrides by key path, the event-only run API, sweep specs, resumable Parquet
tables, local worker processes and a real Dask cluster giving the same table."""

import os
import signal
import subprocess
import sys
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.physics.errors import SceneError
from impact_arm.physics.scene import parse_scene
from impact_arm.physics.simulate import run as run_scene
from impact_arm.calibration.study import Study, apply_overrides, parse_key_path

from impact_arm_bench.generators import key_paths
from scenes import paper_dict, scene_from

pa = pytest.importorskip('pyarrow')
from impact_arm.tools import sweep  # noqa: E402  (needs pyarrow: the studies extra)
from impact_arm.tools.sweep.rows import column_value  # noqa: E402
from impact_arm_bench.sweep import live_descendants  # noqa: E402


def _events(scene, **options):
    """The event-only run's impacts (a simulation error raised)."""
    result = run_scene(scene, samples=False, **options)
    if result.exception:
        raise result.exception
    return result.impacts, result.t_end, result.integrator, result.wall_time


LOOSE = {
    'integrator.preset': 'fast',
    'integrator.method': 'rosenbrock',
    'integrator.rtol': 1e-2,
    'integrator.atol': 1e-4,
    'integrator.contact_rtol': 3e-4,
}
LOOSE_NESTED = {
    ('integrator',): {
        'preset': 'fast',
        'method': 'rosenbrock',
        'rtol': 1e-2,
        'atol': 1e-4,
        'contact_rtol': 3e-4,
    }
}


def test_key_paths_and_overrides_change_only_their_value():
    assert parse_key_path('surfaces[0].mu') == ['surfaces', 0, 'mu']
    assert parse_key_path('materials.steel.E') == ['materials', 'steel', 'E']
    base = {'surfaces': [{'mu': 0.2, 'law': 'hertz'}], 'controller': {'kp': [1.0, 2.0]}}
    out = apply_overrides(
        base, {'surfaces[0].mu': 0.5, 'controller.kp[1]': 7.0, 'integrator.rtol': 1e-3}
    )
    assert out == {
        'surfaces': [{'mu': 0.5, 'law': 'hertz'}],
        'controller': {'kp': [1.0, 7.0]},
        'integrator': {'rtol': 1e-3},
    }
    assert base == {
        'surfaces': [{'mu': 0.2, 'law': 'hertz'}],
        'controller': {'kp': [1.0, 2.0]},
    }  # the base is not touched
    for bad, message in (
        ('surfaces[3].mu', 'surfaces has 1 entries'),
        ('controller.kp.x', 'controller.kp is not a mapping'),
        ('surfaces..mu', 'not a key path'),
    ):
        with pytest.raises(SceneError, match=message.replace('[', r'\[')):
            apply_overrides(base, {bad: 1.0})


def test_a_run_with_overrides_is_the_event_run_of_the_scene_they_describe():
    study = Study('paper', LOOSE)
    result = study.run({'surfaces[0].mu': 0.5, 'controller.kp': [800, 300], 'cycles': 4})
    expected = _events(
        scene_from(
            {
                **LOOSE_NESTED,
                ('surfaces',): [
                    {
                        'height': -1.0,
                        'law': 'elastoplastic',
                        'mu': 0.5,
                        'v_d': 0.02,
                        'material': 'steel',
                    }
                ],
                ('controller', 'kp'): [800.0, 300.0],
            },
            cycles=4,
        )
    )[0]
    assert not result.error and result.impacts == expected
    assert result.summary['impacts'] == 4
    assert result.summary['period'] == expected[3].t_contact - expected[2].t_contact
    assert result.summary['cor_kinematic'] == expected[3].cor_kinematic
    # the override did something: the article's gains give another motion
    assert study.run({'cycles': 4}).impacts != expected


def test_an_arm_striking_several_times_per_cycle_is_summarised_by_its_cycle():
    """The three-link arm strikes, rebounds and strikes twice more 2-3 ms apart in every
    cycle: the summary counts three impacts per cycle, and its period is the cycle's, not
    the few ms."""
    result = Study('three_link').run({'cycles': 10})
    times = [i.t_contact for i in result.impacts]
    assert not result.error and result.summary['impacts_per_cycle'] == 3
    assert 0 < result.summary['settled_after'] < len(times) - 3
    assert result.summary['period'] == times[-1] - times[-4]
    assert times[-1] - times[-2] < 0.01 < 0.4 < result.summary['period']
    # the article's arm: one impact per cycle, the period between the last two contacts
    paper = Study('paper', LOOSE).run({'cycles': 8}).summary
    assert paper['impacts_per_cycle'] == 1 and paper['settled_after'] > 0


def test_refused_values_and_simulation_errors_are_results_not_exceptions():
    study = Study('paper', LOOSE)
    refused = study.run({'surfaces[0].mu': -1.0})
    assert refused.error_kind == 'scene' and 'surfaces[0].mu = -1' in refused.error
    assert refused.summary['impacts'] == 0
    failed = study.run({'materials.steel.E': 1e13, 'cycles': 2})  # beyond the Etsion fit
    assert failed.error_kind == 'simulation' and 'residual indentation fit' in failed.error


def test_a_studys_runs_leave_nothing_behind_for_the_next():
    """A study validates what the runs' overrides leave alone once; a run after refused,
    failed and other runs is the run a fresh study gives, and each refusal its own."""

    def fresh(overrides):
        return Study('paper', {**LOOSE, 'cycles': 2}).run(overrides)

    def same(a, b):
        assert (a.impacts, a.error, a.error_kind) == (b.impacts, b.error, b.error_kind)
        assert {**a.summary, 'wall_time': 0} == {**b.summary, 'wall_time': 0}

    study = Study('paper', {**LOOSE, 'cycles': 2})
    a = {'surfaces[0].mu': 0.4, 'controller.kp[0]': 700.0}
    first = study.run(a)
    assert first.summary['impacts'] == 2
    surface = {'height': -1.0, 'law': 'elastoplastic', 'mu': 0.3, 'v_d': 0.02, 'material': 'steel'}
    runs = [
        {'gravity': 1},  # valid: an int where a number is expected
        {'gravity': True},  # equal to 1, but not a number
        {'controller.kd[0]': 5e4},  # a range across keys (closed-loop rate)
        {'controller.kp': [600.0]},  # one gain for two links
        {'materials.steel.E': 1e13},  # accepted; the simulation fails
        {'surfaces[0]': surface},
    ]
    for overrides in runs:
        same(study.run(overrides), fresh(overrides))
    surface['mu'] = -1.0  # the caller's own mapping, changed after it was run
    refused = study.run({'surfaces[0]': surface})
    assert 'surfaces[0].mu = -1' in refused.error
    same(refused, fresh({'surfaces[0]': surface}))
    same(study.run(a), first)
    same(first, fresh(a))


PATHS = [
    ''.join(f'[{k}]' if isinstance(k, int) else f'.{k}' if i else k for i, k in enumerate(path))
    for path in key_paths(paper_dict())
]
HOSTILE = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.integers(-3, 3),
    st.floats(allow_nan=True, allow_infinity=True),
    st.lists(st.floats(-1e3, 1e3), max_size=3),
    st.just({}),
)


@settings(
    max_examples=100, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck)
)
@given(st.data())
def test_a_studys_scenes_are_those_of_a_fresh_parse(data):
    """Whatever sequence of overrides, a study builds the scene, or gives the refusal, that
    validating the whole overridden data from scratch gives."""
    study = Study('paper')
    base = paper_dict()

    def outcome(build):
        try:
            return build()
        except SceneError as exc:
            return str(exc)

    for _ in range(data.draw(st.integers(1, 5), label='runs')):
        overrides = {}
        for _ in range(data.draw(st.integers(1, 3))):
            path = data.draw(st.sampled_from(PATHS))
            value = base
            for key in parse_key_path(path):
                value = value[key]
            if isinstance(value, float) and data.draw(st.booleans()):
                value *= data.draw(st.floats(0.5, 1.5))  # most runs are accepted
            elif data.draw(st.integers(0, 3)) == 0:
                value = data.draw(HOSTILE)
            overrides[path] = value
        expected = outcome(
            lambda: parse_scene(
                apply_overrides(study.data, overrides),
                origin=f'{study.origin} with overrides',
                path=study.path,
            )
        )
        got = outcome(lambda: study.scene(overrides))
        assert got == expected


def spec(tmp_path, **changes):
    data = {
        'scene': 'paper',
        'set': {**LOOSE, 'cycles': 3},
        'parameters': {
            'surfaces[0].mu': {'grid': [0.1, 0.5, 3]},
            'controller.kp[0]': {'lhs': [400.0, 800.0]},
        },
        'samples': 4,
        'seed': 3,
    }
    data.update(changes)
    return sweep.Spec(data, origin='test', base_dir=str(tmp_path))


def test_spec_runs_are_the_grid_times_seeded_latin_hypercube_samples(tmp_path):
    runs = spec(tmp_path).runs
    assert len(runs) == 12
    assert [r['surfaces[0].mu'] for r in runs[::4]] == [0.1, 0.30000000000000004, 0.5]
    kp = [r['controller.kp[0]'] for r in runs[:4]]
    # Latin hypercube: one draw in each quarter of the range
    assert sorted(int((k - 400.0) / 100.0) for k in kp) == [0, 1, 2, 3]
    assert spec(tmp_path).runs == runs and spec(tmp_path, seed=4).runs != runs
    with pytest.raises(sweep.SpecError, match=r'parameters.cycles grid = \[1, 2\]'):
        spec(tmp_path, parameters={'cycles': {'grid': [1, 2]}})
    with pytest.raises(sweep.SpecError, match='seeds is not a known key'):
        spec(tmp_path, seeds=1)


def test_a_failing_run_is_a_row_and_the_sweep_goes_on(tmp_path):
    s = spec(tmp_path, parameters={'surfaces[0].mu': {'list': [0.2, -1.0, 0.3]}})
    stats = sweep.execute(s, str(tmp_path / 'out'), workers=0, show_progress=False)
    assert stats == {**stats, 'runs': 3, 'ran': 3, 'failed': 1}
    runs = sweep.read_table(str(tmp_path / 'out')).to_pydict()
    assert runs['run'] == [0, 1, 2] and runs['impacts'] == [3, 0, 3]
    assert 'surfaces[0].mu = -1' in runs['error'][1] and not runs['error'][0]
    impacts = sweep.read_table(str(tmp_path / 'out'), 'impacts').to_pydict()
    assert impacts['run'] == [0, 0, 0, 2, 2, 2] and impacts['surfaces[0].mu'][-1] == 0.3


def test_a_typo_in_a_key_path_exits_non_zero_before_any_run(tmp_path, capsys):
    """surfaces[0].muu (and an index past the end) are refused at load with every distinct
    error, the command exits non-zero, and no run is made (no output directory)."""
    with pytest.raises(sweep.SpecError) as refused:
        spec(
            tmp_path,
            parameters={
                'surfaces[0].muu': {'grid': [0.1, 0.5, 3]},
                'controller.kp[2]': {'list': [400.0]},
                'controller.kd[0]': {'lhs': [50.0, 150.0]},
            },
        )
    text = str(refused.value)
    assert '2 key path(s)' in text and 'nothing was run' in text
    assert 'surfaces[0].muu is not a known key' in text and 'controller.kp has 2 entries' in text
    assert 'controller.kd[0]' not in text
    path = tmp_path / 'typo.yaml'
    path.write_text('scene: paper\nparameters:\n  surfaces[0].muu: {grid: [0.1, 0.5, 200]}\n')
    out = tmp_path / 'typo.sweep'
    from impact_arm.tools.cli import main

    assert main(['sweep', str(path), '--workers', '0', '--out', str(out)]) != 0
    assert 'surfaces[0].muu is not a known key' in capsys.readouterr().err
    assert not out.exists()


def test_a_sweep_with_failed_runs_exits_non_zero_listing_the_distinct_errors(tmp_path, capsys):
    path = tmp_path / 'bad.yaml'
    path.write_text(
        'scene: paper\nset: {cycles: 2, integrator.preset: fast}\n'
        'parameters:\n  surfaces[0].mu: {list: [0.2, -1.0, -1.0, 11.0]}\n'
    )
    from impact_arm.tools.cli import main

    assert main(['sweep', str(path), '--workers', '0', '--out', str(tmp_path / 'o')]) == 1
    err = capsys.readouterr().err
    assert '3 run(s) failed with 2 distinct error(s)' in err
    assert '2 x' in err and 'surfaces[0].mu = -1 is out of range' in err
    assert 'surfaces[0].mu = 11 is out of range' in err


def test_impact_rows_are_the_runs_records_whatever_their_overrides():
    """A chunk's impacts table holds each run's impact records, lists spread over key[i]
    columns, also when runs override different keys (their tables are joined by name)."""
    study = Study('paper', {**LOOSE, 'cycles': 2})
    items = [
        (0, {'surfaces[0].mu': 0.2}),
        (1, {'controller.kp': [700, 250]}),
        (2, {'surfaces[0].mu': 0.4}),
    ]
    rows = sweep.run_chunk('rows-test', study.data, {}, ('runs', 'impacts'), items)
    rows = rows['impacts'].sort_by([('run', 'ascending'), ('index', 'ascending')]).to_pylist()
    expected = []
    for index, overrides in items:
        for record in study.run(overrides).impacts:
            row = {'run': index, **{k: column_value(v) for k, v in overrides.items()}}
            for key, value in record.to_dict().items():  # the JSON's keys and lists
                row.update(
                    {f'{key}[{i}]': v for i, v in enumerate(value)}
                    if isinstance(value, list)
                    else {key: value}
                )
            expected.append(row)
    assert len(rows) == len(expected) == 6
    for row, want in zip(rows, expected):
        assert {k: v for k, v in row.items() if v is not None} == want


def without_wall(table):
    return table.drop_columns(['wall_time']) if 'wall_time' in table.column_names else table


def alive(pid):
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as f:
            return f.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except OSError:
        return False


def test_a_sweep_killed_with_sigkill_resumes_and_runs_every_run_exactly_once(tmp_path):
    # 400 runs: once warm, two workers finish ~120 runs/s here, so a test process that a
    # loaded CI machine deschedules for 0.3 s no longer finds 40 runs all done at the kill
    count = 400
    text = (
        'scene: paper\nset: {cycles: 3}\nparameters:\n'
        f'  controller.kp[0]: {{grid: [400, 800, {count}]}}\n'
    )
    path = tmp_path / 'kill.yaml'
    path.write_text(text)
    out = tmp_path / 'kill.sweep'
    child = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'impact_arm.tools.cli',
            'sweep',
            str(path),
            '--workers',
            '2',
            '--batch',
            '3',
            '--out',
            str(out),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and child.poll() is None:
        parts = [n for n in os.listdir(out / 'runs')] if (out / 'runs').exists() else []
        if len([n for n in parts if n.endswith('.parquet')]) >= 2:
            break
        time.sleep(0.005)
    workers = live_descendants(child.pid)
    child.send_signal(signal.SIGKILL)
    child.wait()
    # its worker processes follow it instead of computing runs nobody records
    deadline = time.monotonic() + 15
    while any(alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [pid for pid in workers if alive(pid)]
    for pid in left:  # don't leave them running if the check fails
        os.kill(pid, signal.SIGKILL)
    assert workers and not left, 'worker processes outlived the killed sweep'
    before = sweep.read_table(str(out)).column('run').to_pylist()
    assert 0 < len(before) < count, 'the sweep ended before it could be killed halfway'
    stats = sweep.execute(sweep.Spec.load(str(path)), str(out), workers=0, show_progress=False)
    assert stats['skipped'] == len(before) and stats['ran'] == count - len(before)
    runs = sweep.read_table(str(out))
    assert runs.column('run').to_pylist() == list(range(count))
    fresh = tmp_path / 'fresh'
    sweep.execute(sweep.Spec.load(str(path)), str(fresh), workers=0, show_progress=False)
    assert without_wall(runs).equals(without_wall(sweep.read_table(str(fresh))))
    assert sweep.read_table(str(out), 'impacts').equals(sweep.read_table(str(fresh), 'impacts'))


def test_an_impacts_part_without_its_runs_part_is_redone_not_duplicated(tmp_path):
    s = spec(tmp_path)
    out = str(tmp_path / 'out')
    sweep.execute(s, out, workers=0, batch=4, show_progress=False)
    runs_dir = os.path.join(out, 'runs')
    last = sorted(os.listdir(runs_dir))[-1]
    os.remove(os.path.join(runs_dir, last))  # killed between the two renames
    sweep.ResultStore(out, s)  # opening the store drops the orphan
    assert sorted(os.listdir(os.path.join(out, 'impacts'))) == sorted(os.listdir(runs_dir))
    stats = sweep.execute(s, out, workers=0, show_progress=False)
    assert stats['ran'] == 4
    impacts = sweep.read_table(out, 'impacts').to_pydict()
    assert len(impacts['run']) == 12 * 3
    with pytest.raises(sweep.SpecError, match='another sweep spec'):
        sweep.execute(spec(tmp_path, seed=9), out, workers=0, show_progress=False)


def test_worker_processes_and_a_dask_cluster_give_the_local_table(tmp_path):
    distributed = pytest.importorskip('distributed')
    s = spec(tmp_path, samples=2)
    local, pool, dask = (str(tmp_path / name) for name in ('local', 'pool', 'dask'))
    sweep.execute(s, local, workers=0, show_progress=False)
    sweep.execute(s, pool, workers=2, show_progress=False)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        sweep.execute(s, dask, cluster=cluster.scheduler_address, show_progress=False)
    for table in ('runs', 'impacts'):
        expected = without_wall(sweep.read_table(local, table))
        assert expected.num_rows >= 6
        for other in (pool, dask):
            assert without_wall(sweep.read_table(other, table)).equals(expected), other


def test_sweep_plot_writes_a_png(tmp_path):
    s = spec(tmp_path, samples=2)
    out = str(tmp_path / 'out')
    sweep.execute(s, out, workers=0, show_progress=False)
    path = sweep.plot(out, 'cor_kinematic', 'surfaces[0].mu', 'controller.kp[0]')
    assert '[' not in os.path.basename(path)  # a name a shell takes as it is
    assert sweep.axis_label('controller.kp[0]') == 'controller.kp[0] [N m/rad]'
    assert sweep.axis_label('materials.steel.E') == 'materials.steel.E [Pa]'
    assert sweep.axis_label('F_max') == 'F_max [N]'
    assert sweep.axis_label('surfaces[0].mu') == 'surfaces[0].mu [-]'
    with open(path, 'rb') as f:
        assert f.read(8) == b'\x89PNG\r\n\x1a\n'
    with pytest.raises(sweep.SpecError, match="x 'mu' is not a column"):
        sweep.plot(out, 'cor_kinematic', 'mu')
    from impact_arm.tools.cli import main

    png = str(tmp_path / 'f_max.png')
    assert (
        main(
            [
                'sweep',
                'plot',
                out,
                '--table',
                'impacts',
                '--impact',
                '1',
                '--metric',
                'F_max',
                '--x',
                'controller.kp[0]',
                '-o',
                png,
            ]
        )
        == 0
    )
    assert os.path.getsize(png) > 1000


def test_simulate_no_samples_prints_the_sampled_runs_impacts(tmp_path, capsys):
    from impact_arm.physics.scene import load_scene
    from impact_arm.physics.simulate import run
    from impact_arm.tools.cli import main

    out = tmp_path / 'fast.json'
    assert main(['simulate', '--no-samples', '--preset', 'fast', '--json', str(out)]) == 0
    import json

    fast = json.loads(out.read_text())
    sampled = run(load_scene('paper'), preset='fast')
    assert fast['run']['impacts'] == 15 and fast['run']['q1_range_deg'] == []
    for a, b in zip(fast['impacts'], sampled.impacts):  # the JSON's records, the run's
        assert a['t_contact'] == pytest.approx(b.t_contact, rel=1e-6)
        assert a['F_max'] == pytest.approx(b.F_max, rel=1e-4)  # rtol 1e-5 both
    assert '15 cycles completed' in capsys.readouterr().out
    assert main(['simulate', '--no-samples', '--control-rate', '500']) == 2
    assert 'sampled controller (500 Hz)' in capsys.readouterr().err
