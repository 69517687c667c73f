"""Small scene builders for tests: the article's scene with a few fields changed; and an
impact record of a given pose (``impact_at``)."""

import copy
import os

import yaml

from impact_arm.physics.impact import Impact
from impact_arm.physics.scene import parse_scene
from repo_paths import CONFIG

PAPER = os.path.join(CONFIG, 'paper.yaml')


def paper_dict():
    with open(PAPER, encoding='utf-8') as f:
        return yaml.safe_load(f.read().replace('e9', 'e+9'))


def scene_from(changes=None, **top):
    """The article's scene, with nested ``changes`` {('controller', 'law'): 'pid'} and top-level
    keyword overrides applied."""
    data = copy.deepcopy(paper_dict())
    for path, value in (changes or {}).items():
        node = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    data.update(top)
    return parse_scene(data, origin='test')


# arms of more links, for the paths that must run any arm the offline path runs: link
# lengths and masses, then per joint (kp, kd, ki, down target, up target, initial angle)
# with absolute angles in degrees; each stable sampled at 1 kHz (physics/stability.py), as
# the lockstep runs and simulate --control-rate 1000 sample them
_ARMS = {
    3: (
        [(0.7, 1.0), (0.7, 1.0), (0.6, 0.8)],
        [(600, 100, 1000, -80, 80, 60), (150, 50, 120, -70, 70, 45), (75, 25, 60, -60, 60, 30)],
    ),
    4: (
        [(0.6, 1.0), (0.5, 1.0), (0.5, 0.8), (0.4, 0.8)],
        [
            (600, 100, 1000, -80, 80, 60),
            (150, 30, 120, -70, 70, 45),
            (75, 15, 60, -60, 60, 30),
            (30, 4, 30, -50, 50, 20),
        ],
    ),
}


def arm_dict(n_links, cycles=2, t_max=10.0):
    """The article's scene with an arm of ``n_links`` (3 or 4) links and its controller,
    ``cycles`` down/up cycles: YAML data for a scene file."""
    links, joints = _ARMS[n_links]
    data = copy.deepcopy(paper_dict())
    data['name'] = f'arm{n_links}'
    data['description'] = f'{n_links}-link arm striking the floor (test scene)'
    data['links'] = [{'length': length, 'mass': mass} for length, mass in links]
    controller = data['controller']
    for key, column in (('kp', 0), ('kd', 1), ('ki', 2)):
        controller[key] = [float(j[column]) for j in joints]
    controller['down_target_deg'] = [float(j[3]) for j in joints]
    controller['up_target_deg'] = [float(j[4]) for j in joints]
    data['initial'] = {'q_deg': [float(j[5]) for j in joints], 'qd': [0.0] * n_links}
    data['cycles'], data['t_max'] = cycles, t_max
    return data


def write_arm_scene(directory, n_links, **kwargs) -> str:
    """``arm_dict`` written as DIRECTORY/armN.yaml; returns the path."""
    path = os.path.join(os.fspath(directory), f'arm{n_links}.yaml')
    with open(path, 'w', encoding='utf-8') as f:
        yaml.safe_dump(arm_dict(n_links, **kwargs), f, sort_keys=False)
    return path


# docs/model.md, "What the article reports, and what the package gives" (truncated: 1 % band)
ARTICLE_FIRST_IMPACT = {
    'duration': 1.44e-4,
    'delta_m': 3.53e-4,
    'delta_r': 2.84e-4,
    'F_max': 2.77e4,
    'v_before': [-3.66, -5.54],
    'v_after': [-2.43, 2.23],
    'cor_kinematic': 0.40,
    'T_before': [2.46, 13.95, 16.40],
    'T_after': [4.43, 6.56, 11.02],
    'cor_energetic': [1.34, 0.69, 0.82],
}


def impact_at(q_deg, index=1, t_contact=0.001, F_max=100.0, v_before=(-3.7, -5.5)) -> Impact:
    """A whole impact record whose contact, maximum compression and separation all show the
    absolute link angles ``q_deg`` (made-up numbers elsewhere: for what draws or compares
    impacts, not for their physics)."""
    q = tuple(float(a) for a in q_deg)
    n = len(q)
    return Impact(
        index=index,
        t_contact=t_contact,
        q_contact_deg=q,
        joints_contact_deg=q,
        duration=1.4e-4,
        delta_m=3.5e-4,
        delta_r=2.8e-4,
        F_max=F_max,
        v_before=(float(v_before[0]), float(v_before[1])),
        v_after=(-2.4, 2.2),
        cor_kinematic=0.4,
        T_before=(1.0,) * n + (float(n),),
        T_after=(0.5,) * n + (n / 2,),
        cor_energetic=(0.7,) * (n + 1),
        phase_durations=(1e-6, 9.9e-5, 4e-5),
        q_max_compression_deg=q,
        q_separation_deg=q,
    )
