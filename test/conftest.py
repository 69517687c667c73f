"""Shared fixtures. Every test process keeps DDS on this machine (see DEVELOPERS notes)."""
import os
import random

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
_low, _, _high = os.environ.get('IMPACT_ARM_TEST_DOMAINS', '1-100').partition('-')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(int(_low), int(_high))))
