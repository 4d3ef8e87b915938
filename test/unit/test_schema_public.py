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


ONE_CHAIN = """
  - parent: world
    base: {frame: b0}
    chain:
      - {frame: l1, joint: j1, theta: 0, d: 0.1, a: 0, alpha: 0}
"""


def chains(value, extra=''):
    return f'robot: arm\nchains: {value}\n{extra}'


@pytest.mark.parametrize('text, said', [
    (chains('[]'), 'f.yaml: chains: expected a non-empty list of {parent, base, chain, tool}, '
                   'got a list of 0'),
    (chains('7'), 'f.yaml: chains: expected a non-empty list of {parent, base, chain, tool}, '
                  'got 7 (int)'),
    (chains('\n  - 5'), 'f.yaml: chains[0]: expected a mapping with fields parent, base, chain, '
                        'tool, got 5 (int)'),
    (chains('[' + ', '.join(['{parent: world}'] * 257) + ']'),
     'f.yaml: chains: 257 chains; a robot description has at most 256'),
] + [(chains('\n' + ONE_CHAIN, f'{field}: {{frame: t}}\n'),
      f"f.yaml: field '{field}' goes inside an entry of 'chains' when the file has 'chains' "
      '(give either chains, or base and chain)') for field in ('base', 'chain', 'tool')])
def test_each_mistake_in_chains_says_where_and_what(text, said):
    with pytest.raises(RobotDescriptionError) as caught:
        parse_robot_description(text, 'f.yaml')
    assert str(caught.value) == said == caught.value.public
