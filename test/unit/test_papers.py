"""
The numbers the papers print, reproduced by the core.

Readings of misprints follow docs/paper-errata.md; sources are cited by the keys of
docs/references.md.
"""

import math

from dq_fk_ros.kinematics.dh import DHJoint, homogeneous_from_dq, KinematicChain
from dq_fk_ros.kinematics.dual_quaternion import dq_to_pose_xyzw, DualQuaternion
import numpy as np
import pytest

DEG = math.pi / 180.0

# [Zivkovic2023] Table 3 (RL15), lengths in metres; theta_2 = q2 + 90 deg
A1, A2, A3, D4 = 0.200, 0.600, 0.115, 0.825
PEDESTAL_Z = 0.730


def rl15(pedestal=True):
    joints = [DHJoint(a=A1, alpha=90 * DEG),
              DHJoint(a=A2, theta=90 * DEG),
              DHJoint(a=A3, alpha=90 * DEG),
              DHJoint(d=D4, alpha=-90 * DEG),
              DHJoint(alpha=90 * DEG),
              DHJoint()]
    base = DualQuaternion.from_translation([0, 0, PEDESTAL_Z]) if pedestal else None
    return KinematicChain(joints, base=base)


def test_rl15_zero_pose_is_the_rviz_panel_of_fig4():
    """[Zivkovic2023] Fig. 4: eeCarry_seg6 at (1.025, ~0, 1.445), xyzw (0.7071, 0, 0.7071, 0)."""
    pose = dq_to_pose_xyzw(rl15().forward_all(np.zeros(6))[-1])
    np.testing.assert_allclose(pose[:3], [1.025, 0.0, 1.445], atol=1e-12)
    np.testing.assert_allclose(pose[3:], [0.707107, 0.0, 0.707107, 0.0], atol=5e-7)


def test_rl15_closed_form_position_eqs_21_to_23():
    chain = rl15(pedestal=False)
    rng = np.random.default_rng(15)
    for q in rng.uniform(-math.pi, math.pi, size=(1000, 6)):
        q1, q2, q3 = q[:3]
        reach = A1 + D4 * math.cos(q2 + q3) - A3 * math.sin(q2 + q3) - A2 * math.sin(q2)
        expected = [math.cos(q1) * reach, math.sin(q1) * reach,
                    A3 * math.cos(q2 + q3) + D4 * math.sin(q2 + q3) + A2 * math.cos(q2)]
        np.testing.assert_allclose(chain.forward(q).translation, expected, atol=1e-12)


def test_rl15_table4_half_angles_for_joint_2():
    """[Zivkovic2023] Table 4 (read q2/2 + 45 deg): row 2 rotates about z by half angle q2/2+45."""
    q = np.array([0.0, 0.4, 0.0, 0.0, 0.0, 0.0])
    rel = rl15().relative_all(q)[1]
    half = 0.2 + 45 * DEG
    # row 2 has alpha = 0, so its real part is exactly the z rotation (cos, 0, 0, sin)
    np.testing.assert_allclose(rel[:4], [math.cos(half), 0, 0, math.sin(half)], atol=1e-15)


# [Radavelli2014] section 4.2 (anthropomorphic arm with spherical wrist), Table 2 as read in the
# errata: alpha = +90, 0, +90, -90, +90, 0 deg; a2 = 50, d4 = 30, d6 = 20 (the paper's units)
ANTHRO_EXAMPLES = [
    ((45, 0, 0, 0, 0, 0), (35.3553, 35.3553, -50.0000)),
    ((30, 30, 30, 22.8, 3.6, 0.5), (75.7150, 43.1522, 1.0223)),
    ((12, 77.12, 0, 89.9, 1.3, 163), (58.6684, 12.0065, 37.5984)),
    ((125, 160, 90, 8.1, 78.5, 23), (51.3364, -68.5015, 10.4925)),
]


def anthropomorphic_arm():
    return KinematicChain([DHJoint(alpha=90 * DEG),
                           DHJoint(a=50.0),
                           DHJoint(alpha=90 * DEG),
                           DHJoint(d=30.0, alpha=-90 * DEG),
                           DHJoint(alpha=90 * DEG),
                           DHJoint(d=20.0)])


@pytest.mark.parametrize('q_deg, xyz', ANTHRO_EXAMPLES)
def test_anthropomorphic_arm_tables_3_and_4(q_deg, xyz):
    chain = anthropomorphic_arm()
    q = np.array(q_deg) * DEG
    np.testing.assert_allclose(chain.forward(q).translation, xyz, atol=5e-5)
    batch = chain.forward_batch(q[None, :])
    np.testing.assert_allclose(homogeneous_from_dq(batch[0])[:3, 3], xyz, atol=5e-5)


# [Radavelli2014] section 4.1, the RRC robot: Table 1, two revolute joints and a cylindrical one
def rrc(l1, l2):
    return KinematicChain([DHJoint(a=l1, name='theta1'),
                           DHJoint(a=l2, alpha=math.pi, name='theta2'),
                           DHJoint(joint_type='cylindrical', name='theta3', d_name='d3')])


def test_rrc_per_joint_operators_eq_6():
    l1, l2 = 0.7, 0.4
    chain = rrc(l1, l2)
    rng = np.random.default_rng(6)
    for t1, t2, t3, d3 in rng.uniform(-3, 3, size=(200, 4)):
        c1, s1 = math.cos(t1 / 2), math.sin(t1 / 2)
        c2, s2 = math.cos(t2 / 2), math.sin(t2 / 2)
        c3, s3 = math.cos(t3 / 2), math.sin(t3 / 2)
        expected = [[c1, 0, 0, s1, 0, l1 / 2 * c1, l1 / 2 * s1, 0],
                    [0, c2, s2, 0, -l2 / 2 * c2, 0, 0, -l2 / 2 * s2],
                    [c3, 0, 0, s3, -d3 / 2 * s3, 0, 0, d3 / 2 * c3]]
        np.testing.assert_allclose(chain.relative_all([t1, t2, t3, d3]), expected, atol=1e-15)


def test_rrc_end_pose_eq_5():
    """Eq. (5) of [Radavelli2014], with the rotation's row 2 as corrected in the errata."""
    l1, l2 = 0.7, 0.4
    chain = rrc(l1, l2)
    rng = np.random.default_rng(5)
    for t1, t2, t3, d3 in rng.uniform(-3, 3, size=(200, 4)):
        c, s = math.cos(t1 + t2 - t3), math.sin(t1 + t2 - t3)
        expected = np.array([
            [c, s, 0, l1 * math.cos(t1) + l2 * math.cos(t1 + t2)],
            [s, -c, 0, l1 * math.sin(t1) + l2 * math.sin(t1 + t2)],
            [0, 0, -1, -d3],
            [0, 0, 0, 1]])
        np.testing.assert_allclose(chain.forward([t1, t2, t3, d3]).to_matrix(), expected,
                                   atol=1e-12)
