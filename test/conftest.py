"""Shared fixtures. Every test process keeps DDS on this machine (see DEVELOPERS notes)."""
import os
import random

from ros_helpers import domain_range

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.choice(domain_range())))
