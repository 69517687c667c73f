"""impact_arm: a planar n-link arm striking a hard surface, simulated like real hardware.

Three ROS-free packages hold the behaviour: ``physics`` (scene, model, contact, control,
integrator, simulate, metrics), ``driver`` (the simulated arm as its driver sees it) and
``calibration`` (impacts identified and fitted, studies); ``impact_arm.nodes`` adapts them to
ROS 2.
"""

__version__ = '0.1.0'
