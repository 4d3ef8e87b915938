"""Install dq_fk_ros as an ament_python package (colcon) or editable into a venv (pip)."""

from glob import glob
import os
import re
import runpy

from setuptools import Extension, find_packages, setup
from setuptools.command.develop import develop as _develop
from setuptools.command.install_scripts import install_scripts as _install_scripts

package_name = 'dq_fk_ros'
# the version is written once, in the package (an MCAP file's header names it)
with open('dq_fk_ros/__init__.py', encoding='utf-8') as init:
    version = re.search(r"^__version__ = '([^']+)'", init.read(), re.M)[1]
# the compiled kernel, one file per surface (the module, Chain, Model; kernel_*.h shared)
KERNEL_SOURCES = ['dq_fk_ros/kinematics/_kernel.c', 'dq_fk_ros/kinematics/_kernel_chain.c',
                  'dq_fk_ros/kinematics/_kernel_model.c']
# the node's publishes through rcl (many publishers a call): where rcl's headers are (PyPI
# wheels or a sourced ROS 2), else the node calls rclpy's publish_raw
# (realpath: colcon build --symlink-install runs a link to this file from build/dq_fk_ros)
RCL = runpy.run_path(os.path.join(os.path.dirname(os.path.realpath(__file__)), 'scripts',
                                  'rcl_build.py'))['rcl_paths']()
RCL_EXTENSIONS = [] if RCL is None else [
    Extension('dq_fk_ros.ros._rcl_publish', ['dq_fk_ros/ros/_rcl_publish.c'],
              include_dirs=RCL[0], library_dirs=[RCL[1]], runtime_library_dirs=[RCL[1]],
              libraries=['rcl', 'rmw', 'rcutils'], extra_compile_args=['-O2'], optional=True)]
# tf2_msgs (not on PyPI) carried in the wheel of a pip install, built by rosidl from
# vendor/tf2_msgs in pip's build environment (pyproject.toml); nothing where it is importable
TF2_MSGS = runpy.run_path(os.path.join(os.path.dirname(os.path.realpath(__file__)), 'scripts',
                                       'tf2_msgs_build.py'))
TF2_MSGS_PARTS = {'packages': [], 'package_dir': {}, 'package_data': {}, 'data_files': []}
if TF2_MSGS['wanted']():
    TF2_MSGS_PARTS = TF2_MSGS['wheel_parts'](TF2_MSGS['build'](os.path.join('build', 'tf2_msgs')))

# the programs (console scripts); ros2 run finds them in lib/dq_fk_ros (setup.cfg)
CONSOLE_SCRIPTS = {
    'dq_fk_node': 'dq_fk_ros.ros.executables:run_dq_fk_node',
    'dq_fk': 'dq_fk_ros.cli.dq_fk:main',
    'fake_joint_publisher': 'dq_fk_ros.ros.executables:run_fake_joint_publisher',
    'dq_fk_bag': 'dq_fk_ros.cli.interrupts:run_dq_fk_bag',
    'dq_fk_view': 'dq_fk_ros.ros.executables:run_dq_fk_view',
    'dq_fk_foxglove': 'dq_fk_ros.ros.executables:run_dq_fk_foxglove',
}


def direct_script(name, contents):
    """
    Return console script ``name`` that imports its function, as pip writes one from a wheel.

    ``setup.py develop`` (an editable pip install) and ``install`` (colcon's ament_python)
    write a script that looks its function up through ``importlib.metadata``: ~30 ms of every
    start here (it imports the email package and reads the installed distributions'
    metadata). The first line (the interpreter) is kept. test_ament_layout.py (colcon) and
    test_processes.py (this install) check the scripts installed.
    """
    if name not in CONSOLE_SCRIPTS:
        return contents
    module, function = CONSOLE_SCRIPTS[name].split(':')
    header = contents.splitlines(keepends=True)[0]
    return (f'{header}# {name}: {module}:{function} (dq_fk_ros setup.py, direct_script)\n'
            f'import sys\n\nfrom {module} import {function}\n\n'
            f"if __name__ == '__main__':\n    sys.exit({function}())\n")


class develop(_develop):
    """``setup.py develop`` (pip install -e) writing :func:`direct_script` scripts."""

    def write_script(self, script_name, contents, *args, **kwargs):
        return super().write_script(script_name, direct_script(script_name, contents),
                                    *args, **kwargs)


class install_scripts(_install_scripts):
    """``setup.py install`` (colcon) writing :func:`direct_script` scripts."""

    def write_script(self, script_name, contents, *args, **kwargs):
        return super().write_script(script_name, direct_script(script_name, contents),
                                    *args, **kwargs)


setup(
    name=package_name,
    version=version,
    packages=find_packages(exclude=['test', 'test.*']) + TF2_MSGS_PARTS['packages'],
    package_dir=TF2_MSGS_PARTS['package_dir'],
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xml')),
        ('share/' + package_name + '/web', ['web/index.html', 'web/app.js', 'web/package.json',
                                            'web/package-lock.json']),
    ] + TF2_MSGS_PARTS['data_files'],
    # the tf2 compat path (dq_fk tf compat-path): folders of re-exports, not packages
    package_data=dict(TF2_MSGS_PARTS['package_data'],
                      dq_fk_ros=['compat/README.md', 'compat/*/*/*.py']),
    # the compiled FK kernel: optional (without a C compiler the numpy path runs); -O3
    # vectorises its batch loops; no contraction into fused multiply-adds, so it computes
    # what the reference computes
    # the CDR writer of the node's messages: optional too (the struct packer runs without)
    ext_modules=[Extension('dq_fk_ros.kinematics._kernel', KERNEL_SOURCES,
                           depends=glob('dq_fk_ros/kinematics/kernel_*.h'),
                           extra_compile_args=['-O3', '-ffp-contract=off', '-fno-fast-math'],
                           optional=True),
                 Extension('dq_fk_ros.messages._cdr', ['dq_fk_ros/messages/_cdr.c'],
                           depends=['dq_fk_ros/messages/c_arguments.h'],
                           extra_compile_args=['-O2'], optional=True),
                 # MCAP chunks read and written without a Python object per record
                 # (dq_fk_bag process; optional too: the numpy paths run without)
                 Extension('dq_fk_ros.storage._mcap', ['dq_fk_ros/storage/_mcap.c'],
                           depends=['dq_fk_ros/messages/c_arguments.h'],
                           extra_compile_args=['-O2'], optional=True),
                 # tf2's lookup walk over BufferCore's arrays (dq_fk_ros.tf; optional: the
                 # Python reference runs without); the reference's operations, not contracted
                 Extension('dq_fk_ros.transforms._tf', ['dq_fk_ros/transforms/_tf.c'],
                           depends=['dq_fk_ros/transforms/tf_math.h',
                                    'dq_fk_ros/transforms/tf_cache.h'],
                           extra_compile_args=['-O2', '-ffp-contract=off', '-fno-fast-math'],
                           optional=True)] + RCL_EXTENSIONS,
    # what `pip install dq_fk_ros` needs to run every program (requirements/runtime.txt pins
    # the versions tested); ROS 2 Jazzy's wheels from PyPI. A ROS 2 install builds with colcon,
    # which reads package.xml and installs none of these.
    install_requires=['setuptools', 'numpy', 'PyYAML', 'ros-jazzy-rclpy[fastrtps]',
                      'ros-jazzy-common-interfaces', 'rosbags>=0.11', 'mcap>=1.2', 'xacro>=2.0',
                      'aiohttp>=3.9', 'matplotlib>=3.7'],
    # dq_fk_bag process --scheduler: a Dask cluster (pip install 'dq_fk_ros[cluster]')
    # dq_fk_foxglove: the Foxglove SDK's WebSocket server (pip install 'dq_fk_ros[foxglove]')
    # dq_fk calibrate: Levenberg-Marquardt (pip install 'dq_fk_ros[calibrate]')
    extras_require={'calibrate': ['scipy'], 'cluster': ['dask[distributed]'],
                    'foxglove': ['foxglove-sdk>=0.30']},
    zip_safe=True,
    maintainer='dq_fk_ros developers',
    maintainer_email='dq_fk_ros@example.com',
    description='Dual-quaternion forward kinematics from a YAML DH table, published to ROS 2.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={'console_scripts': [f'{name} = {target}'
                                      for name, target in CONSOLE_SCRIPTS.items()],
                  # the fixtures of dq_fk_ros.testing, in every pytest run once installed
                  'pytest11': ['dq_fk_ros = dq_fk_ros.testing.plugin']},
    cmdclass={'develop': develop, 'install_scripts': install_scripts},
)
