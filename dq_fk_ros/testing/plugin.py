"""
The pytest plugin of dq_fk_ros: ``pip install dq_fk_ros`` registers it (entry point ``pytest11``).

Fixtures (docs/testing.md):

* ``dq_fk_domain`` (session; one per pytest-xdist worker): a ROS domain id no other process
  on the machine holds or uses (:mod:`dq_fk_ros.testing.domains`), set with loopback
  discovery in ``os.environ`` for the tests and every process they start; the id is given.
* ``dq_fk_processes``: a :class:`~dq_fk_ros.testing.processes.ProcessPool` on that domain;
  what it started is stopped at the test's end.
* ``dq_fk_robot``: a :class:`~dq_fk_ros.testing.robot.RobotFactory`:
  ``robot = dq_fk_robot('rl15', joints={'joint_2': 0.5})``; every robot closed at the end.

Importing this module imports neither rclpy nor the package's ROS modules: a pytest run in
an environment with dq_fk_ros installed pays nothing for the plugin until a test asks for
one of its fixtures.
"""

import os
from typing import Iterator

import pytest


@pytest.fixture(scope='session')
def dq_fk_domain() -> Iterator[int]:
    """Yield this test process's private ROS domain id, set in the environment (module doc)."""
    from dq_fk_ros.testing.domains import claim_domain, isolate_environment, \
        restore_environment
    claim = claim_domain()
    saved = isolate_environment(os.environ, claim.domain_id)
    try:
        yield claim.domain_id
    finally:
        restore_environment(os.environ, saved)
        claim.release()


@pytest.fixture
def dq_fk_processes(dq_fk_domain: int) -> Iterator[object]:
    """Yield a ProcessPool whose processes run on the private domain; all stopped afterwards."""
    from dq_fk_ros.testing.processes import ProcessPool
    pool = ProcessPool()
    try:
        yield pool
    finally:
        pool.stop_all()


@pytest.fixture
def dq_fk_robot(dq_fk_domain: int) -> Iterator[object]:
    """Yield a RobotFactory on the private domain; every robot it made closed afterwards."""
    from dq_fk_ros.testing.robot import RobotFactory
    factory = RobotFactory()
    try:
        yield factory
    finally:
        factory.close_all()
