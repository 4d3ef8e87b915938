"""
``dq_fk show ROBOT``: the node and the view with a joint panel, driven from a real browser.

The robot is a small URDF written here (a revolute joint with limits, a mimic of it, a
prismatic joint), so that the transforms a slider must give are written down by hand from
the URDF: a rotation of q about z, the mimic's 2 q + 0.1, a slide of d along x.
"""

import math
import os
import signal
import time

from dq_fk_ros.ros.executables import executable
from dq_fk_ros.testing import wait_until
from proc_table import proc_stat, processes as live
from process_lines import process_lines
import pytest
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration

URDF = """<?xml version="1.0"?>
<robot name="panel_bot">
  <link name="base"/><link name="arm"/><link name="hand"/><link name="slide"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="0 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-1.2" upper="1.0" effort="1" velocity="1"/>
  </joint>
  <joint name="wrist" type="revolute">
    <parent link="arm"/><child link="hand"/><origin xyz="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="shoulder" multiplier="2" offset="0.1"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="hand"/><child link="slide"/><origin xyz="0.2 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0.05" upper="0.4" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def start_show(processes, *args):
    """Start ``dq_fk show`` on a free port; return ``(process, lines, base URL)``."""
    proc = processes.start(executable('dq_fk') + ['show', *args, '--port', '0'])
    lines = process_lines(proc)
    line = lines.until(lambda text: text.startswith('dq_fk show: open '), timeout_s=30)
    assert line is not None, ''.join(lines.lines)
    return proc, lines, line.split('open ', 1)[1].split()[0].rstrip('/')


def children(proc):
    """Return the live processes ``dq_fk show`` started."""
    return live(lambda pid: int(proc_stat(pid)[1]) == proc.pid and proc_stat(pid)[0] != b'Z')


def z_turn(transform, angle):
    """Whether ``transform``'s rotation is ``angle`` rad about z (quaternion x y z w)."""
    r = transform.transform.rotation
    expected = (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))
    sign = 1.0 if r.w >= 0 else -1.0
    return all(abs(sign * a - b) < 1e-6 for a, b in zip((r.x, r.y, r.z, r.w), expected))


def test_a_slider_moves_its_link_mimics_follow_and_ctrl_c_stops_it_all(
        processes, browser, listener, tmp_path):
    robot = tmp_path / 'panel_bot.urdf'
    robot.write_text(URDF)
    proc, lines, url = start_show(processes, str(robot))
    assert len(children(proc)) == 2   # dq_fk_node and dq_fk_view
    latest = {}   # child frame -> its newest transform on /tf
    listener.probe.create_subscription(TFMessage, '/tf', lambda msg: latest.update(
        {t.child_frame_id: t for t in msg.transforms}), 100)
    browser.get(url + '/')
    sliders = {}
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and set(sliders) != {'shoulder', 'rail'}:
        sliders = {e.get_attribute('data-joint'): e for e in
                   browser.find_elements('css selector', '#joints input[type=range]')}
        time.sleep(0.1)
    assert set(sliders) == {'shoulder', 'rail'}  # the mimic has none
    assert (sliders['shoulder'].get_attribute('min'), sliders['shoulder'].get_attribute('max'),
            sliders['rail'].get_attribute('min')) == ('-1.2', '1', '0.05')
    # the prismatic joint's range does not hold 0: it starts in the middle of it
    assert listener.spin_until(lambda: 'slide' in latest and abs(
        latest['slide'].transform.translation.x - (0.2 + 0.225)) < 1e-9)
    assert z_turn(latest['hand'], 0.1)
    # the user drags the slider: an input event on the range element, as the browser sends
    browser.execute_script(
        "const s = document.querySelector('#joints input[data-joint=\"shoulder\"]');"
        "s.value = '0.7'; s.dispatchEvent(new Event('input'));")
    assert listener.spin_until(lambda: z_turn(latest['arm'], 0.7), timeout_s=10), latest['arm']
    assert z_turn(latest['hand'], 2 * 0.7 + 0.1)   # the mimic, computed by the node
    assert abs(latest['arm'].transform.translation.z - 0.5) < 1e-12
    shown = browser.execute_script('return window.dqFkView.mimics.wrist')
    assert abs(shown - 1.5) < 1e-9
    # beyond its limit: held to it, as the slider itself would
    assert browser.execute_script("return window.dqFkView.setJoint('shoulder', 5)")
    assert listener.spin_until(lambda: z_turn(latest['arm'], 1.0), timeout_s=10)
    browser.find_element('id', 'reset-joints').click()
    assert listener.spin_until(lambda: z_turn(latest['arm'], 0.0), timeout_s=10)
    pids = children(proc)
    os.killpg(proc.pid, signal.SIGINT)   # Ctrl-C in the terminal
    assert proc.wait(timeout=20) == 0, ''.join(lines.lines)
    assert wait_until(lambda: not [p for p in pids if os.path.exists(f'/proc/{p}')], 5)


def test_a_robot_that_does_not_load_is_one_line_and_starts_nothing(processes, tmp_path):
    robot = tmp_path / 'broken.urdf'
    robot.write_text('<robot name="x"><link name="a"/><joint name="j" type="revolute">')
    proc = processes.start(executable('dq_fk') + ['show', str(robot), '--port', '0'])
    out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert out.count('\n') == 1 and out.startswith(f'dq_fk show: {robot}'), out


def test_a_process_that_ends_ends_the_show_with_a_line_saying_which(processes, tmp_path):
    proc, lines, url = start_show(processes, 'rl15')
    node = [p for p in children(proc) if b'dq_fk_node' in
            open(f'/proc/{p}/cmdline', 'rb').read()]
    assert len(node) == 1
    view = [p for p in children(proc) if p not in node]
    os.kill(node[0], signal.SIGKILL)
    assert proc.wait(timeout=20) == 1
    assert lines.until(lambda text: 'dq_fk_node ended' in text, timeout_s=5) is not None, \
        ''.join(lines.lines)
    assert wait_until(lambda: not [p for p in view if os.path.exists(f'/proc/{p}')], 5)
