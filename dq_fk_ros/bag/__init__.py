"""Bag layer: reading, processing and writing rosbag2 files with rosbags; no rclpy."""
