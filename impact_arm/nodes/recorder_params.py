"""The recorder node's parameters, declared once (``params.declare``): default, range,
description for ``ros2 param describe`` and the generated table of docs/topics.md."""

from ..contract import TOPICS
from ..io.scene_visuals import DEFAULT_TF_RATE
from .params import Param

LOG_TIMES = ('stamps', 'reception')

PARAMS = (
    Param(
        'output',
        '',
        'MCAP file to write; its directory is created (empty: runs/<date-time>.mcap)',
        'str',
        read_only=True,
        shown_default='`runs/<date-time>.mcap`',
    ),
    Param(
        'topics',
        list(TOPICS),
        'topics to record; "name" or "name:pkg/msg/Type" (contract topics and '
        'published topics need no type)',
        'strs',
        read_only=True,
        shown_default='the contract topics',
        doc='; other topics get their type from the graph once published',
    ),
    Param(
        'scene',
        '',
        'scene file or installed scene name to store in the file (optional); with it the '
        'file also shows the arm in 3D (derived /robot_description, /tf, /impact_markers)',
        'str',
        read_only=True,
    ),
    Param(
        'param_nodes',
        ['simulator', 'controller'],
        'nodes whose parameters are stored at start and at shutdown ([""]: none)',
        'strs',
        read_only=True,
    ),
    Param(
        'flush_interval',
        0.5,
        'seconds between flushes: at most this much is lost if the recorder is killed',
        low=0.0,
        open_low=True,
        read_only=True,
    ),
    Param(
        'tf_rate',
        DEFAULT_TF_RATE,
        'rate of the derived /tf and /impact_markers [Hz of simulated time] (with a scene)',
        low=0.0,
        high=1000.0,
        open_low=True,
        read_only=True,
    ),
    Param(
        'log_time',
        'stamps',
        'log time of each message: stamps = the newest /clock or /joint_states stamp '
        'received (simulated time, as ros2 bag record --use-sim-time; 0 before the first; '
        "an /impact_report at its impact's separation), "
        'reception = the wall clock',
        'str',
        choices=LOG_TIMES,
        read_only=True,
        doc='; with `stamps` a viewer plays the file at 1× and its index is in stamp order',
    ),
)
