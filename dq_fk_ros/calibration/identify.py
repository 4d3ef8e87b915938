"""
A chain's DH parameters identified from measured poses: which can be, their values, how well.

:func:`calibrate` fits :class:`~dq_fk_ros.calibration.dh_model.DhPoseModel` to
measurements in three steps. (1) The two frames alone (the robot's fixed frame in the
measurement frame, started from the rigid fit of the nominal points (Kabsch), and the
measured point or frame in the end frame), the DH table as published: the residuals
"before". (2) Which parameters the data can separate: the rank of the weighted
identification Jacobian at that fit, its columns normalised, by QR in an order of
preference (the frames, then the rows from the base out: theta, d, a, alpha); a column
that adds no rank (relative residual below ``RANK_TOLERANCE``) is held at its nominal
value and named (a row's theta and d that the fixed frame's pose already moves, the d of
the second and third of three parallel axes, what the measured frame absorbs after the last
joint, the measured frame's orientation from positions). (3) Levenberg-Marquardt
(``scipy.optimize.least_squares``, ``method='lm'``, the analytic Jacobian) on those that
can be, positions weighted by ``1/sigma_position`` and orientations by
``1/sigma_orientation``: given, else estimated from the residuals and fitted again.

The observability index is O1 of Borm and Menq: the geometric mean of the singular values
of the identification Jacobian over the square root of the number of measurements, in
metres (angles times the chain's reach, orientation rows too); :func:`plan_configurations`
chooses configurations within the limits that maximise it (its determinant, greedily, then
exchanged).
"""

from dataclasses import dataclass, field

from dq_fk_ros.calibration.dh_model import (
    DhPoseModel, left_jacobian, quaternion_of_rotvec, rotvec_of_quaternion)
from dq_fk_ros.errors import DqFkError
from dq_fk_ros.kinematics.dual_quaternion import quat_from_matrix, quat_multiply
import numpy as np

RANK_TOLERANCE = 1e-6
MAX_MAGNITUDE = 1e4   # m or rad: a joint value or measured coordinate beyond is no robot's
DEFAULT_SIGMA_POSITION = 1e-4     # m, before one is estimated
DEFAULT_SIGMA_ORIENTATION = 1e-3  # rad


def require_scipy() -> None:
    """Raise a one-line :class:`DqFkError` where scipy (Levenberg-Marquardt) is missing."""
    try:
        import scipy.optimize  # noqa: F401
    except ImportError:
        raise DqFkError("calibration needs scipy: pip install 'dq_fk_ros[calibrate]'") \
            from None


@dataclass(frozen=True)
class Measurements:
    """Joint values ``q`` ``(M, dof)``, measured ``positions`` ``(M, 3)`` m, and orientations."""

    q: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray | None = None  # (M, 4) (w, x, y, z), or None: positions only

    def __len__(self):
        return len(self.q)

    def subset(self, rows) -> 'Measurements':
        """Return the measurements ``rows`` (indices or a mask)."""
        return Measurements(self.q[rows], self.positions[rows],
                            None if self.quaternions is None else self.quaternions[rows])


@dataclass
class Residuals:
    """Position (m) and orientation (rad) residuals, per measurement, predicted - measured."""

    position: np.ndarray               # (M, 3)
    orientation: np.ndarray | None     # (M, 3) rotation vectors, or None

    def summary(self) -> dict:
        """Return RMS and max of the position and orientation errors (norms per measurement)."""
        p = np.linalg.norm(self.position, axis=1)
        out = {'position_rms_m': _rms(p), 'position_max_m': float(p.max(initial=0.0)),
               'measurements': int(len(p))}
        if self.orientation is not None:
            o = np.linalg.norm(self.orientation, axis=1)
            out.update(orientation_rms_rad=_rms(o), orientation_max_rad=float(o.max(initial=0)))
        return out


@dataclass
class Calibration:
    """What :func:`calibrate` found: values, which were held, how sure, residuals."""

    model: DhPoseModel
    nominal: np.ndarray                # every parameter, the frames as fitted in step 1
    params: np.ndarray                 # every parameter after the fit (held: nominal)
    std: np.ndarray                    # per parameter (0: held)
    held: list                         # indices held at their nominal values
    sigma_position: float
    sigma_orientation: float | None
    observability: float               # O1, m
    residuals: dict = field(default_factory=dict)   # 'before'/'after' x 'fit'/'holdout'


def _rms(values) -> float:
    values = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean(values ** 2))) if values.size else 0.0


def residuals_of(model, params, data: Measurements) -> Residuals:
    """Return the residuals of ``params`` on ``data``."""
    positions, quaternions = model.predict(params, data.q)
    orientation = None
    if data.quaternions is not None:
        orientation = _rotation_error(quaternions, data.quaternions)
    return Residuals(positions - data.positions, orientation)


def _rotation_error(predicted, measured):
    """Return ``Log(R_pred R_meas^T)``: rotation vectors in the measurement frame."""
    conj = measured * np.array([1.0, -1.0, -1.0, -1.0])
    return rotvec_of_quaternion(quat_multiply(predicted, conj))


def weighted(model: DhPoseModel, params: np.ndarray, data: Measurements, sigma: tuple,
             free: np.ndarray, jacobian: bool = True) -> tuple:
    """
    Return the weighted residual vector and its Jacobian in the ``free`` parameters.

    Rows per measurement: ``dx/sp, dy/sp, dz/sp`` then, with orientations, the rotation
    error over ``so`` (its Jacobian ``J_l^-1(e) omega``, SO(3)'s left Jacobian).
    """
    sp, so = sigma
    positions, quaternions, jac = model.predict(params, data.q, jacobian=True) if jacobian \
        else (*model.predict(params, data.q), None)
    parts = [(positions - data.positions) / sp]
    jparts = [] if jac is None else [jac[:, :3][:, :, free] / sp]
    if data.quaternions is not None:
        error = _rotation_error(quaternions, data.quaternions)
        parts.append(error / so)
        if jac is not None:
            jparts.append(left_jacobian(error, inverse=True) @ jac[:, 3:][:, :, free] / so)
    r = np.concatenate(parts, axis=1).reshape(-1)
    if jac is None:
        return r, None
    return r, np.concatenate(jparts, axis=1).reshape(len(r), len(free))


def fit(model, start, free, data, sigma) -> np.ndarray:
    """Return ``start`` with the ``free`` parameters fitted by Levenberg-Marquardt."""
    from scipy.optimize import least_squares
    free = np.asarray(free)
    params = np.array(start, dtype=float)

    def full(x):
        p = params.copy()
        p[free] = x
        return p

    last = {}   # the residuals and Jacobian of the last x: MINPACK asks for both at it

    def both(x):
        key = x.tobytes()
        if last.get('key') != key:
            last.update(key=key, value=weighted(model, full(x), data, sigma, free))
        return last['value']

    def fun(x):
        return both(x)[0]

    def jac(x):
        return both(x)[1]

    result = least_squares(fun, params[free], jac=jac, method='lm', x_scale='jac',
                           xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200 * (len(free) + 1))
    return full(result.x)


def rigid_start(model, data) -> np.ndarray:
    """Return the nominal parameters with the fixed frame from the points' rigid fit (Kabsch)."""
    params = model.nominal()
    robot, _ = model.predict(params, data.q)
    a, b = robot - robot.mean(axis=0), data.positions - data.positions.mean(axis=0)
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, d]) @ vt
    frames = np.zeros(6)
    frames[3:] = rotvec_of_quaternion(quat_from_matrix(rotation))
    frames[:3] = data.positions.mean(axis=0) - rotation @ robot.mean(axis=0)
    return model.nominal(base_in_measurement=frames)


def frame_indices(model, orientation: bool) -> list:
    """Return the indices of the two frames' parameters (no end rotation from positions)."""
    f = 4 * len(model.row_names)
    return list(range(f, f + 9)) + (list(range(f + 9, f + 12)) if orientation else [])


def preference(model) -> list:
    """Return every parameter's index in the order the rank test takes them."""
    f = 4 * len(model.row_names)
    return list(range(f, f + 12)) + list(range(f))


def identifiable(jacobian: np.ndarray, order) -> tuple:
    """
    Return ``(kept, held)``: the columns of ``jacobian`` that add rank, taken in ``order``.

    Columns are normalised; each is kept when what is left of it after projecting out the
    kept ones (modified Gram-Schmidt, twice: a QR in ``order``) is above ``RANK_TOLERANCE``.
    """
    norms = np.linalg.norm(jacobian, axis=0)
    scale = norms.max(initial=0.0)
    basis, kept, held = [], [], []
    for k in order:
        if norms[k] <= 1e-12 * max(scale, 1e-300):
            held.append(k)
            continue
        v = jacobian[:, k] / norms[k]
        for _ in range(2):
            for b in basis:
                v = v - (b @ v) * b
        left = np.linalg.norm(v)
        if left > RANK_TOLERANCE:
            basis.append(v / left)
            kept.append(k)
        else:
            held.append(k)
    return kept, held


def reach(model) -> float:
    """Return a length scale of the chain (m): the sum of its rows' |a| and |d|, at least 0.1."""
    rows = model.nominal_rows
    return max(0.1, float(np.abs(rows[:, 1]).sum() + np.abs(rows[:, 2]).sum()))


def scaled_jacobian(model, params, q, orientation: bool, columns) -> np.ndarray:
    """Return the identification Jacobian in metres: angles times the reach, per column."""
    _, _, jac = model.predict(params, q, jacobian=True)
    length = reach(model)
    rows = jac if orientation else jac[:, :3]
    if orientation:
        rows = rows * np.array([1, 1, 1, length, length, length])[:, None]
    rows = rows.reshape(-1, jac.shape[2])[:, columns]
    return rows * np.where(model.angular[columns], 1.0 / length, 1.0)


def observability_index(jacobian: np.ndarray, measurements: int) -> float:
    """Return O1 (Borm and Menq): geometric mean singular value over sqrt(measurements)."""
    s = np.linalg.svd(jacobian, compute_uv=False)
    if not len(s) or s[-1] <= 0:
        return 0.0
    return float(np.exp(np.mean(np.log(s))) / np.sqrt(measurements))


def calibrate(model: DhPoseModel, data: Measurements, sigma_position=None,
              sigma_orientation=None, holdout=0.0, seed=0) -> Calibration:
    """
    Identify ``model``'s parameters from ``data`` (see the module).

    :param holdout: the share of the measurements (chosen at random with ``seed``) left out
        of the fit and used to judge it.
    """
    orientation = data.quaternions is not None
    for name, values in (('joint value', data.q), ('measured position', data.positions)):
        if values.size and not np.abs(values).max() <= MAX_MAGNITUDE:
            raise DqFkError(f'a {name} of magnitude {np.abs(values).max():.3g}: at most '
                            f'{MAX_MAGNITUDE:g} (rad, m) is taken')
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(data))
    n_out = int(round(holdout * len(data)))
    test, train = data.subset(order[:n_out]), data.subset(np.sort(order[n_out:]))
    sp = sigma_position or DEFAULT_SIGMA_POSITION
    so = (sigma_orientation or DEFAULT_SIGMA_ORIENTATION) if orientation else None
    frames = frame_indices(model, orientation)
    per = 6 if orientation else 3
    needed = -(-(len(frames) + 4 * len(model.row_names)) // per)
    if len(train) < needed:
        raise DqFkError(f'{len(train)} measurements fitted ({len(data)} given, '
                        f'{len(test)} held out): at least {needed} are needed for the '
                        f'{len(frames) + 4 * len(model.row_names)} parameters, tens more to '
                        f'average the noise')
    # (1) the frames alone, the table as published
    start = fit(model, rigid_start(model, train), frames, train, (sp, so))
    # (2) what the data can separate
    _, jac = weighted(model, start, train, (sp, so), np.arange(len(start)))
    kept, held = identifiable(jac, preference(model))
    kept = sorted(kept)
    # (3) everything that can be, weighted by the noise (estimated: fitted again)
    params = fit(model, start, kept, train, (sp, so))
    if orientation and (sigma_position is None or sigma_orientation is None):
        # two kinds of residual: their weights move the fit; positions alone: they do not
        after = residuals_of(model, params, train)
        dof_share = max(1.0, len(train) * (6 if orientation else 3) - len(kept)) / \
            (len(train) * (6 if orientation else 3))
        if sigma_position is None:
            sp = max(1e-9, _rms(after.position) / np.sqrt(dof_share))
        if sigma_orientation is None:
            so = max(1e-9, _rms(after.orientation) / np.sqrt(dof_share))
        start = fit(model, start, frames, train, (sp, so))
        params = fit(model, start, kept, train, (sp, so))
    elif sigma_position is None:   # the noise, for the standard deviations
        dof = max(1, 3 * len(train) - len(kept))
        sp = max(1e-9, float(np.sqrt(np.sum(residuals_of(model, params, train).position ** 2)
                                     / dof)))
    r, jac = weighted(model, params, train, (sp, so), np.array(kept))
    chi2 = float(r @ r) / max(1, len(r) - len(kept))
    std = np.zeros(len(params))
    try:
        cov = np.linalg.inv(jac.T @ jac) * (chi2 if sigma_position is None else 1.0)
        std[kept] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        std[kept] = np.inf
    scaled = scaled_jacobian(model, params, train.q, orientation, kept)
    result = Calibration(model, start, params, std, sorted(held), sp, so,
                         observability_index(scaled, len(train)))
    result.residuals['before_fit'] = residuals_of(model, start, train).summary()
    result.residuals['after_fit'] = residuals_of(model, params, train).summary()
    if len(test):
        # the frames as fitted on the rest, the two tables judged on what the fit never saw
        result.residuals['before_holdout'] = residuals_of(model, start, test).summary()
        result.residuals['after_holdout'] = residuals_of(model, params, test).summary()
    return result


def plan_configurations(model: DhPoseModel, limits: np.ndarray, angular, count: int,
                        orientation: bool, seed: int = 0, candidates: int = 0) -> tuple:
    """
    Return ``count`` joint configurations within ``limits`` that maximise O1, and its value.

    Candidates are drawn uniformly within the limits (an angle's span beyond a turn taken as
    one turn, -pi to pi); the D-optimal greedy choice (each step the candidate that most
    raises ``det(J^T J)``, by the matrix determinant lemma) is then improved by exchanges.
    The robot's fixed frame is taken as the measurement frame and the measured point as the
    end frame's origin; the identifiable columns are those of every candidate.

    :param angular: per joint, whether its value is an angle (rad) rather than a length.
    """
    rng = np.random.default_rng(seed)
    limits = np.asarray(limits, dtype=float)
    lower, upper = limits[:, 0].copy(), limits[:, 1].copy()
    turn = np.asarray(angular, bool) & (upper - lower > 2 * np.pi)
    lower[turn], upper[turn] = -np.pi, np.pi
    pool = rng.uniform(lower, upper, size=(max(candidates, 20 * count, 400), len(lower)))
    params = model.nominal()
    everything = scaled_jacobian(model, params, pool, orientation, np.arange(len(params)))
    kept, _ = identifiable(everything, preference(model))
    kept = sorted(kept)
    k = 6 if orientation else 3
    blocks = everything[:, kept].reshape(len(pool), k, len(kept))
    ridge = 1e-9 * np.eye(len(kept))
    info = ridge.copy()
    chosen = []
    for _ in range(count):
        gains = _gains(blocks, info)
        gains[chosen] = -np.inf
        best = int(np.argmax(gains))
        chosen.append(best)
        info = info + blocks[best].T @ blocks[best]
    for _ in range(3):   # exchanges: swap a chosen one for a better candidate
        changed = False
        for i, c in enumerate(list(chosen)):
            without = info - blocks[c].T @ blocks[c]
            gains = _gains(blocks, without)
            gains[[x for x in chosen if x != c]] = -np.inf
            best = int(np.argmax(gains))
            if best != c and gains[best] > gains[c] + 1e-9:
                chosen[i] = best
                info = without + blocks[best].T @ blocks[best]
                changed = True
        if not changed:
            break
    q = pool[chosen]
    scaled = blocks[chosen].reshape(-1, len(kept))
    return q, observability_index(scaled, len(chosen))


def _gains(blocks, info):
    """Return ``log det(I + U A^-1 U^T)`` per candidate block ``U``."""
    g = blocks @ np.linalg.inv(info)
    inner = np.eye(blocks.shape[1]) + g @ np.swapaxes(blocks, 1, 2)
    return np.linalg.slogdet(inner)[1]


__all__ = ['calibrate', 'Calibration', 'DhPoseModel', 'identifiable', 'Measurements',
           'require_scipy',
           'observability_index', 'plan_configurations', 'quaternion_of_rotvec',
           'Residuals', 'residuals_of']
