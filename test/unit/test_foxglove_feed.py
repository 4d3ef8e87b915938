"""dq_fk_foxglove's plain parts: its layout file, the mesh assets, the missing-SDK line."""

import json
import os

from dq_fk_ros.description.meshes import MeshAssets
from dq_fk_ros.description.packages import PackageResolver
from dq_fk_ros.viewers.foxglove_live import MISSING, parse_args
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_the_shipped_layout_reads_the_topics_the_node_and_the_server_publish():
    layout = json.load(open(os.path.join(ROOT, 'docs', 'foxglove_layout.json')))
    panels = layout['configById']
    assert {layout['layout']['first'], layout['layout']['second']} == set(panels)
    urdf = [layer for layer in panels['3D!dqfk']['layers'].values()
            if layer['layerId'] == 'foxglove.Urdf']
    assert urdf == [{'layerId': 'foxglove.Urdf', 'label': 'robot_description',
                     'sourceType': 'topic', 'topic': '/robot_description', 'visible': True}]
    # the RL15's end effector on the node's default pose namespace
    plotted = {p['value'].rsplit('.pose.', 1)[0] for p in panels['Plot!dqfk']['paths']}
    assert plotted == {'/dq_fk_node/pose/eeCarry_seg6'} == set(panels['3D!dqfk']['topics'])


def test_mesh_assets_serve_the_urdfs_meshes_and_nothing_else(tmp_path):
    package = tmp_path / 'arm_description'
    (package / 'meshes').mkdir(parents=True)
    (package / 'package.xml').write_text('<package><name>arm_description</name></package>')
    (package / 'meshes' / 'a.stl').write_bytes(b'solid a\nendsolid\n')
    (package / 'meshes' / 'b.stl').write_bytes(b'solid b\nendsolid\n')
    (tmp_path / 'secret.stl').write_bytes(b'not yours')
    os.symlink(tmp_path / 'secret.stl', package / 'meshes' / 'link.stl')
    urdf = ('<robot name="r"><link name="l"><visual><geometry><mesh '
            'filename="package://arm_description/meshes/a.stl"/></geometry></visual>'
            '<visual><geometry><mesh filename="package://arm_description/meshes/link.stl"/>'
            '</geometry></visual></link></robot>')
    assets = MeshAssets(PackageResolver({'arm_description': str(package)}))
    assert assets.fetch('package://arm_description/meshes/a.stl') is None  # no URDF yet
    problems = assets.replace(urdf)
    assert len(problems) == 1 and 'link.stl' in problems[0] and 'outside' in problems[0]
    assert assets.fetch('package://arm_description/meshes/a.stl') == b'solid a\nendsolid\n'
    for uri in ('package://arm_description/meshes/b.stl',  # in the package, not the URDF
                'package://arm_description/meshes/link.stl',  # a link out of the package
                'package://arm_description/meshes/../../secret.stl',
                f'file://{tmp_path}/secret.stl', str(tmp_path / 'secret.stl'), None, 7):
        assert assets.fetch(uri) is None, uri
    assets.replace('<robot name="r"><link name="l"/></robot>')  # a new URDF: a new list
    assert assets.fetch('package://arm_description/meshes/a.stl') is None


def test_options_are_checked_with_one_line(capsys):
    assert parse_args([]).host == '127.0.0.1' and parse_args([]).port == 8765
    for argv, words in ((['--port', '70000'], '--port 70000'), (['--rate', '0'], '--rate 0'),
                        (['--mesh-dir', '/no/such/dir'], '--mesh-dir /no/such/dir'),
                        (['--package', 'nameonly'], 'NAME=DIR')):
        with pytest.raises(SystemExit):
            parse_args(argv)
        assert words in capsys.readouterr().err
    assert 'pip install "dq_fk_ros[foxglove]"' in MISSING
