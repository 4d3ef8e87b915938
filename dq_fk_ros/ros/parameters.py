"""
A node's ROS parameters as one table: declared from it, and printed by ``--help``.

Each :class:`Param` is a name, a default (its type), a description and whether it is read
only; :func:`declare` declares a table's parameters on a node, :func:`help_text` writes the
``--help`` of a program from it (without starting ROS).
"""

from dataclasses import dataclass
import textwrap

from dq_fk_ros.ros.package_paths import DESCRIPTION as PACKAGE_PATHS_DESCRIPTION


@dataclass(frozen=True)
class Param:
    """
    One ROS parameter: ``default`` gives its type; ``read_only``: set at start only.

    A ``default`` of None with ``unset_type`` (``bool``, ``str``...) declares a parameter
    of that type without a value (rclpy's statically typed, unset parameter): its value is
    None until a user sets one.
    """

    name: str
    default: object
    description: str
    read_only: bool = False
    unset_type: type = None


def declare(node, params) -> dict:
    """Declare every parameter of ``params`` on ``node``; return ``{name: value}``."""
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.parameter import Parameter
    types = {bool: Parameter.Type.BOOL, str: Parameter.Type.STRING,
             float: Parameter.Type.DOUBLE, int: Parameter.Type.INTEGER}
    for p in params:
        value = types[p.unset_type] if p.default is None else p.default
        node.declare_parameter(p.name, value, ParameterDescriptor(
            description=p.description, read_only=p.read_only))
    # an unset parameter's value is None (get_parameter raises for it)
    return {p.name: node.get_parameter_or(p.name, None).value for p in params}


def help_text(program, summary, params, package_paths=True) -> str:
    """Return the ``--help`` text of ``program``: how to run it and every parameter."""
    lines = [f'usage: {program} [--ros-args -p NAME:=VALUE ... | --params-file FILE]', '']
    lines += textwrap.wrap(summary, 92)
    lines += ['', 'ROS parameters (default; "read only": at start only):']
    rows = [(p.name, (f'{p.unset_type.__name__}, unset' if p.default is None else
                      repr(p.default)) + (', read only' if p.read_only else ''), p.description)
            for p in params]
    if package_paths:
        rows.append(('package_paths', '[], read only', PACKAGE_PATHS_DESCRIPTION))
    for name, default, description in rows:
        lines.append(f'  {name} ({default})')
        lines += textwrap.wrap(description, 88, initial_indent='      ',
                               subsequent_indent='      ')
    return '\n'.join(lines) + '\n'


def wants_help(argv) -> bool:
    """Say whether ``-h`` or ``--help`` comes before any ``--ros-args`` in ``argv``."""
    args = list(argv[1:])
    if '--ros-args' in args:
        args = args[:args.index('--ros-args')]
    return '-h' in args or '--help' in args


__all__ = ['declare', 'help_text', 'Param', 'wants_help']
