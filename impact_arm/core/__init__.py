"""The physics and integrator core: scene, equations and the generated kernel, contact and
control laws, the phase integrator, metrics, the simulated arm (driver). No ROS imports."""
