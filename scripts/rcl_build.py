"""
Where rcl's headers and library are, for building dq_fk_ros.ros._rcl_publish.

Looked for in this Python's prefix (ROS 2 from PyPI wheels: ``<venv>/include/rcl/rcl``,
``<venv>/lib/librcl.so``), then in every prefix of ``AMENT_PREFIX_PATH`` (a sourced ROS 2
install: ``/opt/ros/jazzy``). setup.py builds the extension only where they are found (else
the node publishes through rclpy's ``publish_raw``); ``scripts/sanitize`` prints them with
``python scripts/rcl_build.py`` (gcc flags, nothing where there is no rcl).
"""

import os
import sys

# the include directories rcl/publisher.h needs (ROS 2 installs a directory per package)
PACKAGES = ('rcl', 'rcutils', 'rmw', 'rosidl_runtime_c', 'rosidl_typesupport_interface',
            'rosidl_dynamic_typesupport', 'rcl_yaml_param_parser', 'type_description_interfaces',
            'service_msgs', 'builtin_interfaces')


def rcl_paths():
    """Return ``(include_dirs, library_dir)`` of the first prefix with rcl, or None."""
    ament = os.environ.get('AMENT_PREFIX_PATH', '')
    prefixes = [sys.prefix] + [p for p in ament.split(os.pathsep) if p]
    for prefix in prefixes:
        include = os.path.join(prefix, 'include')
        lib = os.path.join(prefix, 'lib')
        if os.path.isfile(os.path.join(include, 'rcl', 'rcl', 'publisher.h')) and \
                os.path.isfile(os.path.join(lib, 'librcl.so')):
            dirs = [os.path.join(include, name) for name in PACKAGES]
            return [d for d in dirs if os.path.isdir(d)], lib
    return None


if __name__ == '__main__':
    found = rcl_paths()
    if found:
        includes, lib = found
        print(' '.join([f'-I{d}' for d in includes] + [f'-L{lib}', '-lrcl', '-lrmw', '-lrcutils',
                                                       f'-Wl,-rpath,{lib}']))
