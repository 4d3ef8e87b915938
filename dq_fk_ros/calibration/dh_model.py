"""
The measured pose as a function of a chain's DH parameters, and its analytic Jacobian.

The measured frame M (a laser tracker's reflector, a touch probe's tip, a camera's marker)
is predicted at joint values q as

    T_WM(q) = T_WB * base * F_1(q) ... F_4n(q) * tool * T_EM

with T_WB the robot's fixed frame in the measurement frame W (6 parameters), each DH row's
four factors ([Zivkovic2023] eqs. (13)-(15): ``Rz(theta) Tz(d) Tx(a) Rx(alpha)`` for a
standard row, ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` for a modified one; theta and d add the
joint's value where the row reads one), the file's base and tool as they are, and T_EM the
measured frame in the chain's end frame (its position always, its orientation when
orientation is measured). Rotations of T_WB and T_EM are rotation vectors (rad).

The Jacobian, from the factors. A factor is ``F(p) = exp(p xi / 2)``, its unit screw ``xi``
along the frame's own axis: ``k`` for Rz, ``eps k`` for Tz, ``eps i`` for Tx, ``i`` for Rx.
So ``dF/dp = xi F / 2`` and, for ``Q = A F(p) B``, ``dQ/dp = (A xi A*) Q / 2 = S Q / 2``:
``S`` is the factor's axis as a line in the fixed frame, ``u + eps c x u`` for a rotation
about the line through ``c`` along ``u``, ``eps u`` for a translation along ``u``. With
``Q = r + eps t r / 2`` ([Zivkovic2023] eqs. (17), (18)), ``dQ/dp = S Q / 2`` is a rotation
rate ``omega = u`` and, for a point ``x`` moving with the end, ``dx/dp = u x (x - c)``
(rotations: theta, alpha); ``omega = 0`` and ``dx/dp = u`` (translations: d, a). ``u`` and
``c`` are the prefix ``A``'s z axis (theta, d) or x axis (a, alpha) and its origin, read
off the chain's dual quaternions as they are multiplied. test_calibration.py holds this
Jacobian to central differences of :meth:`DhPoseModel.predict`.
"""

from dataclasses import dataclass

from dq_fk_ros.kinematics.dual_quaternion import (
    dq_multiply_array, dq_translation_array, quat_multiply, quat_to_matrix)
import numpy as np

ROW_FIELDS = ('theta', 'd', 'a', 'alpha')
FACTORS = {'standard': (('z', True, 'theta'), ('z', False, 'd'), ('x', False, 'a'),
                        ('x', True, 'alpha')),
           'modified': (('x', True, 'alpha'), ('x', False, 'a'), ('z', True, 'theta'),
                        ('z', False, 'd'))}
FRAME_FIELDS = ('base_x', 'base_y', 'base_z', 'base_rx', 'base_ry', 'base_rz',
                'end_x', 'end_y', 'end_z', 'end_rx', 'end_ry', 'end_rz')


def quaternion_of_rotvec(v: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``(w, x, y, z)`` of rotation vectors ``(..., 3)`` (rad)."""
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(angle/2)/angle, its series below 1e-8 rad
    k = np.where(angle > 1e-8, np.sin(half) / np.where(angle > 1e-8, angle, 1.0),
                 0.5 - angle ** 2 / 48.0)
    return np.concatenate([np.cos(half), k * v], axis=-1)


def rotvec_of_quaternion(r: np.ndarray) -> np.ndarray:
    """Return the rotation vectors ``(..., 3)`` of unit quaternions ``(w, x, y, z)``."""
    r = np.where(r[..., :1] < 0, -r, r)  # the short way round
    s = np.linalg.norm(r[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, r[..., :1])
    k = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0 / r[..., :1])
    return k * r[..., 1:]


def skew(v: np.ndarray) -> np.ndarray:
    """Return the cross-product matrices of vectors (..., 3): their products with w are v x w."""
    x, y, z = np.moveaxis(v, -1, 0)
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1),
                     np.stack([-y, x, o], -1)], axis=-2)


def left_jacobian(v: np.ndarray, inverse: bool = False) -> np.ndarray:
    """
    Return SO(3)'s left Jacobian of rotation vectors ``(..., 3)`` (or its inverse).

    ``Exp(v + dv) = Exp(J_l(v) dv) Exp(v)`` to first order; ``J_r(v) = J_l(v).T``.
    """
    v = np.asarray(v, dtype=float)
    t = np.linalg.norm(v, axis=-1)[..., None, None]
    big = t > 1e-6
    ts = np.where(big, t, 1.0)
    vx = skew(v)
    vx2 = vx @ vx
    eye = np.broadcast_to(np.eye(3), vx.shape)
    if inverse:
        c2 = np.where(big, 1.0 / ts ** 2 - (1 + np.cos(ts)) / (2 * ts * np.sin(ts)),
                      1.0 / 12.0)
        return eye - 0.5 * vx + c2 * vx2
    c1 = np.where(big, (1 - np.cos(ts)) / ts ** 2, 0.5)
    c2 = np.where(big, (ts - np.sin(ts)) / ts ** 3, 1.0 / 6.0)
    return eye + c1 * vx + c2 * vx2


@dataclass(frozen=True)
class DhPoseModel:
    """
    The chain of a :class:`~dq_fk_ros.kinematics.chain_table.ChainTable`, its DH rows free.

    Parameters, one vector (lengths m, angles rad): per row ``theta, d, a, alpha`` (theta
    and d the row's constants, the joint's value added where the row reads one), then the
    robot's fixed frame in the measurement frame (``base_x .. base_rz``: translation,
    rotation vector) and the measured frame in the chain's end frame (``end_x .. end_rz``).
    """

    convention: str
    base: np.ndarray          # (8,) the file's base, (w, x, y, z, w', x', y', z')
    tool: np.ndarray          # (8,) the file's tool (identity when none)
    theta_index: np.ndarray   # per row, the column of q its theta reads (-1: none)
    d_index: np.ndarray
    scale: np.ndarray
    nominal_rows: np.ndarray  # (rows, 4): theta, d, a, alpha
    row_names: tuple          # a name per row (its frame)

    @classmethod
    def from_table(cls, table, row_names) -> 'DhPoseModel':
        """Return the model of a chain's table, its rows named ``row_names``."""
        identity = np.array([1.0, 0, 0, 0, 0, 0, 0, 0])
        return cls(table.convention, np.array(table.base, dtype=float),
                   identity if table.tool is None else np.array(table.tool, dtype=float),
                   np.asarray(table.theta_index), np.asarray(table.d_index),
                   np.asarray(table.scale, dtype=float),
                   np.stack([table.theta0, table.d0, table.a, table.alpha], axis=1),
                   tuple(row_names))

    @property
    def names(self) -> list:
        """Return every parameter's name: ``<row>.theta`` ... then the frames' fields."""
        return [f'{row}.{field}' for row in self.row_names for field in ROW_FIELDS] + \
            list(FRAME_FIELDS)

    @property
    def angular(self) -> np.ndarray:
        """Return per parameter whether it is an angle (rad) rather than a length (m)."""
        rows = [True, False, False, True] * len(self.row_names)
        return np.array(rows + [False] * 3 + [True] * 3 + [False] * 3 + [True] * 3)

    def nominal(self, base_in_measurement=None, measured_in_end=None) -> np.ndarray:
        """Return the parameter vector of the nominal rows and the two frames given."""
        frames = np.zeros(12)
        if base_in_measurement is not None:
            frames[:6] = base_in_measurement
        if measured_in_end is not None:
            frames[6:] = measured_in_end
        return np.concatenate([self.nominal_rows.reshape(-1), frames])

    def predict(self, params: np.ndarray, q: np.ndarray, jacobian: bool = False) -> tuple:
        """
        Return the measured frame at joint values ``q`` ``(M, dof)``, in the measurement frame.

        :returns: ``(positions (M, 3) m, quaternions (M, 4) (w, x, y, z))``, and with
            ``jacobian`` their derivative ``(M, 6, P)``: rows ``dx, dy, dz`` (m) and the
            rotation rate ``wx, wy, wz`` (rad, measurement frame) per unit of each parameter.
        """
        q = np.asarray(q, dtype=float)
        m, n = len(q), len(self.row_names)
        rows = params[:4 * n].reshape(n, 4)
        t_wb, phi, t_em, psi = params[4 * n:4 * n + 3], params[4 * n + 3:4 * n + 6], \
            params[4 * n + 6:4 * n + 9], params[4 * n + 9:4 * n + 12]
        # the chain's dual quaternion, components first: h[k] is component k of every
        # configuration (the factors multiplied on the right in closed form, _times)
        h = np.repeat(np.asarray(self.base, dtype=float)[:, None], m, axis=1)
        axes = []   # per factor: (parameter index, rotation?, u (M,3), c (M,3))
        for i in range(n):
            values = {'theta': rows[i, 0], 'd': rows[i, 1], 'a': rows[i, 2],
                      'alpha': rows[i, 3]}
            if self.theta_index[i] >= 0:
                values['theta'] = values['theta'] + self.scale[i] * q[:, self.theta_index[i]]
            if self.d_index[i] >= 0:
                values['d'] = values['d'] + self.scale[i] * q[:, self.d_index[i]]
            for axis, rotation, field in FACTORS[self.convention]:
                if jacobian:
                    axes.append((4 * i + ROW_FIELDS.index(field), rotation,
                                 _axis_of(h, axis), _origin_of(h)))
                h = _times(h, axis, rotation, values[field])
        h = np.ascontiguousarray(h.T)
        h = dq_multiply_array(h, self.tool)
        r_end = quat_to_matrix(h[:, :4])
        x = dq_translation_array(h) + r_end @ t_em            # the measured point, robot frame
        q_wb = quaternion_of_rotvec(phi)
        r_wb = quat_to_matrix(q_wb)
        positions = t_wb + x @ r_wb.T
        quaternions = quat_multiply(quat_multiply(
            np.broadcast_to(q_wb, (m, 4)), h[:, :4]), quaternion_of_rotvec(psi))
        if not jacobian:
            return positions, quaternions
        jac = np.zeros((m, 6, len(params)))
        for k, rotation, u, c in axes:
            if rotation:
                jac[:, :3, k] = np.cross(u, x - c) @ r_wb.T
                jac[:, 3:, k] = u @ r_wb.T
            else:
                jac[:, :3, k] = u @ r_wb.T
        f = 4 * n
        jac[:, :3, f:f + 3] = np.eye(3)
        jac[:, :3, f + 3:f + 6] = -skew(x @ r_wb.T) @ left_jacobian(phi)
        jac[:, 3:, f + 3:f + 6] = left_jacobian(phi)
        jac[:, :3, f + 6:f + 9] = r_wb @ r_end
        jac[:, 3:, f + 9:f + 12] = r_wb @ r_end @ left_jacobian(psi)
        return positions, quaternions, jac


def _times(h: np.ndarray, axis: str, rotation: bool, value) -> np.ndarray:
    """
    Return ``h F`` for one factor F ([Zivkovic2023] eqs. (13)-(15)), components first.

    ``Rz(v) = cos(v/2) + k sin(v/2)``, ``Rx(v) = cos(v/2) + i sin(v/2)`` multiply both parts
    of ``h``; ``Tz(v) = 1 + eps k v/2``, ``Tx(v) = 1 + eps i v/2`` add ``r k v/2`` or ``r i
    v/2`` to its dual part (``r`` its real part): the quaternion products written out for
    these sparse factors (test_calibration.py holds the chain to 4x4 products).
    """
    if rotation:
        c, s = np.cos(0.5 * value), np.sin(0.5 * value)
        out = np.empty_like(h)
        for at in (0, 4):
            w, x, y, z = h[at], h[at + 1], h[at + 2], h[at + 3]
            if axis == 'z':   # (w, x, y, z)(c, 0, 0, s)
                out[at], out[at + 1] = w * c - z * s, x * c + y * s
                out[at + 2], out[at + 3] = y * c - x * s, z * c + w * s
            else:             # (w, x, y, z)(c, s, 0, 0)
                out[at], out[at + 1] = w * c - x * s, x * c + w * s
                out[at + 2], out[at + 3] = y * c + z * s, z * c - y * s
        return out
    t = 0.5 * value
    out = h.copy()
    w, x, y, z = h[0], h[1], h[2], h[3]
    if axis == 'z':   # + eps (w, x, y, z)(0, 0, 0, t)
        out[4] -= z * t
        out[5] += y * t
        out[6] -= x * t
        out[7] += w * t
    else:             # + eps (w, x, y, z)(0, t, 0, 0)
        out[4] -= x * t
        out[5] += w * t
        out[6] += z * t
        out[7] -= y * t
    return out


def _axis_of(h: np.ndarray, axis: str) -> np.ndarray:
    """Return the ``(M, 3)`` z or x axis of the frames ``h`` (components first)."""
    w, x, y, z = h[0], h[1], h[2], h[3]
    if axis == 'z':
        return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], 1)
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], 1)


def _origin_of(h: np.ndarray) -> np.ndarray:
    """Return the ``(M, 3)`` origins ``2 d r*`` of the frames ``h`` (components first)."""
    w, x, y, z = h[0], h[1], h[2], h[3]
    dw, dx, dy, dz = h[4], h[5], h[6], h[7]
    return 2 * np.stack([-dw * x + dx * w - dy * z + dz * y,
                         -dw * y + dx * z + dy * w - dz * x,
                         -dw * z - dx * y + dy * x + dz * w], 1)


__all__ = ['DhPoseModel', 'FRAME_FIELDS', 'left_jacobian', 'quaternion_of_rotvec',
           'ROW_FIELDS', 'rotvec_of_quaternion']
