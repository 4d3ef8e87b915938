"""sensor_msgs_py.point_cloud2: dq_fk_ros.ros.point_cloud2 (a re-export)."""

from dq_fk_ros.ros.point_cloud2 import *  # noqa: F401,F403
from dq_fk_ros.ros.point_cloud2 import __all__  # noqa: F401
