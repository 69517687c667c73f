"""The physics: scene, equations and the generated kernel, contact and control laws, the phase
integrator, metrics and offline runs. No ROS imports; imports nothing else of the package but
``contract``."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
