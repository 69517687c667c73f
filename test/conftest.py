"""Shared fixtures. Every test process keeps DDS on this machine (see DEVELOPERS notes)."""
import os
import random

from ros_helpers import domain_range

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.choice(domain_range())))


def pytest_collection_modifyitems(config, items):
    """A test that asks for a ROS environment or the probe node talks DDS: mark it so."""
    import pytest
    for item in items:
        if {'ros_env', 'probe'} & set(getattr(item, 'fixturenames', ())):
            item.add_marker(pytest.mark.dds)
