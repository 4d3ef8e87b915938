"""tf2_geometry_msgs for code written for it: dq_fk_ros.ros.tf_geometry (a re-export)."""

from dq_fk_ros.ros.tf_geometry import *  # noqa: F401,F403
from dq_fk_ros.ros.tf_geometry import __all__  # noqa: F401
