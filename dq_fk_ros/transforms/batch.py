"""
Many lookups at once: one frame's pose in another at N stamps, as arrays (numpy, no ROS).

:func:`lookup_poses` answers what ``BufferCore.lookup`` answers at each stamp (the
reference; ``test_tf_batch.py`` holds them equal), edge by edge over all stamps: each edge
of the path found at the first answerable stamp is interpolated at every stamp (tf2's
rules: its samples around the stamp, translation linearly, rotation by slerp on the shortest
arc, the older sample where the two name different parents), and the poses composed as
arrays. Stamps where an edge of that path names another parent (a tree that changed shape)
are looked up one by one; stamps TF cannot answer are NaN rows. Fast path: the same walk in
C (``_tf.lookup_many``); reference: the numpy edges here (``DQ_FK_PURE_PYTHON=1``), both
held to ``BufferCore.lookup`` by ``test_tf_batch.py``.
"""

from dq_fk_ros.transforms.buffer_core import COMPILED
from dq_fk_ros.transforms.exceptions import TransformException
from dq_fk_ros.transforms.pose_math import IDENTITY
import numpy as np


def _multiply(a, b):
    """Return the Hamilton products of quaternion rows (x y z w), shape (N, 4)."""
    ax, ay, az, aw = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bx, by, bz, bw = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    return np.stack((aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz),
                    axis=1)


def _rotate(q, v):
    """Return each vector row of ``v`` rotated by the unit quaternion row of ``q``."""
    u, w = q[:, :3], q[:, 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def compose_rows(a, b) -> np.ndarray:
    """Return the poses ``a[i] * b[i]`` (rows x y z qx qy qz qw)."""
    return np.concatenate((_rotate(a[:, 3:], b[:, :3]) + a[:, :3], _multiply(a[:, 3:], b[:, 3:])),
                          axis=1)


def inverse_rows(a) -> np.ndarray:
    """Return the inverse of each pose row."""
    q = a[:, 3:] * np.array([-1.0, -1.0, -1.0, 1.0])
    return np.concatenate((-_rotate(q, a[:, :3]), q), axis=1)


def slerp_rows(q0, q1, ratio) -> np.ndarray:
    """Return tf2's slerp of quaternion rows at ``ratio`` (per row): the shortest arc."""
    dot = np.einsum('ij,ij->i', q0, q1)
    norms = np.sqrt(np.einsum('ij,ij->i', q0, q0) * np.einsum('ij,ij->i', q1, q1))
    theta = np.arccos(np.clip(np.abs(dot) / norms, -1.0, 1.0))
    out = q0.copy()
    moving = theta != 0.0
    if moving.any():
        th, r = theta[moving], ratio[moving]
        d = 1.0 / np.sin(th)
        s0 = np.sin((1.0 - r) * th) * d
        s1 = np.sin(r * th) * d * np.where(dot[moving] < 0, -1.0, 1.0)
        out[moving] = q0[moving] * s0[:, None] + q1[moving] * s1[:, None]
    return out


def edge_rows(cache, stamps: np.ndarray) -> tuple:
    """
    Return ``(parent ids, poses, ok)`` of one dynamic edge at sorted-or-not ``stamps`` (ns).

    ``ok`` is False where the edge has no answer (extrapolation), by tf2's rules.
    """
    live = slice(cache.start, cache.count)
    s = np.frombuffer(cache.stamps, dtype=np.int64)[live]
    p = np.frombuffer(cache.parents, dtype=np.int64)[live]
    v = np.frombuffer(cache.values, dtype=np.float64).reshape(-1, 7)[live]
    n = len(s)
    count = len(stamps)
    if n == 0:
        return np.zeros(count, np.int64), np.zeros((count, 7)), np.zeros(count, bool)
    ok = (stamps >= s[0]) & (stamps <= s[-1])
    k = np.clip(np.searchsorted(s, stamps, side='right') - 1, 0, n - 1)
    k[stamps == s[0]] = 0                      # the oldest: its first sample (tf2)
    if n == 1:
        ok = stamps == s[0]
    k2 = np.minimum(k + 1, n - 1)
    exact = (stamps == s[-1]) | (stamps == s[0]) | (k2 == k)
    k = np.where(stamps == s[-1], n - 1, k)
    same_parent = p[k] == p[k2]
    interpolate = ok & ~exact & same_parent
    poses = v[k].copy()
    if interpolate.any():
        i = np.nonzero(interpolate)[0]
        a, b = v[k[i]], v[k2[i]]
        ratio = (stamps[i] - s[k[i]]) / (s[k2[i]] - s[k[i]]).astype(np.float64)
        poses[i, :3] = (1.0 - ratio)[:, None] * a[:, :3] + ratio[:, None] * b[:, :3]
        poses[i, 3:] = slerp_rows(a[:, 3:], b[:, 3:], ratio)
    return p[k].astype(np.int64), poses, ok


def lookup_poses(core, target: str, source: str, stamps_ns) -> np.ndarray:
    """
    Return ``source``'s pose in ``target`` at each stamp: (N, 7) rows x y z qx qy qz qw.

    A row of NaN where TF cannot answer at that stamp (``BufferCore.lookup`` would raise).
    Stamps of 0 mean what ``lookup`` says (the latest common time). Interpolation is tf2's
    slerp (a core made with ``'sclerp'`` is looked up one stamp at a time).
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64).ravel()
    out = np.full((len(stamps), 7), np.nan)
    if not len(stamps):
        return out
    if target == source:
        out[:] = IDENTITY
        return out
    try:
        core.validate(target, 'lookupTransform argument target_frame')
        core.validate(source, 'lookupTransform argument source_frame')
    except TransformException:
        return out
    single = np.zeros(len(stamps), bool)
    if core.sclerp:
        single[:] = True
    single |= stamps == 0
    todo = np.nonzero(~single)[0]
    while len(todo):
        path = None
        for at in todo[:8]:   # the path at an answerable stamp
            try:
                path = core.path(target, source, int(stamps[at]))
                break
            except TransformException:
                single[at] = True
        if path is None:
            todo = todo[8:]
            single[todo] = True
            break
        up, down = path   # [(child id, parent id)] from the source up, from the target up
        t = stamps[todo]
        if COMPILED is not None:   # the same, in C (test_tf_batch.py holds them equal)
            rows = np.empty((len(todo), 7))
            ok = np.empty(len(todo), np.uint8)
            COMPILED.lookup_many(core.caches, up, down, np.ascontiguousarray(t), rows, ok)
            good = ok.view(bool)
            out[todo[good]] = rows[good]
            single[todo[~good]] = True
            break
        good = np.ones(len(todo), bool)
        source_pose = np.tile(IDENTITY, (len(todo), 1))
        target_pose = np.tile(IDENTITY, (len(todo), 1))
        for edges, side in ((up, 'source'), (down, 'target')):
            for child, parent in edges:
                cache = core.caches[child]
                if cache.static:
                    rows = np.tile(cache.values, (len(todo), 1))
                    same = np.full(len(todo), cache.parent == parent)
                    ok = same
                else:
                    parents, rows, ok = edge_rows(cache, t)
                    same = parents == parent
                good &= ok & same
                if side == 'source':
                    source_pose = compose_rows(rows, source_pose)
                else:
                    target_pose = compose_rows(rows, target_pose)
        done = todo[good]
        out[done] = compose_rows(inverse_rows(target_pose[good]), source_pose[good])
        # stamps where the path differed (or an edge had no answer): one by one
        single[todo[~good]] = True
        todo = np.array([], dtype=np.int64)
    for at in np.nonzero(single)[0]:
        try:
            out[at] = core.lookup(target, source, int(stamps[at]))[0]
        except TransformException:
            pass
    return out


__all__ = ['compose_rows', 'edge_rows', 'inverse_rows', 'lookup_poses', 'slerp_rows']
