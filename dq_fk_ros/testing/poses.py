"""
``assert_pose_close``: two poses equal within a distance and an angle, or one line why not.

A pose is a ``geometry_msgs/TransformStamped`` (its frames named in the message), a
``Transform``, ``Pose`` or ``PoseStamped``, or ``((x, y, z), (qx, qy, qz, qw))`` (m;
quaternion x y z w). The angle between two orientations is that of the rotation taking one
to the other, ``2 acos |<q1, q2>|`` ([Zivkovic2023]: q and -q are one rotation). No ROS is
imported: messages are read by their fields.
"""

import math


def _parts(pose, what):
    """Return ``((x, y, z), (qx, qy, qz, qw), name)`` of a pose in any accepted form."""
    name = what
    if hasattr(pose, 'child_frame_id') and hasattr(pose, 'transform'):   # TransformStamped
        name = f'{pose.child_frame_id} in {pose.header.frame_id}'
        pose = pose.transform
    elif hasattr(pose, 'header') and hasattr(pose, 'pose'):              # PoseStamped
        name = f'{what} in {pose.header.frame_id}'
        pose = pose.pose
    if hasattr(pose, 'translation') and hasattr(pose, 'rotation'):       # Transform
        p, q = pose.translation, pose.rotation
    elif hasattr(pose, 'position') and hasattr(pose, 'orientation'):     # Pose
        p, q = pose.position, pose.orientation
    else:
        try:
            (x, y, z), (qx, qy, qz, qw) = pose
            return (float(x), float(y), float(z)), (float(qx), float(qy), float(qz),
                                                    float(qw)), name
        except (TypeError, ValueError):
            raise TypeError(f'{what}: a TransformStamped, Transform, Pose, PoseStamped or '
                            f'((x, y, z), (qx, qy, qz, qw)), not {type(pose).__name__}') \
                from None
    return (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), name


def pose_difference(actual, expected) -> tuple:
    """Return ``(distance in m, angle in rad)`` between two poses (module doc)."""
    (pa, qa, _), (pe, qe, _) = _parts(actual, 'actual'), _parts(expected, 'expected')
    distance = math.dist(pa, pe)
    na, ne = math.sqrt(sum(v * v for v in qa)), math.sqrt(sum(v * v for v in qe))
    if not (na > 0 and ne > 0 and math.isfinite(na) and math.isfinite(ne)):
        return distance, math.nan
    dot = abs(sum(a * e for a, e in zip(qa, qe))) / (na * ne)
    return distance, 2.0 * math.acos(min(1.0, dot))


def assert_pose_close(actual, expected, atol_m: float = 1e-6, atol_rad: float = 1e-6) -> None:
    """
    Raise ``AssertionError`` unless ``actual`` is within ``atol_m``, ``atol_rad`` of ``expected``.

    The message names the frames (a ``TransformStamped``'s child in its parent) and says
    by how much each part is off, beside both poses. A NaN anywhere is never close.
    """
    (pa, qa, name_a), (pe, qe, name_e) = _parts(actual, 'actual'), _parts(expected, 'expected')
    distance, angle = pose_difference(actual, expected)
    problems = []
    if not distance <= atol_m:
        problems.append(f'position off by {_length(distance)} (atol {_length(atol_m)})')
    if not angle <= atol_rad:
        problems.append(f'orientation off by {_angle(angle)} (atol {_angle(atol_rad)})')
    if problems:
        names = name_a if name_a == name_e or name_e == 'expected' else \
            f'{name_a} (expected: {name_e})'
        raise AssertionError(
            f'pose of {names}: {"; ".join(problems)}; actual xyz {_xyz(pa)} q xyzw {_xyz(qa)}, '
            f'expected xyz {_xyz(pe)} q xyzw {_xyz(qe)}')


def _length(m):
    if not math.isfinite(m):
        return str(m)
    return f'{m * 1e3:.4g} mm' if abs(m) >= 1e-3 else f'{m * 1e6:.4g} um'


def _angle(rad):
    return f'{math.degrees(rad):.4g} deg' if math.isfinite(rad) else str(rad)


def _xyz(values):
    return '(' + ', '.join(f'{v:.6g}' for v in values) + ')'


__all__ = ['assert_pose_close', 'pose_difference']
