"""Fixtures of the integration tests: a test-side rclpy context on the private domain."""

import pytest
from ros_harness import Harness


@pytest.fixture
def listener(ros_domain_id):
    """Yield a :class:`ros_harness.Harness` (probe node, publishers, spin loop); close it."""
    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()
