"""The replay node's parameters, declared once (``params.declare``) and checked the same way
by ``impact-arm replay`` before it starts any DDS: default, range, description and the
generated table of docs/topics.md. What depends on the file (its topics, how much of it
``start_offset`` may skip) is ``io.replay_plan``'s to check."""

from .params import Param

WAIT_SUBSCRIBERS_MAX = 30.0  # s

PARAMS = (
    Param(
        'file', '', 'MCAP file to replay (required)', 'str', read_only=True, doc=' (CLI: `FILE`)'
    ),
    Param(
        'rate',
        1.0,
        'speed factor; 1.0 = recorded speed',
        low=0.0,
        high=1000.0,
        open_low=True,
        read_only=True,
        doc=' (CLI: `--rate`)',
    ),
    Param(
        'clock',
        0.0,
        'publish /clock with the recorded time at this many Hz of wall time (0: no /clock)',
        low=0.0,
        high=10000.0,
        read_only=True,
        doc=' (CLI: `--clock [HZ]`, 100 Hz when given without a value)',
    ),
    Param(
        'loop',
        False,
        'start again after the last message',
        'bool',
        read_only=True,
        doc=' (CLI: `--loop`)',
    ),
    Param(
        'topics',
        [''],
        'topics to replay ([""]: all)',
        'strs',
        read_only=True,
        shown_default='all',
        doc=' (CLI: `--topics T …`)',
    ),
    Param(
        'start_offset',
        0.0,
        'seconds of recorded time to skip (less than the recording lasts)',
        low=0.0,
        high=1e9,
        read_only=True,
        doc=' (CLI: `--start-offset S`)',
    ),
    Param(
        'delay',
        0.0,
        'seconds to wait before the first message',
        low=0.0,
        high=3600.0,
        read_only=True,
        doc=' (CLI: `--delay S`)',
    ),
    Param(
        'wait_for_subscribers',
        0,
        f'before starting, wait (at most {WAIT_SUBSCRIBERS_MAX:g} s) until every replayed '
        'topic has this many subscribers',
        'int',
        low=0,
        high=1000,
        read_only=True,
        doc=' (CLI: `--wait-for-subscribers N`)',
    ),
)
