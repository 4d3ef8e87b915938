"""
Dual-quaternion algebra for rigid transformations, in plain numpy.

Conventions, stated once and used everywhere in this module:

* A quaternion is an array ``(w, x, y, z)`` (scalar first), Hamilton product.
  ROS messages use ``(x, y, z, w)``; :func:`quat_wxyz_to_xyzw` and
  :func:`quat_xyzw_to_wxyz` convert at that boundary.
* A dual quaternion ``h = r + eps d`` is an array of 8 numbers
  ``(w, x, y, z, w', x', y', z')``: the real (primary) part ``r`` then the dual part ``d``,
  the layout of [Radavelli2014] eq. (3).
* A pose (rotation ``r``, translation ``t`` in the parent frame) is
  ``h = r + eps (1/2) t r``, so ``x_parent = R x_child + t``; ``t = 2 d r*`` is eq. (17)
  of [Zivkovic2023] and ``r`` is eq. (18).
* Composition is the product ``h_01 * h_12 = h_02`` ([Zivkovic2023] eq. (12)), like 4x4
  homogeneous matrices.
* Unit norm: ``|r| = 1`` and ``r . d = 0``. Canonical sign: the real part has ``w >= 0``
  (``h`` and ``-h`` are the same pose); :func:`canonical` applies it.

The ``*_array`` functions broadcast over leading axes (``(..., 4)`` and ``(..., 8)``) and
serve the batch paths; :class:`DualQuaternion` is the convenient single-pose object.
"""

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

# a dual quaternion as 8 floats (w, x, y, z, w', x', y', z'); a pose (x, y, z, qx, qy, qz, qw)
Coeffs = tuple[float, float, float, float, float, float, float, float]
Pose = tuple[float, float, float, float, float, float, float]


def quat_multiply(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Hamilton product of quaternions ``(..., 4)``, (w, x, y, z) ([Zivkovic2023] Table 1)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_conjugate(q: ArrayLike) -> np.ndarray:
    """Quaternion conjugate ``(w, -x, -y, -z)`` of ``(..., 4)`` arrays."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_from_axis_angle(axis: ArrayLike, angle_rad: float) -> np.ndarray:
    """Return the unit quaternion (w, x, y, z) rotating ``angle_rad`` about ``axis``, eq. (3)."""
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis)
    if not norm > 0.0:
        raise ValueError('rotation axis must be a non-zero vector')
    half = 0.5 * angle_rad
    return np.concatenate([[np.cos(half)], np.sin(half) * axis / norm])


def quat_to_matrix(q: ArrayLike) -> np.ndarray:
    """3x3 rotation matrix (or ``(..., 3, 3)``) of unit quaternions (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quat_from_matrix(m: ArrayLike) -> np.ndarray:
    """Return the unit quaternion (w, x, y, z), ``w >= 0``, of a 3x3 rotation (Shepperd)."""
    m = np.asarray(m, dtype=float)
    if m.shape != (3, 3):
        raise ValueError(f'rotation matrix must be 3x3, got shape {m.shape}')
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    candidates = [trace, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(candidates))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s,
             (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s,
             (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s,
             (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s,
             0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def quat_wxyz_to_xyzw(q: ArrayLike) -> np.ndarray:
    """Reorder quaternions ``(..., 4)`` from (w, x, y, z) to ROS's (x, y, z, w)."""
    return np.asarray(q)[..., [1, 2, 3, 0]]


def quat_xyzw_to_wxyz(q: ArrayLike) -> np.ndarray:
    """Reorder quaternions ``(..., 4)`` from ROS's (x, y, z, w) to (w, x, y, z)."""
    return np.asarray(q)[..., [3, 0, 1, 2]]


def dq_multiply_array(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Dual-quaternion product of ``(..., 8)`` arrays, [Zivkovic2023] eq. (12)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    real = quat_multiply(a[..., :4], b[..., :4])
    dual = quat_multiply(a[..., :4], b[..., 4:]) + quat_multiply(a[..., 4:], b[..., :4])
    return np.concatenate([real, dual], axis=-1)


def dq_from_pose_array(rotation_wxyz: ArrayLike, translation: ArrayLike) -> np.ndarray:
    """Return dual quaternions ``(..., 8)`` of poses: ``r + eps t r / 2``, [Zivkovic2023] (7)."""
    r = np.asarray(rotation_wxyz, dtype=float)
    t = np.asarray(translation, dtype=float)
    t_quat = np.concatenate([np.zeros(t.shape[:-1] + (1,)), t], axis=-1)
    return np.concatenate([r, 0.5 * quat_multiply(t_quat, r)], axis=-1)


def dq_translation_array(h: np.ndarray) -> np.ndarray:
    """Return translations ``(..., 3)`` of unit poses: ``2 d r*``, [Zivkovic2023] eq. (17)."""
    h = np.asarray(h, dtype=float)
    return 2.0 * quat_multiply(h[..., 4:], quat_conjugate(h[..., :4]))[..., 1:]


def canonical(h: np.ndarray) -> np.ndarray:
    """Flip dual quaternions ``(..., 8)`` whose real part has ``w < 0``: the same pose."""
    h = np.asarray(h, dtype=float)
    return np.where(h[..., :1] < 0.0, -h, h)


def dq_to_pose_xyzw(h: np.ndarray) -> np.ndarray:
    """Poses ``(..., 7)``: position x y z then quaternion x y z w (the ROS order), ``w >= 0``."""
    h = canonical(h)
    return np.concatenate([dq_translation_array(h), quat_wxyz_to_xyzw(h[..., :4])], axis=-1)


def pose_xyzw_in(frame: ArrayLike, pose: ArrayLike) -> np.ndarray:
    """
    Return ``pose`` expressed in ``frame``: both ``(..., 7)`` x y z qx qy qz qw, in one frame.

    ``frame^-1 * pose``: position ``R^T (p - p_frame)``, rotation ``q_frame* q``, ``qw >= 0``.
    """
    frame, pose = np.asarray(frame, dtype=float), np.asarray(pose, dtype=float)
    q_frame = quat_xyzw_to_wxyz(frame[..., 3:])
    inverse = quat_conjugate(q_frame)
    offset = np.concatenate([np.zeros(pose.shape[:-1] + (1,)), pose[..., :3] - frame[..., :3]],
                            axis=-1)
    position = quat_multiply(quat_multiply(inverse, offset), q_frame)[..., 1:]
    rotation = quat_multiply(inverse, quat_xyzw_to_wxyz(pose[..., 3:]))
    rotation = np.where(rotation[..., :1] < 0.0, -rotation, rotation)
    return np.concatenate([position, quat_wxyz_to_xyzw(rotation)], axis=-1)


def pose_xyzw_from_coeffs(h: Sequence[float]) -> Pose:
    """
    Pose ``(x, y, z, qx, qy, qz, qw)`` of 8 plain floats, ``qw >= 0``; no numpy.

    The position is the vector part of ``2 d r*`` ([Zivkovic2023] eq. (17)); the scalar fast
    path of :func:`dq_to_pose_xyzw` for one dual quaternion.
    """
    w, x, y, z, dw, dx, dy, dz = h
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
        dw, dx, dy, dz = -dw, -dx, -dy, -dz
    return (2.0 * (dx * w - dw * x - dy * z + dz * y),
            2.0 * (dy * w - dw * y + dx * z - dz * x),
            2.0 * (dz * w - dw * z - dx * y + dy * x),
            x, y, z, w)


def dq_multiply_coeffs(a: Sequence[float], b: Sequence[float]) -> Coeffs:
    """[Zivkovic2023] eq. (12) on two 8-tuples (floats, or equal-length arrays each)."""
    aw, ax, ay, az, bw_, bx_, by_, bz_ = a
    cw, cx, cy, cz, dw, dx, dy, dz = b
    return (
        aw * cw - ax * cx - ay * cy - az * cz,
        aw * cx + ax * cw + ay * cz - az * cy,
        aw * cy - ax * cz + ay * cw + az * cx,
        aw * cz + ax * cy - ay * cx + az * cw,
        aw * dw - ax * dx - ay * dy - az * dz + bw_ * cw - bx_ * cx - by_ * cy - bz_ * cz,
        aw * dx + ax * dw + ay * dz - az * dy + bw_ * cx + bx_ * cw + by_ * cz - bz_ * cy,
        aw * dy - ax * dz + ay * dw + az * dx + bw_ * cy - bx_ * cz + by_ * cw + bz_ * cx,
        aw * dz + ax * dy - ay * dx + az * dw + bw_ * cz + bx_ * cy - by_ * cx + bz_ * cw,
    )


def dq_inverse_coeffs(h: Sequence[float]) -> Coeffs:
    """Inverse of a unit dual quaternion given as 8 plain floats: both parts conjugated."""
    w, x, y, z, dw, dx, dy, dz = h
    return (w, -x, -y, -z, dw, -dx, -dy, -dz)


def dq_normalize_array(h: ArrayLike) -> np.ndarray:
    """
    Project ``(..., 8)`` arrays onto unit dual quaternions.

    The real part is scaled to norm 1 and the dual part is scaled alike, then its component
    along the real part is removed, so that ``r . d = 0``.
    """
    h = np.asarray(h, dtype=float)
    norm = np.linalg.norm(h[..., :4], axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError('cannot normalise a dual quaternion whose real part is zero')
    r = h[..., :4] / norm
    d = h[..., 4:] / norm
    d = d - np.sum(r * d, axis=-1, keepdims=True) * r
    return np.concatenate([r, d], axis=-1)


class DualQuaternion:
    """
    A dual quaternion ``r + eps d``, stored as 8 floats (w, x, y, z, w', x', y', z').

    Construct poses with :meth:`from_pose`, :meth:`from_matrix` or :meth:`identity`;
    compose them with ``*`` ([Zivkovic2023] eq. (12)).
    """

    __slots__ = ('coeffs',)

    def __init__(self, coeffs: ArrayLike):
        coeffs = np.array(coeffs, dtype=float).reshape(-1)
        if coeffs.shape != (8,):
            raise ValueError(f'a dual quaternion has 8 coefficients, got {coeffs.size}')
        self.coeffs = coeffs

    # -- construction ------------------------------------------------------------------
    @classmethod
    def from_array(cls, coeffs: ArrayLike) -> 'DualQuaternion':
        """Wrap a float64 array of shape (8,) without copying or checking it."""
        h = cls.__new__(cls)
        h.coeffs = coeffs
        return h

    @classmethod
    def identity(cls) -> 'DualQuaternion':
        """Return the identity transform."""
        return cls([1.0, 0, 0, 0, 0, 0, 0, 0])

    @classmethod
    def from_pose(cls, rotation_wxyz: ArrayLike = (1.0, 0.0, 0.0, 0.0),
                  translation: ArrayLike = (0.0, 0.0, 0.0)) -> 'DualQuaternion':
        """Pose from a unit quaternion (w, x, y, z) and a translation in the parent frame."""
        r = np.asarray(rotation_wxyz, dtype=float)
        norm = np.linalg.norm(r)
        if not norm > 0.0:
            raise ValueError('rotation quaternion must be non-zero')
        return cls(dq_from_pose_array(r / norm, translation))

    @classmethod
    def from_rotation(cls, axis: ArrayLike, angle_rad: float) -> 'DualQuaternion':
        """Pure rotation by ``angle_rad`` about ``axis`` through the origin."""
        return cls.from_pose(quat_from_axis_angle(axis, angle_rad))

    @classmethod
    def from_translation(cls, translation: ArrayLike) -> 'DualQuaternion':
        """Pure translation (metres)."""
        return cls.from_pose(translation=translation)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike) -> 'DualQuaternion':
        """Pose from a 4x4 homogeneous transformation matrix."""
        matrix = np.asarray(matrix, dtype=float)
        if matrix.shape != (4, 4):
            raise ValueError(f'homogeneous matrix must be 4x4, got shape {matrix.shape}')
        return cls.from_pose(quat_from_matrix(matrix[:3, :3]), matrix[:3, 3])

    # -- parts -------------------------------------------------------------------------
    @property
    def real(self) -> np.ndarray:
        """Real (primary) part, a quaternion (w, x, y, z); the rotation of a unit pose."""
        return self.coeffs[:4]

    @property
    def dual(self) -> np.ndarray:
        """Dual part, a quaternion (w, x, y, z)."""
        return self.coeffs[4:]

    @property
    def rotation_wxyz(self) -> np.ndarray:
        """Rotation quaternion (w, x, y, z), [Zivkovic2023] eq. (18) (sign as stored)."""
        return self.coeffs[:4].copy()

    @property
    def translation(self) -> np.ndarray:
        """Return the position (x, y, z) of a unit pose, [Zivkovic2023] eq. (17)."""
        return dq_translation_array(self.coeffs)

    def to_matrix(self) -> np.ndarray:
        """4x4 homogeneous transformation matrix of a unit dual quaternion."""
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(self.coeffs[:4])
        m[:3, 3] = self.translation
        return m

    def to_pose_xyzw(self) -> np.ndarray:
        """Position (x, y, z) and quaternion (x, y, z, w) with ``w >= 0``, as 7 floats."""
        return dq_to_pose_xyzw(self.coeffs)

    # -- algebra -----------------------------------------------------------------------
    def __mul__(self, other):
        """Dual-quaternion product, [Zivkovic2023] eq. (12): composition of transforms."""
        if isinstance(other, DualQuaternion):
            return DualQuaternion(dq_multiply_array(self.coeffs, other.coeffs))
        if np.isscalar(other):
            return DualQuaternion(self.coeffs * float(other))
        return NotImplemented

    def __rmul__(self, scalar):
        """Scale by a real number."""
        if np.isscalar(scalar):
            return DualQuaternion(self.coeffs * float(scalar))
        return NotImplemented

    def __add__(self, other):
        """Sum of two dual quaternions."""
        return DualQuaternion(self.coeffs + other.coeffs)

    def __sub__(self, other):
        """Difference of two dual quaternions."""
        return DualQuaternion(self.coeffs - other.coeffs)

    def __neg__(self):
        """Negate all 8 coefficients (the same pose for a unit dual quaternion)."""
        return DualQuaternion(-self.coeffs)

    def __repr__(self):
        """Show the 8 coefficients in (w, x, y, z, w', x', y', z') order."""
        return 'DualQuaternion(' + ', '.join(f'{c:.9g}' for c in self.coeffs) + ')'

    def conjugate(self) -> 'DualQuaternion':
        """Quaternion conjugate of both parts, ``r* + eps d*``: the inverse of a unit pose."""
        return DualQuaternion(np.concatenate([quat_conjugate(self.real),
                                              quat_conjugate(self.dual)]))

    def dual_number_conjugate(self) -> 'DualQuaternion':
        """Dual-number conjugate ``r - eps d``."""
        return DualQuaternion(np.concatenate([self.real, -self.dual]))

    def combined_conjugate(self) -> 'DualQuaternion':
        """Both conjugates at once, ``r* - eps d*`` (used to transform points)."""
        return DualQuaternion(np.concatenate([quat_conjugate(self.real),
                                              -quat_conjugate(self.dual)]))

    def norm(self) -> tuple[float, float]:
        """Dual-number norm ``(|r|, r . d / |r|)`` (real part, dual part)."""
        n = float(np.linalg.norm(self.real))
        if n == 0.0:
            return 0.0, 0.0
        return n, float(np.dot(self.real, self.dual)) / n

    def is_unit(self, tol: float = 1e-9) -> bool:
        """Whether ``|r| = 1`` and ``r . d = 0`` within ``tol``."""
        n_real, n_dual = self.norm()
        return abs(n_real - 1.0) <= tol and abs(n_dual) <= tol

    def normalized(self) -> 'DualQuaternion':
        """Return the nearest unit dual quaternion (see :func:`dq_normalize_array`)."""
        return DualQuaternion(dq_normalize_array(self.coeffs))

    def canonical(self) -> 'DualQuaternion':
        """Return the same pose with ``w >= 0`` in the real part."""
        return DualQuaternion(canonical(self.coeffs))

    def inverse(self) -> 'DualQuaternion':
        """Multiplicative inverse ``r^-1 - eps r^-1 d r^-1`` (any non-zero real part)."""
        r = self.real
        n2 = float(np.dot(r, r))
        if n2 == 0.0:
            raise ZeroDivisionError('dual quaternion with zero real part has no inverse')
        r_inv = quat_conjugate(r) / n2
        d_inv = -quat_multiply(quat_multiply(r_inv, self.dual), r_inv)
        return DualQuaternion(np.concatenate([r_inv, d_inv]))

    def transform_point(self, point: ArrayLike) -> np.ndarray:
        """Map a point (x, y, z) from the child frame to the parent frame."""
        point = np.asarray(point, dtype=float)
        p = np.concatenate([[0.0], point])
        rotated = quat_multiply(quat_multiply(self.real, p), quat_conjugate(self.real))
        return rotated[1:] + self.translation

    def isclose(self, other: 'DualQuaternion', atol: float = 1e-9) -> bool:
        """Whether both represent the same pose (``h`` or ``-h``) within ``atol``."""
        a, b = self.coeffs, other.coeffs
        return bool(np.allclose(a, b, atol=atol, rtol=0) or np.allclose(a, -b, atol=atol, rtol=0))

    # -- screw motion ------------------------------------------------------------------
    def screw_parameters(self) -> tuple[float, float, np.ndarray, np.ndarray]:
        """
        Screw of a unit pose: ``(theta, d, axis, moment)``.

        Rotation ``theta`` (rad, in [0, pi] after canonical sign) about and translation ``d``
        along the line with unit direction ``axis`` and moment ``moment`` (Pluecker).
        For a pure translation, ``axis`` is its direction and ``moment`` is zero.
        """
        h = canonical(self.coeffs)
        r, d = h[:4], h[4:]
        t = dq_translation_array(h)
        sin_half = float(np.linalg.norm(r[1:]))
        theta = 2.0 * float(np.arctan2(sin_half, r[0]))
        if sin_half < 1e-12:
            dist = float(np.linalg.norm(t))
            axis = t / dist if dist > 0.0 else np.array([0.0, 0.0, 1.0])
            return 0.0, dist, axis, np.zeros(3)
        axis = r[1:] / sin_half
        dist = float(np.dot(t, axis))
        # d = (1/2) t r; its parts give the moment: m = (d_vec - (dist/2) cos(th/2) axis)/sin(th/2)
        moment = (d[1:] - 0.5 * dist * r[0] * axis) / sin_half
        return theta, dist, axis, moment

    @classmethod
    def from_screw_parameters(cls, theta: float, dist: float, axis: ArrayLike,
                              moment: ArrayLike) -> 'DualQuaternion':
        """Return the unit pose of a screw motion (inverse of :meth:`screw_parameters`)."""
        axis = np.asarray(axis, dtype=float)
        moment = np.asarray(moment, dtype=float)
        c, s = np.cos(0.5 * theta), np.sin(0.5 * theta)
        real = np.concatenate([[c], s * axis])
        dual = np.concatenate([[-0.5 * dist * s], s * moment + 0.5 * dist * c * axis])
        return cls(np.concatenate([real, dual]))

    def power(self, tau: float) -> 'DualQuaternion':
        """``h ** tau`` of a unit pose: the same screw axis, ``tau`` times the motion."""
        theta, dist, axis, moment = self.screw_parameters()
        return DualQuaternion.from_screw_parameters(tau * theta, tau * dist, axis, moment)

    def sclerp(self, other: 'DualQuaternion', tau: float) -> 'DualQuaternion':
        """Screw-linear interpolation ``self (self^-1 other)^tau``, ``tau`` in [0, 1]."""
        return self * (self.conjugate() * other).power(tau)
