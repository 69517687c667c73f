"""The nodes' parameters as static types: one frozen dataclass per node, a field per
parameter of its table (simulator_params.py, controller_params.py, recorder_params.py,
replay_params.py) typed as ``Param.check`` returns it, which ``params.declare`` fills and the
node reads as ``self.p.publish_rate``; a ``ros2 param set`` makes a new one with ``replace``.
The scene-dependent tables have the same names whatever the scene, so the classes are fixed.

Generated from the tables by ``python -m impact_arm.nodes.param_docs``: edit the tables and
run it again (a test fails while this file differs from its output).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from ..contract import ControlTrigger, SimulatorMode, StartAfter, WatchdogPolicy
from ..driver.session import Release


@dataclass(frozen=True)
class SimulatorParameters:
    """The simulator node's parameters, checked."""

    scene: str
    publish_rate: float
    mode: SimulatorMode
    rate_factor: float
    command_timeout: float
    watchdog_policy: WatchdogPolicy
    brake_torque: float
    release_on: Release
    release_after: float
    command_latency_periods: int
    max_effort: float
    joints: list[str]
    preset: str
    thread_priority: int
    diagnostics_period: float
    step_periods: int
    frame_id: str
    joint_commands_topic: str
    joint_states_topic: str
    joint_states_gap: int
    tf_rate: float
    recorder_window: int
    rod_radius: float
    publish_tf: bool

    def replace(self, **changes: Any) -> SimulatorParameters:
        """A copy with ``changes`` (checked values by parameter name)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class ControllerParameters:
    """The controller node's parameters, checked."""

    scene: str
    law: str
    rate: float
    trigger: ControlTrigger
    p: list[float]
    i: list[float]
    d: list[float]
    i_clamp_max: float
    i_clamp_min: float
    u_clamp_max: float
    u_clamp_min: float
    antiwindup_strategy: str
    space: str
    down_target: list[float]
    up_target: list[float]
    switch_height: float
    surface_height: float
    force_threshold: float
    reversal_band: float
    latency_periods: int
    anticipate_impacts: bool
    implicit_periods: int
    implicit_window: float
    wrench_tolerance: float
    joints: list[str]
    command_readers: int
    startup_hold: float
    start_after: StartAfter
    command_history: int
    cycles: int
    thread_priority: int

    def replace(self, **changes: Any) -> ControllerParameters:
        """A copy with ``changes`` (checked values by parameter name)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class RecorderParameters:
    """The recorder node's parameters, checked."""

    output: str
    topics: list[str]
    scene: str
    param_nodes: list[str]
    flush_interval: float
    tf_rate: float
    log_time: str

    def replace(self, **changes: Any) -> RecorderParameters:
        """A copy with ``changes`` (checked values by parameter name)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class ReplayParameters:
    """The replay node's parameters, checked."""

    file: str
    rate: float
    clock: float
    loop: bool
    topics: list[str]
    start_offset: float
    delay: float
    wait_for_subscribers: int

    def replace(self, **changes: Any) -> ReplayParameters:
        """A copy with ``changes`` (checked values by parameter name)."""
        return dataclasses.replace(self, **changes)
