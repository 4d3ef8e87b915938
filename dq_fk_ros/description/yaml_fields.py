"""
The robot description file's YAML, read safely, and its fields checked one by one.

:class:`UniqueKeyLoader` is PyYAML's safe loader refusing a key given twice and reading
YAML 1.2's exponents as numbers; :class:`FieldReader` checks a field (a mapping of known
fields, a finite number in the file's units, a vector, a name, a frame id, a choice) and
raises a one-line :class:`~dq_fk_ros.errors.RobotDescriptionError` naming the file, the
place and the field. :func:`yaml_number` writes a float both YAML dialects read back.
:mod:`.schema` reads the sections with them.
"""

import math
import re

from dq_fk_ros.description.robot_model import MAX_LENGTH_M, MAX_NAME_CHARS, TF_FRAME_ID
from dq_fk_ros.errors import describe, RobotDescriptionError, short
import yaml


class UniqueKeyLoader(yaml.SafeLoader):
    """A SafeLoader that refuses a mapping with the same key twice."""


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f'duplicate key {short(key)}', key_node.start_mark)
        seen.add(key)
    return yaml.SafeLoader.construct_mapping(loader, node, deep)


UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                _construct_mapping)
# YAML 1.2 writes exponents as 5e-05 or 1E16 (no point, or no sign): YAML 1.1, PyYAML's
# dialect, reads those as strings; robot files take them as numbers
UniqueKeyLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


def yaml_number(value: object) -> float:
    """
    Write a finite float so that YAML 1.1 and 1.2 both read it back as the same float.

    ``repr`` gives the shortest text that reads back exactly; YAML 1.1 also wants a point
    in the mantissa and a sign in the exponent (``5e-05`` -> ``5.0e-05``).
    """
    text = repr(float(value))
    mantissa, e, exponent = text.partition('e')
    if e and '.' not in mantissa:
        text = f'{mantissa}.0e{exponent}'
    return text


class FieldReader:
    """
    The field checks of a robot description file, each error one line naming the file.

    ``length``/``angle``: the file's units in metres and radians (set from its ``units``).
    """

    def __init__(self, source: str):
        """Read the fields of the file ``source`` (its name, for the messages)."""
        self.source = source
        self.length = 1.0
        self.angle = 1.0

    def fail(self, where: str, message: str) -> None:
        """Raise the one-line :class:`RobotDescriptionError` of ``where`` (always raises)."""
        prefix = f'{self.source}: {where}: ' if where else f'{self.source}: '
        raise RobotDescriptionError(prefix + message)

    def mapping(self, value: object, where: str, allowed: tuple, required: tuple = ()) -> dict:
        """Return ``value`` if it is a mapping of ``allowed`` fields holding ``required``."""
        if not isinstance(value, dict):
            self.fail(where, f'expected a mapping with fields {", ".join(allowed)}, '
                      f'got {describe(value)}')
        for key in value:
            if key not in allowed:
                self.fail(where, f'unknown field {short(key)}; allowed fields: '
                          f'{", ".join(allowed)}')
        for key in required:
            if key not in value:
                self.fail(where, f'missing field {key!r} (required: {", ".join(required)})')
        return value

    def number(self, value: object, where: str, field: str, unit: float = 1.0) -> float:
        """Return a finite number times ``unit`` (not a bool, not a string)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, f'field {field!r} must be a number, got {describe(value)}')
        try:
            scaled = float(value) * unit
        except OverflowError:  # an integer beyond the float range
            scaled = math.inf
        if not math.isfinite(scaled):
            self.fail(where, f'field {field!r} must be a finite number, got '
                      f'{describe(value)}')
        return scaled

    def offset(self, value: object, where: str, field: str) -> float:
        """Return a length given in the file's unit in metres (at most :data:`MAX_LENGTH_M`)."""
        metres = self.number(value, where, field, self.length)
        if abs(metres) > MAX_LENGTH_M:
            self.fail(where, f'field {field!r} is {metres:g} m; offsets are at most '
                      f'{MAX_LENGTH_M:g} m')
        return metres

    def vector(self, value: object, where: str, field: str, size: int,
               unit: float = 1.0) -> list[float]:
        """Return a list of ``size`` finite numbers times ``unit``."""
        if not isinstance(value, list) or len(value) != size:
            self.fail(where, f'field {field!r} must be a list of {size} numbers, '
                      f'got {describe(value)}')
        return [self.number(v, where, f'{field}[{k}]', unit) for k, v in enumerate(value)]

    def name(self, value: object, where: str, field: str, pattern: re.Pattern,
             what: str) -> str:
        """Return a name matching ``pattern`` (``what`` it must be, for the message)."""
        if not isinstance(value, str) or len(value) > MAX_NAME_CHARS or \
                not pattern.fullmatch(value):
            self.fail(where, f'field {field!r} must be {what} (at most {MAX_NAME_CHARS} '
                      f'characters), got {describe(value)}')
        return value

    def frame(self, value: object, where: str, field: str = 'frame') -> str:
        """Return a tf2 frame id."""
        return self.name(value, where, field, TF_FRAME_ID,
                         'a tf2 frame id (printable ASCII without spaces, not starting with '
                         'a slash)')

    def choice(self, value: object, where: str, field: str, allowed: tuple) -> str:
        """Return ``value`` if it is one of ``allowed``."""
        if not isinstance(value, str) or value not in allowed:
            self.fail(where, f'field {field!r} is {short(value)}; allowed: {", ".join(allowed)}')
        return value


__all__ = ['FieldReader', 'UniqueKeyLoader', 'yaml_number']
