"""
Which transforms tf2 takes: the checks ``BufferCore.set_transform`` makes before storing one.

tf2's ``BufferCore::setTransformImpl`` (Jazzy) refuses, each with its code: a frame its own
parent (``TF_SELF_TRANSFORM``), an empty child or parent (``TF_NO_CHILD_FRAME_ID``,
``TF_NO_FRAME_ID``), a NaN (``TF_NAN_INPUT``), a quaternion whose squared norm is off 1 by
``QUATERNION_TOLERANCE`` or more (``TF_DENORMALIZED_QUATERNION``). Not tf2's, bounds of this
package (docs/security.md): an infinite translation (``TF_INF_INPUT``), a stamp that is no
int64 of ns (``TF_BAD_STAMP``), a frame id of more than ``MAX_FRAME_ID`` characters
(``TF_LONG_FRAME_ID``: 10 000 names of 50 KB had held a listener at 1 GiB).
"""

import math

QUATERNION_TOLERANCE = 10e-3     # tf2's QUATERNION_NORMALIZATION_TOLERANCE (on the norm^2)
MAX_FRAME_ID = 1024              # characters of a frame id; a longer one is refused
INT64 = (-(1 << 63), 1 << 63)    # times are int64 ns, as tf2's TimePoint


def admit(parent: str, child: str, stamp_ns, values, authority: str) -> tuple:
    """
    Return ``(None, values normalised)`` or ``(code, one line saying why)``.

    :param parent: the frame id, a leading ``/`` already stripped; ``child`` likewise.
    :param values: ``(x, y, z, qx, qy, qz, qw)``.
    """
    source = f'from authority "{authority}"'
    if len(parent) > MAX_FRAME_ID or len(child) > MAX_FRAME_ID:
        return 'TF_LONG_FRAME_ID', (
            f'TF_LONG_FRAME_ID: Ignoring transform {source} naming a frame id of more than '
            f'{MAX_FRAME_ID} characters (child "{child[:40]}", parent "{parent[:40]}")')
    if child == parent:
        return 'TF_SELF_TRANSFORM', (
            f'TF_SELF_TRANSFORM: Ignoring transform {source} with frame_id and '
            f'child_frame_id "{child}" because they are the same')
    if not child:
        return 'TF_NO_CHILD_FRAME_ID', (
            f'TF_NO_CHILD_FRAME_ID: Ignoring transform {source} because child_frame_id not set')
    if not parent:
        return 'TF_NO_FRAME_ID', (
            f'TF_NO_FRAME_ID: Ignoring transform with child_frame_id "{child}" {source} '
            'because frame_id not set')
    x, y, z, qx, qy, qz, qw = (float(v) for v in values)
    norm2 = qx * qx + qy * qy + qz * qz + qw * qw
    about = f'for child_frame_id "{child}" {source}'
    if any(v != v for v in (x, y, z, qx, qy, qz, qw)):
        return 'TF_NAN_INPUT', (
            f'TF_NAN_INPUT: Ignoring transform {about} because of a nan value in the transform')
    if not abs(norm2 - 1.0) < QUATERNION_TOLERANCE:
        return 'TF_DENORMALIZED_QUATERNION', (
            f'TF_DENORMALIZED_QUATERNION: Ignoring transform {about} because of an invalid '
            f'quaternion in the transform ({qx:f} {qy:f} {qz:f} {qw:f})')
    if not all(math.isfinite(v) for v in (x, y, z)):
        return 'TF_INF_INPUT', (
            f'TF_INF_INPUT: Ignoring transform {about} because of an infinite translation')
    if not (type(stamp_ns) is int and INT64[0] <= stamp_ns < INT64[1]):
        return 'TF_BAD_STAMP', (
            f'TF_BAD_STAMP: Ignoring transform {about} because its stamp is not an int64 of ns')
    n = math.sqrt(norm2)
    return None, (x, y, z, qx / n, qy / n, qz / n, qw / n)


__all__ = ['admit', 'INT64', 'MAX_FRAME_ID', 'QUATERNION_TOLERANCE']
