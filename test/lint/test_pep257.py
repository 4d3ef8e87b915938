"""ament_pep257 over the package, as ``ros2 pkg create`` sets it up."""

import os

from ament_pep257.main import main
import pytest

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CHECKED = ['dq_fk_ros', 'test', 'benchmarks']


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    paths = [os.path.join(PACKAGE_ROOT, p) for p in CHECKED
             if os.path.exists(os.path.join(PACKAGE_ROOT, p))]
    rc = main(argv=paths)
    assert rc == 0, 'Found code style errors / warnings'
