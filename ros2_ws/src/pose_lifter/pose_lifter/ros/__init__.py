"""The ROS 2 shell, the only subpackage that imports rclpy: nodes, parameters, checks, markers,
statistics and diagnostics (one counter), and the one run loop of every executable."""
