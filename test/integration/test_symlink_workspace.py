"""
Description packages as ROS 2 developers build them: ``colcon build --symlink-install``.

The test makes a real workspace of two ament_cmake description packages (colcon and
ament_cmake are test requirements): ``arm_macros`` installs a xacro macro and a mesh,
``arm_description`` a xacro that includes the macro through ``$(find arm_macros)`` and so names
``package://arm_macros/meshes/link.stl``. With ``--symlink-install`` every installed file is
a link into ``src/``. Sourced as usual (``AMENT_PREFIX_PATH``), the xacro expands as xacro's
own command line expands it and the mesh is served byte for byte; a name that leaves its
package as text, or a link to another file name, is still refused.
"""

import os
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.meshes import MeshAssets
from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.description.urdf_reader import read_urdf_text
from dq_fk_ros.description.xacro_sandbox import default_read_roots
from dq_fk_ros.errors import RobotDescriptionError
import pytest

pytestmark = pytest.mark.integration

VENV = os.path.dirname(os.path.dirname(sys.executable))
MESH = b'solid link\nendsolid link\n'
PACKAGE_XML = ('<?xml version="1.0"?><package format="3"><name>{0}</name>'
               '<version>0.0.1</version><description>test</description>'
               '<maintainer email="dev@example.com">dev</maintainer><license>MIT</license>'
               '<buildtool_depend>ament_cmake</buildtool_depend>'
               '<export><build_type>ament_cmake</build_type></export></package>')
CMAKE = ('cmake_minimum_required(VERSION 3.8)\nproject({0} NONE)\n'
         'find_package(ament_cmake REQUIRED)\n'
         'install(DIRECTORY urdf meshes DESTINATION share/${{PROJECT_NAME}})\nament_package()\n')
MACROS = ('<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
          '<xacro:macro name="arm_link" params="name"><link name="${name}"><visual><geometry>'
          '<mesh filename="package://arm_macros/meshes/link.stl"/></geometry></visual></link>'
          '</xacro:macro></robot>')
ARM = ('<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">'
       '<xacro:include filename="$(find arm_macros)/urdf/macros.xacro"/>'
       '<xacro:arm_link name="base"/><xacro:arm_link name="l1"/>'
       '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
       '<axis xyz="0 0 1"/><origin xyz="0 0 ${0.1 * 3}"/>'
       '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    """Build the workspace with --symlink-install; return ``(ws, sourced environment)``."""
    ws = tmp_path_factory.mktemp('desc_ws')
    for name in ('arm_macros', 'arm_description'):
        for folder in ('urdf', 'meshes'):
            (ws / 'src' / name / folder).mkdir(parents=True)
        (ws / 'src' / name / 'package.xml').write_text(PACKAGE_XML.format(name))
        (ws / 'src' / name / 'CMakeLists.txt').write_text(CMAKE.format(name))
    (ws / 'src' / 'arm_macros' / 'meshes' / 'link.stl').write_bytes(MESH)
    (ws / 'src' / 'arm_macros' / 'urdf' / 'macros.xacro').write_text(MACROS)
    (ws / 'src' / 'arm_description' / 'urdf' / 'arm.urdf.xacro').write_text(ARM)
    (ws / 'src' / 'arm_description' / 'meshes' / 'keep.stl').write_bytes(MESH)
    env = dict(os.environ, AMENT_PREFIX_PATH=VENV, CMAKE_PREFIX_PATH=VENV,
               PATH=f'{VENV}/bin:{os.environ["PATH"]}')
    build = subprocess.run([os.path.join(VENV, 'bin', 'colcon'), 'build', '--symlink-install'],
                           cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    sourced = subprocess.run(['bash', '-c', '. install/setup.sh && echo $AMENT_PREFIX_PATH'],
                             cwd=ws, env=env, capture_output=True, text=True, check=True)
    return ws, dict(env, AMENT_PREFIX_PATH=sourced.stdout.strip())


def test_the_install_space_is_links_into_src(workspace):
    ws, env = workspace
    mesh = ws / 'install' / 'arm_macros' / 'share' / 'arm_macros' / 'meshes' / 'link.stl'
    assert mesh.is_symlink() and os.path.realpath(mesh) == \
        str(ws / 'src' / 'arm_macros' / 'meshes' / 'link.stl')
    assert str(ws / 'install' / 'arm_macros') in env['AMENT_PREFIX_PATH'].split(os.pathsep)


def test_a_xacro_including_another_packages_macros_expands_as_xacro_does(
        workspace, monkeypatch):
    ws, env = workspace
    monkeypatch.setenv('AMENT_PREFIX_PATH', env['AMENT_PREFIX_PATH'])
    path = ws / 'install' / 'arm_description' / 'share' / 'arm_description' / 'urdf' / \
        'arm.urdf.xacro'
    ours = read_urdf_text(path, default_read_roots(path))
    theirs = subprocess.run([os.path.join(VENV, 'bin', 'xacro'), str(path)], env=env,
                            capture_output=True, text=True, check=True).stdout

    def canonical(text):
        return ElementTree.canonicalize(text, strip_text=True)
    assert canonical(ours) == canonical(theirs)
    assert 'package://arm_macros/meshes/link.stl' in ours and '0.3' in ours


def test_its_meshes_are_served_byte_for_byte_and_nothing_else(workspace, tmp_path):
    ws, env = workspace
    resolver = PackageResolver(environ=env, python=())
    share = ws / 'install' / 'arm_macros' / 'share' / 'arm_macros'
    (tmp_path / 'secret.stl').write_bytes(b'solid secret\nendsolid\n')
    other = share / 'meshes' / 'other.stl'
    if not other.is_symlink():  # a link to another name: not one a build makes
        os.symlink(tmp_path / 'secret.stl', other)
    uris = ['package://arm_macros/meshes/link.stl',
            'package://arm_macros/meshes/other.stl',
            'package://arm_macros/../arm_description/meshes/keep.stl',
            'package://arm_macros/meshes/%2e%2e/%2e%2e/arm_description/meshes/keep.stl',
            f'file://{ws}/src/arm_macros/meshes/link.stl',
            f'{ws}/src/arm_macros/meshes/link.stl']
    urdf = '<robot name="r">' + ''.join(
        f'<link name="l{k}"><visual><geometry><mesh filename="{u}"/></geometry></visual>'
        f'</link>' for k, u in enumerate(uris)) + '</robot>'
    assets = MeshAssets(resolver)
    problems = assets.replace(urdf)
    assert assets.fetch(uris[0]) == MESH
    for uri in uris[1:]:
        assert assets.fetch(uri) is None, uri
    assert len(problems) == 5 and all('secret' not in p for p in problems)


def test_a_xacro_that_leaves_its_package_as_text_is_still_refused(
        workspace, monkeypatch, tmp_path):
    ws, env = workspace
    monkeypatch.setenv('AMENT_PREFIX_PATH', env['AMENT_PREFIX_PATH'])
    (tmp_path / 'secret.xacro').write_text('<robot name="secret"><link name="s"/></robot>')
    folder = tmp_path / 'mine'
    folder.mkdir()
    depth = len(str(ws).strip('/').split('/')) + 8
    escape = '/'.join(['..'] * depth) + str(tmp_path / 'secret.xacro')
    path = folder / 'robot.urdf.xacro'
    path.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                    f'<xacro:include filename="$(find arm_macros)/{escape}"/>'
                    '<link name="a"/></robot>')
    with pytest.raises(RobotDescriptionError, match='refused, outside'):
        read_urdf_text(path, default_read_roots(path))
