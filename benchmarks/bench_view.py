"""
dq_fk_view under load: latency from a JointState to the pose in the page, and its CPU.

Processes: dq_fk_node (RL15), dq_fk_view, headless Chromium showing the page (Selenium),
and this script publishing JointStates at each rate (stamped with the send time; the node
stamps its TF with it, the view passes the newest TF stamp to the page, which notes when
each poses message arrived). Latency = arrival in the page - JointState stamp, over every
poses message of the window; the view sends at most ``--view-rate`` poses messages a second,
so at high input rates most JointStates are (by design) never shown: the figure is the age
of what the page shows. CPU: the view process's user + system time over the window (/proc).

Run with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a private ROS_DOMAIN_ID (``make bench``
sets both): ``python benchmarks/bench_view.py [--rates 100 1000] [--seconds 10]``.
"""

import argparse
import os
import select
import shutil
import signal
import subprocess
import sys
import time

from dq_fk_ros.ros.executables import executable
import numpy as np
import rclpy
from sensor_msgs.msg import JointState

NAMES = [f'joint_{k}' for k in range(1, 7)]


def cpu_seconds(pid):
    """Return the user + system CPU seconds of a process (Linux /proc)."""
    with open(f'/proc/{pid}/stat', encoding='ascii') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def start_view(rate):
    proc = subprocess.Popen(executable('dq_fk_view') + ['--port', '0', '--rate', str(rate)],
                            stdout=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if select.select([proc.stdout], [], [], 0.2)[0]:
            line = proc.stdout.readline()
            if line.startswith('dq_fk_view: open '):
                return proc, line.split('open ', 1)[1].strip()
    raise SystemExit('dq_fk_view did not start')


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    if not shutil.which('chromium'):
        raise SystemExit('bench_view needs chromium and chromium-driver (apt-get install '
                         'chromium chromium-driver)')
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which('chromium')
    for flag in ('--headless=new', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
                 '--enable-unsafe-swiftshader', '--disable-background-networking',
                 '--window-size=1280,800'):
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(shutil.which('chromedriver')), options=options)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--rates', type=float, nargs='+', default=[100.0, 1000.0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--view-rate', type=float, default=30.0)
    args = parser.parse_args(argv)
    node = subprocess.Popen(executable('dq_fk_node') + ['--ros-args', '--log-level', 'warn'],
                            start_new_session=True)
    view, url = start_view(args.view_rate)
    driver = browser()
    rclpy.init()
    probe = rclpy.create_node('dq_fk_bench_view')
    pub = probe.create_publisher(JointState, 'joint_states', 100)
    rows = []
    try:
        driver.get(url)
        msg = JointState(name=NAMES, position=[0.0] * 6)
        deadline = time.monotonic() + 30
        while not driver.execute_script('return window.dqFkView && '
                                        'window.dqFkView.arrivals.length > 0'):
            msg.header.stamp = probe.get_clock().now().to_msg()
            pub.publish(msg)
            time.sleep(0.05)
            if time.monotonic() > deadline:
                raise SystemExit('the page never got poses')
        for rate in args.rates:
            driver.execute_script('window.dqFkView.arrivals = []')
            period = 1.0 / rate
            start_cpu, start = cpu_seconds(view.pid), time.monotonic()
            next_send, sent, k = start, 0, 0
            while time.monotonic() - start < args.seconds:
                now = time.monotonic()
                if now < next_send:
                    time.sleep(min(next_send - now, 0.001))
                    continue
                k += 1
                msg.position = [0.5 * np.sin(0.01 * k + j) for j in range(6)]
                msg.header.stamp = probe.get_clock().now().to_msg()
                pub.publish(msg)
                sent += 1
                next_send += period
            elapsed = time.monotonic() - start
            cpu = (cpu_seconds(view.pid) - start_cpu) / elapsed * 100.0
            time.sleep(0.3)
            arrivals = driver.execute_script('return window.dqFkView.arrivals')
            latency = np.array([arrival - stamp / 1e6 for stamp, arrival in arrivals
                                if stamp > 0])
            rows.append((rate, sent / elapsed, len(latency), np.percentile(latency, 50),
                         np.percentile(latency, 99), cpu))
    finally:
        driver.quit()
        probe.destroy_node()
        rclpy.try_shutdown()
        for proc in (view, node):
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=10)
    print(f'# dq_fk_view: JointState -> pose in the page (headless Chromium), RL15, '
          f'{args.seconds:g} s per rate, view rate {args.view_rate:g}/s')
    print('| input Hz | sent/s | poses messages in the page | p50 ms | p99 ms | view CPU % |')
    print('|---|---|---|---|---|---|')
    for rate, achieved, count, p50, p99, cpu in rows:
        print(f'| {rate:g} | {achieved:.0f} | {count} | {p50:.1f} | {p99:.1f} | {cpu:.1f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
