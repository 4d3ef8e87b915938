"""The output types' definitions and hashes kept in the package are rosbags' Jazzy store's."""

from dq_fk_ros.bag.output_types import from_typestore, OUTPUT_TYPES
from dq_fk_ros.messages.outputs import OUTPUTS
import pytest


@pytest.mark.parametrize('msgtype', sorted(OUTPUT_TYPES))
def test_each_kept_definition_and_hash_is_the_type_stores(msgtype):
    assert OUTPUT_TYPES[msgtype] == from_typestore(msgtype)


def test_every_output_a_bag_carries_has_its_type():
    written = {o.msgtype for o in OUTPUTS if o.msgtype != 'diagnostic_msgs/msg/DiagnosticArray'}
    assert written <= set(OUTPUT_TYPES)
