"""tf2_ros.buffer_interface: dq_fk_ros.ros.tf_registration (a re-export)."""

from dq_fk_ros.ros.tf_registration import *  # noqa: F401,F403
from dq_fk_ros.ros.tf_registration import __all__  # noqa: F401
