"""Bag layer: processing bags (one, a window, a fleet), discovery of work, progress; no rclpy."""
