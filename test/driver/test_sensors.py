"""Hardware-like sensing (driver/sensors.py, the scene's ``sensors`` section): the simulated
driver reports quantised, noisy, finite-difference or filtered, late readings of the state,
and the physics underneath is the same."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.driver.arm import SimulatedArm
from impact_arm.driver.sensors import Sensors, latency_periods, sensed_series
from impact_arm.physics.errors import SceneError
from impact_arm.physics.scene import SENSORS, RateReading, SensorSpec
from scenes import scene_from

RATE = 1000.0


def run_arm(sensors=None, periods=400, torque=(30.0, -8.0), rate=RATE):
    """The article's arm released under a constant torque (no contact within ``periods``):
    the published ticks and the true state of each period, joint space."""
    scene = scene_from(sensors=sensors) if sensors is not None else scene_from()
    arm = SimulatedArm(scene, rate, trace=False)
    arm.apply(torque)
    ticks, truth = [arm.sample()], []
    n = arm.n
    truth.append(_true(arm, n))
    for _ in range(periods):
        ticks.append(arm.step())
        truth.append(_true(arm, n))
    return ticks, truth


def _true(arm, n):
    from impact_arm.contract import to_joint_space

    y = arm.integrator.state.y
    return to_joint_space(y[:n].tolist()), to_joint_space(y[n : 2 * n].tolist())


def series(ticks, field):
    return np.array([getattr(t, field) for t in ticks], float)


def test_ideal_sensors_publish_the_exact_state():
    ticks, truth = run_arm(periods=50)
    assert series(ticks, 'position').tolist() == [q for q, _ in truth]
    assert series(ticks, 'velocity').tolist() == [qd for _, qd in truth]


def test_positions_are_quantised_to_the_encoder_step():
    counts = 4096
    step = 2 * math.pi / counts
    ticks, truth = run_arm({'counts_per_revolution': counts}, periods=300)
    q = series(ticks, 'position')
    # every published position is a whole number of counts, the nearest to the true angle
    counts_read = q / step
    assert np.max(np.abs(counts_read - np.round(counts_read))) < 1e-6
    assert np.max(np.abs(q - np.array([p for p, _ in truth]))) <= step / 2 * (1 + 1e-9)
    # the smallest change a joint shows is one count
    moves = np.abs(np.diff(q, axis=0))
    assert np.min(moves[moves > 0]) == pytest.approx(step, rel=1e-9)


def test_noise_has_the_stated_deviation_and_is_reproducible():
    sigma_q, sigma_qd, sigma_e = 1e-3, 0.05, 0.2
    spec = {'position_noise': sigma_q, 'rate_noise': sigma_qd, 'effort_noise': sigma_e, 'seed': 7}
    ticks, truth = run_arm(spec, periods=2000)
    again, _ = run_arm(spec, periods=2000)
    assert series(ticks, 'position').tolist() == series(again, 'position').tolist()
    errors = {
        'position': (series(ticks, 'position') - np.array([q for q, _ in truth]), sigma_q),
        'velocity': (series(ticks, 'velocity') - np.array([qd for _, qd in truth]), sigma_qd),
    }
    ideal, _ = run_arm(periods=2000)
    errors['effort'] = (series(ticks, 'effort') - series(ideal, 'effort'), sigma_e)
    for name, (err, sigma) in errors.items():
        # 2 x 2001 draws: the sample deviation is within 5 standard errors (sigma / sqrt(2N))
        n = err.size
        assert abs(np.std(err) - sigma) < 5 * sigma / math.sqrt(2 * n), name
        assert abs(np.mean(err)) < 5 * sigma / math.sqrt(n), name
    other, _ = run_arm({**spec, 'seed': 8}, periods=50)
    assert series(other, 'position').tolist() != series(ticks, 'position')[:51].tolist()


def test_difference_rates_are_the_differences_of_the_published_positions():
    ticks, truth = run_arm(
        {'counts_per_revolution': 1 << 17, 'position_noise': 1e-5, 'rate': 'difference'}
    )
    q, qd = series(ticks, 'position'), series(ticks, 'velocity')
    assert qd[0].tolist() == [0.0, 0.0]
    assert qd[1:].tolist() == ((q[1:] - q[:-1]) * RATE).tolist()  # bit for bit
    # and they follow the true rates (half a period behind, on the average)
    true_qd = np.array([v for _, v in truth])
    mid = 0.5 * (true_qd[1:] + true_qd[:-1])
    assert np.median(np.abs(qd[1:] - mid)) < 0.05


def test_filtered_rates_are_a_first_order_low_pass_of_the_differences():
    cutoff = 50.0
    spec = {'counts_per_revolution': 1 << 14, 'rate': 'filtered', 'rate_cutoff': cutoff}
    ticks, _ = run_arm(spec, periods=300)
    q, qd = series(ticks, 'position'), series(ticks, 'velocity')
    diff = np.vstack([np.zeros(2), (q[1:] - q[:-1]) * RATE])
    alpha = 1 - math.exp(-2 * math.pi * cutoff / RATE)
    y = np.zeros(2)
    expected = []
    for d in diff:
        y = y + alpha * (d - y)
        expected.append(y)
    assert np.allclose(qd, expected, rtol=0, atol=1e-9)
    # smoother than the differences: the quantisation steps are filtered out
    assert np.std(np.diff(qd[100:, 0])) < 0.5 * np.std(np.diff(diff[100:, 0]))


@pytest.mark.parametrize('latency, periods', [(0.003, 3), (0.0025, 3), (0.001, 1)])
def test_state_latency_shifts_the_published_states_by_whole_periods(latency, periods):
    ideal, _ = run_arm(periods=200)
    late, _ = run_arm({'state_latency': latency}, periods=200)
    assert latency_periods(latency, RATE) == periods
    for field in ('position', 'velocity'):
        a, b = series(ideal, field), series(late, field)
        assert b[periods:].tolist() == a[:-periods].tolist()
        assert (b[:periods] == a[0]).all()  # the first reading until the delay has passed
    # the stamps, the efforts and the physics are not delayed
    assert series(late, 't').tolist() == series(ideal, 't').tolist()
    assert series(late, 'effort').tolist() == series(ideal, 'effort').tolist()


def test_effort_and_wrench_latency_delay_their_own_readings():
    scene = scene_from(sensors={'effort_latency': 0.002, 'wrench_latency': 0.001})
    arm = SimulatedArm(scene, RATE, trace=False)
    ideal = SimulatedArm(scene_from(), RATE, trace=False)
    late_ticks, ideal_ticks = [], []
    for k in range(120):
        tau = [10.0 * math.sin(k / 7.0), 2.0 * k / 120]  # a torque that changes every period
        for a, out in ((arm, late_ticks), (ideal, ideal_ticks)):
            a.apply(tau)
            out.append(a.step())
    e_late, e = series(late_ticks, 'effort'), series(ideal_ticks, 'effort')
    assert e_late[2:].tolist() == e[:-2].tolist()
    w_late, w = series(late_ticks, 'wrench'), series(ideal_ticks, 'wrench')
    assert w_late[1:].tolist() == w[:-1].tolist()
    assert series(late_ticks, 'position').tolist() == series(ideal_ticks, 'position').tolist()


def test_a_repeated_sample_in_one_period_repeats_the_reading():
    arm = SimulatedArm(scene_from(sensors={'position_noise': 1e-3}), RATE, trace=False)
    first = arm.sample()
    assert arm.sample().position == first.position  # the lockstep driver republishes
    stepped = arm.step()
    assert arm.sample().position == stepped.position != first.position
    arm.reset()
    assert arm.sample().position == first.position  # the seed's sequence again


def test_the_series_helper_is_the_drivers_chain():
    spec = SensorSpec(
        counts_per_revolution=2048, position_noise=1e-4, rate=RateReading.DIFFERENCE, seed=3
    )
    ticks, truth = run_arm(
        {'counts_per_revolution': 2048, 'position_noise': 1e-4, 'rate': 'difference', 'seed': 3},
        periods=100,
    )
    ideal, _ = run_arm(periods=100)
    q, qd, _, _ = sensed_series(
        spec,
        RATE,
        series(ideal, 'position'),
        series(ideal, 'velocity'),
        series(ideal, 'effort'),
        series(ideal, 'wrench'),
    )
    assert q.tolist() == series(ticks, 'position').tolist()
    assert qd.tolist() == series(ticks, 'velocity').tolist()


@pytest.mark.parametrize(
    'section, key',
    [
        ({'counts_per_revolution': 0}, 'sensors.counts_per_revolution'),
        ({'counts_per_revolution': 1.5}, 'sensors.counts_per_revolution'),
        ({'position_noise': -1e-3}, 'sensors.position_noise'),
        ({'position_noise': float('nan')}, 'sensors.position_noise'),
        ({'rate': 'kalman'}, 'sensors.rate'),
        ({'rate': 'filtered'}, 'sensors.rate_cutoff'),
        ({'rate_cutoff': 10.0}, 'sensors.rate_cutoff'),
        ({'rate': 'difference', 'rate_noise': 0.1}, 'sensors.rate_noise'),
        ({'state_latency': 1.5}, 'sensors.state_latency'),
        ({'effort_latency': float('inf')}, 'sensors.effort_latency'),
        ({'seed': -1}, 'sensors.seed'),
        ({'latency': 0.001}, 'sensors.latency'),
    ],
)
def test_bad_sensor_keys_are_refused_in_one_line_naming_the_key(section, key):
    with pytest.raises(SceneError) as err:
        scene_from(sensors=section)
    message = str(err.value)
    assert key in message and '\n' not in message


def test_sensor_keys_are_override_keys():
    from impact_arm.calibration.study import Study

    scene = Study('paper').scene({'sensors.counts_per_revolution': 1 << 17, 'sensors.seed': 4})
    assert scene.sensors.counts_per_revolution == 1 << 17 and scene.sensors.seed == 4
    assert Study('paper').scene().sensors == SensorSpec() and SensorSpec().ideal


def test_sensors_refuse_a_bad_rate():
    with pytest.raises(ValueError, match='rate'):
        Sensors(SensorSpec(), 0.0, 2)


# ------------------------------------------------------------------ synthetic recordings
def test_synthetic_recordings_carry_the_scenes_sensor_effects():
    from impact_arm.io.synthetic import synthetic_recording

    exact = synthetic_recording(cycles=1, noise={})
    late = synthetic_recording(
        cycles=1,
        overrides={
            'sensors.effort_latency': 0.002,
            'sensors.rate': 'difference',
            'sensors.counts_per_revolution': 1 << 16,
        },
    )
    assert late.effort[2:].tolist() == exact.effort[:-2].tolist()
    step = 2 * math.pi / (1 << 16)
    counts = late.position / step
    assert np.max(np.abs(counts - np.round(counts))) < 1e-6
    rate = 1000.0  # the publish rate
    assert late.velocity[1:].tolist() == ((late.position[1:] - late.position[:-1]) * rate).tolist()


def test_driver_recordings_read_through_the_same_sensors():
    from impact_arm.io.synthetic import driver_recording

    rec = driver_recording(cycles=1, overrides={'sensors.rate': 'difference'}, t_max=0.3)
    rate = 1000.0  # the driver's rate
    assert rec.velocity[1:].tolist() == ((rec.position[1:] - rec.position[:-1]) * rate).tolist()


# --------------------------------------------------------------------------- fuzzing
SENSOR_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=6),
    st.sampled_from(['exact', 'difference', 'filtered']),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=0, max_value=1.5),
    st.sampled_from([5e-324, -0.0, 1e308, 1e-300, 2.0**64, 1e-3, 1e6]),
)


@settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck)
)
@given(st.dictionaries(st.sampled_from(sorted(SENSORS) + ['latency']), SENSOR_VALUES, max_size=6))
def test_fuzzed_sensor_sections_are_refused_in_one_line_or_read_finite(section):
    try:
        scene = scene_from(sensors=section)
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    # accepted: the chain turns finite states into finite readings at any publish rate
    for rate in (1.0, 1000.0, 1e6):
        k = np.arange(50)[:, None]
        q, qd, tau, w = sensed_series(
            scene.sensors,
            rate,
            np.hstack([1e-3 * k, -2e-3 * k]),
            np.full((50, 2), 3.0),
            np.full((50, 2), -20.0),
            np.full((50, 2), 100.0),
        )
        assert all(np.isfinite(x).all() for x in (q, qd, tau, w)), (section, rate)


# ------------------------------------------------------------------------------- over DDS
def test_the_simulator_node_publishes_what_its_sensors_read(probe, ros_env, tmp_path):
    """A lockstep simulator of a scene with a 4096-count encoder, difference rates and efforts
    2 ms late, answered by a stand-in controller whose torque counts the periods: the joint
    states on the wire are on the encoder's grid, their rates are the differences of their
    positions, and each effort is the command of three periods before (one period of hold,
    two of latency)."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from ros_helpers import simulator, start_process, stamp, wait_for
    from scenes import PAPER

    counts = 4096
    scene = tmp_path / 'sensed.yaml'
    scene.write_text(
        open(PAPER, encoding='utf-8').read()
        + f'\nsensors:\n  counts_per_revolution: {counts}\n  rate: difference\n'
        + '  effort_latency: 0.002\n'
    )
    pub = probe.publisher(Float64MultiArray, '/effort_controller/commands')
    states, answered = {}, set()

    def command(k):
        return [0.1 * k, -0.05 * k]

    def on_state(msg):
        k = round(stamp(msg) * RATE)
        states.setdefault(k, msg)
        # (not before our writer matched: the simulator repeats stamp 0 until a command)
        if k not in answered and pub.get_subscription_count() > 0:
            answered.add(k)
            pub.publish(Float64MultiArray(data=command(k)))

    with probe.lock:
        sub = probe.node.create_subscription(JointState, '/joint_states', on_state, 100)
    try:
        with start_process(
            simulator('mode:=lockstep', 'rate_factor:=0.0', f'scene:={scene}'),
            ros_env,
            tmp_path,
            'sim',
        ) as sim:
            assert wait_for(lambda: len(states) > 40 or not sim.alive(), timeout=90), sim.stderr
    finally:
        with probe.lock:
            probe.node.destroy_subscription(sub)
    ks = sorted(states)[:40]
    assert ks == list(range(40))
    q = np.array([list(states[k].position) for k in ks])
    qd = np.array([list(states[k].velocity) for k in ks])
    effort = np.array([list(states[k].effort) for k in ks])
    step = 2 * math.pi / counts
    assert np.max(np.abs(q / step - np.round(q / step))) < 1e-6
    assert qd[1:].tolist() == ((q[1:] - q[:-1]) * RATE).tolist()
    for k in range(4, 40):
        assert effort[k].tolist() == pytest.approx(command(k - 3), abs=1e-12), k


def test_bench_fit_takes_sensor_keys_for_its_recordings():
    from impact_arm.physics.errors import ImpactArmError
    from impact_arm_bench.fit import sensor_overrides

    assert sensor_overrides(['rate=difference', 'effort_latency=0.002']) == {
        'sensors.rate': 'difference',
        'sensors.effort_latency': 0.002,
    }
    with pytest.raises(ImpactArmError, match="--sensor 'rate'"):
        sensor_overrides(['rate'])


# ------------------------------------------------------------------------ offline MCAP
def _offline_joint_states(tmp_path, name, scene):
    from pathlib import Path

    from rosbags.highlevel import AnyReader

    from impact_arm.io.offline_mcap import OfflineRecorder
    from impact_arm.physics.simulate import run

    path = tmp_path / f'{name}.mcap'
    rec = OfflineRecorder(path, scene)
    result = None
    try:
        result = run(scene, observer=rec, keep_samples=False)
    finally:
        rec.close(result)
    rows = []
    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == '/joint_states']
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            rows.append((list(msg.position), list(msg.velocity), list(msg.effort)))
    return [np.array([r[i] for r in rows]) for i in range(3)]


def test_offline_recordings_carry_the_sensed_joint_states(tmp_path):
    """``impact-arm simulate --mcap`` of a scene with sensors writes what the driver would
    publish, read back with rosbags; without the section, the exact samples as before."""
    counts = 1 << 15
    sensed = scene_from(
        sensors={'counts_per_revolution': counts, 'rate': 'difference', 'effort_latency': 0.003},
        cycles=1,
    )
    q, qd, effort = _offline_joint_states(tmp_path, 'sensed', sensed)
    q0, _, effort0 = _offline_joint_states(tmp_path, 'exact', scene_from(cycles=1))
    step = 2 * math.pi / counts
    assert np.max(np.abs(q / step - np.round(q / step))) < 1e-6
    assert np.max(np.abs(q - q0)) <= step / 2 * (1 + 1e-9)
    assert qd[1:].tolist() == ((q[1:] - q[:-1]) * RATE).tolist()
    assert effort[3:].tolist() == effort0[:-3].tolist()
