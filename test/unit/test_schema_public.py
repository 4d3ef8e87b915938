"""What a robot file's error may say to a peer: the file's own words only if it is one."""

from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.errors import RobotDescriptionError
import pytest

CHAIN = """
robot: arm
base: {frame: b0}
chain:
  - {frame: l1, joint: j1, theta: 0, d: 0.1, a: hunter2, alpha: 0}
"""
CHAINS = """
robot: arm
chains:
  - parent: world
    base: {frame: b0}
    chain:
      - {frame: l1, joint: j1, theta: 0, d: 0.1, a: hunter2, alpha: 0}
"""
GENERIC = 'not a robot description'


def public(text):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(text, 'f.yaml')
    return caught.value.public


@pytest.mark.parametrize('text', [CHAIN, CHAINS])
def test_a_robot_file_with_a_mistake_says_which_field_in_public(text):
    said = public(text)
    assert GENERIC not in said and "'a'" in said


@pytest.mark.parametrize('text', [
    CHAIN + 'password: hunter2\n',            # a field of no robot file: no robot file
    CHAIN.replace('robot: arm', '1: hunter2\nrobot: arm'),   # a key that is no name
    CHAIN.replace('base: {frame: b0}\n', ''),   # a chain without a base
    CHAIN.replace('chain:', 'links:'),          # neither chain nor chains
])
def test_a_file_that_is_no_robot_file_is_never_quoted(text):
    said = public(text)
    assert GENERIC in said and 'hunter2' not in said
