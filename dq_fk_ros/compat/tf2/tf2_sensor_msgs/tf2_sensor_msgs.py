"""tf2_sensor_msgs.tf2_sensor_msgs: dq_fk_ros.ros.tf_cloud (a re-export)."""

from dq_fk_ros.ros.tf_cloud import *  # noqa: F401,F403
from dq_fk_ros.ros.tf_cloud import __all__  # noqa: F401
