"""Generators of hostile input, shared by the stress benchmarks and the tests (which import
impact_arm_bench: test/conftest.py): mutated scene files (``mutate``, ``key_paths``) and
malformed command payloads (``malformed_commands``). Seeded: the same generator gives the
same inputs, so a failure found once can be replayed."""

from __future__ import annotations

import math
import random
import struct

WILD_NUMBERS = (
    0,
    -0.0,
    1e308,
    -1e308,
    1e-300,
    5e-324,
    2.0**64,
    10**400,
    -(10**400),
    float('nan'),
    float('inf'),
    -float('inf'),
    1e-12,
    1e12,
    -1.0,
    0.5,
    1e6,
)
WILD_VALUES = ('text', '', None, True, [], {}, [1, 2], {'x': 1})
YAML_SNIPPETS = (
    '1:30',
    '017',
    '0b101',
    '1_000',
    'yes',
    'off',
    '.nan',
    '-.inf',
    '!!str 5',
    '!!binary aGVsbG8=',
    '!!python/object:os.system x',
    '2001-12-14',
    '~',
    '!!float 1e999',
    '"\\ud800"',
    '&a 1',
    '*undefined',
)


# ----------------------------------------------------------------------------- mutation
def key_paths(node, path=()):
    """Every key/index path inside a nested dict/list, leaves and inner nodes, not the root."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from key_paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from key_paths(v, path + (i,))
    if path:
        yield path


# what a real arm's joints add (scene ``joints``): ordinary values and the extremes the scene
# must either run to a finite end or refuse (Coulomb smoothing at 1e-4 rad/s, a rotor 100x
# the link's own inertia, friction far above any torque)
JOINT_VALUES = {
    'damping': (0.0, 0.01, 1.0, 50.0, 1e4),
    'friction': (0.0, 0.1, 1.0, 100.0, 1e5),
    'friction_v_d': (1e-6, 1e-4, 0.01, 1.0),
    'armature': (0.0, 1e-3, 0.1, 100 / 12, 1e3),
}


# a struck plate's mount (scene ``surfaces[i].mount``): from a free plate (stiffness 0) to one
# far stiffer than the contact (1e11 N/m under 10 kg), light and heavy plates, over-damped
MOUNT_VALUES = {
    'mass': (0.01, 1.0, 10.0, 1e3, 1e-6),
    'stiffness': (0.0, 1e5, 1e8, 1e11, 1e13),
    'damping_ratio': (0.0, 0.05, 1.0, 10.0),
}


def random_mount(rng):
    """A ``mount`` mapping; its last, extreme values drawn rarely."""
    return {
        k: values[-1] if rng.random() < 0.1 else rng.choice(values[:-1])
        for k, values in MOUNT_VALUES.items()
        if k != 'damping_ratio' or rng.random() < 0.7
    }


def random_joints(n, rng):
    """A ``joints`` list for n links, each key present or left to its default; the last,
    extreme value of each key is drawn rarely, so that most such scenes run."""
    return [
        {
            k: values[-1] if rng.random() < 0.1 else rng.choice(values[:-1])
            for k, values in JOINT_VALUES.items()
            if rng.random() < 0.6
        }
        for _ in range(n)
    ]


def _resize_links(data, n, rng):
    """n links, every per-link vector resized to match (or, sometimes, left wrong)."""
    links = data.get('links')
    if not isinstance(links, list) or not links:
        return
    data['links'] = [
        dict(links[min(k, len(links) - 1)]) if isinstance(links[0], dict) else links[0]
        for k in range(n)
    ]
    if rng.random() < 0.8:
        for section, key in (
            ('controller', 'kp'),
            ('controller', 'kd'),
            ('controller', 'ki'),
            ('controller', 'down_target_deg'),
            ('controller', 'up_target_deg'),
            ('initial', 'q_deg'),
            ('initial', 'qd'),
        ):
            vector = data.get(section, {}).get(key) if isinstance(data.get(section), dict) else None
            if isinstance(vector, list) and vector:
                data[section][key] = [vector[min(k, len(vector) - 1)] for k in range(n)]
        joints = data.get('joints')
        if isinstance(joints, list) and joints:
            data['joints'] = [joints[min(k, len(joints) - 1)] for k in range(n)]


def _general_links(data, rng):
    """Links that are not uniform rods: centres of mass off mid-length and off the axis,
    inertias from a point-like to a far-spread mass (then open to the mutations below)."""
    links = data.get('links')
    if not isinstance(links, list):
        return
    for link in links:
        length, mass = (link.get(k) if isinstance(link, dict) else None for k in ('length', 'mass'))
        if not all(isinstance(v, float) and math.isfinite(v) for v in (length, mass)):
            continue
        link['com_x'] = length * rng.uniform(-0.3, 1.2)
        link['com_y'] = length * rng.uniform(-0.3, 0.3)
        link['inertia'] = mass * length * length * rng.choice((1e-7, 1e-3, 0.05, 0.3, 2.0))


def _sensors_section(rng: random.Random) -> dict:
    """A ``sensors`` section of extreme but mostly valid values (the mutations below may then
    break it): 1-count encoders, 1 rad noise, a filter far above or below the rate, 1 s of
    latency."""
    rate = rng.choice(('exact', 'difference', 'filtered'))
    section = {
        'counts_per_revolution': rng.choice((1, 3, 4096, 2**40)),
        'position_noise': rng.choice((0.0, 1e-9, 1.0)),
        'effort_noise': rng.choice((0.0, 1e6)),
        'wrench_noise': rng.choice((0.0, 1e9)),
        'rate': rate,
        'state_latency': rng.choice((0.0, 1e-9, 1.0)),
        'effort_latency': rng.choice((0.0, 0.0025, 1.0)),
        'wrench_latency': rng.choice((0.0, 1.0)),
        'seed': rng.choice((0, 2**32 - 1)),
    }
    if rate == 'filtered':
        section['rate_cutoff'] = rng.choice((1e-3, 1e6))
    elif rate == 'exact':
        section['rate_noise'] = rng.choice((0.0, 1e3))
    return section


def mutate(base: dict, rng: random.Random) -> str:
    """One mutated scene, as YAML text."""
    import copy

    import yaml

    data = copy.deepcopy(base)
    if rng.random() < 0.3 and isinstance(data.get('links'), list):
        data['joints'] = random_joints(len(data['links']), rng)
    surfaces = data.get('surfaces')
    if rng.random() < 0.2 and isinstance(surfaces, list) and surfaces:
        if isinstance(surfaces[0], dict):
            surfaces[0]['mount'] = random_mount(rng)
    if rng.random() < 0.3:
        _resize_links(data, rng.randint(3, 8), rng)
    if rng.random() < 0.3:
        _general_links(data, rng)
    if rng.random() < 0.2:  # a driver's sensors, at the edges of their ranges
        data['sensors'] = _sensors_section(rng)
    if rng.random() < 0.15 and isinstance(data.get('surfaces'), list) and data['surfaces']:
        data['surfaces'][0]['height'] = rng.choice((-3.0, -2.0, -50.0, 1e6))  # out of reach
    for _ in range(rng.choice((0, 1, 1, 2, 3))):  # 0: only the links or surfaces changed
        paths = list(key_paths(data))
        if not paths:
            break
        path = rng.choice(paths)
        parent = data
        try:
            for key in path[:-1]:
                parent = parent[key]
            action = rng.random()
            if action < 0.2 and isinstance(parent, dict):
                del parent[path[-1]]
            elif action < 0.6:
                parent[path[-1]] = rng.choice(WILD_NUMBERS)
            elif action < 0.75:
                parent[path[-1]] = rng.choice(WILD_VALUES)
            elif action < 0.85 and isinstance(parent, dict):
                parent[rng.choice(('extra', 'Gravity', 'links_', 'x' * 300))] = 1.0
            else:
                value = parent[path[-1]]
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    parent[path[-1]] = value * rng.choice((1e-9, 1e-3, 1e3, 1e9))
        except (KeyError, IndexError, TypeError):
            continue
    text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
    lines = text.splitlines()
    for _ in range(rng.choice((0, 0, 1, 2))):  # spellings only text can carry
        k = rng.randrange(len(lines))
        key, sep, _ = lines[k].partition(': ')
        kind = rng.random()
        if sep and kind < 0.6:
            lines[k] = f'{key}: {rng.choice(YAML_SNIPPETS)}'
        elif kind < 0.8:
            lines.insert(k + 1, lines[k])  # a duplicate key (or a doubled item)
        else:
            lines.insert(
                0,
                'a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1]\n'
                + '\n'.join(
                    f'a{j}: &a{j} [' + ', '.join([f'*a{j - 1}'] * 8) + ']' for j in range(1, 7)
                ),
            )
    return '\n'.join(lines) + '\n'


def malformed_commands(rng, count, n=2):
    """Float64MultiArray payloads the simulator must refuse, each certainly invalid: shorter
    than any n-double message (not empty: see the module doc; and short by 4 bytes at least:
    the middleware pads a payload to a multiple of 4 with zeros), truncated, absurd or wrong
    lengths, an unknown encapsulation, non-finite values."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray

    def array(values):
        return serialize_message(Float64MultiArray(data=values))

    good = array([0.5] * n)
    shortest = len(good)
    out = []
    while len(out) < count:
        kind = rng.randrange(6)
        if kind == 0:
            out.append(rng.randbytes(rng.randrange(1, shortest - 3)))
        elif kind == 1:
            out.append(good[: rng.randrange(1, shortest - 3)])
        elif kind == 2:  # the data length (bytes 12-15 of a layout-free array) absurd
            out.append(
                good[:12] + struct.pack('<I', rng.choice((2**31 - 1, 2**32 - 1, n + 1))) + good[16:]
            )
        elif kind == 3:
            out.append(b'\x07\x01\x00\x00' + good[4:])
        elif kind == 4:
            out.append(array([0.25] * rng.choice([k for k in range(6) if k != n])))
        else:
            values = [0.25] * n
            values[rng.randrange(n)] = rng.choice((math.nan, math.inf, -math.inf))
            out.append(array(values))
    return out
