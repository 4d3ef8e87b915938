"""
tf2_py's ``BufferCore``: ``TransformStamped`` in and out, rclpy times, over the array core.

What code written for ``tf2_py`` (``import tf2_py as tf2; tf2.BufferCore()``) and tf2_ros's
``Buffer`` (its base class) call: ``set_transform(t, authority)``, ``lookup_transform_core``,
``can_transform_core`` (``(bool, why)``), the ``_full`` forms, ``get_latest_common_time``,
``lookupVelocityCore``... as geometry2's ``tf2_py/src/tf2_py.cpp`` binds them. The rules
are :class:`dq_fk_ros.transforms.buffer_core.BufferCore` (integer ns, pose tuples
``(x, y, z, qx, qy, qz, qw)``); this module converts and holds the lock.
"""

import math
import threading

from builtin_interfaces.msg import Time as TimeMsg
from dq_fk_ros.transforms.buffer_core import BufferCore, DEFAULT_CACHE_TIME_NS, MAX_FRAMES
from dq_fk_ros.transforms.pose_math import _multiply, _rotate, compose
from geometry_msgs.msg import TransformStamped
from rclpy.duration import Duration
from rclpy.time import Time


def time_ns(value) -> int:
    """
    Return ``value`` in ns: an rclpy ``Time``, a ``builtin_interfaces/Time`` or int ns.

    :raises TypeError: anything else (one line naming the type).
    """
    if isinstance(value, Time):
        return value.nanoseconds
    if isinstance(value, TimeMsg):
        return value.sec * 1_000_000_000 + value.nanosec
    if type(value) is int:
        return value
    raise TypeError(f'a time is an rclpy Time, a builtin_interfaces Time or int ns, not '
                    f'{type(value).__name__}')


def duration_ns(value) -> int:
    """Return ``value`` (rclpy ``Duration``, a ``builtin_interfaces/Duration`` or int) in ns."""
    if isinstance(value, Duration):
        return value.nanoseconds
    if type(value) is int:
        return value
    if hasattr(value, 'sec') and hasattr(value, 'nanosec'):
        return int(value.sec) * 1_000_000_000 + int(value.nanosec)
    raise TypeError(f'a duration is an rclpy Duration or int ns, not {type(value).__name__}')


def to_message(target, source, pose, stamp_ns) -> TransformStamped:
    """
    Return a ``TransformStamped`` of ``pose`` (x y z qx qy qz qw) at ``stamp_ns``.

    The fields are set on the default message's own parts (about 1.5 us over the empty
    message's construction; its constructor with keyword arguments costs twice that).
    """
    msg = TransformStamped()
    header, transform = msg.header, msg.transform
    header.frame_id, msg.child_frame_id = target, source
    stamp = header.stamp
    stamp.sec, stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    t, r = transform.translation, transform.rotation
    t.x, t.y, t.z = pose[0], pose[1], pose[2]
    r.x, r.y, r.z, r.w = pose[3], pose[4], pose[5], pose[6]
    return msg


def from_message(transform) -> tuple:
    """Return ``(parent, child, stamp ns, (x y z qx qy qz qw))`` of a ``TransformStamped``."""
    t, r = transform.transform.translation, transform.transform.rotation
    return (transform.header.frame_id, transform.child_frame_id,
            time_ns(transform.header.stamp),
            (float(t.x), float(t.y), float(t.z), float(r.x), float(r.y), float(r.z),
             float(r.w)))


class MessageBufferCore:
    """
    tf2_py's ``BufferCore`` (module doc); ``core`` is the array core, ``lock`` guards it.

    :param cache_time: how long each edge keeps its samples (``Duration``; tf2's 10 s).
    :param interpolation: ``'slerp'`` (tf2's) or ``'sclerp'`` (screw motion, not tf2's).
    :param max_frames: frame names held at most; transforms naming more are refused.
    """

    def __init__(self, cache_time=None, interpolation='slerp', max_frames=MAX_FRAMES,
                 log=None):
        """Start empty."""
        cache_ns = DEFAULT_CACHE_TIME_NS if cache_time is None else duration_ns(cache_time)
        self.lock = threading.Lock()
        self._changed = threading.Condition(self.lock)
        self.core = BufferCore(cache_ns, interpolation, max_frames, log)

    # -- in -------------------------------------------------------------------------------
    def set_transform(self, transform: TransformStamped, authority: str) -> None:
        """Store a transform (tf2's refusals are counted in ``core.refused`` and logged)."""
        self._store(transform, authority, False)

    def set_transform_static(self, transform: TransformStamped, authority: str) -> None:
        """Store a static transform, valid at every time."""
        self._store(transform, authority, True)

    def _store(self, transform, authority, static) -> bool:
        """Store one transform under the lock; return whether it was taken."""
        parent, child, stamp, pose = from_message(transform)
        with self._changed:
            done = self.core.set_transform(parent, child, stamp, pose, authority, static)
            self._changed.notify_all()
        return done

    def clear(self) -> None:
        """Forget every sample (frame names stay, as tf2's ``clear``)."""
        with self.lock:
            self.core.clear()

    # -- out ------------------------------------------------------------------------------
    def lookup_transform_core(self, target_frame: str, source_frame: str,
                              time) -> TransformStamped:
        """Return ``source_frame`` in ``target_frame`` at ``time`` (0: the latest common)."""
        stamp = time_ns(time)
        with self.lock:
            pose, used = self.core.lookup(target_frame, source_frame, stamp)
        return to_message(target_frame, source_frame, pose, used)

    def lookup_transform_full_core(self, target_frame: str, target_time, source_frame: str,
                                   source_time, fixed_frame: str) -> TransformStamped:
        """Return ``source_frame`` at ``source_time`` in ``target_frame`` at ``target_time``."""
        target_ns, source_ns = time_ns(target_time), time_ns(source_time)
        with self.lock:
            pose, used = self.core.lookup_full(target_frame, target_ns, source_frame,
                                               source_ns, fixed_frame)
        return to_message(target_frame, source_frame, pose, used)

    def can_transform_core(self, target_frame: str, source_frame: str, time) -> tuple:
        """Return ``(True, '')`` or ``(False, why)`` as tf2_py's."""
        stamp = time_ns(time)
        with self.lock:
            return self.core.can_transform(target_frame, source_frame, stamp)

    def can_transform_full_core(self, target_frame: str, target_time, source_frame: str,
                                source_time, fixed_frame: str) -> tuple:
        """Return ``(True, '')`` or ``(False, why)`` for the lookup via ``fixed_frame``."""
        target_ns, source_ns = time_ns(target_time), time_ns(source_time)
        with self.lock:
            return self.core.can_transform_full(target_frame, target_ns, source_frame,
                                                source_ns, fixed_frame)

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Time:
        """Return the latest time both frames' path has (rclpy ``Time``; tf2's rules)."""
        with self.lock:
            target = self.core.validate(target_frame, 'get_latest_common_time')
            source = self.core.validate(source_frame, 'get_latest_common_time')
            error, stamp = self.core.latest_common_time(target, source)
        if error is not None:
            raise error
        return Time(nanoseconds=stamp)

    def lookupVelocityCore(self, tracking_frame, observation_frame, time,   # noqa: N802
                           averaging_interval) -> tuple:
        """Return ``((vx, vy, vz), (wx, wy, wz))`` of ``tracking_frame`` (tf2's)."""
        return self.lookupVelocityFullCore(tracking_frame, observation_frame,
                                           observation_frame, (0.0, 0.0, 0.0),
                                           tracking_frame, time, averaging_interval)

    def lookupVelocityFullCore(self, tracking_frame, observation_frame,   # noqa: N802
                               reference_frame, reference_point, reference_point_frame, time,
                               averaging_interval) -> tuple:
        """
        Return tf2's ``lookupVelocity``: ``((vx, vy, vz), (wx, wy, wz))``, m/s and rad/s.

        Followed from geometry2's ``tf2/src/buffer_core.cpp`` (``BufferCore::lookupVelocity``):
        the motion between two lookups ``averaging_interval`` apart (ending at the latest
        common time at most), expressed in ``reference_frame`` about
        ``reference_point`` (in ``reference_point_frame``).
        """
        with self.lock:
            return _velocity(self.core, tracking_frame, observation_frame, reference_frame,
                             tuple(float(v) for v in reference_point), reference_point_frame,
                             time_ns(time), duration_ns(averaging_interval))

    def all_frames_as_yaml(self, current_time=None) -> str:
        """Return tf2's ``allFramesAsYAML``."""
        with self.lock:
            return self.core.all_frames_as_yaml(0 if current_time is None
                                                else time_ns(current_time))

    def all_frames_as_string(self) -> str:
        """Return tf2's ``allFramesAsString``."""
        with self.lock:
            return self.core.all_frames_as_string()

    def _allFramesAsDot(self, time=None) -> str:   # noqa: N802
        """Return view_frames' Graphviz text (tf2_py's ``_allFramesAsDot``)."""
        with self.lock:
            return self.core.all_frames_as_dot(0 if time is None else time_ns(time))

    def _getFrameStrings(self) -> list:   # noqa: N802
        """Return every frame name known (tf2_py's ``_getFrameStrings``)."""
        with self.lock:
            return self.core.frame_names()

    def _frameExists(self, frame_id: str) -> bool:   # noqa: N802
        """Return whether ``frame_id`` is known (tf2_py's ``_frameExists``)."""
        with self.lock:
            return frame_id in self.core.ids


def _velocity(core, tracking, observation, reference, point, point_frame, stamp, interval):
    """tf2's ``lookupVelocity`` on the array core, in tf2's order (seconds as doubles)."""
    error, latest = core.latest_common_time(core.ids.get(observation, 0),
                                            core.ids.get(tracking, 0))
    latest = 0 if error is not None else latest   # tf2 ignores the error here
    t, dt = stamp / 1e9, interval / 1e9
    end = min(t + dt * 0.5, latest / 1e9)
    start = max(0.00001 + dt, end) - dt
    corrected = end - start
    first, _ = core.lookup(observation, tracking, int(start * 1e9))
    last, _ = core.lookup(observation, tracking, int(end * 1e9))
    conj = (-first[3], -first[4], -first[5], first[6])
    qx, qy, qz, qw = _multiply(conj, last[3:])
    if qw < 0.0:   # as tf2's Matrix3x3::getRotation: w >= 0
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    angle = 2.0 * math.acos(min(1.0, qw))
    s = math.sqrt(max(0.0, 1.0 - qw * qw))
    axis = (1.0, 0.0, 0.0) if s < 10 * 2.220446049250313e-16 else (qx / s, qy / s, qz / s)
    o = _rotate(first[3:], axis)
    velocity = tuple((b - a) / corrected for a, b in zip(first[:3], last[:3]))
    rotation = tuple(v * angle / corrected for v in o)
    inverse, _ = core.lookup(reference, tracking, int(t * 1e9))
    out_rot = _rotate(inverse[3:], rotation)
    out_vel = _add(_rotate(inverse[3:], velocity), _cross(inverse[:3], out_rot))
    origin = inverse[:3]
    desired, _ = core.lookup(reference, point_frame, int(t * 1e9))
    desired = compose(desired, tuple(point) + (0.0, 0.0, 0.0, 1.0))[:3]
    delta = tuple(d - o for d, o in zip(desired, origin))
    out_vel = _add(out_vel, _cross(out_rot, delta))
    return out_vel, out_rot


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


__all__ = ['duration_ns', 'from_message', 'MessageBufferCore', 'time_ns', 'to_message']
