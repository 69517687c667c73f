"""Header stamps and transform chains of /tf messages, composed by hand (no tf2)."""

import numpy as np


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def rotation(q):
    """3x3 matrix of a unit quaternion message (x, y, z, w)."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def compose(chain):
    """Position in the first parent of the last child, composing TransformStamped's."""
    R, p = np.eye(3), np.zeros(3)
    for t in chain:
        v = t.transform.translation
        p = p + R @ np.array([v.x, v.y, v.z])
        R = R @ rotation(t.transform.rotation)
    return p


def tip_in_world(msg, tip):
    """World position of frame 'tip' from a /tf message and the static tip transform."""
    frames = {t.child_frame_id: t for t in msg.transforms}
    chain, parent = [], 'world'
    while parent != tip.header.frame_id:
        t = next(f for f in frames.values() if f.header.frame_id == parent)
        chain.append(t)
        parent = t.child_frame_id
    return compose(chain + [tip])
