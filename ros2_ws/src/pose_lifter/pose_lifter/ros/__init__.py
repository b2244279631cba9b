"""The ROS 2 shell, the only subpackage that imports rclpy: nodes, parameters, checks, markers,
diagnostics."""
