"""DualQuaternion algebra against the independent 4x4 reference in ``homogeneous.py``."""

import math

from dq_fk_ros.kinematics.dual_quaternion import (
    canonical, dq_from_pose_array, dq_multiply_array, dq_normalize_array, dq_to_pose_xyzw,
    DualQuaternion, pose_xyzw_from_coeffs, pose_xyzw_in, quat_from_axis_angle,
    quat_from_matrix, quat_multiply, quat_to_matrix, quat_wxyz_to_xyzw, quat_xyzw_to_wxyz)
import homogeneous as hm
import numpy as np
import pytest

RNG_SEED = 20261121


def random_matrix(rng):
    """Return a random rigid transform as a 4x4 matrix (Rodrigues of a random axis and angle)."""
    m = hm.rodrigues(rng.normal(size=3), rng.uniform(-np.pi, np.pi))
    m[:3, 3] = rng.uniform(-2.0, 2.0, size=3)
    return m


@pytest.fixture
def rng():
    return np.random.default_rng(RNG_SEED)


def test_matrix_round_trip(rng):
    for _ in range(1000):
        m = random_matrix(rng)
        h = DualQuaternion.from_matrix(m)
        assert h.is_unit(1e-12)
        np.testing.assert_allclose(h.to_matrix(), m, atol=1e-12)


def test_product_is_matrix_product(rng):
    for _ in range(1000):
        a, b = random_matrix(rng), random_matrix(rng)
        h = DualQuaternion.from_matrix(a) * DualQuaternion.from_matrix(b)
        np.testing.assert_allclose(h.to_matrix(), a @ b, atol=1e-12)


def test_from_pose_is_rotation_then_translation_in_parent(rng):
    for _ in range(200):
        axis, angle, t = rng.normal(size=3), rng.uniform(-3, 3), rng.normal(size=3)
        expected = hm.trans(*t) @ hm.rodrigues(axis, angle)
        h = DualQuaternion.from_rotation(axis, angle) * DualQuaternion.from_translation([0, 0, 0])
        h = DualQuaternion.from_pose(h.rotation_wxyz, t)
        np.testing.assert_allclose(h.to_matrix(), expected, atol=1e-12)
        np.testing.assert_allclose(h.translation, t, atol=1e-12)


def test_inverse_and_conjugate_are_matrix_inverse(rng):
    for _ in range(500):
        m = random_matrix(rng)
        h = DualQuaternion.from_matrix(m)
        np.testing.assert_allclose(h.inverse().to_matrix(), np.linalg.inv(m), atol=1e-12)
        np.testing.assert_allclose(h.conjugate().to_matrix(), np.linalg.inv(m), atol=1e-12)
        assert (h * h.inverse()).isclose(DualQuaternion.identity(), atol=1e-12)


def test_inverse_of_non_unit_dual_quaternion(rng):
    h = DualQuaternion(rng.normal(size=8))
    assert (h * h.inverse()).isclose(DualQuaternion.identity(), atol=1e-12)
    assert (h.inverse() * h).isclose(DualQuaternion.identity(), atol=1e-12)


def test_transform_point(rng):
    for _ in range(500):
        m, p = random_matrix(rng), rng.normal(size=3)
        expected = (m @ np.append(p, 1.0))[:3]
        np.testing.assert_allclose(DualQuaternion.from_matrix(m).transform_point(p), expected,
                                   atol=1e-12)


def test_point_transform_by_combined_conjugate_sandwich(rng):
    """``h (1 + eps p) h~`` with the combined conjugate moves a point ([Radavelli2014] eq. (4))."""
    m, p = random_matrix(rng), rng.normal(size=3)
    h = DualQuaternion.from_matrix(m)
    point = DualQuaternion([1, 0, 0, 0, 0, *p])
    moved = h * point * h.combined_conjugate()
    np.testing.assert_allclose(moved.dual[1:], (m @ np.append(p, 1.0))[:3], atol=1e-12)


def test_norm_and_normalize(rng):
    h = DualQuaternion.from_matrix(random_matrix(rng))
    n_real, n_dual = h.norm()
    assert abs(n_real - 1.0) < 1e-14 and abs(n_dual) < 1e-14
    noisy = DualQuaternion(3.0 * h.coeffs + 1e-3 * rng.normal(size=8))
    assert not noisy.is_unit()
    fixed = noisy.normalized()
    assert fixed.is_unit(1e-14)
    np.testing.assert_allclose(fixed.to_matrix(), h.to_matrix(), atol=2e-3)
    with pytest.raises(ValueError):
        dq_normalize_array(np.zeros(8))


def test_canonical_sign_keeps_pose(rng):
    h = DualQuaternion.from_matrix(random_matrix(rng))
    flipped = -h
    assert flipped.canonical().coeffs[0] >= 0
    np.testing.assert_allclose(flipped.canonical().to_matrix(), h.to_matrix(), atol=1e-12)
    batch = np.stack([h.coeffs, -h.coeffs])
    assert np.all(canonical(batch)[:, 0] >= 0)


def test_quaternion_order_helpers():
    wxyz = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(quat_wxyz_to_xyzw(wxyz), [0.2, 0.3, 0.4, 0.1])
    np.testing.assert_array_equal(quat_xyzw_to_wxyz(quat_wxyz_to_xyzw(wxyz)), wxyz)


def test_pose_xyzw_matches_matrix(rng):
    for _ in range(200):
        m = random_matrix(rng)
        pose = dq_to_pose_xyzw(DualQuaternion.from_matrix(m).coeffs)
        assert pose[6] >= 0
        np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]), m, atol=1e-12)


def test_batch_product_broadcasts(rng):
    a = np.stack([DualQuaternion.from_matrix(random_matrix(rng)).coeffs for _ in range(5)])
    b = DualQuaternion.from_matrix(random_matrix(rng)).coeffs
    out = dq_multiply_array(a, b)
    for k in range(5):
        np.testing.assert_allclose(out[k], (DualQuaternion(a[k]) * DualQuaternion(b)).coeffs)


def test_screw_parameters_round_trip(rng):
    for _ in range(300):
        h = DualQuaternion.from_matrix(random_matrix(rng))
        assert DualQuaternion.from_screw_parameters(*h.screw_parameters()).isclose(h, 1e-10)


def test_sclerp_of_a_screw_about_z_is_the_partial_screw():
    """Rz(theta) Tz(d) interpolates to Rz(tau theta) Tz(tau d), written as matrices."""
    theta, d = 2.0, 0.7
    start = DualQuaternion.identity()
    end = DualQuaternion.from_matrix(hm.rot_z(theta) @ hm.trans(z=d))
    for tau in (0.0, 0.25, 0.5, 0.9, 1.0):
        expected = hm.rot_z(tau * theta) @ hm.trans(z=tau * d)
        np.testing.assert_allclose(start.sclerp(end, tau).to_matrix(), expected, atol=1e-12)


def test_sclerp_between_general_poses(rng):
    for _ in range(100):
        m0, axis, angle = random_matrix(rng), rng.normal(size=3), rng.uniform(0.1, 3.0)
        point, slide = rng.normal(size=3), rng.normal()
        # a screw about a line through `point` along `axis`, written with matrices
        u = axis / np.linalg.norm(axis)

        def screw(tau):
            return (hm.trans(*point) @ hm.rodrigues(u, tau * angle) @ hm.trans(*-point)
                    @ hm.trans(*(tau * slide * u)))
        h0 = DualQuaternion.from_matrix(m0)
        h1 = DualQuaternion.from_matrix(m0 @ screw(1.0))
        for tau in (0.0, 0.3, 0.5, 1.0):
            np.testing.assert_allclose(h0.sclerp(h1, tau).to_matrix(), m0 @ screw(tau),
                                       atol=1e-10)


def test_sclerp_pure_translation():
    start = DualQuaternion.identity()
    end = DualQuaternion.from_translation([1.0, -2.0, 0.5])
    np.testing.assert_allclose(start.sclerp(end, 0.5).translation, [0.5, -1.0, 0.25],
                               atol=1e-15)


def test_bad_inputs_are_clear_errors():
    with pytest.raises(ValueError, match='8 coefficients'):
        DualQuaternion([1, 2, 3])
    with pytest.raises(ValueError, match='4x4'):
        DualQuaternion.from_matrix(np.eye(3))
    with pytest.raises(ValueError, match='non-zero'):
        DualQuaternion.from_rotation([0, 0, 0], 1.0)
    with pytest.raises(ZeroDivisionError):
        DualQuaternion(np.zeros(8)).inverse()


def test_scalar_pose_conversion_matches_the_array_one(rng):
    from dq_fk_ros.kinematics.dual_quaternion import pose_xyzw_from_coeffs
    for _ in range(300):
        h = DualQuaternion.from_matrix(random_matrix(rng)).coeffs * rng.choice([-1.0, 1.0])
        np.testing.assert_allclose(pose_xyzw_from_coeffs(h.tolist()), dq_to_pose_xyzw(h),
                                   atol=1e-14)


def test_the_three_conjugates(rng):
    h = DualQuaternion(rng.normal(size=8))
    r, d = h.coeffs[:4], h.coeffs[4:]
    star = np.array([1.0, -1, -1, -1])
    np.testing.assert_array_equal(h.conjugate().coeffs, np.concatenate([r * star, d * star]))
    np.testing.assert_array_equal(h.dual_number_conjugate().coeffs, np.concatenate([r, -d]))
    np.testing.assert_array_equal(h.combined_conjugate().coeffs,
                                  h.dual_number_conjugate().conjugate().coeffs)


def test_scaling_by_a_number_and_nothing_else(rng):
    h = DualQuaternion(rng.normal(size=8))
    np.testing.assert_allclose((2.5 * h).coeffs, 2.5 * h.coeffs)
    with pytest.raises(TypeError):
        np.ones(8).tolist() * h  # a list is not a scale factor


def test_pose_array_conversion_works_on_batches(rng):
    rotations = np.array([DualQuaternion.from_rotation(rng.normal(size=3), a).real
                          for a in rng.uniform(-3, 3, 5)])
    translations = rng.normal(size=(5, 3))
    batch = dq_from_pose_array(rotations, translations)
    assert batch.shape == (5, 8)
    for h, r, t in zip(batch, rotations, translations):
        np.testing.assert_allclose(h, DualQuaternion.from_pose(r, t).coeffs, atol=1e-15)


def test_quat_from_matrix_takes_nested_lists():
    np.testing.assert_allclose(quat_from_matrix([[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
                               [math.sqrt(0.5), math.sqrt(0.5), 0, 0], atol=1e-15)


def test_repr_shows_the_eight_coefficients_in_order():
    h = DualQuaternion([1, 0, 0, 0, 0, 0.25, -0.5, 1e-12])
    assert repr(h) == 'DualQuaternion(1, 0, 0, 0, 0, 0.25, -0.5, 1e-12)'


def test_screw_of_the_identity_is_no_motion_about_z():
    theta, d, axis, moment = DualQuaternion.identity().screw_parameters()
    assert (theta, d) == (0.0, 0.0)
    np.testing.assert_array_equal(axis, [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(moment, [0.0, 0.0, 0.0])


def test_isclose_knows_both_signs_of_a_pose():
    h = DualQuaternion.from_rotation([1, 2, 3], 0.7) * DualQuaternion.from_translation([1, 0, 2])
    assert h.isclose(DualQuaternion(-h.coeffs)) and h.isclose(h)
    assert not h.isclose(DualQuaternion.identity())


def test_normalising_a_batch_makes_each_row_a_unit_pose(rng):
    batch = rng.normal(size=(6, 8))
    unit = dq_normalize_array(batch)
    assert unit.shape == (6, 8)
    for row, h in zip(unit, batch):
        np.testing.assert_allclose(np.linalg.norm(row[:4]), 1.0, atol=1e-15)
        np.testing.assert_allclose(np.dot(row[:4], row[4:]), 0.0, atol=1e-15)
        np.testing.assert_allclose(row, dq_normalize_array(h), atol=1e-15)


def test_the_plain_float_product_and_inverse_match_the_class():
    from dq_fk_ros.kinematics.dual_quaternion import dq_inverse_coeffs, dq_multiply_coeffs
    rng = np.random.default_rng(11)
    for _ in range(20):
        a = DualQuaternion.from_pose(rng.normal(size=4), rng.normal(size=3))
        b = DualQuaternion.from_pose(rng.normal(size=4), rng.normal(size=3))
        product = dq_multiply_coeffs(tuple(a.coeffs), tuple(b.coeffs))
        np.testing.assert_allclose(product, (a * b).coeffs, atol=1e-14)
        inverse = dq_inverse_coeffs(tuple(a.coeffs))
        np.testing.assert_allclose(inverse, a.inverse().coeffs, atol=1e-14)
        np.testing.assert_allclose(dq_multiply_coeffs(inverse, tuple(a.coeffs)),
                                   [1, 0, 0, 0, 0, 0, 0, 0], atol=1e-14)


def test_pose_xyzw_in_is_the_inverse_frame_times_the_pose():
    """``pose_xyzw_in`` against 4x4 matrices, batched."""
    rng = np.random.default_rng(11)
    frames, poses, expected = [], [], []
    for _ in range(20):
        a = DualQuaternion.from_rotation(rng.normal(size=3), rng.uniform(-3, 3)) * \
            DualQuaternion.from_translation(rng.normal(size=3))
        b = DualQuaternion.from_rotation(rng.normal(size=3), rng.uniform(-3, 3)) * \
            DualQuaternion.from_translation(rng.normal(size=3))
        frames.append(a.to_pose_xyzw())
        poses.append(b.to_pose_xyzw())
        expected.append(np.linalg.inv(a.to_matrix()) @ b.to_matrix())
    got = pose_xyzw_in(np.array(frames), np.array(poses))
    assert (got[:, 6] >= 0).all()
    for pose, matrix in zip(got, expected):
        np.testing.assert_allclose(hm.matrix_of_pose(pose[:3], pose[3:]), matrix, atol=1e-12)


def test_negation_negates_every_coefficient():
    h = DualQuaternion.from_pose([0.0, 0.6, 0.0, 0.8], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal((-h).coeffs, -h.coeffs)


def test_the_norm_of_a_dual_number_and_of_zero():
    """``||h|| = |r| + eps (r . d) / |r|``; zero's norm is zero, not a division by it."""
    h = DualQuaternion(np.array([2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    assert h.norm() == (2.0, 1.0)
    assert DualQuaternion(np.zeros(8)).norm() == (0.0, 0.0)


def test_is_unit_needs_both_conditions_and_its_tolerance_is_inclusive():
    assert DualQuaternion.identity().is_unit(tol=0.0)   # exactly 1 and exactly 0
    assert not DualQuaternion(np.array([1.0 + 1e-6, 0, 0, 0, 0, 0, 0, 0])).is_unit()
    assert not DualQuaternion(np.array([1.0, 0, 0, 0, 0.5, 0, 0, 0])).is_unit()  # r . d != 0
    assert DualQuaternion(np.array([1.0 + 1e-10, 0, 0, 0, 0, 0, 0, 0])).is_unit()


def test_zero_has_no_inverse_and_says_why():
    with pytest.raises(ZeroDivisionError, match='^dual quaternion with zero real part has no '
                                                'inverse$'):
        DualQuaternion(np.array([0.0, 0, 0, 0, 1.0, 0, 0, 0])).inverse()


@pytest.mark.parametrize('dist', [0.5, 2.0])
def test_a_pure_translation_screws_along_its_direction_however_short(dist):
    theta, d, axis, moment = DualQuaternion.from_pose([1.0, 0.0, 0.0, 0.0],
                                                      [dist, 0.0, 0.0]).screw_parameters()
    assert (theta, d) == (0.0, pytest.approx(dist))
    np.testing.assert_allclose(axis, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(moment, np.zeros(3))


def of_xyzw(pose):
    """Return the DualQuaternion of a pose x y z qx qy qz qw."""
    return DualQuaternion.from_pose([pose[6], pose[3], pose[4], pose[5]], pose[:3])


def test_a_pose_in_a_frame_for_one_pose_and_for_a_grid_of_poses():
    """``(7,)`` and ``(a, b, 7)`` arrays as well as ``(n, 7)``: the last axis is the pose."""
    rng = np.random.default_rng(3)

    def poses(shape):
        q = rng.normal(size=shape + (4,))
        return np.concatenate([rng.normal(size=shape + (3,)),
                               q / np.linalg.norm(q, axis=-1, keepdims=True)], axis=-1)
    frames, targets = poses((2, 3)), poses((2, 3))
    grid = pose_xyzw_in(frames, targets)
    assert grid.shape == (2, 3, 7)
    for i in range(2):
        for j in range(3):
            one = pose_xyzw_in(frames[i, j], targets[i, j])
            assert one.shape == (7,)
            np.testing.assert_allclose(grid[i, j], one, atol=1e-12)
            expected = (of_xyzw(frames[i, j]).inverse() * of_xyzw(targets[i, j])).to_pose_xyzw()
            if expected[6] < 0:
                expected[3:] = -expected[3:]
            np.testing.assert_allclose(one, expected, atol=1e-12)


def test_sums_differences_and_scalings_are_coefficient_wise():
    a = DualQuaternion([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    b = DualQuaternion([0.5, -1.0, 0.25, 2.0, -3.0, 1.0, 0.0, 4.0])
    np.testing.assert_array_equal((a + b).coeffs, a.coeffs + b.coeffs)
    np.testing.assert_array_equal((a - b).coeffs, a.coeffs - b.coeffs)
    np.testing.assert_array_equal((a * 2).coeffs, 2.0 * a.coeffs)
    np.testing.assert_array_equal((0.5 * a).coeffs, 0.5 * a.coeffs)
    np.testing.assert_array_equal((a * np.float64(3.0)).coeffs, 3.0 * a.coeffs)


def test_isclose_is_absolute_and_takes_either_sign():
    big = DualQuaternion([1e6, 0, 0, 0, 0, 0, 0, 0])
    near = DualQuaternion([1e6 + 1e-3, 0, 0, 0, 0, 0, 0, 0])   # 1e-9 relative, 1e-3 absolute
    assert not big.isclose(near) and not big.isclose(-near)
    assert big.isclose(near, atol=1e-2) and big.isclose(-near, atol=1e-2)
    unit = DualQuaternion.from_rotation([0, 0, 1], 0.3)
    assert unit.isclose(-unit) and not unit.isclose(DualQuaternion.from_rotation([0, 0, 1], 0.31))


def test_only_a_negative_w_is_flipped():
    """A half turn (w = 0 exactly) keeps its sign: the documented rule is w < 0."""
    half_turn = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0])
    np.testing.assert_array_equal(canonical(half_turn), half_turn)
    np.testing.assert_array_equal(canonical(-half_turn), -half_turn)
    assert pose_xyzw_from_coeffs(half_turn.tolist())[3:] == (1.0, 0.0, 0.0, 0.0)
    assert pose_xyzw_from_coeffs((-half_turn).tolist())[3:] == (-1.0, 0.0, 0.0, 0.0)


def test_a_rotation_about_no_axis_is_refused():
    for axis in ([0, 0, 0], [0.0, 0.0, 0.0], [np.nan, 0, 0]):
        with pytest.raises(ValueError, match='^rotation axis must be a non-zero vector$'):
            quat_from_axis_angle(axis, 0.5)
    np.testing.assert_allclose(quat_from_axis_angle([0, 0, 2], math.pi),
                               [0.0, 0.0, 0.0, 1.0], atol=1e-15)


def test_whole_numbers_in_give_floats_out():
    """Integer input (a YAML 0, a list of ints) must not make integer arithmetic."""
    product = quat_multiply([1, 2, 3, 4], [5, 6, 7, 8])
    assert product.dtype == np.float64
    np.testing.assert_array_equal(product, quat_multiply([1.0, 2, 3, 4], [5.0, 6, 7, 8]))
    for a, b in (([1, 2, 3, 4], [5.0, 6, 7, 8]), ([1.0, 2, 3, 4], [5, 6, 7, 8])):
        assert quat_multiply(a, b).dtype == np.float64
    h = DualQuaternion([[1, 0, 0, 0], [0, 1, 2, 3]])   # nested: flattened
    assert h.coeffs.dtype == np.float64 and h.coeffs.shape == (8,)


def test_each_refusal_says_what_it_needs():
    with pytest.raises(ValueError) as caught:
        dq_normalize_array([[0, 0, 0, 0, 1, 2, 3, 4]])
    assert str(caught.value) == 'cannot normalise a dual quaternion whose real part is zero'
    with pytest.raises(ValueError) as caught:
        DualQuaternion.from_pose([0, 0, 0, 0], [1, 2, 3])
    assert str(caught.value) == 'rotation quaternion must be non-zero'
    with pytest.raises(ValueError) as caught:
        quat_from_matrix(np.eye(4))
    assert str(caught.value) == 'rotation matrix must be 3x3, got shape (4, 4)'


def test_quat_from_matrix_is_a_unit_quaternion_with_w_not_negative():
    half = math.sqrt(0.5)
    for q in ([half, 0, 0, half], [0.1, -0.7, 0.5, 0.5], [0.9, -0.1, 0.3, -0.3]):
        q = np.array(q) / np.linalg.norm(q)
        for sign in (1, -1):   # either quaternion of the rotation: the one with w >= 0
            np.testing.assert_allclose(quat_from_matrix(quat_to_matrix(sign * q)), q,
                                       atol=1e-12)
    # a matrix a little off a rotation (scaled, as summed rounding leaves it): still unit
    q = quat_from_matrix(1.01 * quat_to_matrix([half, half, 0, 0]))
    np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-12)
