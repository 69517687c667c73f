"""ROS 2 nodes: thin adapters of the core to topics and parameters."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
