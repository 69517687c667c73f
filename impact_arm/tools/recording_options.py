"""The options that say how to read the arm's samples from a recording (``--joints``,
``--states-topic``, ``--wrench-topic``), declared once for every command that reads one
(``fit``, ``compare``)."""

from __future__ import annotations

import argparse


def add_recording_arguments(
    parser: argparse.ArgumentParser, *, states_of: str = '', without_wrench: str = ''
) -> None:
    """Declare ``--joints``, ``--states-topic`` and ``--wrench-topic`` on ``parser``.

    ``states_of`` follows "topic" in the states option's help (" of the recordings" for a
    command that reads two); ``without_wrench`` follows the wrench default in its help (what
    the command does when no wrench was recorded)."""
    parser.add_argument(
        '--joints',
        default=None,
        metavar='A,B,...',
        help='joint names in the joint states, base first (default joint1..jointN)',
    )
    parser.add_argument(
        '--states-topic',
        default=None,
        metavar='T',
        help=f'sensor_msgs/JointState topic{states_of} (default /joint_states)',
    )
    parser.add_argument(
        '--wrench-topic',
        default=None,
        metavar='T',
        help=f'geometry_msgs/WrenchStamped topic (default /contact_wrench if recorded'
        f'{without_wrench})',
    )
