"""KinematicChain against the independent 4x4 reference, on random chains and configurations."""

import math
import re

from dq_fk_ros.kinematics.dh import DHJoint, homogeneous_from_dq, KinematicChain
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion, quat_to_matrix
import homogeneous as hm
import numpy as np
import pytest

N_CONFIGS = 2000


def random_chain(rng, convention, n_rows=6,
                 types=('revolute', 'prismatic', 'cylindrical', 'fixed')):
    """Return a random DH table with random row types, offsets and scales, base and tool."""
    joints = []
    for i in range(n_rows):
        joints.append(DHJoint(
            a=rng.uniform(0, 1), alpha=rng.uniform(-np.pi, np.pi), d=rng.uniform(-1, 1),
            theta=rng.uniform(-np.pi, np.pi), joint_type=str(rng.choice(types)),
            scale=float(rng.choice([1.0, -1.0, rng.uniform(0.5, 2)])), name=f'j{i}'))
    base = random_pose(rng)
    tool = random_pose(rng)
    return KinematicChain(joints, convention, base=DualQuaternion.from_matrix(base),
                          tool=DualQuaternion.from_matrix(tool)), base, tool


def random_pose(rng):
    m = hm.rodrigues(rng.normal(size=3), rng.uniform(-np.pi, np.pi))
    m[:3, 3] = rng.uniform(-1, 1, size=3)
    return m


def reference_rows(chain, q):
    """Evaluate the DH table at q from the joints' own fields (not the chain's index map)."""
    rows, k = [], 0
    for j in chain.joints:
        theta, d = j.theta, j.d
        if j.joint_type in ('revolute', 'cylindrical'):
            theta += j.scale * q[k]
            k += 1
        if j.joint_type in ('prismatic', 'cylindrical'):
            d += j.scale * q[k]
            k += 1
        rows.append((theta, d, j.a, j.alpha))
    assert k == len(q)
    return rows


@pytest.mark.parametrize('convention', ['standard', 'modified'])
@pytest.mark.parametrize('seed', [1, 2, 3])
def test_forward_all_matches_matrices(convention, seed):
    rng = np.random.default_rng(seed)
    chain, base, tool = random_chain(rng, convention)
    q = rng.uniform(-3, 3, size=(N_CONFIGS, chain.dof))
    batch = chain.forward_all_batch(q)
    end_batch = chain.forward_batch(q)
    assert batch.shape == (N_CONFIGS, len(chain.joints) + 2, 8)
    for k in range(N_CONFIGS):
        expected = np.array(hm.chain_frames(reference_rows(chain, q[k]), convention, base, tool))
        np.testing.assert_allclose(homogeneous_from_dq(batch[k]), expected, atol=1e-12)
        np.testing.assert_allclose(homogeneous_from_dq(end_batch[k]), expected[-1], atol=1e-12)
        if k % 10 == 0:  # the scalar path on a tenth of them
            single = chain.forward_all(q[k])
            np.testing.assert_allclose(homogeneous_from_dq(single), expected, atol=1e-12)
            np.testing.assert_allclose(chain.forward(q[k]).to_matrix(), expected[-1],
                                       atol=1e-12)


@pytest.mark.parametrize('convention', ['standard', 'modified'])
def test_relative_transforms_match_matrices(convention):
    rng = np.random.default_rng(7)
    chain, _, _ = random_chain(rng, convention)
    step = hm.dh_standard if convention == 'standard' else hm.dh_modified
    qs = rng.uniform(-3, 3, size=(300, chain.dof))
    rel_batch = chain.relative_all_batch(qs)
    for k, q in enumerate(qs):
        expected = [step(*row) for row in reference_rows(chain, q)]
        np.testing.assert_allclose(homogeneous_from_dq(chain.relative_all(q)), expected,
                                   atol=1e-12)
        np.testing.assert_allclose(homogeneous_from_dq(rel_batch[k]), expected, atol=1e-12)


def test_outputs_are_unit_with_canonical_sign_over_a_long_chain():
    rng = np.random.default_rng(11)
    chain, _, _ = random_chain(rng, 'standard', n_rows=200)
    q = rng.uniform(-3, 3, size=(50, chain.dof))
    out = chain.forward_all_batch(q)
    real, dual = out[..., :4], out[..., 4:]
    assert np.max(np.abs(np.linalg.norm(real, axis=-1) - 1.0)) < 1e-13
    assert np.max(np.abs(np.sum(real * dual, axis=-1))) < 1e-13
    assert np.all(out[..., 0] >= 0.0)
    assert np.all(chain.forward_all(q[0])[:, 0] >= 0.0)


def test_standard_and_modified_tables_of_the_same_robot_agree():
    """
    Standard <-> modified conversion, derived from Tx(a) Rx(alpha) = Rx(alpha) Tx(a).

    ``prod_i Rz Tz Tx(a_i) Rx(alpha_i)`` regroups as
    ``prod_i [Rx(alpha_{i-1}) Tx(a_{i-1}) Rz Tz] Tx(a_n) Rx(alpha_n)``: the modified table
    takes (a, alpha) from the row before (zero for row 1) and the last row's (a, alpha)
    becomes a tool transform; standard frame i = modified frame i * Tx(a_i) Rx(alpha_i).
    """
    rng = np.random.default_rng(5)
    standard, _, _ = random_chain(rng, 'standard', types=('revolute', 'prismatic'))
    std_joints = standard.joints
    mod_joints = [DHJoint(a=prev.a, alpha=prev.alpha, d=j.d, theta=j.theta,
                          joint_type=j.joint_type, scale=j.scale, name=j.name)
                  for prev, j in zip((DHJoint(),) + std_joints[:-1], std_joints)]
    last = std_joints[-1]
    tail = DualQuaternion.from_matrix(hm.trans(x=last.a) @ hm.rot_x(last.alpha))
    modified = KinematicChain(mod_joints, 'modified', base=standard.base,
                              tool=tail * standard.tool)
    for q in rng.uniform(-3, 3, size=(500, standard.dof)):
        s_frames = homogeneous_from_dq(standard.forward_all(q))
        m_frames = homogeneous_from_dq(modified.forward_all(q))
        np.testing.assert_allclose(s_frames[-1], m_frames[-1], atol=1e-12)
        for i, j in enumerate(std_joints, start=1):
            np.testing.assert_allclose(
                s_frames[i], m_frames[i] @ hm.trans(x=j.a) @ hm.rot_x(j.alpha), atol=1e-12)


def fk_vector(chain, q):
    return chain.forward(q).coeffs


def central_difference(f, q, j, eps=1e-6):
    """Return (f(q + eps e_j) - f(q - eps e_j)) / 2 eps."""
    step = np.zeros(len(q))
    step[j] = eps
    return (f(q + step) - f(q - step)) / (2 * eps)


@pytest.mark.parametrize('convention', ['standard', 'modified'])
def test_dual_quaternion_jacobian_matches_finite_differences(convention):
    rng = np.random.default_rng(21)
    chain, _, _ = random_chain(rng, convention)
    for q in rng.uniform(-3, 3, size=(50, chain.dof)):
        jac = chain.jacobian_dq(q)
        assert jac.shape == (8, chain.dof)
        for j in range(chain.dof):
            fd = central_difference(lambda x: fk_vector(chain, x), q, j)
            np.testing.assert_allclose(jac[:, j], fd, atol=1e-7)


@pytest.mark.parametrize('convention', ['standard', 'modified'])
def test_geometric_jacobian_matches_finite_differences(convention):
    rng = np.random.default_rng(22)
    chain, _, _ = random_chain(rng, convention)
    for q in rng.uniform(-3, 3, size=(50, chain.dof)):
        jac = chain.jacobian_geometric(q)
        m = chain.forward(q).to_matrix()
        for j in range(chain.dof):
            m_dot = central_difference(lambda x: chain.forward(x).to_matrix(), q, j)
            lin = m_dot[:3, 3]
            skew = m_dot[:3, :3] @ m[:3, :3].T
            ang = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
            np.testing.assert_allclose(jac[:3, j], lin, atol=1e-7)
            np.testing.assert_allclose(jac[3:, j], ang, atol=1e-7)


def test_twist_and_pose_rate_along_a_trajectory():
    """Twist and J_dq qdot against central differences of the pose along q(t)."""
    rng = np.random.default_rng(23)
    chain, _, _ = random_chain(rng, 'standard')
    q0, amp, freq = (rng.uniform(-2, 2, chain.dof), rng.uniform(0.2, 1, chain.dof),
                     rng.uniform(0.5, 2, chain.dof))

    def q_of(t):
        return q0 + amp * np.sin(freq * t)

    def qdot_of(t):
        return amp * freq * np.cos(freq * t)
    h = 1e-6
    for t in np.linspace(0.0, 3.0, 31):
        v, w = chain.twist(q_of(t), qdot_of(t))
        m_plus = chain.forward(q_of(t + h)).to_matrix()
        m_minus = chain.forward(q_of(t - h)).to_matrix()
        m = chain.forward(q_of(t)).to_matrix()
        np.testing.assert_allclose(v, (m_plus[:3, 3] - m_minus[:3, 3]) / (2 * h), atol=1e-7)
        skew = (m_plus[:3, :3] - m_minus[:3, :3]) / (2 * h) @ m[:3, :3].T
        np.testing.assert_allclose(w, [skew[2, 1], skew[0, 2], skew[1, 0]], atol=1e-7)
        rate = chain.pose_rate(q_of(t), qdot_of(t))
        fd = (fk_vector(chain, q_of(t + h)) - fk_vector(chain, q_of(t - h))) / (2 * h)
        np.testing.assert_allclose(rate, fd, atol=1e-7)


def test_mimic_row_follows_its_source_joint():
    joints = [DHJoint(a=0.3, name='shoulder'),
              DHJoint(a=0.2, follows='shoulder', scale=-0.5, theta=0.1),
              DHJoint(d=0.1, joint_type='prismatic', name='slide')]
    chain = KinematicChain(joints)
    assert chain.joint_names == ('shoulder', 'slide')
    q = np.array([0.7, 0.05])
    expected = hm.chain_frames([(0.7, 0, 0.3, 0), (0.1 - 0.35, 0, 0.2, 0),
                                (0, 0.15, 0, 0)], 'standard')
    np.testing.assert_allclose(homogeneous_from_dq(chain.forward_all(q)), expected, atol=1e-12)
    # the mimic row's motion counts towards the source joint's Jacobian column
    fd = central_difference(lambda x: fk_vector(chain, x), q, 0)
    np.testing.assert_allclose(chain.jacobian_dq(q)[:, 0], fd, atol=1e-7)


def test_joint_names_and_limits():
    chain = KinematicChain([
        DHJoint(name='a1', limits=(-1.0, 1.0)),
        DHJoint(joint_type='cylindrical', name='c', limits=((-2.0, 2.0), (0.0, 0.5))),
        DHJoint(joint_type='fixed', a=1.0)])
    assert chain.joint_names == ('a1', 'c', 'c_d')
    np.testing.assert_array_equal(chain.limits, [[-1, 1], [-2, 2], [0, 0.5]])
    assert chain.dof == 3 and chain.n_frames == 4


def test_clear_errors_for_bad_input():
    with pytest.raises(ValueError, match='convention'):
        KinematicChain([DHJoint()], convention='craig')
    with pytest.raises(ValueError, match='joint_type'):
        DHJoint(joint_type='spherical')
    with pytest.raises(ValueError, match='finite'):
        DHJoint(a=math.nan)
    with pytest.raises(ValueError, match='used twice'):
        KinematicChain([DHJoint(name='x'), DHJoint(name='x')])
    with pytest.raises(ValueError, match='unknown joint'):
        KinematicChain([DHJoint(name='x'), DHJoint(follows='y')])
    chain = KinematicChain([DHJoint(), DHJoint()])
    with pytest.raises(ValueError, match='expected 2 joint values'):
        chain.forward_all([1.0])
    with pytest.raises(ValueError, match=r'\(N, 2\)'):
        chain.forward_all_batch(np.zeros(2))


def test_rotation_helper_consistency():
    """quat_to_matrix agrees with Rodrigues (guards the reference used above)."""
    q = DualQuaternion.from_rotation([1, 2, 3], 0.8).real
    np.testing.assert_allclose(quat_to_matrix(q), hm.rodrigues([1, 2, 3], 0.8)[:3, :3],
                               atol=1e-15)


@pytest.mark.parametrize('convention', ['standard', 'modified'])
def test_frame_poses_are_absolute_and_relative_transforms(convention):
    rng = np.random.default_rng(31)
    chain, base, tool = random_chain(rng, convention)
    for q in rng.uniform(-3, 3, size=(100, chain.dof)):
        absolute, relative = chain.frame_poses(q)
        assert chain.row_poses(q.tolist()) == relative  # lists and arrays alike
        expected = hm.chain_frames(reference_rows(chain, q), convention, base, tool)
        assert len(absolute) == len(expected) and len(relative) == len(chain.joints)
        for pose, m in zip(absolute, expected):
            np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]), m, atol=1e-12)
            assert pose[6] >= 0.0
        for i, pose in enumerate(relative):
            np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]),
                                       np.linalg.inv(expected[i]) @ expected[i + 1],
                                       atol=1e-12)
            assert pose[6] >= 0.0 and all(type(v) is float for v in pose)
    with pytest.raises(ValueError, match=f'expected {chain.dof} joint values'):
        chain.row_poses(np.zeros(chain.dof + 1))


@pytest.mark.parametrize('convention', ['standard', 'modified'])
def test_the_unrolled_frame_poses_are_the_general_path_to_the_bit(convention):
    """frame_poses' straight-line code: exactly the floats of the looping path."""
    rng = np.random.default_rng(37)
    chains = [random_chain(rng, convention, n_rows=n)[0] for n in (1, 3, 6, 9)]
    chains.append(KinematicChain([DHJoint(), DHJoint(joint_type='fixed', a=0.2)],
                                 convention))  # identity base, a fixed row, no tool
    chains.append(KinematicChain([DHJoint(joint_type='prismatic', a=0.1),
                                  DHJoint(alpha=0.3)], convention))  # q[0] moves d from 0
    for chain in chains:
        for q in rng.uniform(-4, 4, size=(200, chain.dof)):
            assert chain.frame_poses(q) == chain.frame_poses_general(q)
            assert chain.frame_poses(q.tolist()) == chain.frame_poses_general(q)
        assert chain.frame_poses_code.source.startswith('def frame_poses(q):')
        with pytest.raises(ValueError, match=f'expected {chain.dof} joint values'):
            chain.frame_poses([0.0] * (chain.dof + 1))


def test_forward_and_forward_all_agree_at_a_half_turn():
    """At w exactly 0 (a base turned by pi) both keep the same representative (w >= 0)."""
    base = DualQuaternion.from_array(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]))
    chain = KinematicChain([DHJoint(a=0.2), DHJoint(joint_type='fixed', d=0.1)], base=base)
    end = chain.forward([0.0]).coeffs
    assert end[0] == 0.0
    np.testing.assert_array_equal(end, chain.forward_all([0.0])[-1])


def test_a_product_with_constants_written_out_is_the_product():
    """_product_code: zero terms left out, factors 1.0 dropped, the values unchanged."""
    from dq_fk_ros.kinematics.dh_code import _product_code
    from dq_fk_ros.kinematics.dual_quaternion import dq_multiply_coeffs
    rng = np.random.default_rng(8)
    names = [f'a{k}' for k in range(8)]
    for _ in range(200):
        b = tuple(float(v) for v in rng.choice([0.0, 1.0, -1.0, 0.5, -0.25, 3.0], 8))
        a = tuple(float(v) for v in rng.normal(size=8))
        code = _product_code(names, b)
        values = tuple(eval(c, dict(zip(names, a))) for c in code)  # noqa: S307 (our code)
        assert values == dq_multiply_coeffs(a, b)
        assert all('* 0.0' not in c and '* 1.0' not in c for c in code)
    assert _product_code(names, (0.0,) * 8) == ['0.0'] * 8


def test_row_poses_keep_qw_non_negative_at_half_turns():
    """A row turned by theta = pi +- a little: the quaternion flips sign, never qw < 0."""
    for convention in ('standard', 'modified'):
        chain = KinematicChain([DHJoint(a=0.3, alpha=0.4, d=0.1)], convention)
        for theta in (math.pi - 1e-9, math.pi, math.pi + 1e-9, -math.pi - 1e-9, 3.5, -3.5):
            (pose,) = chain.row_poses([theta])
            assert pose[6] >= 0.0
            m = hm.chain_frames(reference_rows(chain, np.array([theta])), convention,
                                np.eye(4), None)[1]
            np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]), m, atol=1e-14)


def test_row_parameters_is_the_dh_table_at_q():
    """The theta and d of every row at q: offsets plus scaled joint values."""
    rng = np.random.default_rng(41)
    for convention in ('standard', 'modified'):
        chain, _, _ = random_chain(rng, convention)
        q = rng.uniform(-2, 2, chain.dof)
        theta, d = chain.row_parameters(q)
        expected = reference_rows(chain, q)
        assert len(theta) == len(d) == len(chain.joints) == len(expected)
        np.testing.assert_allclose(theta, [r[0] for r in expected], atol=1e-15)
        np.testing.assert_allclose(d, [r[1] for r in expected], atol=1e-15)
    with pytest.raises(ValueError, match='expected'):
        chain.row_parameters(np.zeros(chain.dof + 1))


def test_a_joint_without_limits_is_unbounded():
    chain = KinematicChain([DHJoint(a=1.0, name='j1'),
                            DHJoint(joint_type='prismatic', name='j2', limits=(0, 1))])
    assert chain.limits.tolist() == [[-math.inf, math.inf], [0.0, 1.0]]


def test_rows_without_names_get_numbered_joint_names():
    chain = KinematicChain([DHJoint(a=0.1), DHJoint(joint_type='prismatic'),
                            DHJoint(joint_type='cylindrical'), DHJoint(joint_type='fixed')])
    assert chain.joint_names == ('joint_1', 'joint_2', 'joint_3', 'joint_3_d')


def test_batches_longer_than_one_chunk_equal_single_configurations():
    from dq_fk_ros.kinematics.chain_batches import BATCH_CHUNK
    chain = KinematicChain([DHJoint(a=0.3, alpha=0.5, name='j1'),
                            DHJoint(d=0.2, alpha=-0.4, name='j2', joint_type='prismatic')])
    q = np.random.default_rng(3).uniform(-1, 1, size=(BATCH_CHUNK + 3, 2))
    batch = chain.forward_all_batch(q)
    ends = chain.forward_batch(q)
    for k in (0, BATCH_CHUNK - 1, BATCH_CHUNK, BATCH_CHUNK + 2):
        np.testing.assert_allclose(batch[k], chain.forward_all(q[k]), atol=1e-15)
        np.testing.assert_allclose(ends[k], chain.forward(q[k]).coeffs, atol=1e-15)


def test_a_row_following_an_unknown_joint_is_named_by_its_number():
    with pytest.raises(ValueError, match=re.escape(
            "row 2 follows unknown joint 'ghost'; joints are ['j1']")):
        KinematicChain([DHJoint(name='j1'), DHJoint(follows='ghost')])


def test_the_variables_read_as_angles_are_the_revolute_and_cylindrical_thetas():
    from dq_fk_ros.kinematics.chain_variables import chain_variables
    rows = [DHJoint(name='a'), DHJoint(joint_type='prismatic', name='b'),
            DHJoint(joint_type='cylindrical', name='c'),
            DHJoint(joint_type='revolute', follows='b'), DHJoint(joint_type='fixed')]
    variables = chain_variables(rows)
    assert variables.names == ('a', 'b', 'c', 'c_d')
    assert variables.angular.tolist() == [True, False, True, False]  # b stays a length
    assert variables.theta_index.tolist() == [0, -1, 2, 1, -1]
    assert variables.d_index.tolist() == [-1, 1, 3, -1, -1]


def test_the_class_methods_are_the_bound_fast_calls():
    """``forward_all``/``forward`` are bound to the engine per chain; the methods say the same."""
    chain, _, _ = random_chain(np.random.default_rng(7), 'standard')
    q = np.random.default_rng(8).uniform(-1, 1, chain.dof)
    frames = KinematicChain.forward_all(chain, q)
    np.testing.assert_array_equal(frames, chain.forward_all(q))
    out = np.empty_like(frames)
    assert KinematicChain.forward_all(chain, q, out) is out
    np.testing.assert_array_equal(out, frames)
    end = KinematicChain.forward(chain, q)
    assert isinstance(end, DualQuaternion)
    fast = chain.forward(q)
    np.testing.assert_array_equal(np.concatenate([end.real, end.dual]),
                                  np.concatenate([fast.real, fast.dual]))


def test_a_chain_pickles_without_its_generated_code_and_computes_the_same():
    """A fleet's worker processes get chains by pickle: bound calls made again on load."""
    import pickle
    chain, _, _ = random_chain(np.random.default_rng(9), 'modified')
    chain.frame_poses_code   # made on first use: not pickled
    state = chain.__getstate__()
    assert not {'frame_poses_code', 'forward_all', 'forward'} & set(state)
    copy = pickle.loads(pickle.dumps(chain))
    q = np.random.default_rng(10).uniform(-1, 1, chain.dof)
    np.testing.assert_array_equal(copy.forward_all(q), chain.forward_all(q))
    assert copy.joint_names == chain.joint_names


def test_joint_velocities_of_the_wrong_count_are_one_clear_error():
    chain, _, _ = random_chain(np.random.default_rng(11), 'standard')
    with pytest.raises(ValueError, match=rf'^expected {chain.dof} joint velocities, got shape '
                                         rf'\({chain.dof + 1},\)$'):
        chain.twist(np.zeros(chain.dof), np.zeros(chain.dof + 1))


def test_forward_batch_fills_the_array_given_as_out_and_refuses_one_of_another_shape():
    rng = np.random.default_rng(21)
    chain, _, _ = random_chain(rng, 'standard')
    q = rng.uniform(-3, 3, size=(5, chain.dof))
    out = np.full((5, 8), np.nan)
    assert chain.forward_batch(q, out=out) is out
    np.testing.assert_array_equal(out, chain.forward_batch(q))
    for wrong in (np.zeros((5, 9)), np.zeros((5, 8), dtype=np.float32), np.zeros((8, 5)).T,
                  [[0.0] * 8] * 5):
        with pytest.raises(ValueError, match=r'out must be .*\(N, 8\) array'):
            chain.forward_batch(q, out=wrong)


def test_a_base_and_tool_given_unnormalized_are_taken_as_the_unit_ones():
    rng = np.random.default_rng(22)
    unit, base, tool = random_chain(rng, 'modified')
    scaled = KinematicChain(unit.joints, 'modified',
                            base=2.5 * DualQuaternion.from_matrix(base),
                            tool=0.3 * DualQuaternion.from_matrix(tool))
    assert np.allclose(scaled.base.coeffs, unit.base.coeffs, atol=1e-15)
    assert np.allclose(scaled.tool.coeffs, unit.tool.coeffs, atol=1e-15)
    q = rng.uniform(-2, 2, size=(4, unit.dof))
    np.testing.assert_allclose(scaled.forward_all_batch(q), unit.forward_all_batch(q),
                               atol=1e-12)
    assert (scaled.convention, scaled.dof, scaled.n_frames) == \
        ('modified', unit.dof, len(unit.joints) + 2)
    bare = KinematicChain([DHJoint(a=0.3, name='s', limits=(-1.0, 2.0)),
                           DHJoint(joint_type='fixed'),
                           DHJoint(joint_type='cylindrical', name='c')],
                          'standard')
    assert bare.tool is None and bare.n_frames == 4 and bare.dof == 3
    assert list(bare.joint_names) == ['s', 'c', 'c_d'] and bare.convention == 'standard'
    assert np.asarray(bare.limits)[0].tolist() == [-1.0, 2.0]
    assert [j.joint_type for j in bare.joints] == ['revolute', 'fixed', 'cylindrical']
    np.testing.assert_array_equal(bare.base.coeffs, [1, 0, 0, 0, 0, 0, 0, 0])


def test_forward_all_batch_fills_the_array_given_as_out_and_refuses_one_of_another_shape():
    rng = np.random.default_rng(23)
    chain, _, _ = random_chain(rng, 'standard')
    q = rng.uniform(-3, 3, size=(3, chain.dof))
    out = np.full((3, chain.n_frames, 8), np.nan)
    assert chain.forward_all_batch(q, out=out) is out
    np.testing.assert_array_equal(out, chain.forward_all_batch(q))
    for wrong in (np.zeros((3, chain.n_frames + 1, 8)), np.zeros((3, chain.n_frames, 7)),
                  np.zeros((3, chain.n_frames, 8), dtype=np.float32)):
        with pytest.raises(ValueError, match=rf'out must be .*\(N, {chain.n_frames}, 8\)'):
            chain.forward_all_batch(q, out=wrong)
    frozen = np.zeros((3, chain.n_frames, 8))
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match='writable'):
        chain.forward_all_batch(q, out=frozen)


def test_homogeneous_from_dq_keeps_the_leading_shape_and_is_a_rigid_transform():
    rng = np.random.default_rng(24)
    matrices = np.array([[random_pose(rng) for _ in range(3)] for _ in range(2)])
    dqs = [[DualQuaternion.from_matrix(m).coeffs.tolist() for m in row] for row in matrices]
    got = homogeneous_from_dq(dqs)   # nested lists, (2, 3, 8)
    assert got.shape == (2, 3, 4, 4)
    np.testing.assert_allclose(got, matrices, atol=1e-12)
    np.testing.assert_array_equal(got[..., 3, :], np.broadcast_to([0, 0, 0, 1], (2, 3, 4)))
    np.testing.assert_allclose(homogeneous_from_dq(dqs[0][0]), matrices[0, 0], atol=1e-12)


def test_a_twist_of_the_wrong_number_of_joint_velocities_says_how_many_were_expected():
    chain, _, _ = random_chain(np.random.default_rng(25), 'standard',
                               types=('revolute',))
    with pytest.raises(ValueError, match=r'^expected 6 joint velocities, got shape \(5,\)$'):
        chain.twist(np.zeros(6), np.zeros(5))
