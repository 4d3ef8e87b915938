"""
Fixtures shared by every test: DDS isolation and process clean-up.

One fixture owns DDS isolation: the pytest process and every process a test starts run
with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID`` that no other test
run on this machine holds at the same time. Both fixtures are the package's own pytest
plugin's (dq_fk_ros.testing.plugin, docs/testing.md), which users get with the package.
"""

import os

from hypothesis import HealthCheck, settings
import pytest

# Property-based fuzzing (hypothesis): a modest example count keeps `make test` fast; set
# DQ_FK_FUZZ=long for a deeper search (e.g. before a release, or after changing an input path).
settings.register_profile('ci', max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile('long', max_examples=2000, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get('DQ_FK_FUZZ', 'ci'))


@pytest.fixture(scope='session', autouse=True)
def ros_domain_id(dq_fk_domain):
    """
    Isolate DDS for the whole run: the plugin's ``dq_fk_domain``, for every test.

    A private domain id with loopback discovery (dq_fk_ros.testing.domains), one per
    pytest-xdist worker: the harness users get is the one these tests run on.
    """
    return dq_fk_domain


@pytest.fixture
def processes(dq_fk_processes):
    """Start processes that see only this run's DDS domain; all stopped at teardown."""
    return dq_fk_processes
