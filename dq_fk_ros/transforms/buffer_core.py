"""
tf2's BufferCore without ROS: transforms per child frame in arrays, looked up by tf2's rules.

The rules are those of ros2/geometry2's ``tf2/src/buffer_core.cpp`` and ``cache.cpp``
(Jazzy), written here from their behaviour; times are integer nanoseconds, as tf2 keeps
them. Each child frame has one cache of (stamp, parent, translation, rotation) samples:

* **Insert** (``TimeCache::insertData``): samples older than ``cache_time_ns`` before the
  newest are pruned first (by the newest before this insert); a sample older than that
  bound is refused (tf2's ``TF_OLD_DATA``); an exact duplicate (stamp, parent and values) is
  not stored twice; another sample of a stamp the edge holds is refused (``TF_REPEATED_DATA``,
  ROS 1's tf2: Jazzy keeps every distinct one, see :mod:`~dq_fk_ros.transforms.edges`). A static
  transform is one sample valid at every time (``StaticCache``); a frame switching between
  static and dynamic starts a new cache. Rejected and counted by code (:attr:`refused`), each
  code logged at once and then at most once per ``log_every_s``: a frame id empty after a
  leading ``/`` is stripped or longer than ``MAX_FRAME_ID``, a frame that is its own parent,
  a NaN, a quaternion whose squared norm is off 1 by 0.01 or more, frames past
  ``max_frames``. Stored quaternions are normalised.
* **One edge at time t** (``TimeCache::findClosest``, ``getData``): t = 0 gives the newest
  sample; one sample answers its own stamp only ("Lookup would require extrapolation at
  time ..."); t after the newest or before the oldest raises (into the future / the past);
  between two samples of one parent: translation interpolated linearly, rotation by slerp
  on the shortest arc (tf2's ``Quaternion::slerp``); of two parents: the older sample (a
  child's parent may change over time).
* **A lookup** (``walkToTopParent``): from the source up to the root, then from the target
  up to where it met the source's path; target == source is the identity for any name;
  t = 0 is the latest time common to every moving edge of the path (``getLatestCommonTime``;
  a path of static edges only: 0); more than 1000 steps is a loop (``LookupException``).

``interpolation='sclerp'`` (not tf2's) interpolates an edge by the screw motion between its
samples (``DualQuaternion.sclerp``, the screw interpolation of dual-quaternion kinematics);
the default is tf2's.

The edges (one child frame's samples) are :mod:`dq_fk_ros.transforms.edges`, the pose
arithmetic :mod:`dq_fk_ros.transforms.pose_math`.
"""

import time as _time

from dq_fk_ros.errors import printable_line
from dq_fk_ros.kinematics.kernel import load_compiled
from dq_fk_ros.transforms.admission import admit, INT64, MAX_FRAME_ID, QUATERNION_TOLERANCE
from dq_fk_ros.transforms.edges import display_time, MovingEdge, REPEATED, StaticEdge, STORED
from dq_fk_ros.transforms.exceptions import (ConnectivityException, ExtrapolationException,
                                             InvalidArgumentException, LookupException)
from dq_fk_ros.transforms.frames_text import frames_dot, frames_yaml
from dq_fk_ros.transforms.pose_math import compose, IDENTITY, inverse

MAX_GRAPH_DEPTH = 1000           # tf2's: a longer walk is a loop
DEFAULT_CACHE_TIME_NS = 10 * 10**9
MAX_FRAMES = 10_000              # frame names held at most; more are refused (one log line)
LOG_EVERY_S = 10.0               # a code's refusals: one log line per this many seconds
INTERPOLATIONS = ('slerp', 'sclerp')
# the walk in C (transforms/_tf.c): lookup's fast path, this module's _walk its reference
COMPILED, COMPILED_WHY = load_compiled('dq_fk_ros.transforms._tf')


class BufferCore:
    """
    tf2's BufferCore (module doc): ``set_transform`` in, ``lookup_transform`` out, ns times.

    Poses are tuples ``(x, y, z, qx, qy, qz, qw)``. Thread-safety is the caller's
    (:class:`dq_fk_ros.ros.tf_buffer.Buffer` holds a lock).
    """

    def __init__(self, cache_time_ns: int = DEFAULT_CACHE_TIME_NS, interpolation: str = 'slerp',
                 max_frames: int = MAX_FRAMES, log=None, log_every_s: float = LOG_EVERY_S):
        """
        Start empty.

        :param cache_time_ns: how long before the newest sample an edge keeps its samples.
        :param interpolation: ``'slerp'`` (tf2's) or ``'sclerp'`` (screw motion, not tf2's).
        :param max_frames: frame names held at most; transforms naming more are refused.
        :param log: called with one line for a refused transform (default: dropped): the
            first of each tf2 code at once, later ones at most once per ``log_every_s``.
        """
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got "
                             f'{printable_line(interpolation, 40)!r}')
        if type(cache_time_ns) is not int or cache_time_ns < 0:
            raise ValueError(f'cache_time_ns must be a non-negative integer, got '
                             f'{cache_time_ns!r}')
        self.cache_time_ns = cache_time_ns
        self.sclerp = interpolation == 'sclerp'
        self.max_frames = max_frames
        self.log = log or (lambda line: None)
        self.ids = {}            # frame name -> id (1...)
        self.names = ['NO_PARENT']
        self.caches = [None]     # id -> StaticEdge | MovingEdge | None (a root or a parent only)
        self.authority = {}      # id -> the authority of its last accepted transform
        self.refused = {}        # tf2's code (TF_OLD_DATA, ...) -> transforms refused
        self.log_every_s = log_every_s
        self._logged = {}        # code -> monotonic time of its last line

    # -- in -------------------------------------------------------------------------------
    def set_transform(self, parent: str, child: str, stamp_ns: int, values,
                      authority: str = '', static: bool = False) -> bool:
        """
        Store one transform of ``child`` in ``parent`` at ``stamp_ns``; False if refused.

        :param values: ``(x, y, z, qx, qy, qz, qw)``.
        """
        parent, child = strip_slash(parent), strip_slash(child)
        code, checked = admit(parent, child, stamp_ns, values, authority)
        if code is not None:
            return self._refuse(code, checked)
        child_id, parent_id = self.frame_index(child), self.frame_index(parent)
        if not child_id or not parent_id:
            return self._refuse('TF_TOO_MANY_FRAMES', f'TF_TOO_MANY_FRAMES: Ignoring '
                                f'transforms naming new frames '
                                f'past {self.max_frames} (this one: "{child}" in "{parent}")')
        values = checked
        cache = self.caches[child_id]
        if static:
            if cache is None or not cache.static:
                cache = self.caches[child_id] = StaticEdge(parent_id, values)
            cache.parent, cache.values = parent_id, values
            self.authority[child_id] = authority
            return True
        if cache is None or cache.static:
            # edges of one robot fill in step: rooms of 8 to 23 samples spread their growth
            # over many messages (one message growing all of tiago's stalled 50 ms)
            cache = self.caches[child_id] = MovingEdge(self.cache_time_ns, 8 + child_id % 16)
        done = cache.insert(stamp_ns, parent_id, values)
        if done == STORED:
            self.authority[child_id] = authority
            return True
        if done == REPEATED:
            return self._refuse('TF_REPEATED_DATA', f'TF_REPEATED_DATA ignoring data with '
                                f'redundant timestamp for frame {child} (parent {parent}) at '
                                f'time {display_time(stamp_ns)} according to authority '
                                f'{authority}')
        return self._refuse('TF_OLD_DATA', f'TF_OLD_DATA ignoring data from the past for frame '
                            f'{child} at time {display_time(stamp_ns)} according to authority '
                            f'{authority}')

    def _refuse(self, code: str, line: str) -> bool:
        """
        Count a refused transform by its tf2 code; log it, one line a code every log_every_s.

        The first of a code is logged at once, later ones at most once per ``log_every_s``
        with the count so far (a peer repeating a refusal cannot flood the log). False.
        """
        count = self.refused[code] = self.refused.get(code, 0) + 1
        now = _time.monotonic()
        last = self._logged.get(code)
        if last is None or now - last >= self.log_every_s:
            self._logged[code] = now
            self.log(printable_line(line, 360)
                     + (f' ({count} refused so far)' if count > 1 else ''))
        return False

    @property
    def refused_frames(self) -> int:
        """Return how many transforms were refused for naming frames past the cap."""
        return self.refused.get('TF_TOO_MANY_FRAMES', 0)

    def frame_index(self, name: str) -> int:
        """Return the index of frame ``name``, added if new (0: over the frame cap)."""
        found = self.ids.get(name)
        if found is not None:
            return found
        if len(self.names) > self.max_frames:
            return 0
        self.ids[name] = len(self.names)
        self.names.append(name)
        self.caches.append(None)
        return self.ids[name]

    def clear(self) -> None:
        """Forget every sample (frame names stay, as tf2's ``clear``)."""
        for k, cache in enumerate(self.caches):
            if cache is not None and not cache.static:
                self.caches[k] = MovingEdge(self.cache_time_ns, 8 + k % 16)
            elif cache is not None:
                self.caches[k] = None

    # -- out ------------------------------------------------------------------------------
    def validate(self, name: str, what: str) -> int:
        """Return the id of frame ``name``; raise as tf2's ``validateFrameId`` does."""
        if not name:
            raise InvalidArgumentException(f'Invalid argument "{name}" passed to {what} - in '
                                           'tf2 frame_ids cannot be empty')
        if name[0] == '/':
            raise InvalidArgumentException(f'Invalid argument "{name}" passed to {what} - in '
                                           "tf2 frame_ids cannot start with a '/'")
        found = self.ids.get(name, 0)
        if not found:
            raise LookupException(f'"{name}" passed to {what} does not exist. ')
        return found

    def lookup(self, target: str, source: str, time_ns: int) -> tuple:
        """
        Return ``(pose of source in target, time used in ns)``; raise tf2's exceptions.

        Fast path: the walk in C (``_tf.lookup``, for slerp); reference: :meth:`_walk`,
        which also says why when tf2 raises (``test_the_compiled_walk_is_the_reference``).
        """
        if target == source:
            if time_ns == 0:
                cache = self.caches[self.ids.get(target, 0)]
                return IDENTITY, cache.newest_stamp() if cache is not None else 0
            return IDENTITY, time_ns
        target_id = self.validate(target, 'lookupTransform argument target_frame')
        source_id = self.validate(source, 'lookupTransform argument source_frame')
        _check_time(time_ns)
        if COMPILED is not None and not self.sclerp:
            found = COMPILED.lookup(self.caches, target_id, source_id, time_ns)
            if found is not None:
                return found[1:], found[0]
        error, pose, time_used = self._walk(time_ns, target_id, source_id, True)
        if error is not None:
            raise error
        return pose, time_used

    def lookup_full(self, target: str, target_ns: int, source: str, source_ns: int,
                    fixed: str) -> tuple:
        """Return ``(pose, time used)`` of source at source_ns in target at target_ns via fixed."""
        self.validate(target, 'lookupTransform argument target_frame')
        self.validate(source, 'lookupTransform argument source_frame')
        self.validate(fixed, 'lookupTransform argument fixed_frame')
        source_in_fixed, _ = self.lookup(fixed, source, source_ns)
        fixed_in_target, time_used = self.lookup(target, fixed, target_ns)
        return compose(fixed_in_target, source_in_fixed), time_used

    def can_transform(self, target: str, source: str, time_ns: int) -> tuple:
        """Return ``(True, '')`` or ``(False, why)`` as tf2's ``canTransform``."""
        if target == source:
            return True, ''
        _check_time(time_ns)
        for name, what in ((target, 'target_frame'), (source, 'source_frame')):
            why = self._invalid(name, f'canTransform argument {what}')
            if why:
                return False, why
        error, _, _ = self._walk(time_ns, self.ids[target], self.ids[source], False)
        return (True, '') if error is None else (False, str(error))

    def can_transform_full(self, target, target_ns, source, source_ns, fixed) -> tuple:
        """Return ``(True, '')`` or ``(False, why)`` as tf2's ``canTransform`` via ``fixed``."""
        for name, what in ((target, 'target_frame'), (source, 'source_frame'),
                           (fixed, 'fixed_frame')):
            why = self._invalid(name, f'canTransform argument {what}')
            if why:
                return False, why
        for a, b, t in ((target, fixed, target_ns), (fixed, source, source_ns)):
            if a != b:
                error, _, _ = self._walk(t, self.ids[a], self.ids[b], False)
                if error is not None:
                    return False, str(error)
        return True, ''

    def _invalid(self, name, what):
        if not name:
            return f'Invalid frame ID "{name}" passed to {what} - in tf2 frame_ids cannot be empty'
        if name[0] == '/':
            return (f'Invalid frame ID "{name}" passed to {what} - in tf2 frame_ids cannot '
                    "start with a '/'")
        if name not in self.ids:
            return f'Invalid frame ID "{name}" passed to {what} - frame does not exist'
        return ''

    def _gather(self, frame, time_ns):
        cache = self.caches[frame]
        if cache.static:
            return cache.parent, cache.values, None
        return cache.get(time_ns, self.sclerp)

    def path(self, target: str, source: str, time_ns: int) -> tuple:
        """
        Return the edges a lookup composes: ``(up from source, up from target)``.

        Each a list of ``(child id, parent id)``, edges both walks share (above where they
        meet) left out; raises as :meth:`lookup`. What :mod:`dq_fk_ros.transforms.batch`
        interpolates at many stamps.
        """
        target_id = self.validate(target, 'lookupTransform argument target_frame')
        source_id = self.validate(source, 'lookupTransform argument source_frame')
        edges = ([], [])
        error, _, _ = self._walk(time_ns, target_id, source_id, True, edges)
        if error is not None:
            raise error
        up, down = edges
        while up and down and up[-1] == down[-1]:
            up.pop()
            down.pop()
        return up, down

    def _walk(self, time_ns, target, source, accumulate, edges=None):
        """tf2's ``walkToTopParent``: ``(error or None, pose of source in target, time)``."""
        if source == target:
            return None, IDENTITY, time_ns
        if time_ns == 0:
            error, time_ns = self.latest_common_time(target, source)
            if error is not None:
                return error, None, 0
        caches = self.caches
        frame, top = source, source
        source_pose = IDENTITY
        might_extrapolate, extrapolation_text = False, ''
        depth = 0
        while frame != 0:
            if caches[frame] is None:
                top = frame
                break
            parent, values, error = self._gather(frame, time_ns)
            if parent == 0:
                top = frame
                might_extrapolate, extrapolation_text = True, error[1]
                break
            if frame == target:   # the target is above the source
                return None, source_pose, time_ns
            if accumulate:
                source_pose = compose(values, source_pose)
                if edges is not None:
                    edges[0].append((frame, parent))
            top, frame = frame, parent
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return self._loop(), None, 0
        frame, depth = target, 0
        target_pose = IDENTITY
        while frame != top:
            if caches[frame] is None:
                break
            parent, values, error = self._gather(frame, time_ns)
            if parent == 0:
                return ExtrapolationException(
                    f'{error[1]}, when looking up transform from frame '
                    f'[{self.names[source]}] to frame [{self.names[target]}]'), None, 0
            if frame == source:   # the source is above the target
                if edges is not None:
                    edges[0].clear()   # (the source walk reached the top past the source)
                return None, inverse(target_pose), time_ns
            if accumulate:
                target_pose = compose(values, target_pose)
                if edges is not None:
                    edges[1].append((frame, parent))
            frame = parent
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return self._loop(), None, 0
        if frame != top:
            if might_extrapolate:
                return ExtrapolationException(
                    f'{extrapolation_text}, when looking up transform from frame '
                    f'[{self.names[source]}] to frame [{self.names[target]}]'), None, 0
            return ConnectivityException(
                f"Could not find a connection between '{self.names[target]}' and "
                f"'{self.names[source]}' because they are not part of the same tree.Tf has "
                'two or more unconnected trees.'), None, 0
        if not accumulate:
            return None, None, time_ns
        return None, compose(inverse(target_pose), source_pose), time_ns

    def _loop(self):
        return LookupException('The tf tree is invalid because it contains a loop.\n'
                               + self.all_frames_as_string())

    def latest_common_time(self, target: int, source: int) -> tuple:
        """tf2's ``getLatestCommonTime``: ``(error or None, ns)`` for the ids given."""
        if source == 0 or target == 0:
            return LookupException('Source or target frame is not yet defined'), 0
        caches = self.caches
        if source == target:
            cache = caches[source]
            return None, cache.newest_stamp() if cache is not None else 0
        chain = []   # (latest stamp, parent) from the source up
        frame, depth, common = source, 0, None
        while (edge := self._latest_edge(frame)) is not None:
            stamp, parent = edge
            common = _earliest(common, stamp)
            chain.append(edge)
            frame = parent
            if frame == target:
                return None, common or 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return self._loop(), 0
        frame, depth, common, meet = target, 0, None, 0
        parents = {p for _, p in chain}
        while (edge := self._latest_edge(frame)) is not None:
            stamp, parent = edge
            common = _earliest(common, stamp)
            if parent in parents:
                meet = parent
                break
            frame = parent
            if frame == source:
                return None, common or 0
            depth += 1
            if depth > MAX_GRAPH_DEPTH:
                return self._loop(), 0
        if meet == 0:
            return ConnectivityException(
                f"Could not find a connection between '{self.names[target]}' and "
                f"'{self.names[source]}' because they are not part of the same tree.Tf has "
                'two or more unconnected trees.'), 0
        for stamp, parent in chain:
            common = _earliest(common, stamp)
            if parent == meet:
                break
        return None, common or 0

    def _latest_edge(self, frame):
        """Return ``(newest stamp, parent)`` of ``frame``'s edge, None at a root or empty."""
        cache = self.caches[frame] if frame else None
        if cache is None:
            return None
        edge = cache.latest()
        return edge if edge[1] else None

    # -- what is known --------------------------------------------------------------------
    def all_frames_as_string(self) -> str:
        """Return tf2's ``allFramesAsString``: "Frame C exists with parent P." per line."""
        lines = []
        for k in range(1, len(self.names)):
            cache = self.caches[k]
            if cache is None:
                continue
            parent = cache.latest()[1] if len(cache) else 0
            lines.append(f'Frame {self.names[k]} exists with parent {self.names[parent]}.\n')
        return ''.join(lines)

    def frames_info(self, now_ns: int = 0) -> list:
        """
        Return per child frame what view_frames and tf2_monitor show.

        ``[{'frame', 'parent', 'broadcaster', 'rate', 'most_recent', 'oldest',
        'buffer_length', 'delay'}]`` (times in ns; rate in Hz as tf2 computes it).
        """
        out = []
        for k in range(1, len(self.names)):
            cache = self.caches[k]
            if cache is None or not len(cache):
                continue
            newest, oldest = cache.newest_stamp(), cache.oldest_stamp()
            span = newest - oldest
            rate = len(cache) * 1e9 / (span if span > 100_000 else 100_000)
            out.append({'frame': self.names[k], 'parent': self.names[cache.latest()[1]],
                        'broadcaster': self.authority.get(k, 'no recorded authority'),
                        'rate': rate, 'most_recent': newest, 'oldest': oldest,
                        'buffer_length': span,
                        'delay': now_ns - newest if now_ns else None, 'static': cache.static})
        return out

    def all_frames_as_yaml(self, now_ns: int = 0) -> str:
        """Return tf2's ``allFramesAsYAML`` (``now_ns``: also each frame's delay)."""
        return frames_yaml(self.frames_info(now_ns), now_ns)

    def all_frames_as_dot(self, now_ns: int = 0) -> str:
        """Return the Graphviz text of view_frames (tf2's ``_allFramesAsDot``)."""
        return frames_dot(self.frames_info(now_ns), now_ns)

    def frame_names(self) -> list:
        """Return every frame name known, in the order first seen."""
        return self.names[1:]


def _earliest(common, stamp):
    """Fold an edge's newest stamp into the common time (None: none yet; 0, static: none)."""
    return common if stamp == 0 else stamp if common is None else min(common, stamp)


def strip_slash(name: str) -> str:
    """Return a frame id as tf2 stores it: one leading ``/`` taken off."""
    name = str(name)
    return name[1:] if name.startswith('/') else name


def _check_time(time_ns):
    if type(time_ns) is not int or not INT64[0] <= time_ns < INT64[1]:
        raise InvalidArgumentException(f'a time must be int64 nanoseconds, got '
                                       f'{printable_line(repr(time_ns), 40)}')


__all__ = ['BufferCore', 'DEFAULT_CACHE_TIME_NS', 'LOG_EVERY_S', 'MAX_FRAME_ID', 'MAX_FRAMES',
           'MAX_GRAPH_DEPTH',
           'QUATERNION_TOLERANCE', 'strip_slash']
