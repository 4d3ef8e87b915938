"""
The Fast DDS profiles in config/, each read by Fast DDS with the node's /tf flowing under it.

docs/node.md, "Big robots at high rates" and "A subscriber joining holds /tf".
"""

import glob
import os
import signal
import sys

import pytest
from ros_harness import start, unique_node_name

pytestmark = pytest.mark.integration

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROFILES = sorted(glob.glob(os.path.join(ROOT, 'config', '*.xml')))

# a subscriber process of its own: the profile is read once per process, when DDS starts
SUBSCRIBER = """
import sys, time
import rclpy
from tf2_msgs.msg import TFMessage
rclpy.init()
node = rclpy.create_node(sys.argv[1])
got = []
node.create_subscription(TFMessage, '/tf', got.append, 10)
deadline = time.monotonic() + 20
while not got and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
print('received /tf' if got else 'no /tf within 20 s', flush=True)
"""


def output_after_sigint(proc):
    """Stop a process of the ``processes`` fixture and return what it printed."""
    os.killpg(proc.pid, signal.SIGINT)
    out, _ = proc.communicate(timeout=15)
    return out


def test_the_config_folder_ships_profiles():
    names = [os.path.basename(p) for p in PROFILES]
    assert 'fastdds_large_tf_localhost.xml' in names
    assert 'fastdds_short_shm_check_localhost.xml' in names


@pytest.mark.parametrize('profile', PROFILES, ids=os.path.basename)
def test_fast_dds_reads_the_profile_and_tf_flows_under_it(processes, profile):
    env = {'FASTRTPS_DEFAULT_PROFILES_FILE': profile}
    node = start(processes, 'dq_fk_node', env=env)
    start(processes, 'fake_joint_publisher', env=env)
    subscriber = processes.start(
        [sys.executable, '-c', SUBSCRIBER, unique_node_name('dq_fk_test_profile')], env=env)
    out, _ = subscriber.communicate(timeout=60)
    assert 'received /tf' in out, out
    assert 'XMLPARSER' not in out, out
    node_out = output_after_sigint(node)
    assert 'XMLPARSER' not in node_out, node_out


def test_a_damaged_profile_is_reported_so_the_check_above_can_fail(processes, tmp_path):
    text = open(os.path.join(ROOT, 'config', 'fastdds_short_shm_check_localhost.xml')).read()
    damaged = tmp_path / 'damaged.xml'
    damaged.write_text(text.replace('healthy_check_timeout_ms>', 'healthy_check_timeout>'))
    proc = processes.start(
        [sys.executable, '-c', 'import rclpy; rclpy.init(); rclpy.create_node("p")'],
        env={'FASTRTPS_DEFAULT_PROFILES_FILE': str(damaged)})
    out, _ = proc.communicate(timeout=60)
    assert 'XMLPARSER' in out and 'healthy_check_timeout' in out, out
