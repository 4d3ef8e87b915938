"""
dq_fk_view in a real browser (Debian's headless Chromium) and against WebSocket clients.

Every program runs as its own process on this run's private DDS domain: dq_fk_node, the
fake joint publisher and dq_fk_view; the page's state (``window.dqFkView``) is read through
Selenium and compared with the core FK of the published joints.
"""

import asyncio
import json
import os
import shutil
import time
import xml.etree.ElementTree as ElementTree

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path
from dq_fk_ros.description.to_urdf import robot_to_urdf
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
from dq_fk_ros.ros.executables import executable
import homogeneous_tf as htf
import numpy as np
from proc_table import listening
from process_lines import process_lines
import pytest
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_harness import set_robot_file, start

pytestmark = pytest.mark.integration

RL15_Q = [0.2, 0.3, -0.2, 0.1, 0.4, -0.5]
SCREENSHOT_ENV = 'DQ_FK_VIEW_SCREENSHOT'  # also save the screenshot there (README picture)


def start_view(processes, *args):
    """Start dq_fk_view on a free port; return ``(process, base URL)`` once it listens."""
    proc = processes.start(executable('dq_fk_view') + ['--port', '0', *args])
    reader = process_lines(proc)  # keeps what comes before the address (a mesh's problem)
    line = reader.until(lambda text: text.startswith('dq_fk_view: open '), timeout_s=20)
    if line is None:
        raise AssertionError(f'dq_fk_view did not start: {"".join(reader.lines)}')
    return proc, line.split('open ', 1)[1].strip().rstrip('/')


def wait_for(driver, script, timeout_s=20.0):
    """Run ``script`` in the page until it returns something true; return that."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f'the page never gave {script!r}')


def test_the_page_shows_every_frame_where_the_kinematics_put_it(
        processes, browser, tmp_path, listener):
    model = load_robot_description(shipped_robot_path('rl15'))
    node = start(processes, 'dq_fk_node')
    fake = start(processes, 'fake_joint_publisher', 'mode:=fixed',
                 f'positions:=[{", ".join(str(v) for v in RL15_Q)}]', 'rate_hz:=20.0')
    _, url = start_view(processes, '--stale-after', '0.6')
    browser.get(url + '/')
    urdf_links = sorted(link.get('name') for link in
                        ElementTree.fromstring(robot_to_urdf(model)).iter('link'))
    wait_for(browser, f'return window.dqFkView && window.dqFkView.robotLinks.length == '
                      f'{len(urdf_links)} && Object.keys(window.dqFkView.frames).length == '
                      f'{len(urdf_links) - 1}')
    state = browser.execute_script('return window.dqFkView')
    assert sorted(state['robotLinks']) == urdf_links  # the URDF, placed by TF
    assert state['fixedFrame'] == 'world' and state['selected'] == 'eeCarry_seg6'
    expected = homogeneous_from_dq(model.chain.forward_all(np.array(RL15_Q)))
    for name, m in zip(model.frame_names, expected):
        frame = state['frames'][name]
        np.testing.assert_allclose(htf.pose_matrix_of_tuple(frame['position'] +
                                                            frame['quaternion']),
                                   m, atol=1e-9, err_msg=name)
        assert not frame['stale']
    # the panel: the end effector's pose, as the paper's RViz panel shows it
    pose = state['frames']['eeCarry_seg6']
    lines = browser.find_element('id', 'selected-pose').text.split('\n')
    assert lines == ['position x y z', ' '.join(f'{v:.6f}' for v in pose['position']),
                     'quaternion x y z w', ' '.join(f'{v:.6f}' for v in pose['quaternion'])]
    assert browser.find_element('id', 'selected-name').text == 'eeCarry_seg6'
    # the picture: not blank, and the end effector's name where the camera puts its origin
    # two animation frames later, whatever had changed is drawn (the page draws on change)
    browser.set_script_timeout(20)
    assert browser.execute_async_script(
        'const done = arguments[arguments.length - 1];'
        'requestAnimationFrame(() => requestAnimationFrame(() => done(true)));')
    shot = tmp_path / 'view.png'
    browser.save_screenshot(str(shot))
    if os.environ.get(SCREENSHOT_ENV):
        shutil.copy(shot, os.environ[SCREENSHOT_ENV])
    from matplotlib.image import imread
    image = imread(shot)[:, :, :3]
    assert (np.abs(image - image[5, 5]).max(axis=2) > 0.1).mean() > 0.02, 'a blank picture'
    where = browser.execute_script("return window.dqFkView.project('eeCarry_seg6')")
    assert 0 < where['x'] < image.shape[1] - 100 and 10 < where['y'] < image.shape[0] - 10
    label = browser.execute_script(
        "const r = document.querySelector('.frame-label[data-frame=\"eeCarry_seg6\"]')"
        '.getBoundingClientRect(); return {left: r.left, top: r.top, bottom: r.bottom};')
    assert abs(label['left'] - where['x']) < 2.0
    assert abs((label['top'] + label['bottom']) / 2 - where['y']) < 2.0
    row, col = int(where['y']), int(where['x'])
    text = image[row - 6:row + 6, col + 2:col + 90]
    assert (text.max(axis=2) < 0.35).sum() > 15, \
        f'the name is not drawn there: {where}, {label}, {image.shape}, {shot}'
    # clicking another frame's name selects it
    browser.execute_script(
        "document.querySelector('.frame-label[data-frame=\"elbow_seg3\"]')"
        ".dispatchEvent(new PointerEvent('pointerdown', {bubbles: true}))")
    assert wait_for(browser, "return window.dqFkView.selected == 'elbow_seg3' && "
                             "document.getElementById('selected-name').textContent")
    # joint states stop: the moving frames grey out, the static ones do not
    fake.send_signal(2)
    fake.wait(timeout=10)
    wait_for(browser, "return window.dqFkView.frames['eeCarry_seg6'].stale")
    state = browser.execute_script('return window.dqFkView.frames')
    assert not state['base_seg0']['stale'] and not state['wrist_seg5_dh_z']['stale']
    assert 'stale' in browser.find_element(
        'css selector', '.frame-label[data-frame="eeCarry_seg6"]').get_attribute('class')
    # a robot reload: the page rebuilds the model from the new description
    version = browser.execute_script('return window.dqFkView.robotVersion')
    set_robot_file(listener, shipped_robot_path('puma560'), node.node_name)
    links = wait_for(browser, f'return window.dqFkView.robotVersion > {version} && '
                              f'window.dqFkView.robotLinks')
    assert 'puma_link6' in links and 'eeCarry_seg6' not in links


async def _client(session, url, count=1, timeout_s=15.0):
    """Connect to the view's WebSocket; return it and its first ``count`` messages."""
    ws = await session.ws_connect(url.replace('http', 'ws') + '/ws')
    messages = []
    deadline = time.monotonic() + timeout_s
    while len(messages) < count and time.monotonic() < deadline:
        msg = await ws.receive(timeout=max(deadline - time.monotonic(), 0.1))
        messages.append(json.loads(msg.data))
    return ws, messages


async def _until(ws, predicate, timeout_s=15.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = await ws.receive(timeout=max(deadline - time.monotonic(), 0.1))
        data = json.loads(msg.data)
        if predicate(data):
            return data
    raise AssertionError('no such message')


async def _status(session, url):
    async with session.get(url + '/status') as response:
        return await response.json()


def test_the_server_with_many_rude_and_early_clients(processes, listener):
    import aiohttp
    view, url = start_view(processes)
    port = int(url.rsplit(':', 1)[1])

    async def scenario():
        async with aiohttp.ClientSession() as session:
            # a page opened before any robot is known: it gets both once they come
            early, none = await _client(session, url, count=0)
            assert none == []
            node = start(processes, 'dq_fk_node')
            start(processes, 'fake_joint_publisher', 'rate_hz:=100.0')
            robot = await _until(early, lambda m: m['type'] == 'robot')
            assert 'eeCarry_seg6' in robot['urdf']
            await _until(early, lambda m: m['type'] == 'frames' and len(m['frames']) == 12)
            # 20 pages at once: each has the robot and the frames
            many = [await _client(session, url, count=2) for _ in range(20)]
            for _, first in many:
                assert sorted(m['type'] for m in first) == ['frames', 'robot']
            assert (await _status(session, url))['clients'] == 21
            # one goes away mid-stream without closing: the others go on
            many[0][0]._response.connection.transport.abort()
            for ws, _ in many[1:]:
                await _until(ws, lambda m: m['type'] == 'frames')
            # rude input: binary, not JSON, unknown, too big; counted, nobody harmed
            rude = many[1][0]
            await rude.send_bytes(b'\x00\x01')
            await rude.send_str('not json')
            await rude.send_str('{"type": "shutdown"}')
            await many[2][0].send_str('x' * 100_000)
            await rude.send_str('{"type": "hello"}')
            for _ in range(50):
                counts = await _status(session, url)
                if counts['bad_input'] >= 4 and counts['clients'] <= 19:
                    break
                await asyncio.sleep(0.1)
            assert counts['bad_input'] == 4 and counts['clients'] == 19
            await _until(rude, lambda m: m['type'] == 'frames')
            # a robot reload: the pages get the new description
            client = AsyncParameterClient(listener.probe, node.node_name)
            assert client.wait_for_services(timeout_sec=10.0)
            future = client.set_parameters([Parameter(
                'robot_description_file', value=shipped_robot_path('panda'))])
            listener.spin_until(future.done)
            assert future.result().results[0].successful
            robot = await _until(early, lambda m: m['type'] == 'robot')
            assert 'panda_link7' in robot['urdf']
            for ws in [early] + [ws for ws, _ in many[1:]]:
                await ws.close()

    asyncio.run(scenario())
    assert listening([view.pid]) == {('0100007F', port)}  # loopback only, nothing else


def test_a_bag_played_into_the_node_drives_the_view(processes, tmp_path):
    """``dq_fk_bag play`` -> dq_fk_node -> dq_fk_view: the page gets the bag's poses."""
    import aiohttp
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    model = load_robot_description(shipped_robot_path('rl15'))
    q = np.array([0.4, -0.3, 0.2, 0.1, -0.6, 0.5])
    t0 = 1_600_000_000_000_000_000
    stamps = [t0 + k * 20_000_000 for k in range(200)]  # 4 s at 50 Hz
    with Writer(tmp_path / 'bag', version=9) as writer:
        conn = writer.add_connection('/joint_states', 'sensor_msgs/msg/JointState',
                                     typestore=store)
        for stamp in stamps:
            header = types['std_msgs/msg/Header'](stamp=types['builtin_interfaces/msg/Time'](
                sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id='')
            msg = types['sensor_msgs/msg/JointState'](
                header=header, name=list(model.joint_names), position=q,
                velocity=np.zeros(0), effort=np.zeros(0))
            writer.write(conn, stamp, bytes(store.serialize_cdr(
                msg, 'sensor_msgs/msg/JointState')))
    start(processes, 'dq_fk_node')
    _, url = start_view(processes)
    processes.start(executable('dq_fk_bag') + ['play', str(tmp_path / 'bag'), '--loop',
                                               '--quiet', '--wait-for-subscribers', '1'])

    async def scenario():
        async with aiohttp.ClientSession() as session:
            ws, _ = await _client(session, url, count=0)
            message = await _until(ws, lambda m: m['type'] == 'frames' and
                                   m['stamp_ns'] in stamps, timeout_s=30)
            await ws.close()
            return message

    message = asyncio.run(scenario())
    poses = {f[0]: f[2:9] for f in message['frames']}
    expected = homogeneous_from_dq(model.chain.forward(q).coeffs)
    np.testing.assert_allclose(htf.pose_matrix_of_tuple(poses['eeCarry_seg6']), expected,
                               atol=1e-9)


def test_foreign_pages_and_hosts_are_refused(processes):
    """
    Refuse other sites' pages and rebinding hosts (403); long paths and deep JSON are harmless.

    /ws streamed the URDF and the poses to ``Origin: http://evil.example`` and to a rebinding
    ``Host``; a long URL gave a 500 with a traceback; nested JSON a RecursionError.
    """
    import aiohttp
    view, url = start_view(processes)
    start(processes, 'dq_fk_node')
    port = url.rsplit(':', 1)[1]

    async def scenario():
        async with aiohttp.ClientSession() as session:
            for headers in ({'Origin': 'http://evil.example'},
                            {'Origin': f'http://evil.example:{port}'},
                            {'Origin': 'null'},
                            {'Host': f'evil.example:{port}'},
                            {'Host': f'attacker.127.0.0.1.nip.example:{port}'},
                            {'Host': f'evil.example:{port}',
                             'Origin': f'http://evil.example:{port}'}):
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await session.ws_connect(url.replace('http', 'ws') + '/ws',
                                             headers=headers)
                assert refused.value.status == 403, headers
            async with session.get(url + '/status', headers={'Host': 'evil.example'}) as r:
                assert r.status == 403
            # its own page, by each loopback name, still works
            for own in (url, url.replace('127.0.0.1', 'localhost')):
                ws = await session.ws_connect(own.replace('http', 'ws') + '/ws',
                                              headers={'Origin': own})
                await _until(ws, lambda m: m['type'] == 'robot')
                await ws.send_str('[' * 30_000 + ']' * 30_000)      # 60 KB of nesting
                await ws.close()
            for path in ('/vendor/three/' + 'a' * 5000, '/' + 'b' * 5000,
                         '/vendor/three/..%2f..%2f..%2fetc%2fpasswd'):
                async with session.get(url + path) as r:
                    body = await r.text()
                    assert r.status in (403, 404) and 'Traceback' not in body, (path, r.status)
            for _ in range(50):
                counts = await _status(session, url)
                if counts['bad_input'] >= 2:
                    break
                await asyncio.sleep(0.1)
            assert (counts['bad_input'], counts['refused_origins'],
                    counts['refused_hosts']) == (2, 3, 4), counts

    asyncio.run(scenario())
    assert view.poll() is None


def test_allow_host_adds_a_name(processes):
    import aiohttp
    _, url = start_view(processes, '--allow-host', 'robot.local')
    port = url.rsplit(':', 1)[1]

    async def scenario():
        async with aiohttp.ClientSession() as session:
            async with session.get(url + '/status',
                                   headers={'Host': f'robot.local:{port}'}) as r:
                assert r.status == 200
            async with session.get(url + '/status', headers={'Host': f'other:{port}'}) as r:
                assert r.status == 403

    asyncio.run(scenario())


def test_half_sent_requests_cannot_take_the_server(processes):
    """1100 connections that never finish their headers: /status answers, stderr stays quiet."""
    import socket
    import urllib.request
    proc, url = start_view(processes)
    port = int(url.rsplit(':', 1)[1])
    held = []
    try:
        for _ in range(1100):  # more than a process's 1024 descriptors
            sock = socket.create_connection(('127.0.0.1', port))
            sock.sendall(b'GET / HTTP/1.1\r\nHost: 127.0.0.1')
            held.append(sock)
        # the deadline: answered within 10 s while the 1100 are held (an eviction each)
        with urllib.request.urlopen(url + '/status', timeout=10) as response:
            status = json.loads(response.read())
        assert status['evicted_connections'] >= 1100 - 256
    finally:
        for sock in held:
            sock.close()
    with urllib.request.urlopen(url + '/status', timeout=10) as response:
        assert response.status == 200   # it serves on, once the flood has gone
    assert proc.poll() is None
    proc.send_signal(2)
    out, err = proc.communicate(timeout=10)
    said = (out or '') + (err or '')  # (the harness may join stderr to stdout)
    assert 'Traceback' not in said and 'out of system resource' not in said, said[-2000:]
    assert len(said) < 2000, said[-2000:]


def test_ctrl_c_stops_it_with_pages_open_even_one_that_never_reads(processes):
    """Open pages held aiohttp's stop for its 60 s shutdown timeout (dq_fk show killed it)."""
    import aiohttp
    import signal
    node = start(processes, 'dq_fk_node')
    view, url = start_view(processes)

    async def scenario():
        async with aiohttp.ClientSession() as session:
            # the robot, once the node's description reached the view (on connecting, or
            # later: a loaded machine's first message was 'frames'; fresh-clone run, seed
            # 2722394477)
            reader, _ = await _client(session, url, count=0)
            await _until(reader, lambda m: m['type'] == 'robot')
            silent = await session.ws_connect(url.replace('http', 'ws') + '/ws',
                                              autoclose=False)   # never answers a close
            os.killpg(view.pid, signal.SIGINT)
            loop = asyncio.get_running_loop()
            code = await loop.run_in_executor(None, lambda: view.wait(timeout=8))
            await silent.close()
            return code

    assert asyncio.run(scenario()) == 0
    assert node.poll() is None
