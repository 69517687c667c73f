"""Is a recording complete? Every period from stamp 0 on every per-period topic, a command for
each, every impact report.

``impact-arm run`` checks its file with this once the recorder has closed it. In lockstep
nothing forces a loss (the simulator waits for the recorder), so a gap is a defect and the run
fails; in realtime the counts say what the run lost. Reads raw MCAP records (no rosbags, no
rclpy): header stamps straight from the CDR bytes, impact reports as JSON.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from ..contract import (
    COMMANDS,
    CONTACT_FORCE_PEAK,
    CONTACT_WRENCH,
    IMPACT_REPORT,
    JOINT_STATES,
    LOSSES_METADATA,
    SURFACE_MOUNTS,
)
from ..physics.errors import ImpactArmError
from ..physics.impact import impact_from_json
from .mcap_ros2 import iter_raw, read_metadata, topics_info
from .msgdefs import typestore
from .wire import MalformedMessage, header_stamp_ns


# what the simulator publishes once per period, stamped with the period's time (the plates of
# mounted surfaces only for a scene that has them); /clock is best effort, not among them
PERIOD_TOPICS = (JOINT_STATES, CONTACT_WRENCH, CONTACT_FORCE_PEAK, SURFACE_MOUNTS)


@dataclass
class RecordingCheck:
    periods: int  # distinct /joint_states stamps on the period grid
    missing_periods: list  # period numbers absent between 0 and the last one
    commands: int
    impact_reports: int
    missing_reports: list = field(default_factory=list)  # impact indices absent
    lost: dict = field(default_factory=dict)  # topic -> samples the recorder never got
    # the other per-period topics: topic -> period numbers absent between 0 and the last
    # period of any of them (a topic expected but not in the file misses every period)
    missing_on: dict = field(default_factory=dict)
    # the missing periods at the end, after the file's last /joint_states (a recorder that
    # stopped receiving): no sequence gap shows them, the run's end does
    lost_tail: int = 0
    rate: float = 0.0  # Hz: the period grid, for times in the summary

    @property
    def complete(self) -> bool:
        return not self._problems()

    def _problems(self) -> list[str]:
        problems = []
        if self.missing_periods:
            first = self.missing_periods[0]
            problems.append(f'{len(self.missing_periods)} periods missing (first: period {first})')
        for topic, missing in sorted(self.missing_on.items()):
            if missing:
                problems.append(
                    f'{len(missing)} periods missing on {topic} (first: period {missing[0]})'
                )
        if self.commands < self.periods - 1:
            problems.append(f'{self.periods - 1 - self.commands} commands missing')
        if self.missing_reports:
            problems.append(f'impact reports missing: {self.missing_reports[:10]}')
        return problems

    def summary(self, lockstep: bool = True, failed: str = '') -> str:
        """What the file holds; in lockstep also whether it is complete. In realtime a
        period may run on the previous command (the controller was late: no command is
        missing) and the recorder's loss count says what was lost. ``failed``: why the run
        failed, if it did; the file then never counts as complete."""
        text = (
            f'{self.periods} periods from t = 0, {self.commands} commands, '
            f'{self.impact_reports} impact reports'
        )
        if failed:
            text += f': INCOMPLETE, the run failed ({failed})'
        elif lockstep:
            problems = self._problems()
            text += ': complete' if not problems else ': INCOMPLETE, ' + '; '.join(problems)
        else:
            text += f', {len(self.missing_periods)} periods not in the file'
            last = self.missing_periods[-1] if self.missing_periods else -1
            if self.lost_tail and self.lost_tail > last:  # not one period in the file
                text += ' (the recorder received no joint state)'
            elif self.lost_tail and self.rate > 0:
                ends = (last - self.lost_tail) / self.rate
                text += (
                    f' (the file ends at t = {ends:.3f} s, the run at {last / self.rate:.3f} s: '
                    'the recorder received nothing after it)'
                )
        # what the recorder counted as never received (a best-effort /clock may lose samples
        # while the periods themselves are all there)
        lost = ', '.join(f'{t} {n}' for t, n in sorted(self.lost.items()) if n)
        return text + (f'; lost on the way (counted by the recorder): {lost}' if lost else '')


def check_recording(
    path: str | os.PathLike, rate: float, expected: tuple[str, ...] = (), until: float = 0.0
) -> RecordingCheck:
    """Count what ``path`` holds against a run at ``rate`` Hz that started at stamp 0.
    Period k has stamp k / rate on every per-period topic the file has (``PERIOD_TOPICS``)
    and on those ``expected`` (the run's own, e.g. /surface_mounts for a scene with a mount:
    absent from the file, it misses every period); each period after the first was started
    by one command. (A run with a reset repeats stamps: they count once.) ``until``: the
    run's last simulated time [s], when known: the periods up to it count even after the
    file's last sample (a recorder that stopped receiving loses the tail without a gap its
    sequence numbers could show)."""
    recorded = topics_info(path)
    periodic = [t for t in PERIOD_TOPICS if t == JOINT_STATES or t in recorded or t in expected]
    read_string = None
    stamps: dict[str, set[int]] = {topic: set() for topic in periodic}
    indices: list[int | None]  # None: a report that cannot be read
    commands, indices = 0, []
    for m in iter_raw(path, [*periodic, COMMANDS, IMPACT_REPORT], log_time_order=False):
        if m.topic in stamps:
            try:
                stamps[m.topic].add(round(header_stamp_ns(m.data) * rate * 1e-9))
            except MalformedMessage:
                pass
        elif m.topic == COMMANDS:
            commands += 1
        else:
            if read_string is None:
                read_string = typestore().deserialize_cdr
            try:
                indices.append(int(impact_from_json(read_string(m.data, m.type_name).data).index))
            except (ImpactArmError, ValueError, TypeError):
                indices.append(None)
    last = max((max(seen, default=-1) for seen in stamps.values()), default=-1)
    last = max(last, math.floor(until * rate + 1e-6))
    grid = set(range(last + 1))
    missing = sorted(grid - stamps[JOINT_STATES])
    lost_tail = last - max(stamps[JOINT_STATES], default=-1)
    missing_on = {t: sorted(grid - seen) for t, seen in stamps.items() if t != JOINT_STATES}
    known = {i for i in indices if i is not None}
    missing_reports = sorted(set(range(1, max(known, default=0) + 1)) - known)
    losses = read_metadata(path).get(LOSSES_METADATA, {})
    lost = {key.partition(':')[2]: int(n) for key, n in losses.items() if key.startswith('lost:')}
    return RecordingCheck(
        len(stamps[JOINT_STATES]),
        missing,
        commands,
        len(indices),
        missing_reports,
        lost,
        missing_on,
        lost_tail,
        rate,
    )
