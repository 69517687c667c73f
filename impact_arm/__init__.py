"""impact_arm: a planar n-link arm striking a hard surface, simulated like real hardware.

The core (scene, model, contact, control, integrator, simulate, metrics) is plain Python/numpy
with no rclpy import; ``impact_arm.nodes`` adapts it to ROS 2.
"""

__version__ = '0.1.0'
