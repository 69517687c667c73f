"""Shared fixtures. Every test process keeps DDS on this machine (see DEVELOPERS notes)."""
import os
import random

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
