"""ament_flake8 over the package, as ``ros2 pkg create`` sets it up (Jazzy configuration)."""

import os

from ament_flake8.main import main_with_errors
import pytest

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CHECKED = ['dq_fk_ros', 'test', 'benchmarks', 'setup.py']


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    paths = [os.path.join(PACKAGE_ROOT, p) for p in CHECKED
             if os.path.exists(os.path.join(PACKAGE_ROOT, p))]
    rc, errors = main_with_errors(argv=paths)
    assert rc == 0, 'Found %d code style errors / warnings:\n' % len(errors) + '\n'.join(errors)
