"""The ROS-free driver loop on a fake clock, for the driver and session tests: the real
``SimulatedArm`` of a scene, only the wall clock is fake."""

from impact_arm.driver.arm import SimulatedArm
from impact_arm.driver.realtime import DriverLoop, WatchdogPolicy


RATE = 1000.0


P = 1.0 / RATE


class FakeClock:
    """Wall time that moves only when the loop sleeps or a step 'costs' time."""

    def __init__(self):
        self.now = 100.0
        self.sleeps = []
        self.cost = {}  # period index -> wall seconds its physics takes
        self.take_cost = 0.0  # wall seconds one take of a queued command takes

    def __call__(self):
        return self.now

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.now += seconds


def make_loop(
    scene,
    clock,
    commands=None,
    published=None,
    logs=None,
    timeout=0.1,
    checked=None,
    policy=WatchdogPolicy.ZERO,
):
    """A loop whose queued commands come from ``commands`` (wall time of arrival ->
    torques; the string 'garbage' is a message that fails its check); ``checked`` collects
    every message the loop checks, in order. The watchdog's ``policy`` is zero torque here,
    which these tests were written for (the driver's default brakes)."""
    arm = SimulatedArm(scene, RATE, max_effort=5000.0, trace=False)
    step = arm.step
    commands = commands if commands is not None else {}

    def costly_step():
        clock.now += clock.cost.get(arm.periods, 0.0)
        return step()

    arm.step = costly_step

    def take_command():
        due = [k for k in sorted(commands) if k <= clock.now]
        clock.now += clock.take_cost
        return commands.pop(due[0]) if due else None

    def accept(raw, now):
        if checked is not None:
            checked.append(raw)
        if raw == 'garbage':
            return False
        loop.command(raw, now)
        return True

    loop = DriverLoop(
        arm,
        wall_period=P,
        command_timeout=timeout,
        take_command=take_command,
        accept=accept,
        publish=(published if published is not None else []).append,
        log=lambda level, text: (logs if logs is not None else []).append(text),
        clock=clock,
        sleep=clock.sleep,
        max_takes=10,
        policy=policy,
    )
    return loop
