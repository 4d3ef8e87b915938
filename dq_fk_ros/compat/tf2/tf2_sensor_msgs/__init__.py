"""tf2_sensor_msgs for code written for it: dq_fk_ros.ros.tf_cloud (a re-export)."""

from dq_fk_ros.ros.tf_cloud import do_transform_cloud, transform_points  # noqa: F401

__all__ = ['do_transform_cloud', 'transform_points']
