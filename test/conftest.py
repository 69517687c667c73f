"""Shared fixtures. Every test process keeps DDS on this machine (CONTRIBUTING.md). The tests
mirror the package in folders (test/physics, test/driver, ...); their helpers, stand-in scripts
and paths are in test/support, importable by name from every folder. The benchmarks' package
(bench/impact_arm_bench) is importable: some tests check its helpers."""

import os
import random
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), 'support'))
sys.path.insert(
    0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'bench')
)

from ros_helpers import domain_range

# the DDS fixtures (ros_env, probe) for every test module, without importing them by name
pytest_plugins = ('ros_helpers',)

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.choice(domain_range())))


def pytest_collection_modifyitems(config, items):
    """A test that asks for a ROS environment or the probe node talks DDS: mark it so."""
    import pytest

    for item in items:
        if {'ros_env', 'probe'} & set(getattr(item, 'fixturenames', ())):
            item.add_marker(pytest.mark.dds)
