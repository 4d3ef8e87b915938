"""
tf2_ros's ``BufferInterface`` and its registrations: ``buffer.transform(msg, target)``.

As geometry2's ``tf2_ros_py/tf2_ros/buffer_interface.py``: a converter written for tf2
(``tf2_ros.TransformRegistration().add(MyStamped, do_transform_my)``) registers here the same
way, and ``buffer.transform`` looks the message's type up, asks for the transform from its
``header.frame_id`` at its ``header.stamp`` and applies it. The registrations are shared by
every buffer (class-level maps, as tf2_ros's). Not as tf2_ros: a type nobody registered is
looked up among this package's own converters (geometry_msgs' stamped types,
``sensor_msgs/PointCloud2``: :mod:`dq_fk_ros.ros.tf_geometry`, :mod:`dq_fk_ros.ros.tf_cloud`)
before :class:`TypeException` is raised; a converter the user registered is never replaced.
"""

from copy import deepcopy
from typing import Callable

from geometry_msgs.msg import TransformStamped
from std_msgs.msg import Header


class TypeException(Exception):
    """A type no transform or conversion is registered for (tf2_ros's)."""

    def __init__(self, errstr: str) -> None:
        """Keep ``errstr`` (tf2_ros's attribute)."""
        super().__init__(errstr)
        self.errstr = errstr


class NotImplementedException(Exception):
    """A ``BufferInterface`` whose lookups were not written (tf2_ros's)."""

    def __init__(self) -> None:
        """Say what is missing."""
        self.errstr = 'CanTransform or LookupTransform not implemented'
        super().__init__(self.errstr)


def _missing(key) -> TypeException:
    return TypeException(f'Type {key} is not loaded or supported')


def _load_own_converters() -> None:
    """Register this package's converters for what no one registered (module doc)."""
    from dq_fk_ros.ros import tf_cloud, tf_geometry   # noqa: F401 (they register)


class TransformRegistration:
    """Message type -> ``do_transform(msg, transform)``, shared by every buffer."""

    __type_map = {}

    def print_me(self) -> None:
        """Print the map (tf2_ros's)."""
        print(TransformRegistration.__type_map)

    def add(self, key, callback) -> None:
        """Register ``callback(msg, TransformStamped) -> msg`` for messages of type ``key``."""
        TransformRegistration.__type_map[key] = callback

    def add_default(self, key, callback) -> None:
        """Register ``callback`` for ``key`` unless something is registered for it already."""
        TransformRegistration.__type_map.setdefault(key, callback)

    def get(self, key) -> Callable:
        """Return the callback for ``key``; raise :class:`TypeException` if none."""
        found = TransformRegistration.__type_map.get(key)
        if found is None:
            _load_own_converters()
            found = TransformRegistration.__type_map.get(key)
        if found is None:
            raise _missing(key)
        return found


class ConvertRegistration:
    """Conversions between message types and other representations (tf2_ros's)."""

    __to_msg_map = {}
    __from_msg_map = {}
    __convert_map = {}

    def add_from_msg(self, key, callback) -> None:
        """Register ``callback(msg) -> key`` (from a message to type ``key``)."""
        ConvertRegistration.__from_msg_map[key] = callback

    def add_to_msg(self, key, callback) -> None:
        """Register ``callback(obj) -> msg`` for objects of type ``key``."""
        ConvertRegistration.__to_msg_map[key] = callback

    def add_convert(self, key, callback) -> None:
        """Register ``callback(a) -> b`` for ``key = (type of a, type of b)``."""
        ConvertRegistration.__convert_map[key] = callback

    def get_from_msg(self, key) -> Callable:
        """Return the from-message conversion of ``key``; :class:`TypeException` if none."""
        return _get(ConvertRegistration.__from_msg_map, key)

    def get_to_msg(self, key) -> Callable:
        """Return the to-message conversion of ``key``; :class:`TypeException` if none."""
        return _get(ConvertRegistration.__to_msg_map, key)

    def get_convert(self, key) -> Callable:
        """Return the conversion of ``key = (from, to)``; :class:`TypeException` if none."""
        return _get(ConvertRegistration.__convert_map, key)


def _get(table, key):
    found = table.get(key)
    if found is None:
        raise _missing(key)
    return found


def convert(a, b_type) -> object:
    """Return ``a`` as ``b_type`` (tf2_ros's ``convert``: direct, a copy, or via a message)."""
    c = ConvertRegistration()
    try:
        return c.get_convert((type(a), b_type))(a)
    except TypeException:
        if type(a) is b_type:
            return deepcopy(a)
        return c.get_from_msg(b_type)(c.get_to_msg(type(a))(a))


def Stamped(obj, stamp, frame_id) -> object:   # noqa: N802 (tf2_ros's name)
    """Set ``obj.header`` to ``frame_id`` at ``stamp``; return ``obj`` (tf2_ros's)."""
    obj.header = Header(frame_id=frame_id, stamp=stamp)
    return obj


class BufferInterface:
    """
    tf2_ros's ``BufferInterface``: ``transform`` and ``transform_full`` over the lookups.

    A subclass gives ``lookup_transform``, ``lookup_transform_full``, ``can_transform`` and
    ``can_transform_full`` (:class:`~dq_fk_ros.ros.tf_buffer.Buffer`,
    :class:`~dq_fk_ros.ros.tf_buffer_client.BufferClient`).
    """

    def __init__(self) -> None:
        """Share the registrations (``self.registration``, as tf2_ros's)."""
        self.registration = TransformRegistration()

    def transform(self, object_stamped, target_frame: str, timeout=None,
                  new_type=None) -> object:
        """
        Return ``object_stamped`` in ``target_frame`` (at its own stamp).

        :param timeout: how long to wait for the transform (``Duration``; None: not).
        :param new_type: a type to convert the result to (``convert``).
        """
        do_transform = self.registration.get(type(object_stamped))
        header = object_stamped.header
        result = do_transform(object_stamped, self._lookup(
            target_frame, header.frame_id, header.stamp, timeout))
        return result if new_type is None else convert(result, new_type)

    def transform_full(self, object_stamped, target_frame: str, target_time,
                       fixed_frame: str, timeout=None, new_type=None) -> object:
        """Return ``object_stamped`` in ``target_frame`` at ``target_time``, via ``fixed``."""
        do_transform = self.registration.get(type(object_stamped))
        header = object_stamped.header
        args = (target_frame, target_time, header.frame_id, header.stamp, fixed_frame)
        transform = (self.lookup_transform_full(*args) if timeout is None
                     else self.lookup_transform_full(*args, timeout))
        result = do_transform(object_stamped, transform)
        return result if new_type is None else convert(result, new_type)

    def _lookup(self, target, source, stamp, timeout):
        if timeout is None:
            return self.lookup_transform(target, source, stamp)
        return self.lookup_transform(target, source, stamp, timeout)

    def lookup_transform(self, target_frame, source_frame, time,
                         timeout=None) -> TransformStamped:
        """Return the transform (a subclass's)."""
        raise NotImplementedException()

    def lookup_transform_full(self, target_frame, target_time, source_frame, source_time,
                              fixed_frame, timeout=None) -> TransformStamped:
        """Return the transform via ``fixed_frame`` (a subclass's)."""
        raise NotImplementedException()

    def can_transform(self, target_frame, source_frame, time, timeout=None) -> bool:
        """Return whether the transform can be given (a subclass's)."""
        raise NotImplementedException()

    def can_transform_full(self, target_frame, target_time, source_frame, source_time,
                           fixed_frame, timeout=None) -> bool:
        """Return whether the transform via ``fixed_frame`` can be given (a subclass's)."""
        raise NotImplementedException()


__all__ = ['BufferInterface', 'convert', 'ConvertRegistration', 'NotImplementedException',
           'Stamped', 'TransformRegistration', 'TypeException']
