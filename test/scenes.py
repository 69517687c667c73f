"""Small scene builders for tests: the article's scene with a few fields changed."""

import copy
import os

import yaml

from impact_arm.physics.scene import parse_scene

PAPER = os.path.join(os.path.dirname(__file__), '..', 'config', 'paper.yaml')


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
