"""
Headless demo: run dq_fk_node with the default robot for a few seconds, then stop it.

Run as ``python -m dq_fk_ros.demo`` (``make demo``), with ``ROS_DOMAIN_ID`` and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` set by the caller.
"""

import argparse
import os
import signal
import subprocess
import sys
import time


def main(argv=None):
    """Start the node as its own process, let it run ``--seconds``, stop it with SIGINT."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=3.0,
                        help='how long the node runs before the demo stops it (default 3)')
    args = parser.parse_args(argv)
    print(f"demo: ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')} "
          f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}")
    node = subprocess.Popen([sys.executable, '-m', 'dq_fk_ros.node'])
    try:
        time.sleep(args.seconds)
    finally:
        node.send_signal(signal.SIGINT)
        rc = node.wait(timeout=10)
    print(f'demo: dq_fk_node stopped (exit code {rc})')
    return rc


if __name__ == '__main__':
    sys.exit(main())
