"""The ROS-free sessions (driver/session.py) and the controller's input handling
(driver/control_inputs.py) on a fake clock, as the simulator and controller nodes drive them;
and the watchdog's brake policy against a controller that goes silent in the down-swing."""

import math

import pytest
from fake_loop import RATE, FakeClock, make_loop
from repo_paths import EXAMPLES

from impact_arm.contract import SimulatorMode, WatchdogPolicy, WatchdogState, to_absolute
from impact_arm.physics.control import CycleController
from impact_arm.driver.control_inputs import ControlInputs
from impact_arm.driver.arm import CommandError, SimulatedArm
from impact_arm.physics.model import ArmModel
from impact_arm.driver.realtime import DEFAULT_COMMAND_TIMEOUT
from impact_arm.physics.scene import load_scene, resolve_scene_path
from impact_arm.driver.session import (
    JointCommand,
    Level,
    LockstepSession,
    Outputs,
    RealtimeSession,
    Release,
)

P = 1.0 / RATE


@pytest.fixture(scope='module')
def scene():
    return load_scene(resolve_scene_path('paper'))


def session(kind, scene, clock, published, logs=None, **kwargs):
    arm = SimulatedArm(scene, RATE, max_effort=100.0, trace=False)
    outputs = Outputs(
        publish=published.append,
        log=lambda level, text: (logs if logs is not None else []).append(text),
    )
    return kind(
        arm,
        publish_rate=RATE,
        rate_factor=kwargs.pop('rate_factor', 1.0),
        command_timeout=0.1,
        command_order=[1, 0],
        outputs=outputs,
        clock=clock,
        sleep=clock.sleep,
        **{'policy': WatchdogPolicy.ZERO, **kwargs},
    )


def test_commands_are_checked_reordered_counted_and_clipped(scene):
    clock, published, logs = FakeClock(), [], []
    s = session(RealtimeSession, scene, clock, published, logs)
    assert not s.offer(lambda: s.ordered([1.0]))  # wrong length
    assert not s.offer(lambda: s.ordered([math.nan, 0.0]))  # not finite
    assert s.rejected == 2 and len(logs) == 1  # logged once a second

    def malformed():
        raise CommandError('truncated')

    assert not s.offer(malformed) and s.rejected == 3
    assert s.offer(lambda: s.ordered([500.0, 2.0]))  # joints in the order [2, 1]
    assert s.clipped == 1 and s.loop.commands == 1
    s.loop.realtime_period()
    assert s.arm.command == [2.0, 100.0]


def test_realtime_session_status_snapshot_says_what_the_arm_does(scene):
    clock, published = FakeClock(), []
    s = session(RealtimeSession, scene, clock, published)
    s.publish_initial()
    status = s.take_status()
    assert status.level is Level.WARN and status.message.startswith('waiting for the first')
    assert status.diagnostics.watchdog is WatchdogState.WAITING
    assert status.diagnostics.mode is SimulatorMode.REALTIME
    assert 'lockstep_repeats' not in dict(status.diagnostics.values())
    s.offer(lambda: [1.0, 0.0])
    s.run(lambda: s.arm.periods >= 10)
    status = s.take_status()
    assert status.level is Level.OK and status.message == 'running'
    assert status.diagnostics.periods_published == 10 and status.diagnostics.commands == 1
    assert status.diagnostics.watchdog_policy is WatchdogPolicy.ZERO
    clock.now += 1.0  # the controller went silent
    assert s.take_status().message == 'no command for more than 0.1 s: torques zeroed'
    assert s.set_e_stop(True) and not s.set_e_stop(True)
    assert s.take_status().level is Level.ERROR
    assert s.pause(True) == 'paused' and s.step(3) == (True, '3 period(s) requested')
    assert s.pause(False) == 'running' and s.step(1)[0] is False
    s.fail('broken')
    assert s.reset() == (False, 'stopped: broken')
    assert s.take_status().message == 'stopped: broken'


def test_a_step_before_any_command_says_the_arm_waits_braked(scene):
    """~/step while paused and not yet released: the periods are requested, but the arm
    waits braked at t = 0 for a command (docs/ros2_control.md); the answer says so instead
    of a bare 'requested' after which nothing moves."""
    clock, published = FakeClock(), []
    s = session(RealtimeSession, scene, clock, published)
    s.publish_initial()
    assert s.pause(True) == 'paused'
    ok, message = s.step(2)
    assert ok and message.startswith('2 period(s) requested; the arm stays braked')
    s.offer(lambda: [1.0, 0.0])
    assert s.step(2) == (True, '2 period(s) requested')


def test_lockstep_session_runs_one_period_per_command_and_holds_while_paused(scene):
    clock, published = FakeClock(), []
    s = session(LockstepSession, scene, clock, published, rate_factor=0.0)
    s.publish_initial()
    for _ in range(3):
        s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 3 and [round(t.t * RATE) for t in published] == [0, 1, 2, 3]
    s.pause(True)
    s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 3  # held until resumed or stepped
    s.step(2)  # the waiting command runs one at once
    assert s.arm.periods == 4
    s.offer(lambda: [0.0, 0.0])
    s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 5  # the second step, then held again
    s.pause(False)  # resuming answers the waiting command
    assert s.arm.periods == 6
    assert s.reset() == (
        True,
        'reset to the initial state at t = 0; brakes on until the next command',
    )
    assert s.arm.periods == 0 and published[-1].t == 0.0
    assert s.take_status().diagnostics.mode is SimulatorMode.LOCKSTEP


def test_lockstep_session_repeats_an_unanswered_period_once_a_second(scene):
    clock, published, logs = FakeClock(), [], []
    controller_there = [True]
    s = session(
        LockstepSession,
        scene,
        clock,
        published,
        logs,
        rate_factor=0.0,
        controller_present=lambda: controller_there[0],
    )
    s.publish_initial()
    s.tick()
    assert len(published) == 2 and published[-1].t == 0.0  # before the first command
    s.offer(lambda: [0.0, 0.0])
    clock.now += 0.5
    s.tick()
    assert len(published) == 3  # answered recently enough
    clock.now += 0.6
    s.tick()
    assert len(published) == 4 and published[-1] is published[-2] and s.repeats == 1
    assert 'published it again (1 so far)' in logs[-1]
    clock.now += 1.1
    controller_there[0] = False  # not once it left
    s.tick()
    assert len(published) == 4


def test_lockstep_session_waits_for_the_recorder_within_its_window(scene):
    clock, published, logs = FakeClock(), [], []
    recorder_there = [True]
    s = session(
        LockstepSession,
        scene,
        clock,
        published,
        logs,
        rate_factor=0.0,
        recorder_window=3,
        recorder_present=lambda: recorder_there[0],
    )
    s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 0 and s.waits_for_recorder == 1  # no progress yet
    s.recorder_progress(0)
    assert s.arm.periods == 1  # the deferred command ran
    s.offer(lambda: [0.0, 0.0])
    s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 3
    s.offer(lambda: [0.0, 0.0])
    assert s.arm.periods == 3 and s.deferred is not None  # 3 periods ahead: held
    s.recorder_progress(round(1e9 * P))
    assert s.arm.periods == 4
    s.offer(lambda: [0.0, 0.0])
    s.tick()
    assert s.arm.periods == 4 and 'waiting for the recorder' in logs[-1]
    recorder_there[0] = False  # it left: go on without
    s.tick()
    assert s.arm.periods == 5 and logs[-1] == 'the recorder left: the run goes on without it'
    assert s.take_status().diagnostics.periods_waiting_for_recorder == 3


# ----------------------------------------------------------------- the controller's inputs
def inputs(scene, sent, clock=None, **kwargs):
    model = ArmModel(scene)
    ctrl = CycleController.for_scene(model, scene.controller)
    logs = kwargs.pop('logs', [])
    return ControlInputs(
        ctrl,
        ['joint1', 'joint2'],
        [0, 1],
        1000.0,
        kwargs.pop('trigger', 'joint_states'),
        sent.append,
        log=logs.append,
        clock=clock or FakeClock(),
        **kwargs,
    )


def state(c, t, q=None, qd=(0.0, 0.0), effort=()):
    """A joint state at t; by default one that moves (a driver's repetitions are equal)."""
    sec, nanosec = divmod(round(t * 1e9), 1_000_000_000)
    q = (1.0 + math.sin(t), 0.5) if q is None else q
    c.joint_state(sec, nanosec, ['joint1', 'joint2'], list(q), list(qd), list(effort))


def test_a_state_waits_for_the_wrench_of_its_instant_and_the_force_is_latched(scene):
    sent = []
    c = inputs(scene, sent)
    state(c, 0.0)
    assert sent == [] and c.waiting is not None  # its wrench comes first
    c.wrench(0, 0, (0.0, 5.0))
    c.wrench(0, 0, (0.0, 2.0))  # latched: the largest counts
    assert len(sent) == 1 and c.normal_force == 2.0  # (the tick took 5.0, reset)
    c.wrench(0, 1_000_000, (0.0, 7.0))
    c.wrench(0, 1_000_000, (0.0, 3.0))
    assert c.normal_force == 7.0
    state(c, 0.001)
    assert len(sent) == 2 and c.normal_force is None
    # a state whose wrench never comes: the next state ticks without it, and states stop
    # waiting for wrenches until one arrives again
    state(c, 0.002)
    state(c, 0.003)
    assert len(sent) == 3 and c.dropped['missing_wrenches'] == 1 and not c.wrench_flowing
    state(c, 0.004)
    assert len(sent) == 4


def test_a_stamp_jump_is_dropped_unless_the_next_sample_confirms_it(scene):
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False)
    state(c, 0.0)
    state(c, 0.001)
    assert len(sent) == 2
    state(c, 2.0**31)  # one bad stamp: dropped
    assert c.dropped['stamp_jumps'] == 1 and len(sent) == 2
    state(c, 0.002)  # the stream goes on
    assert len(sent) == 3
    c.ctrl.mode = 'up'
    state(c, 0.0)  # back in time: a reset?
    assert len(sent) == 3 and c.dropped['stamp_jumps'] == 2
    state(c, 0.0)  # confirmed: re-armed there
    assert len(sent) == 4 and c.ctrl.mode == 'down'


def test_a_stream_that_paused_resumes_with_its_stamps_ahead(scene):
    """A driver stamping with the wall clock and paused by its machine for 3 s resumes 3 s
    ahead: that time passed, the sample ticks. The same jump after 1 ms of silence is a bad
    stamp."""
    sent = []
    clock = FakeClock()
    c = inputs(scene, sent, clock=clock, wrench_publishers=lambda: False)
    state(c, 0.0)
    clock.now += 0.001
    state(c, 0.001)
    clock.now += 3.0
    state(c, 3.001)
    assert len(sent) == 3 and c.dropped['stamp_jumps'] == 0
    clock.now += 0.001
    state(c, 6.002)
    assert len(sent) == 3 and c.dropped['stamp_jumps'] == 1


def test_bad_samples_are_dropped_and_counted(scene):
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False)
    assert not c.wrench(0, 0, (math.nan, 0.0))
    state(c, 0.0, q=(1e4, 0.0))
    state(c, 0.0, qd=(math.inf, 0.0))
    assert c.dropped['out_of_range_wrenches'] == 1 and c.dropped['out_of_range_states'] == 2
    assert sent == []
    state(c, 0.0)
    assert len(sent) == 1


def test_the_first_command_waits_for_the_start_up_hold_and_the_readers(scene):
    sent, clock, matched = [], FakeClock(), [False]
    c = inputs(
        scene,
        sent,
        clock,
        startup_hold=4.0,
        ready=lambda: matched[0],
        wrench_publishers=lambda: False,
    )
    state(c, 0.0)
    clock.now += 4.0
    state(c, 0.0)
    assert sent == []  # held, readers not matched
    matched[0] = True
    state(c, 0.0)
    assert len(sent) == 1


def test_trigger_timer_ticks_on_the_latest_state_only(scene):
    sent = []
    c = inputs(scene, sent, trigger='timer', wrench_publishers=lambda: False)
    c.timer()
    state(c, 0.0)
    assert sent == []
    c.timer()
    c.timer()
    assert len(sent) == 2


# ------------------------------------------------------------------ the watchdog's brake
def _silenced_in_the_down_swing(scene, policy, silence_from=0.1, silence=0.5, t_end=3.0):
    """The article's controller closing the loop on a fake clock (each command 0.5 ms after
    the state it answers), silent for ``silence`` s from simulated time ``silence_from`` (the
    down-swing before the first impact at 0.24 s). Returns the impact times by ``t_end``
    and the loop."""
    clock, published, commands = FakeClock(), [], {}
    loop = make_loop(scene, clock, commands, published, timeout=DEFAULT_COMMAND_TIMEOUT)
    loop.watchdog.policy = WatchdogPolicy(policy)
    ctrl = CycleController.for_scene(loop.arm.model, scene.controller)
    answered, impacts = None, []
    while loop.arm.t < t_end:
        loop.realtime_period()
        tick = published[-1]
        impacts += [record.t_contact for record, _ in tick.impacts]
        if tick is answered or silence_from <= tick.t < silence_from + silence:
            continue
        answered = tick
        commands[clock.now + 0.0005] = ctrl.update(
            tick.t,
            to_absolute(tick.position),
            to_absolute(tick.velocity),
            normal_force=tick.wrench[1],
        )
    return impacts, loop


def test_the_brake_holds_the_arm_through_a_silence_in_the_down_swing(scene):
    """A controller silenced 0.5 s in the down-swing: with the brake, the impacts of an
    undisturbed run less at most the one delayed cycle; with zero torque the arm drops onto
    the surface and chatters there (the danger is real)."""
    undisturbed, _ = _silenced_in_the_down_swing(scene, 'brake', silence=0.0)
    braked, loop = _silenced_in_the_down_swing(scene, 'brake')
    assert len(undisturbed) - 1 <= len(braked) <= len(undisturbed), (undisturbed, braked)
    assert min(braked) > 0.6  # no impact while braked (0.12 ... 0.6 s)
    dog = loop.watchdog
    assert dog.brakes == 1 and dog.timeouts == 1 and dog.state is WatchdogState.OK
    # limited, and reported: the stop needed the brake's whole rated torque
    assert 0 < dog.brake_peak <= loop.arm.brake_torque
    dropped, _ = _silenced_in_the_down_swing(scene, 'zero')
    assert len(dropped) > len(undisturbed) + 10


def test_the_brake_is_released_by_the_next_valid_command(scene):
    clock = FakeClock()
    loop = make_loop(scene, clock, {100.0: [3.0, -2.0]}, timeout=0.01)
    loop.watchdog.policy = WatchdogPolicy.BRAKE
    for _ in range(13):
        loop.realtime_period()
    assert loop.watchdog.state is WatchdogState.TIMEOUT and loop.watchdog.brakes == 1
    braking = loop.arm.command
    assert braking != [0.0, 0.0] and max(map(abs, braking)) <= loop.arm.brake_torque
    loop.command([1.0, 1.0], clock.now)
    loop.realtime_period()
    assert loop.arm.command == [1.0, 1.0] and loop.watchdog.state is WatchdogState.OK


def test_typed_kinds_are_their_text_wherever_text_was_used():
    import json

    from impact_arm.physics.kinds import EventKind

    kind = EventKind.MAX_COMPRESSION
    assert kind == 'max_compression' and str(kind) == f'{kind}' == 'max_compression'
    assert {'max_compression': 1}[kind] == 1 and json.dumps([kind]) == '["max_compression"]'
    assert EventKind('separation') is EventKind.SEPARATION
    assert WatchdogState.TIMEOUT == 'timeout' and f'{WatchdogPolicy.BRAKE}' == 'brake'


@pytest.mark.parametrize('kind', [RealtimeSession, LockstepSession])
def test_zero_joint_commands_leave_the_arm_braked_with_time_stopped(scene, kind):
    """Topic hardware writes zeros from its activation on, before any controller runs: with
    the default release rule they neither release the brakes nor start time, in either mode;
    the first command with a torque does. Command arrays keep starting on the first one."""
    clock, published = FakeClock(), []
    s = session(kind, scene, clock, published, release=Release.NONZERO_JOINT_COMMAND)
    s.publish_initial()
    q0 = list(published[0].position)
    for _ in range(50):
        assert s.offer(JointCommand(lambda: [0.0, 0.0]))
        if kind is RealtimeSession:
            s.loop.realtime_period()
    assert s.arm.periods == 0 and s.arm.t == 0.0 and not s.released()
    assert all(tick.t == 0.0 and list(tick.position) == q0 for tick in published)
    assert s.zero_before_release == 50 and s.loop.commands == 0
    assert s.take_status().diagnostics.zero_commands_before_release == 50
    assert s.offer(JointCommand(lambda: [0.0, 1.0]))  # a controller drives it
    if kind is RealtimeSession:
        s.loop.realtime_period()
    assert s.arm.periods == 1 and s.released()
    assert s.offer(JointCommand(lambda: [0.0, 0.0]))  # once released, zeros are commands
    if kind is RealtimeSession:
        s.loop.realtime_period()
    assert s.arm.periods == 2 and s.arm.command == [0.0, 0.0]
    # a command array starts at once under this rule, and any command under first_command
    for release, read in (
        (Release.NONZERO_JOINT_COMMAND, lambda: [0.0, 0.0]),
        (Release.FIRST_COMMAND, JointCommand(lambda: [0.0, 0.0])),
    ):
        other = session(kind, scene, clock, [], release=release)
        other.offer(read)
        if kind is RealtimeSession:
            other.loop.realtime_period()
        assert other.arm.periods == 1
    # nonzero_command holds arrays too
    held = session(kind, scene, clock, [], release=Release.NONZERO_COMMAND)
    held.offer(lambda: [0.0, 0.0])
    if kind is RealtimeSession:
        held.loop.realtime_period()
    assert held.arm.periods == 0


# ------------------------------------------------- a ros2_control driver's joint states
WALL = 1_764_000_000.0  # a wall-clock stamp (s), as joint_state_broadcaster stamps


def test_a_broadcasters_repetitions_are_not_periods_and_wall_stamps_tick(scene):
    """joint_state_broadcaster republishes the hardware's latest state at each controller
    manager update, with the update's wall-clock stamp: a new sample ticks once, its
    repetitions (same values, newer stamps) do not, even off the simulated grid."""
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False)
    ticked_on = []
    for k in range(20):  # an update every 0.25 ms, a new sample every 5th (a slow driver)
        q = (1.0 + 0.01 * (k // 5), 0.5)
        state(c, WALL + k * 0.00025 + (0.00004 if k % 3 else 0.0), q=q)
        if len(sent) > len(ticked_on):
            ticked_on.append(q[0])
    # each new sample ticked, once: a repetition that reached the next tick first would
    # have ticked on stale values and made the new sample wait a whole period
    assert ticked_on == [1.0, 1.01, 1.02, 1.03] and c.repeated == 16
    # an arm that really stands still is not starved: the same values once the repetition
    # window (1.5 periods) has passed tick again
    state(c, WALL + 0.0060, q=(1.03, 0.5))
    assert len(sent) == 5


def test_a_wrench_on_another_clock_is_latched_never_waited_for(scene):
    """The simulator's wrench (simulated stamps) beside a broadcaster's joint states (wall
    clock): no state waits for it or is dropped as missing its wrench; its force still
    switches the cycle at the next tick."""
    sent = []
    c = inputs(scene, sent, wrench_tolerance=0.01)
    for k in range(10):
        c.wrench(0, k * 1_000_000, (0.0, 0.0))
        state(c, WALL + k * 0.001)
    assert len(sent) == 10 and c.waiting is None and not any(c.dropped.values())
    c.wrench(0, 10_000_000, (0.0, 500.0))  # an impact, on the other clock
    state(c, WALL + 0.010)
    assert c.ctrl.mode == 'up' and len(sent) == 11
    # a wrench on the states' own clock within the tolerance is still waited for
    same = inputs(scene, [], wrench_tolerance=0.01)
    same.wrench(1, 0, (0.0, 0.0))
    state(same, 1.001)
    assert same.waiting is not None


def test_the_latency_is_measured_from_the_efforts_the_driver_reports(scene):
    """A driver reporting the torque acting now: with two commands still on their way the
    controller counts two, and predicts over them (latency_periods -1)."""
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False, latency_periods=-1)
    acting = [[0.0, 0.0]] * 3
    for k in range(10):
        state(c, k * 0.001, effort=acting[-3])
        acting.append(sent[-1])
    assert c.measured_latency == 2 and len(c.in_flight()) == 2
    fixed = inputs(scene, [], wrench_publishers=lambda: False, latency_periods=1)
    state(fixed, 0.0)
    state(fixed, 0.001)
    assert len(fixed.in_flight()) == 1


def test_warming_up_the_prediction_sends_nothing_and_changes_no_command(scene):
    """The node warms the prediction and the implicit law before its first tick: no
    command, no counter, and the commands that follow are those of a cold start."""
    sent, cold = [], []
    warm = inputs(scene, sent, wrench_publishers=lambda: False, latency_periods=-1)
    reference = inputs(scene, cold, wrench_publishers=lambda: False, latency_periods=-1)
    warm.warm_up(scene.q0, scene.qd0)
    assert sent == [] and warm.implicit_commands == 0 and warm.latency_seen == {}
    assert warm.ctrl.switches == 0 and warm.ctrl._last_t is None
    for c, out in ((warm, sent), (reference, cold)):
        c.implicit_periods = 1
        for k in range(60):
            back = min(len(out) - 1, 2 + (k > 40) * (k % 2))  # then 2 and 3 recur: implicit
            state(c, k * 0.001, effort=out[-1 - back] if out else ())
    assert warm.implicit_commands == reference.implicit_commands > 0
    assert sent == cold


def test_prediction_keeps_the_limit_cycle_under_command_latency(scene):
    """The article's controller and arm in one process (lockstep session and the
    controller's input handling, joined by queues), the driver delaying each command by one
    period: acting on the sampled state the arm strikes twice per cycle; predicting over the
    measured latency, it strikes as without latency."""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, 0, 0, t_max=2.5)
    late = closed_loop(scene, 1, 0, t_max=2.5)
    predicted = closed_loop(scene, 1, -1, t_max=2.5)
    two = closed_loop(scene, 2, -1, t_max=2.5)
    assert base.second_strikes == 0 and base.impacts >= 5
    assert late.second_strikes >= 3
    for run in (predicted, two):
        assert not run.failed and run.second_strikes == 0
        assert run.impacts == base.impacts
        assert max(run.delta_m) == pytest.approx(max(base.delta_m), rel=0.02)


@pytest.mark.parametrize('latency', [1, 2])
@pytest.mark.parametrize('every', [5, 20])
def test_a_repeated_state_costs_the_cycle_nothing(scene, latency, every):
    """A driver stack's update that finds no new state repeats its previous one
    (TopicBasedSystem behind a broadcaster; the simulator's joint_states_gap). The controller
    then computes that update's command on its latest state predicted a period further, so
    the arm strikes as if every state had come, in the rebound too: held a period longer
    instead (the repetition skipped), a command moves the strikes by milliseconds."""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, latency, -1, t_max=2.5)
    gaps = closed_loop(scene, latency, -1, t_max=2.5, repeat_every=every, repeat_quiet=0.0)
    assert base.impacts >= 5 and not gaps.failed and gaps.impacts == base.impacts
    assert gaps.t_contact == pytest.approx(base.t_contact, abs=1e-6)
    assert gaps.delta_m == pytest.approx(base.delta_m, rel=1e-5)


@pytest.mark.parametrize('latency', [4, 5])
def test_without_a_force_sensor_a_predicting_controller_sees_the_impact_in_the_sample(
    scene, latency
):
    """No contact wrench (an arm without a force sensor): the controller tells the impact
    from the tip's reversal. Judged on its prediction, whose free motion goes through the
    surface, the reversal showed periods late and at 4 periods of latency the arm struck
    twice every cycle; judged on the sample, it strikes as the run with the wrench does."""
    from impact_arm.tools.latency_study import closed_loop

    sensed = closed_loop(scene, latency, -1, t_max=2.5)
    blind = closed_loop(scene, latency, -1, t_max=2.5, force_sensor=False)
    assert sensed.second_strikes == 0 and sensed.impacts >= 5
    assert not blind.failed and blind.second_strikes == 0
    # (at some impacts the reversal shows a period after the force: ms over the run)
    assert blind.t_contact == pytest.approx(sensed.t_contact, abs=5e-3)
    assert max(blind.delta_m) == pytest.approx(max(sensed.delta_m), rel=0.02)


def test_a_latency_that_varies_by_a_period_is_told_from_a_pipeline_filling(scene):
    """The commands in flight fill at start-up (latencies 0, 1, 2 measured once each): a
    steady latency, the law stays explicit. Latencies 2 and 3 recurring (an unsynchronised
    driver stack): the law is evaluated on the state its own command leads to."""
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False, latency_periods=-1)
    c.implicit_periods = 1
    for k in range(40):
        back = min(len(sent) - 1, 2)
        state(c, k * 0.001, effort=sent[-1 - back] if sent else ())
    assert c.measured_latency == 2 and not c.latency_varies() and c.implicit_commands == 0
    for k in range(40, 52):
        state(c, k * 0.001, effort=sent[-3 - k % 2])
    assert c.latency_varies() and c.implicit_commands > 0
    off = inputs(scene, [], wrench_publishers=lambda: False, latency_periods=-1)
    assert off.implicit_periods == 0  # the input handling's default; the node's is 1
    with pytest.raises(ValueError, match='implicit_periods = -1'):
        inputs(scene, [], implicit_periods=-1)


@pytest.mark.parametrize('latency, seed', [(0, 4), (1, 3), (2, 4)])
def test_an_implicit_law_keeps_the_limit_cycle_when_the_latency_varies(scene, latency, seed):
    """Each command a period later than ``latency`` at random (half of them): predicting over
    the measured latency alone the arm strikes twice after some impacts; with the law
    evaluated on the state its own command leads to (implicit_periods 1), once per cycle,
    with the penetration of the run without latency."""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, 0, 0, t_max=2.5)
    # without the impact's anticipation, which hides some of these second strikes
    kw = dict(jitter=0.5, seed=seed, anticipate_impacts=False)
    explicit = closed_loop(scene, latency, -1, 2.5, implicit_periods=0, **kw)
    implicit = closed_loop(scene, latency, -1, 2.5, implicit_periods=1, **kw)
    assert explicit.second_strikes >= 1
    assert not implicit.failed and implicit.second_strikes == 0
    assert implicit.impacts == base.impacts
    assert max(implicit.delta_m) == pytest.approx(max(base.delta_m), rel=0.02)


@pytest.mark.parametrize('latency', [2, 4, 8])
def test_an_anticipated_impact_keeps_the_cycle_of_the_run_without_latency(scene, latency):
    """A steady latency, predicted: with the impact anticipated (the up half's command from
    the state the prediction shows in the surface, the tip stopped there) the limit cycle is
    the run's without latency to 0.1 %, at the same penetration; switching only when a
    sample shows the impact, the commands in flight push the tip into the surface and the
    cycle is longer by at least 0.2 % (0.5 % at 4 periods, 1.5 % at 8)."""
    from impact_arm.tools.latency_study import closed_loop

    # (12 strikes; at 8 periods the first comes 10 ms early: no 13th falls in so)
    base = closed_loop(scene, 0, 0, t_max=4.8)
    ahead = closed_loop(scene, latency, latency, t_max=4.8)
    late = closed_loop(scene, latency, latency, t_max=4.8, anticipate_impacts=False)
    for run in (ahead, late):
        assert not run.failed and run.second_strikes == 0 and run.impacts == base.impacts
    assert ahead.mean_cycle() == pytest.approx(base.mean_cycle(), rel=1e-3)
    assert late.mean_cycle() > base.mean_cycle() * 1.002
    assert max(ahead.delta_m) == pytest.approx(max(base.delta_m), rel=0.01)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_an_anticipated_impact_keeps_the_cycle_when_the_latency_varies(scene, seed):
    """Commands two periods late, 70 % of them a third (an unsynchronised driver stack),
    the latency measured: the cycle stays within 1 % of the run without latency, at its
    penetration (the up command never meets the approach: the switch waits for an impact
    a period before the predicted state); switching on the sampled impact it is longer."""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, 0, 0, t_max=5.0)
    kw = dict(jitter=0.7, seed=seed)
    ahead = closed_loop(scene, 2, -1, 5.0, **kw)
    late = closed_loop(scene, 2, -1, 5.0, anticipate_impacts=False, **kw)
    assert not ahead.failed and ahead.second_strikes == 0 and ahead.impacts == base.impacts
    assert ahead.mean_cycle() == pytest.approx(base.mean_cycle(), rel=0.01)
    assert late.mean_cycle() > ahead.mean_cycle()
    assert max(ahead.delta_m) == pytest.approx(max(base.delta_m), rel=0.01)


@pytest.mark.parametrize('latency, spread', [(1, 1), (1, 3)])
def test_the_implicit_law_in_the_rebound_only_keeps_the_cycle(scene, latency, spread):
    """A latency that varies (1..2 and 1..4 periods): the implicit law only for the rebound
    (implicit_window, 50 ms after the switch to the up half) strikes once per cycle like
    the law implicit throughout, at the penetration of the run without latency, and keeps
    the cycle within 1 % of it, where the law implicit throughout slows it by more."""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, 0, 0, t_max=6.0)
    for seed in (1, 2, 3):
        kw = dict(jitter=0.5, seed=seed, spread=spread)
        rebound = closed_loop(scene, latency, -1, 6.0, **kw)
        always = closed_loop(scene, latency, -1, 6.0, implicit_window=math.inf, **kw)
        for run in (rebound, always):
            assert not run.failed and run.second_strikes == 0 and run.impacts == base.impacts
        assert rebound.mean_cycle() == pytest.approx(base.mean_cycle(), rel=0.01)
        assert always.mean_cycle() > rebound.mean_cycle()
        assert max(rebound.delta_m) == pytest.approx(max(base.delta_m), rel=0.03)


@pytest.mark.parametrize('spread, seed', [(3, 5), (4, 4)])
def test_the_implicit_law_looks_further_ahead_when_the_latency_varies_more(scene, spread, seed):
    """Each command taking 1 to 1 + spread periods (a driver stack scheduled worse than the
    controller's period, as a loaded machine makes it): the law looks ahead at least half
    the recurring latencies' spread, and the arm strikes once per cycle, the base run's
    impacts with its penetration. (One period ahead, these draws strike twice.)"""
    from impact_arm.tools.latency_study import closed_loop

    base = closed_loop(scene, 0, 0, t_max=10.0)
    run = closed_loop(scene, 1, -1, 10.0, jitter=0.5, seed=seed, spread=spread)
    assert not run.failed and run.second_strikes == 0
    assert run.impacts == base.impacts
    assert max(run.delta_m) == pytest.approx(max(base.delta_m), rel=0.02)


@pytest.mark.parametrize('seed, t_max', [(7, 1.5), (9, 10.0)])
def test_a_latency_burst_at_an_impact_does_not_strike_twice(seed, t_max):
    """The URDF example, its commands delayed in bursts (1 period, now and then 2 or 3 for a
    few periods: a loaded machine's driver stack). A burst that begins at an impact holds
    the rebound's first, largest command up to three periods where the law planned one; the
    implicit law looks as far ahead there (the spread plus one period) and the arm strikes
    once per cycle, with the base run's impacts and penetration. (Half the spread ahead, as
    after the rebound's first milliseconds, these draws strike twice.)"""
    from impact_arm.tools.latency_study import LatencyBursts, closed_loop

    urdf = load_scene(f'{EXAMPLES}/real_arm.yaml')
    base = closed_loop(urdf, 0, 0, t_max=t_max)
    run = closed_loop(urdf, 1, -1, t_max, seed=seed, bursts=LatencyBursts(1, 0.05, 2))
    assert not run.failed and run.second_strikes == 0
    assert run.impacts == base.impacts
    assert max(run.delta_m) == pytest.approx(max(base.delta_m), rel=0.02)


def test_latency_bursts_reject_what_no_machine_does():
    from impact_arm.tools.latency_study import LatencyBursts

    with pytest.raises(ValueError, match='probability = 1.5'):
        LatencyBursts(1, 1.5, 2)
    with pytest.raises(ValueError, match='top = 0'):
        LatencyBursts(1, 0.1, 0)


def test_a_stale_echo_or_a_wild_prediction_does_not_steer_the_arm(scene):
    """An effort matching a command sent long ago (a driver holding an old one) is no
    latency; a prediction that leaves any arm's range (torques in flight no arm could take)
    is not acted on: the sampled state is, and the fall-back is counted."""
    sent = []
    c = inputs(scene, sent, wrench_publishers=lambda: False, latency_periods=-1)
    for k in range(20):
        state(c, k * 0.001, effort=sent[-1] if sent else ())
    assert c.measured_latency == 0 and len(sent) == 20
    state(c, 0.020, effort=sent[-12])  # eleven commands back: a stale echo
    assert c.measured_latency == 0
    state(c, 0.021, effort=sent[-4])
    assert c.measured_latency == 3
    wild = inputs(scene, [], wrench_publishers=lambda: False, latency_periods=2)
    state(wild, 0.0)
    wild.sent.extend([[1e9, -1e9], [1e9, -1e9]])
    state(wild, 0.001)
    assert wild.dropped['unsafe_predictions'] == 1
    assert all(math.isfinite(v) and abs(v) < 1e5 for v in wild.sent[-1])


class _EveryPeriodCosts(dict):
    """Each period's physics takes 2.5 periods of wall time: each one stalls the schedule."""

    def get(self, key, default=None):
        return 2.5 / RATE


def test_diagnostics_read_while_the_loop_records_stalls_see_one_snapshot(scene):
    """The loop thread records a stall each period while another thread takes the status as
    fast as it can, switching threads every microsecond: no error, and the periods published
    plus skipped never run ahead of the wall time read beside them."""
    import sys
    import threading

    clock, published = FakeClock(), []
    s = session(RealtimeSession, scene, clock, published)
    arm_step = s.arm.step

    def costly_step():
        clock.now += 2.5 / RATE
        return arm_step()

    s.arm.step = costly_step
    assert s.offer(lambda: s.ordered([0.0, 0.0]))
    done, stop = threading.Event(), threading.Event()
    failures = []

    def loop():
        try:
            # until the reader has taken its snapshots (how many periods that takes depends
            # on the machine), with a bound
            for _ in range(200_000):
                if stop.is_set():
                    break
                s.loop.realtime_period()
        except Exception as exc:  # noqa: BLE001 - reported by the test
            failures.append(exc)
        finally:
            done.set()

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        thread = threading.Thread(target=loop)
        thread.start()
        snapshots = 0
        while not done.is_set():
            status = s.take_status().diagnostics
            scheduled = status.periods_published + status.periods_skipped
            assert scheduled <= status.wall_time * RATE + 2, status  # (one period in progress)
            assert len(status.periods_skipped_at_s) <= 8
            snapshots += 1
            # both sides busy for a while, however the threads happen to be scheduled
            if snapshots >= 50 and s.loop.skipped > 100:
                stop.set()
        thread.join()
    finally:
        sys.setswitchinterval(switch)
    assert not failures, failures
    assert s.loop.skipped > 100 and snapshots >= 50


def test_the_law_waits_until_the_driver_answers_its_first_command(scene):
    """A driver stack's initial values (the same state restamped each update, efforts zero):
    the first command goes out and then again, unchanged, the law never running on a state
    that does not answer. Once the driver reports the first command's effort the law runs."""
    from impact_arm.driver.control_inputs import Answer

    sent = []
    clock = FakeClock()
    c = inputs(scene, sent, clock=clock, wrench_publishers=lambda: False, latency_periods=-1)
    q0 = (1.0, 0.5)
    for k in range(200):
        clock.now += 0.001
        state(c, 0.001 * k, q=q0, effort=(0.0, 0.0))
    assert len(sent) > 50 and all(command == sent[0] for command in sent)
    assert c.answered_by is None and c.unanswered == len(sent) - 1
    assert c.ctrl.switches == 0
    # each one in the history the latency is measured against, as the law's own would be
    assert len(c.sent) == min(len(sent), c.sent.maxlen)
    clock.now += 0.001
    state(c, 0.2, q=q0, effort=sent[0])  # the hardware applies it (the arm still braked)
    assert c.answered_by is Answer.EFFORT
    clock.now += 0.001
    state(c, 0.201, q=(1.0001, 0.5), qd=(0.1, 0.0), effort=sent[0])
    assert sent[-1] != sent[0]  # the law's own command


def test_a_driver_that_reports_no_effort_answers_by_moving(scene):
    sent = []
    clock = FakeClock()
    c = inputs(scene, sent, clock=clock, wrench_publishers=lambda: False)
    state(c, 0.0, q=(1.0, 0.5))
    clock.now += 0.002
    state(c, 0.002, q=(1.0, 0.5))  # a repetition after the window: the first command again
    assert len(sent) == 2 and sent[1] == sent[0] and c.answered_by is None
    clock.now += 0.001
    state(c, 0.003, q=(1.001, 0.5), qd=(0.5, 0.0))
    assert c.answered_by is not None and c.answered_by.value == 'motion'
    assert len(sent) == 3 and sent[2] != sent[0]


def test_release_after_runs_braked_periods_until_its_time_then_releases():
    """Lockstep ``release_after``: each command before the release runs a braked period (time
    advances, the arm stays, the period goes out), zero or not; from the release time on the
    first non-zero JointState command releases the brakes and runs the first real period."""
    from impact_arm.driver.session import JointCommand, LockstepSession, Outputs

    arm = SimulatedArm(load_scene(resolve_scene_path('paper')), RATE, trace=False)
    q0 = arm.sample().position
    ticks = []
    session = LockstepSession(
        arm,
        publish_rate=RATE,
        rate_factor=0.0,
        command_timeout=math.inf,
        command_order=[0, 1],
        outputs=Outputs(publish=ticks.append),
        clock=lambda: 0.0,
        sleep=lambda s: None,
        release_after=3 / RATE,
        release='nonzero_joint_command',
    )
    for torques in ([0.0, 0.0], [5.0, 1.0], [5.0, 1.0]):
        assert session.offer(JointCommand(lambda t=torques: list(t)))
    assert not session.released() and session.braked_periods == 3
    assert [t.t for t in ticks] == pytest.approx([1 / RATE, 2 / RATE, 3 / RATE])
    assert all(t.position == q0 for t in ticks) and session.zero_before_release == 1
    session.offer(JointCommand(lambda: [0.0, 0.0]))  # zero: braked still, time running
    assert not session.released() and session.braked_periods == 4
    session.offer(JointCommand(lambda: [5.0, 1.0]))
    assert session.released() and arm.periods == 5 and ticks[-1].position != q0
    assert session.take_status(0.0).diagnostics.braked_periods == 4
    with pytest.raises(ValueError, match='release_after'):
        LockstepSession(
            arm,
            publish_rate=RATE,
            rate_factor=0.0,
            command_timeout=1.0,
            command_order=[0, 1],
            release_after=float('nan'),
        )
