"""ROS 2 nodes: thin adapters of the core to topics and parameters."""
