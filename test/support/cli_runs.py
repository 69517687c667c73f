"""``impact-arm run`` as a user starts it, and its recording read back with rosbags."""

import subprocess
from pathlib import Path

from ros_helpers import PYTHON


def impact_arm_run(argv, env, cwd, timeout=400):
    proc = subprocess.run(
        [PYTHON, '-m', 'impact_arm.tools.cli', 'run', *argv],
        env=env,
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=timeout,
    )
    return proc.returncode, proc.stdout


def read_back(path):
    """{topic: [message]} of an MCAP file, by rosbags (in log-time order)."""
    from rosbags.highlevel import AnyReader

    by_topic = {}
    with AnyReader([Path(path)]) as reader:
        for conn, _, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return by_topic
