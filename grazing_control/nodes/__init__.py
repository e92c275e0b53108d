"""ROS 2 node adapters; the only part of grazing_control that imports rclpy."""
