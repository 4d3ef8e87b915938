"""The joint panel of dq_fk_view (dq_fk_ros.viewers.view_panel), as joint_state_publisher_gui."""

import math

from dq_fk_ros.viewers.view_panel import JointPanel
from hypothesis import given, strategies as st

URDF = """<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/><link name="d"/><link name="e"/>
  <link name="f"/><link name="g"/>
  <joint name="limited" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-0.5" upper="2.0" effort="1" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="b"/><child link="c"/></joint>
  <joint name="lift" type="prismatic"><parent link="c"/><child link="d"/>
    <limit lower="0.1" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="follower" type="revolute"><parent link="d"/><child link="e"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="limited" multiplier="-2" offset="0.25"/></joint>
  <joint name="orphan" type="revolute"><parent link="e"/><child link="f"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="nowhere"/></joint>
  <joint name="bolted" type="fixed"><parent link="f"/><child link="g"/></joint>
</robot>"""


def panel():
    made = JointPanel()
    made.take_description(URDF)
    return made


def test_a_slider_per_moving_joint_within_its_limits_mimics_follow():
    spec = panel().spec()
    assert [j[:4] for j in spec['joints']] == [
        ['limited', -0.5, 2.0, 0.0],
        ['spin', -math.pi, math.pi, 0.0],        # continuous: one turn either way
        ['lift', 0.1, 0.3, 0.2],                 # 0 outside the range: its middle
        ['orphan', -1.0, 1.0, 0.0]]              # mimic of no joint: a joint of its own (RSP)
    assert spec['mimics'] == [['follower', 'limited', -2.0, 0.25]]
    assert panel().joint_state() == (['limited', 'spin', 'lift', 'orphan'], [0.0, 0.0, 0.2, 0.0])


def test_page_values_are_clamped_and_anything_odd_is_refused_whole():
    p = panel()
    assert p.take_page({'type': 'joints', 'positions': {'limited': 9, 'lift': 0.0}})
    assert p.joint_state()[1][:3] == [2.0, 0.0, 0.1]
    for refused in ({'positions': {'limited': 1.0, 'follower': 1.0}},   # no slider of its own
                    {'positions': {'limited': float('nan')}},
                    {'positions': {'limited': True}},
                    {'positions': {'limited': 10 ** 400}},   # JSON's integers have no bound
                    {'positions': {'limited': '1'}},
                    {'positions': dict.fromkeys('abcdefgh', 0.0)},
                    {'positions': [1.0]}, {'positions': None}, []):
        assert not p.take_page(refused), refused
    assert p.joint_state()[1][:3] == [2.0, 0.0, 0.1]   # nothing of a refused message taken


def test_a_new_robot_keeps_the_values_of_joints_it_shares_and_a_bad_one_empties_it():
    p = panel()
    p.take_page({'positions': {'limited': 1.5, 'spin': 3.0}})
    p.take_description(URDF.replace('upper="2.0"', 'upper="1.0"').replace(
        '<joint name="spin" type="continuous"><parent link="b"/><child link="c"/></joint>',
        '<joint name="spin" type="fixed"><parent link="b"/><child link="c"/></joint>'))
    assert p.joint_state() == (['limited', 'lift', 'orphan'], [1.0, 0.2, 0.0])
    p.take_description('<robot name="broken">')
    assert p.joint_state() == ([], [])


@given(st.dictionaries(st.text(max_size=8), st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.none(), st.text(),
    st.booleans()), max_size=6))
def test_any_positions_leave_every_slider_within_its_limits(positions):
    p = panel()
    p.take_page({'type': 'joints', 'positions': positions})
    limits = {j[0]: (j[1], j[2]) for j in p.spec()['joints']}
    for name, value in zip(*p.joint_state()):
        assert limits[name][0] <= value <= limits[name][1] and math.isfinite(value)
