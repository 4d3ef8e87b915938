"""
What the test fixtures of dq_fk_ros.testing cost (docs/testing.md): seconds, best and worst.

For each of ``--repeat`` rounds, on a domain claimed here as ``dq_fk_domain`` claims it:
the claim; ``dq_fk_robot('rl15')`` until ``wait_for('world', 'eeCarry_seg6')`` answers (the
node, the joint source and the listener started, the first TF received); a
``set_joints`` round trip (until TF shows the joints); the teardown (every process
stopped). No target: the figures are what a user's test pays.

Run: ``python benchmarks/bench_testing.py [--repeat 5]`` (``make bench``).
"""

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from bench_results import figure  # noqa: E402

GROUP = 'The test fixtures'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--repeat', type=int, default=5)
    args = parser.parse_args(argv)
    from dq_fk_ros.testing.domains import claim_domain, isolate_environment, \
        restore_environment
    from dq_fk_ros.testing.robot import RobotFactory
    times = {'claim': [], 'start': [], 'set_joints': [], 'teardown': []}
    for k in range(args.repeat):
        begin = time.perf_counter()
        claim = claim_domain()
        times['claim'].append(time.perf_counter() - begin)
        saved = isolate_environment(os.environ, claim.domain_id)
        factory = RobotFactory()
        try:
            begin = time.perf_counter()
            robot = factory('rl15')
            robot.wait_for('world', 'eeCarry_seg6')
            times['start'].append(time.perf_counter() - begin)
            begin = time.perf_counter()
            robot.set_joints({'joint_2': 0.1 * (k + 1)})
            times['set_joints'].append(time.perf_counter() - begin)
        finally:
            begin = time.perf_counter()
            factory.close_all()
            times['teardown'].append(time.perf_counter() - begin)
            restore_environment(os.environ, saved)
            claim.release()
    print(f'The test fixtures (dq_fk_ros.testing), {args.repeat} rounds, best / worst:')
    for what, label in (('claim', 'dq_fk_domain: claim a domain'),
                        ('start', "dq_fk_robot('rl15') until its first TF"),
                        ('set_joints', 'set_joints until TF shows them'),
                        ('teardown', 'teardown: every process stopped')):
        best, worst = min(times[what]) * 1e3, max(times[what]) * 1e3
        figure(f'{label} (worst {worst:.0f} ms)', best, 'ms', group=GROUP)
    return 0


if __name__ == '__main__':
    sys.exit(main())
