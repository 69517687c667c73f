"""``impact-arm bench controller_tick``: what the controller node's control thread spends on
one joint-state sample, in Python, without ROS.

The stream: the offline closed loop of ``impact_arm.tools.latency_study`` (the article's scene
unless ``--scene``; the simulated arm, the node's default parameters, each command delayed by
``--latency`` periods and by one more with probability ``--jitter``, as the unsynchronised
ros2_control stack of ``bench ros2control`` delays them), recorded as the controller receives
it: per period a ``geometry_msgs/WrenchStamped`` and a ``sensor_msgs/JointState`` with names,
positions, velocities and the acting efforts, serialized to CDR bytes (``msgdefs.serialize_cdr``,
the bytes DDS hands over).

The replay: the node's own per-sample methods (``Controller._on_wrench``,
``_on_joint_state``, ``_send``, ``_publish``) on an object built as ``Controller.__init__``
builds its inputs (``CycleController``, ``ControlInputs``, ``ChatterWatch``,
``PatchedMessage``) from the parameter table's defaults, with no node, no middleware: the
publisher keeps the bytes, the diagnostics are not built. So what is timed is everything the
control thread does per period besides waiting, taking and publishing: parsing, the input
checks, the latency measurement, the prediction over the commands in flight, the law, the
implicit law while the latency varies, the chatter watch and the command's serialization.
The replayed commands equal the recorded run's (the efforts in the stream match them, so the
latency is measured as in the run); the bench says whether they do.

Per round: the whole stream once (a fresh controller); the thread's CPU time over the
round per joint state (with its wrench), which a preemption by other work on the machine
does not inflate as it does wall time, and the median wall time of a joint state within the
round; ``--repeats`` rounds, median and worst of the CPU figure printed. ``--idle MS``: one
more round sleeping MS ms after each state, as the node's thread waits for the next sample:
with a period's sleep in between (caches and predictors gone cold, as in the node) the same
work costs more CPU than back to back. ``--profile``: one more round under
cProfile, the top entries by own time.
"""

from __future__ import annotations

import statistics
import time

DEFAULT_SECONDS = 3.0


def add_arguments(parser):
    parser.add_argument(
        '--scene', default='paper', help='scene name or YAML path (default: the article)'
    )
    parser.add_argument(
        '--seconds',
        type=float,
        default=DEFAULT_SECONDS,
        help=f'simulated seconds of the stream (default {DEFAULT_SECONDS:g})',
    )
    parser.add_argument(
        '--latency', type=int, default=2, help='periods each command is delayed (default 2)'
    )
    parser.add_argument(
        '--jitter',
        type=float,
        default=0.3,
        help='chance a command takes one period more (default 0.3: the latency varies)',
    )
    parser.add_argument('--repeats', type=int, default=5, help='timed rounds (default 5)')
    parser.add_argument(
        '--idle',
        type=float,
        default=0.0,
        metavar='MS',
        help='also one round sleeping MS ms after each state, as the node waits for the next '
        '(its caches go cold meanwhile); thread CPU per state (default 0: no such round)',
    )
    parser.add_argument('--profile', action='store_true', help='cProfile one more round')
    parser.add_argument('--json', metavar='FILE', help='write the figures as JSON')


def record_stream(scene, seconds: float, latency: int, jitter: float, seed: int = 0):
    """The samples the controller gets in the offline closed loop, as (kind, CDR bytes) in
    arrival order (a period's wrench before its joint state), and the commands it sent."""
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState

    from impact_arm.io.msgdefs import serialize_cdr
    from impact_arm.tools.latency_study import closed_loop

    names = list(scene.joint_names)
    stream: list[tuple[str, bytes]] = []

    def tap(sec, nanosec, tick):
        wrench = WrenchStamped()
        wrench.header.stamp.sec, wrench.header.stamp.nanosec = sec, nanosec
        wrench.wrench.force.x, wrench.wrench.force.y = (float(f) for f in tick.wrench)
        state = JointState(
            name=names,
            position=[float(v) for v in tick.position],
            velocity=[float(v) for v in tick.velocity],
            effort=[float(v) for v in tick.effort],
        )
        state.header.stamp.sec, state.header.stamp.nanosec = sec, nanosec
        stream.append(('wrench', serialize_cdr(wrench)))
        stream.append(('state', serialize_cdr(state)))

    result = closed_loop(
        scene, latency, -1, t_max=seconds, jitter=jitter, seed=seed, spread=1, tap=tap
    )
    return stream, result


class _Publisher:
    """Keeps what the node would publish."""

    def __init__(self):
        self.sent: list[bytes] = []

    def publish(self, data):
        self.sent.append(data)


class _Logger:
    def info(self, *args, **kwargs):
        pass

    warning = error = info


def replay_controller(scene, **overrides):
    """The controller node's per-sample state without a node: an object of the node's class
    (its methods as they are) configured by its own ``_configure`` step from the parameter
    table's defaults and ``overrides``, with no publisher, reader or thread (``_activate``
    never runs; the publisher is a stub). ``replay(node, stream)`` feeds it."""
    from impact_arm.nodes.controller import Controller
    from impact_arm.nodes.controller_params import check, parameter_table
    from impact_arm.nodes.param_types import ControllerParameters
    from impact_arm.nodes.params import scene_joint_names

    table = parameter_table(scene)
    # each value as the node declares it: the table's default, checked (enums parsed);
    # no start-up hold, which only waits for DDS discovery
    given = {'startup_hold': 0.0, **overrides}
    values = {
        p.name: p.check(
            given.get(p.name, list(p.default) if isinstance(p.default, tuple) else p.default)
        )
        for p in table
    }
    node = Controller.__new__(Controller)  # (no rclpy Node: its __init__ is never run)
    logger = _Logger()
    node.get_logger = lambda: logger
    # what the node asks its readers: here every sample is delivered
    node._readers_matched = lambda: True
    node._wrench_published = lambda: True
    node.scene = scene
    node.table = table
    node.p = ControllerParameters(**values)
    node.joint_names = scene_joint_names(scene)
    node.command_order = check(node.p, node.joint_names)
    node._configure()
    node.pub = _Publisher()
    node._publish_diagnostics = lambda: None
    return node


def replay(node, stream, clock=time.perf_counter, idle: float = 0.0) -> list[float]:
    """Feed ``stream`` to ``node`` as its control thread does (under its lock, a wrench
    then the state); the time of each joint state with the wrench before it [s] by
    ``clock``. ``idle`` > 0: sleep that long after each state, as the thread waits for the
    next one (not counted)."""
    on_wrench, on_state, lock = node._on_wrench, node._on_joint_state, node.lock
    times = []
    start = clock()
    for kind, raw in stream:
        with lock:
            if kind == 'wrench':
                on_wrench(raw)
                continue
            on_state(raw)
        end = clock()
        times.append(end - start)
        if idle > 0:
            time.sleep(idle)
            end = clock()
        start = end
    return times


def commands(node) -> list[list[float]]:
    """The commands ``node`` published, read back from their bytes."""
    from impact_arm.io.wire import float64_array_data

    return [float64_array_data(raw) for raw in node.pub.sent]


def run(args) -> int:
    import json

    from impact_arm.physics.scene import load_scene, resolve_scene_path

    scene = load_scene(resolve_scene_path(args.scene))
    stream, result = record_stream(scene, args.seconds, args.latency, args.jitter)
    states = sum(kind == 'state' for kind, _ in stream)
    rounds, medians = [], []
    first = None
    for _ in range(max(1, args.repeats)):
        node = replay_controller(scene)
        cpu = time.thread_time()
        times = replay(node, stream)
        rounds.append((time.thread_time() - cpu) / len(times))
        medians.append(statistics.median(times))
        if first is None:
            first = node
    assert first is not None
    inputs = first.inputs
    print(
        f'{scene.name}: {states} joint states ({args.seconds:g} s; latency {args.latency}, '
        f'jitter {args.jitter:g}), {result.impacts} impacts offline; replayed: '
        f'{first.sent} commands, {first.cycle_count.strikes} strikes, '
        f'implicit {inputs.implicit_commands}, '
        f'latency {dict(sorted(inputs.latency_seen.items()))}'
    )
    median, worst = statistics.median(rounds), max(rounds)
    print(
        f'CPU per joint state (with its wrench), mean over a round: median {median * 1e6:.1f} '
        f'us, worst {worst * 1e6:.1f} us of {len(rounds)} rounds; wall time per joint state, '
        f'median within a round: {" ".join(f"{m * 1e6:.1f}" for m in medians)} us'
    )
    idle_us = None
    if args.idle > 0:
        node = replay_controller(scene)
        times = replay(node, stream, clock=time.thread_time, idle=args.idle * 1e-3)
        idle_us = sum(times) / len(times) * 1e6
        print(f'CPU per joint state with {args.idle:g} ms idle after each: {idle_us:.1f} us')
    if args.profile:
        import cProfile
        import pstats

        node = replay_controller(scene)
        profiler = cProfile.Profile()
        profiler.enable()
        replay(node, stream)
        profiler.disable()
        pstats.Stats(profiler).sort_stats('tottime').print_stats(25)
    if args.json:
        with open(args.json, 'w') as f:
            json.dump(
                {
                    'scene': scene.name,
                    'states': states,
                    'implicit_commands': inputs.implicit_commands,
                    'round_mean_us': [r * 1e6 for r in rounds],
                    'median_us': median * 1e6,
                    'wall_median_us': [m * 1e6 for m in medians],
                    'idle_ms': args.idle,
                    'idle_cpu_us': idle_us,
                    'worst_us': worst * 1e6,
                },
                f,
                indent=1,
            )
    return 0
