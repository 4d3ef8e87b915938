"""The ``package_paths`` parameter the package's nodes share: where ``$(find NAME)`` is."""

from dq_fk_ros.description.packages import parse_package_option
from dq_fk_ros.errors import ParameterError
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

DESCRIPTION = ('for a xacro: packages as NAME=DIR (string array), found before the ament '
               'index, ROS_PACKAGE_PATH and the folders above the file')


def declare_package_paths(node) -> dict:
    """
    Declare ``package_paths`` (read only) on ``node``; return ``{name: folder}``.

    Not given: no explicit packages. A malformed entry or a missing folder raises
    :class:`~dq_fk_ros.errors.ParameterError` with one line.
    """
    node.declare_parameter('package_paths', Parameter.Type.STRING_ARRAY,
                           ParameterDescriptor(description=DESCRIPTION, read_only=True))
    try:
        entries = node.get_parameter('package_paths').value
    except ParameterUninitializedException:  # not given
        return {}
    try:
        return dict(parse_package_option(e, 'parameter package_paths:') for e in entries)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None


__all__ = ['declare_package_paths']
