"""sensor_msgs_py where the environment has none: its point_cloud2 (dq_fk_ros's)."""
