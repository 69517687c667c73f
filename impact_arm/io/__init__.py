"""Message and file I/O: message definitions, CDR on the hot path, the ROS 2 MCAP writer and
reader, the offline recorder, the replay schedule, URDF and scene visuals."""
