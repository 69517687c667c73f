"""Message and file I/O: message definitions, CDR on the hot path, the ROS 2 MCAP writer and
reader, the offline recorder, the replay schedule, URDF and scene visuals."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
