"""Validation against measured drops (calibration/drops.py, ``bench validate``) and the
rigid-body impact laws it compares with (physics/bodies/impulse.py), on drops this project
simulates itself and writes in the recorded drops' CSV format."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from impact_arm.calibration.drops import (
    HEADER,
    Model,
    body_model,
    find_impacts,
    fit,
    normal_cor,
    on_one_floor,
    predict,
    read_drop,
)
from impact_arm.physics.bodies.impulse import Restitution, point_impact
from impact_arm.physics.bodies.model import simulate_body
from impact_arm.physics.bodies.scene import BodyState
from impact_arm.physics.kinds import EventKind
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
SIDE = 0.06
DT = 0.004
TRUE = {'mu': 0.25, 'yield_speed': 0.01, 'corner_radius': 0.002}


# ------------------------------------------------------------------ rigid-body impact laws
@pytest.mark.parametrize('law', list(Restitution))
def test_without_friction_both_laws_reverse_the_normal_velocity_by_e(law):
    k2 = SIDE**2 / 6
    rx, rz = 0.021, -0.034
    after = point_impact(0.4, -2.0, 7.0, rx, rz, k2, 0.0, 0.6, law)
    un_before, un_after = -2.0 + 7.0 * rx, after.vz + after.omega * rx
    assert un_after == pytest.approx(-0.6 * un_before, rel=1e-12)
    assert after.vx == 0.4
    # angular momentum about the contact point is kept: the impulse passes through it
    before_l = k2 * 7.0 - (rx * -2.0 - rz * 0.4)
    after_l = k2 * after.omega - (rx * after.vz - rz * after.vx)
    assert after_l == pytest.approx(before_l, rel=1e-12)


def test_elastic_frictionless_impact_keeps_the_energy():
    k2 = SIDE**2 / 6
    after = point_impact(0.4, -2.0, 7.0, -0.03, -0.03, k2, 0.0, 1.0, Restitution.POISSON)
    before_e = 0.4**2 + 2.0**2 + k2 * 7.0**2
    assert after.vx**2 + after.vz**2 + k2 * after.omega**2 == pytest.approx(before_e, rel=1e-12)


@pytest.mark.parametrize('law', list(Restitution))
def test_high_friction_stops_the_slip_and_it_stays_stopped(law):
    k2 = SIDE**2 / 6
    rx, rz = 0.02, -0.035
    after = point_impact(0.3, -2.0, 0.0, rx, rz, k2, 5.0, 0.5, law)
    assert after.stuck
    assert after.vx - after.omega * rz == pytest.approx(0.0, abs=1e-12)


def test_sliding_friction_takes_mu_times_the_normal_impulse():
    k2 = SIDE**2 / 6
    after = point_impact(3.0, -1.0, 0.0, 0.0, -0.03, k2, 0.1, 0.5, Restitution.NEWTON)
    assert not after.stuck
    assert after.vx - 3.0 == pytest.approx(-0.1 * after.normal_impulse, rel=1e-12)


# ---------------------------------------------------------------- drops this project makes
def simulated_drop(
    seed: int, params: dict, duration: float = 0.6
) -> tuple[np.ndarray, list[float]]:
    """A drop of the square as our model gives it, sampled every DT like the recordings:
    positions exact, velocities backward differences (as the recordings' are); and the times
    its corners touched the floor."""
    rng = np.random.default_rng(seed)
    model = body_model(Model.OURS, params, SIDE)
    start = BodyState(
        0.0,
        rng.uniform(0.12, 0.16),
        rng.uniform(-math.pi, math.pi),
        rng.uniform(-0.6, 0.6),
        rng.uniform(-2.2, -1.5),
        rng.uniform(-10, 10),
    )
    run = simulate_body(model, start, duration, trace=200_000)
    steps = run.trace
    times = np.arange(int(duration / DT)) * DT
    rows = np.zeros((len(times), 6))
    for k, t in enumerate(times):
        last = steps[np.searchsorted(steps[:, 0], t, side='right') - 1]
        s = t - last[0]  # ballistic from the last step (no contact starts between steps)
        x, z, th, vx, vz, w = last[1:]
        rows[k, :3] = (x + vx * s, z + vz * s - 9.81 * s * s / 2, th + w * s)
    rows[1:, 3:] = np.diff(rows[:, :3], axis=0) / DT
    rows[0, 3:] = rows[1, 3:]
    return rows, [e.t for e in run.events if e.kind == EventKind.CONTACT]


def write_drop(path: str, rows: np.ndarray) -> None:
    with open(path, 'w', encoding='utf-8') as f:
        f.write(','.join(HEADER) + '\n')
        for row in rows:
            f.write(','.join(repr(float(v)) for v in row) + '\n')


@pytest.fixture(scope='module')
def drops(tmp_path_factory):
    folder = tmp_path_factory.mktemp('drops')
    contacts = {}
    for seed in range(12):
        rows, contacts[f'traj_{seed + 1}.csv'] = simulated_drop(seed, TRUE)
        write_drop(str(folder / f'traj_{seed + 1}.csv'), rows)
    return str(folder), contacts


def _impacts(folder: str) -> list:
    found = []
    for name in sorted(os.listdir(folder)):
        path = os.path.join(folder, name)
        found += find_impacts(read_drop(path), DT, SIDE, path)
    return found


def test_impacts_of_simulated_drops_are_found_on_the_floor_and_predicted(drops):
    folder, contacts = drops
    impacts, floor = on_one_floor(_impacts(folder), SIDE)
    assert len(impacts) >= 12  # every drop's first impact at least
    # found when a corner touched, to a small part of a row (an impact of two corners in
    # quick succession is found between them: where the fitted flights meet)
    offsets = [min(abs(i.t - t) for t in contacts[i.file]) for i in impacts]
    assert np.median(offsets) < 0.1 * DT
    assert np.percentile(offsets, 75) < 0.3 * DT
    # the sharp corner of a rounded one reaches past the floor by up to r (sqrt 2 - 1)
    assert -TRUE['corner_radius'] * (math.sqrt(2) - 1) <= floor < 0
    # the true model predicts what the fits of the sampled record measured
    predicted = predict(Model.OURS, TRUE, impacts, SIDE)
    measured = np.array([i.post for i in impacts])
    error = np.abs(predicted - measured)
    assert np.median(error[:, :2]) < 0.02
    assert np.median(error[:, 2]) < 0.02 * 2 / SIDE
    cor = [normal_cor(i, m, SIDE) for i, m in zip(impacts, measured, strict=True)]
    assert 0.1 < np.median(cor) < 1.0


def test_a_fit_on_simulated_drops_beats_the_wrong_parameters(drops):
    impacts, _ = on_one_floor(_impacts(drops[0]), SIDE)
    result = fit(Model.CONSTANT_COR, impacts, SIDE, evaluations=25)
    assert result.params['mu'] == pytest.approx(TRUE['mu'], abs=0.08)
    wrong = dict(result.params, mu=0.02, e=0.95)
    measured = np.array([i.post for i in impacts])
    good = np.abs(predict(Model.CONSTANT_COR, result.params, impacts, SIDE) - measured)
    bad = np.abs(predict(Model.CONSTANT_COR, wrong, impacts, SIDE) - measured)
    assert np.median(good) < 0.5 * np.median(bad)


def test_a_drop_file_with_a_wrong_header_is_refused(tmp_path):
    path = tmp_path / 'bad.csv'
    path.write_text('x,y\n1,2\n')
    with pytest.raises(ValueError, match='header must be x,z,th,vx,vz,vth'):
        read_drop(str(path))


def test_bench_validate_writes_every_test_impact_in_the_issue_shape(drops, tmp_path):
    out = tmp_path / 'v.json'
    result = subprocess.run(
        [
            sys.executable,
            '-m',
            'impact_arm.tools.cli',
            'bench',
            'validate',
            '--train',
            drops[0],
            '--json',
            str(out),
            '--evaluations',
            '9',
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    assert 'ours' in result.stdout and 'newton' in result.stdout
    data = json.loads(out.read_text())
    assert set(data['fitted']) == {'ours', 'newton', 'poisson', 'constant_cor'}
    entry = data['drops'][0]
    assert set(entry) == {'file', 'impact', 't', 'pre', 'measured', 'predicted'}
    assert set(entry['predicted']) == {'ours', 'newton', 'poisson', 'constant_cor'}
    test_files = {f'traj_{n}.csv' for n in (2, 4, 6, 8, 10, 12)}  # every second, natural order
    assert {d['file'] for d in data['drops']} <= test_files
    assert all(len(d['measured']) == 3 and d['impact'] >= 1 for d in data['drops'])


@pytest.mark.parametrize(
    'extra, words',
    [
        (['--train', 'nope'], "--train = 'nope' is not a folder"),
        (['--train', '.', '--json', 'no/such/folder/v.json'], 'its folder does not exist'),
        (['--train', '.', '--side', '-1'], '--side = -1 is out of range'),
    ],
)
def test_bench_validate_refuses_bad_arguments_in_one_line(extra, words):
    result = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'bench', 'validate', *extra],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert result.returncode == 2
    assert words in result.stderr and len(result.stderr.strip().splitlines()) == 1
