"""
dq_fk_view draws the robot a user knows: the vendor's meshes, the URDF's shapes, no helpers.

Vendor URDFs of example-robot-data (a dev requirement): dq_fk_node publishes them, the fake
joint publisher holds fixed joint values, dq_fk_view serves the page and the meshes the URDF
names (``--package example-robot-data=...``), and headless Chromium draws them. Every visual
of the URDF is compared with pinocchio's placement of its link times the visual's origin.
"""

import math
import os
import shutil
import time
import urllib.error
import urllib.request
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.description.shipped import shipped_robot_path
import homogeneous_tf as htf
import numpy as np
import pinocchio_oracle as oracle
from process_lines import process_lines
import pytest
from ros_harness import set_robot_file, start
from test_view import start_view, wait_for
from vendor_urdfs import robots_dir

pytestmark = pytest.mark.integration
SCREENSHOT_DIR_ENV = 'DQ_FK_VIEW_SCREENSHOTS'  # also save the pictures there (README, make)
VENDORS = {'ur5': 'ur_description/urdf/ur5_robot.urdf',
           'panda': 'panda_description/urdf/panda.urdf',
           'tiago_dual': 'tiago_description/robots/tiago_dual.urdf'}  # a whole tree


def erd_package():
    """Return ``--package example-robot-data=<its share folder>``."""
    return f'--package=example-robot-data={os.path.dirname(robots_dir())}'


def fixed_positions(model):
    """Joint values inside every joint's limits, away from zero (a pose that shows the arm)."""
    values = []
    for k, (lower, upper) in enumerate(model.limits):
        value = 0.4 if k % 2 else -0.6
        values.append(float(np.clip(value, lower, upper)) if math.isfinite(lower) else value)
    return values


def origin_matrix(element):
    """Return the 4x4 of a URDF ``<origin>`` (identity if absent)."""
    if element is None:
        return np.eye(4)
    xyz = [float(v) for v in element.get('xyz', '0 0 0').split()]
    roll, pitch, yaw = (float(v) for v in element.get('rpy', '0 0 0').split())
    from dq_fk_ros.description.robot_model import rpy_matrix
    m = np.eye(4)
    m[:3, :3] = rpy_matrix(roll, pitch, yaw)
    m[:3, 3] = xyz
    return m


def urdf_visuals(text):
    """Return ``[(link, index, kind, origin 4x4 times the mesh's scale), ...]`` per visual."""
    out = []
    for link in ElementTree.fromstring(text).findall('link'):
        for index, visual in enumerate(link.findall('visual')):
            geometry = visual.find('geometry')
            kind = geometry[0].tag if geometry is not None and len(geometry) else 'none'
            scale = np.eye(4)
            if kind == 'mesh' and geometry[0].get('scale'):
                scale[:3, :3] = np.diag([float(v) for v in geometry[0].get('scale').split()])
            out.append((link.get('name'), index, kind,
                        origin_matrix(visual.find('origin')) @ scale))
    return out


def show(processes, urdf_path, *view_args, positions=None):
    """Start the node, fixed joint states and the view for a URDF; return (model, view, url)."""
    model = load_robot(urdf_path).model
    positions = fixed_positions(model) if positions is None else positions
    node = start(processes, 'dq_fk_node', f'robot_description_file:={urdf_path}')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={urdf_path}',
          'mode:=fixed', f'positions:=[{", ".join(repr(v) for v in positions)}]',
          'rate_hz:=20.0')
    view, url = start_view(processes, erd_package(), *view_args)
    view.robot_node = node  # (the node's unique name, for its parameters)
    return model, positions, view, url


def robot_pixels(browser, tmp_path, name, timeout_s=30.0):
    """
    Return the canvas drawn with and without the robot: ``(image, mask of its pixels)``.

    Drawn at once by the page (``dqFkView.drawNow``: no waiting for the browser to show a
    frame), again until the robot has pixels or ``timeout_s`` (a loaded machine's WebGL
    may take a while to have every mesh's shaders ready). A screenshot of the page is kept.
    """
    import base64
    import io
    from matplotlib.image import imread

    def picture(visible):
        browser.execute_script(f'window.dqFkView.setRobotVisible({str(visible).lower()})')
        url = browser.execute_script('return window.dqFkView.drawNow()')
        return imread(io.BytesIO(base64.b64decode(url.split(',', 1)[1])))[:, :, :3]
    deadline = time.monotonic() + timeout_s
    while True:
        image, without = picture(True), picture(False)
        robot = np.abs(image - without).max(axis=2) > 0.05
        if robot.mean() > 0.01 or time.monotonic() > deadline:
            break
    browser.execute_script('window.dqFkView.setRobotVisible(true)')
    shot = tmp_path / f'{name}.png'
    browser.save_screenshot(str(shot))
    if os.environ.get(SCREENSHOT_DIR_ENV):
        shutil.copy(shot, os.path.join(os.environ[SCREENSHOT_DIR_ENV], f'dq_fk_view_{name}.png'))
    return image, robot


@pytest.mark.parametrize('name', sorted(VENDORS))
def test_a_vendor_robot_is_drawn_with_its_meshes_where_pinocchio_puts_them(
        name, processes, browser, tmp_path):
    urdf_path = os.path.join(robots_dir(), VENDORS[name])
    model, positions, view, url = show(processes, urdf_path)
    urdf = load_robot(urdf_path).urdf
    visuals = urdf_visuals(urdf)
    browser.get(url + '/')
    wait_for(browser, f'return window.dqFkView.visuals.length == {len(visuals)} && '
                      "window.dqFkView.visuals.every((v) => v.state == 'loaded' || "
                      "v.state == 'primitive') && window.dqFkView.visualPoses()"
                      '.every((v) => v.placed)', timeout_s=40)
    # robot_state_publisher's tree: every URDF link below the fixed frame
    wait_for(browser, 'return Object.keys(window.dqFkView.frames).length >= '
                      f'{len(model.links)}')
    page = browser.execute_script('return window.dqFkView.visualPoses()')
    assert [(v['link'], v['index'], v['kind']) for v in page] == \
        [(link, index, kind) for link, index, kind, _ in visuals]
    assert all(v['state'] == 'loaded' for v in page if v['kind'] == 'mesh')
    # every visual where pinocchio puts its link, times the visual's origin
    pin_model = oracle.urdf_model(urdf, mimic=False)
    values = dict(zip(model.joint_names, positions))
    for joint in ElementTree.fromstring(urdf).iter('joint'):  # the mimic finger's value
        mimic = joint.find('mimic')
        if mimic is not None:
            values[joint.get('name')] = float(mimic.get('multiplier', '1')) * \
                values[mimic.get('joint')] + float(mimic.get('offset', '0'))
    fixed = browser.execute_script('return window.dqFkView.fixedFrame')
    links = sorted({link for link, _, _, _ in visuals} | {fixed})
    placements = oracle.link_placements(pin_model, oracle.configuration(pin_model, values),
                                        links)
    root = np.linalg.inv(placements[fixed])
    for (link, index, kind, origin), shown in zip(visuals, page):
        expected = root @ placements[link] @ origin  # (a mirrored mesh: a negative scale)
        np.testing.assert_allclose(np.array(shown['matrix']).reshape(4, 4).T, expected,
                                   atol=1e-9, err_msg=f'{name}: {link} visual {index}')
    # no request of the page went unanswered (meshes, scripts, icon)
    failed = browser.execute_script(
        'return performance.getEntriesByType("resource").filter((e) => e.responseStatus '
        '&& e.responseStatus >= 400).map((e) => [e.name, e.responseStatus])')
    assert failed == []
    # the robot's own pixels, where the camera projects its links
    image, robot = robot_pixels(browser, tmp_path, name)
    assert robot.mean() > 0.01, 'the robot draws next to no pixels'
    near = 0
    drawn = sorted({link for link, _, kind, _ in visuals if kind == 'mesh'})
    for link in drawn:
        where = browser.execute_script(f'return window.dqFkView.project({link!r})')
        if where is None:
            continue
        row, col = int(where['y']), int(where['x'])
        near += bool(robot[max(row - 25, 0):row + 25, max(col - 25, 0):col + 25].any())
    assert near >= 0.8 * len(drawn), f'{near} of {len(drawn)} links have robot pixels'


def test_a_missing_mesh_is_a_grey_box_and_one_log_line(processes, browser, tmp_path):
    urdf_path = os.path.join(robots_dir(), VENDORS['ur5'])
    text = load_robot(urdf_path).urdf
    gone = 'package://example-robot-data/robots/ur_description/meshes/ur5/visual/forearm.dae'
    assert gone in text
    broken = tmp_path / 'ur5_broken.urdf'
    broken.write_text(text.replace(gone, gone.replace('forearm.dae', 'no_such_mesh.dae')))
    _, _, view, url = show(processes, str(broken))
    browser.get(url + '/')
    states = wait_for(browser, 'const v = window.dqFkView.visuals; return v.length == 7 && '
                               "v.every((x) => x.state == 'loaded' || x.state == "
                               "'placeholder') && v.map((x) => [x.link, x.state])",
                      timeout_s=40)
    assert dict(states) == {'base_link': 'loaded', 'shoulder_link': 'loaded',
                            'upper_arm_link': 'loaded', 'forearm_link': 'placeholder',
                            'wrist_1_link': 'loaded', 'wrist_2_link': 'loaded',
                            'wrist_3_link': 'loaded'}
    reader = process_lines(view)
    # (the line may come before the view's address, which start_view waited for)
    assert reader.first(lambda line: 'no_such_mesh' in line, 30), 'no line about the mesh'
    reader.new_lines(1.0)   # a second line would come with the first: a window for it
    lines = [line for line in reader.lines if 'no_such_mesh' in line]
    assert len(lines) == 1 and lines[0].startswith(
        'dq_fk_view: mesh package://example-robot-data/robots/ur_description/meshes/ur5/'
        'visual/no_such_mesh.dae: cannot be read (No such file or directory)')


def test_the_server_serves_only_the_current_robots_meshes(processes, listener, tmp_path):
    urdf_path = os.path.join(robots_dir(), VENDORS['ur5'])
    _, _, view, url = show(processes, urdf_path)

    def status(path):
        try:
            with urllib.request.urlopen(url + path, timeout=5) as response:
                return response.status
        except urllib.error.HTTPError as exc:
            return exc.code

    assert listener.spin_until(lambda: status('/mesh/0/base.dae') == 200, timeout_s=20)
    secret = tmp_path / 'secret.dae'
    secret.write_text('<COLLADA>secret</COLLADA>')
    for path in ('/mesh/0/../../../../etc/passwd', '/mesh/0/%2e%2e%2f%2e%2e%2fetc%2fpasswd',
                 '/mesh/0/base.stl', '/mesh/99/base.dae', '/mesh/-1/base.dae',
                 f'/mesh/0/{secret}', '/mesh/0/%2Fetc%2Fpasswd', '/mesh/x/base.dae',
                 '/vendor/../setup.py', '/mesh/0/shoulder.dae'):
        assert status(path) == 404, path
    # a robot reload: the list follows the new robot's URDF
    set_robot_file(listener, shipped_robot_path('rl15'), view.robot_node.node_name)
    assert listener.spin_until(lambda: status('/mesh/0/base.dae') == 404, timeout_s=20)


def test_helper_frames_are_hidden_until_asked_and_no_labels_overlap(processes, browser,
                                                                    tmp_path):
    start(processes, 'dq_fk_node')
    start(processes, 'fake_joint_publisher', 'mode:=fixed',
          'positions:=[0.2, 0.3, -0.2, 0.1, 0.4, -0.5]', 'rate_hz:=20.0')
    _, url = start_view(processes)
    browser.get(url + '/')
    wait_for(browser, "return window.dqFkView.frames['eeCarry_seg6'] && "
                      "window.dqFkView.frames['wrist_seg5_dh_z']")
    listed = browser.execute_script(
        "return [...document.querySelectorAll('#frame-list li')].map((li) => li.textContent)")
    assert 'eeCarry_seg6' in listed and not [n for n in listed if '_dh_z' in n]
    hidden = browser.execute_script(
        "return Object.keys(window.dqFkView.frames).filter((n) => n.endsWith('_dh_z'))"
        '.map((n) => document.querySelector(`.frame-label[data-frame="${n}"]`))'
        '.map((e) => e ? e.getBoundingClientRect().width : 0)')  # never drawn, or not shown
    assert len(hidden) == 5 and all(width == 0 for width in hidden)
    # no two visible labels overlap (their boxes, measured in the page)
    wait_for(browser, 'return new Promise((r) => setTimeout(() => r(true), 500))')
    boxes = browser.execute_script('return window.dqFkView.labelBoxes()')
    assert len(boxes) == 7
    for a in boxes:
        for b in boxes:
            if a['frame'] < b['frame']:
                overlap = (min(a['right'], b['right']) - max(a['left'], b['left']) > 0.5 and
                           min(a['bottom'], b['bottom']) - max(a['top'], b['top']) > 0.5)
                assert not overlap, (a, b)
    if os.environ.get(SCREENSHOT_DIR_ENV):
        browser.save_screenshot(os.path.join(os.environ[SCREENSHOT_DIR_ENV], 'dq_fk_view.png'))
    # the toggle shows them, in the list and in the view
    browser.find_element('id', 'show-helpers').click()
    listed = wait_for(browser, "const l = [...document.querySelectorAll('#frame-list li')]"
                               '.map((li) => li.textContent); return l.some((n) => '
                               "n.endsWith('_dh_z')) && l")
    assert len([n for n in listed if n.endswith('_dh_z')]) == 5
    assert browser.execute_script('return window.dqFkView.showHelpers') is True


PRIMITIVES = """<?xml version="1.0"?>
<robot name="shapes">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base"/>
  <link name="post">
    <visual><origin xyz="0 0 0.2" rpy="0 0 0"/><geometry><box size="0.1 0.2 0.4"/></geometry>
      <material name="red"/></visual>
  </link>
  <link name="arm">
    <visual><origin xyz="0.15 0 0" rpy="0 1.5707963267948966 0"/>
      <geometry><cylinder radius="0.03" length="0.3"/></geometry>
      <material name="green"><color rgba="0 1 0 1"/></material></visual>
  </link>
  <link name="bare"/>
  <link name="ball">
    <visual><origin xyz="0 0 0" rpy="0.3 0.2 0.1"/><geometry><sphere radius="0.05"/></geometry>
      <material name="blue"><color rgba="0 0 1 1"/></material></visual>
  </link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="post"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="post"/><child link="arm"/>
    <origin xyz="0 0 0.4" rpy="0 0 0.5"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="fixed" type="fixed"><parent link="arm"/><child link="bare"/>
    <origin xyz="0.3 0 0"/></joint>
  <joint name="j3" type="continuous"><parent link="bare"/><child link="ball"/>
    <origin xyz="0.05 0 0"/><axis xyz="1 0 0"/></joint>
</robot>
"""


def test_the_urdfs_own_shapes_with_their_colours_and_a_segment_for_a_bare_link(
        processes, browser, tmp_path):
    path = tmp_path / 'shapes.urdf'
    path.write_text(PRIMITIVES)
    model, positions, _, url = show(processes, str(path), positions=[0.4, -0.7, 1.1])
    browser.get(url + '/')
    wait_for(browser, 'return window.dqFkView.visuals.length == 3 && window.dqFkView'
                      '.visualPoses().every((v) => v.placed)')
    wait_for(browser, "return window.dqFkView.frames['ball']")
    page = browser.execute_script('return window.dqFkView.visualPoses()')
    assert [(v['link'], v['kind'], v['state']) for v in page] == [
        ('post', 'box', 'primitive'), ('arm', 'cylinder', 'primitive'),
        ('ball', 'sphere', 'primitive')]
    assert [v['color'] for v in page] == [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    pin_model = oracle.urdf_model(PRIMITIVES)
    placements = oracle.link_placements(
        pin_model, oracle.configuration(pin_model, dict(zip(model.joint_names, positions))),
        ['base', 'post', 'arm', 'ball'])
    root = np.linalg.inv(placements['base'])
    for (link, index, kind, origin), shown in zip(urdf_visuals(PRIMITIVES), page):
        np.testing.assert_allclose(
            htf.pose_matrix_of_tuple(shown['position'] + shown['quaternion']),
            root @ placements[link] @ origin, atol=1e-9, err_msg=link)
    # the links without a visual: a segment from their parent link (as dq_fk plot draws)
    assert sorted(map(tuple, browser.execute_script('return window.dqFkView.segments'))) == \
        [('arm', 'bare')]


XACRO = """<?xml version="1.0"?>
<robot name="parts" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="pkg" value="package://parts_description/meshes"/>
  <xacro:macro name="part" params="name file z">
    <link name="${name}">
      <visual><origin xyz="0 0 ${z}"/>
        <geometry><mesh filename="${pkg}/${file}" scale="0.5 0.5 0.5"/></geometry></visual>
    </link>
  </xacro:macro>
  <link name="base"/>
  <xacro:part name="obj_part" file="tetra.obj" z="0.1"/>
  <xacro:part name="stl_part" file="tetra.stl" z="0.2"/>
  <joint name="a" type="revolute"><parent link="base"/><child link="obj_part"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="obj_part"/><child link="stl_part"/>
    <origin xyz="0.3 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>
"""
TETRA = [(0, 0, 0), (0.2, 0, 0), (0, 0.2, 0), (0, 0, 0.2)]
FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def test_obj_and_stl_meshes_of_a_xacro_package(processes, browser, tmp_path):
    package = tmp_path / 'parts_description'
    (package / 'meshes').mkdir(parents=True)
    (package / 'urdf').mkdir()
    (package / 'package.xml').write_text('<package><name>parts_description</name></package>')
    (package / 'meshes' / 'tetra.obj').write_text(
        ''.join(f'v {x} {y} {z}\n' for x, y, z in TETRA) +
        ''.join(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in FACES))
    (package / 'meshes' / 'tetra.stl').write_text(
        'solid tetra\n' + ''.join(
            'facet normal 0 0 0\nouter loop\n' +
            ''.join(f'vertex {TETRA[k][0]} {TETRA[k][1]} {TETRA[k][2]}\n' for k in face) +
            'endloop\nendfacet\n' for face in FACES) + 'endsolid tetra\n')
    xacro = package / 'urdf' / 'parts.urdf.xacro'
    xacro.write_text(XACRO)
    start(processes, 'dq_fk_node', f'robot_description_file:={xacro}')
    start(processes, 'fake_joint_publisher', f'robot_description_file:={xacro}',
          'mode:=fixed', 'positions:=[0.5, -0.8]', 'rate_hz:=20.0')
    _, url = start_view(processes, f'--package=parts_description={package}')
    browser.get(url + '/')
    page = wait_for(browser, 'const v = window.dqFkView.visualPoses(); return v.length == 2 && '
                             "v.every((x) => x.state == 'loaded' && x.placed) && v",
                    timeout_s=30)
    assert [(v['link'], v['uri']) for v in page] == [
        ('obj_part', 'package://parts_description/meshes/tetra.obj'),
        ('stl_part', 'package://parts_description/meshes/tetra.stl')]
    # where the URDF puts them, their scale included
    c, s = math.cos(0.5), math.sin(0.5)
    obj_link = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    c2, s2 = math.cos(-0.8), math.sin(-0.8)
    stl_link = obj_link @ np.array([[1, 0, 0, 0.3], [0, c2, -s2, 0], [0, s2, c2, 0],
                                    [0, 0, 0, 1]])
    half = np.diag([0.5, 0.5, 0.5, 1.0])
    for shown, link, z in ((page[0], obj_link, 0.1), (page[1], stl_link, 0.2)):
        lift = np.eye(4)
        lift[2, 3] = z
        np.testing.assert_allclose(np.array(shown['matrix']).reshape(4, 4).T,
                                   link @ lift @ half, atol=1e-9, err_msg=shown['link'])
