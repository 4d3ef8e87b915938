"""
The parameters of dq_fk_node as one typed object, with the checks of their values.

:data:`NODE_PARAMETERS` is the table the node declares and ``dq_fk_node --help`` prints;
:class:`NodeParameters` holds one value of each (field names = parameter names), built by
:meth:`NodeParameters.from_values` and changed by :meth:`NodeParameters.changed`, both of
which refuse a value the node cannot use with a one-line :class:`ParameterError`. Plain
Python: test_node_parameters.py checks it without ROS.
"""

from dataclasses import dataclass, fields, replace
import math
import os

from dq_fk_ros.description.from_urdf import NODE_OPTIONS
from dq_fk_ros.description.loading import (
    FileAccess, load_robot, resolve_robot, robot_from_urdf_text)
from dq_fk_ros.description.robot_model import FRAME_ID, MAX_NAME_CHARS, TF_FRAME_ID
from dq_fk_ros.description.shipped import shipped_robots_dir
from dq_fk_ros.description.urdf_reader import tf_name
from dq_fk_ros.errors import DqFkError, first_line, ParameterError, printable_line
from dq_fk_ros.messages.joint_states import OUT_OF_LIMITS_POLICIES
from dq_fk_ros.ros.parameters import Param
import numpy as np

# the parameters that say which robot: changing any of them reloads it
ROBOT_PARAMETERS = ('robot_description_file', 'robot_description', 'urdf_base_link',
                    'urdf_tip_link')
RELIABILITIES = ('best_effort', 'reliable')
QOS_DEPTH_MAX = 100_000  # joint states the subscription may queue (tens of MB for an arm)
INPUT_BATCH_MS_DEFAULT = 2.0  # see docs/node.md, "How it keeps up"
INPUT_BATCH_MS_MAX = 100.0
MIN_RATE_HZ = 0.01  # publish_frequency, max_publish_rate_hz: 0 (off) or at least this
MAX_RATE_HZ = 1e6
MAX_FRAME_PREFIX_CHARS = 64
PUBLISH_FREQUENCY_DEFAULT = 20.0  # robot_state_publisher's (Jazzy), Hz

# the node's parameters (declared from this table; `dq_fk_node --help` prints it)
NODE_PARAMETERS = (
    Param('robot_description_file', '',
          'the robot: a DH YAML file, a URDF or xacro file (converted on load), or a shipped '
          'robot name (rl15, ur5e...); empty: rl15. Setting it at run time reloads the robot if '
          'it is valid.'),
    Param('robot_description', '',
          'URDF XML, as robot_state_publisher takes it; if set, used instead of '
          'robot_description_file'),
    Param('urdf_base_link', '',
          'for a URDF: the link the robot starts at (the fixed frame; the tree below it is '
          'published); empty: the root link'),
    Param('urdf_tip_link', '',
          'for a URDF: the link the first DH chain ends at (the end effector); empty: the child '
          'of the last moving joint of the longest chain'),
    Param('publish_frequency', PUBLISH_FREQUENCY_DEFAULT,
          'as robot_state_publisher (and its default): at most this many /tf messages per '
          'second of JointState stamps; 0: every update. The pose and twist topics are sent '
          'at every update'),
    Param('ignore_timestamp', False,
          'as robot_state_publisher: publish /tf at every update whatever publish_frequency '
          'says'),
    Param('publish_dh_frames', None,
          'put the DH frames the kinematics computes with (and their URDF helper links) on '
          "TF and ~/pose beside the links; unset: the robot's default (false for a URDF: "
          "TF is robot_state_publisher's tree; true for a DH file, whose DH frames are its "
          'link frames)', unset_type=bool),
    Param('frame_prefix', '',
          'prepended to every frame id except the fixed frame'),
    Param('publish_tf', True,
          'publish /tf and /tf_static'),
    Param('publish_poses', True,
          'publish ~/pose/<frame> (PoseStamped in the fixed frame)'),
    Param('publish_robot_description', True,
          'publish the URDF of the robot on robot_description (transient local), as '
          'robot_state_publisher does; re-sent on reload'),
    Param('publish_unread_topics', False,
          'fill and publish ~/pose and ~/twist topics that nobody subscribes to (by default '
          'they are skipped; /tf is always published)'),
    Param('publish_twist', True,
          'publish ~/twist/<frame> for the end effector (and tool) when every joint has a '
          'velocity'),
    Param('use_joint_state_stamp', True,
          'stamp outputs with the JointState stamp (a zero stamp: the node clock); false: '
          'always the node clock'),
    Param('max_publish_rate_hz', 0.0,
          'at most this many updates per second; 0: all'),
    Param('out_of_limits', 'warn',
          'joint values outside their limits: warn | clamp | reject'),
    Param('robot_description_dirs', '',
          'folders (separated by colons, as ROS_PACKAGE_PATH) that robot_description_file may '
          "name at run time, symlinks resolved; empty: the start-up file's folder. The shipped "
          'robots are always allowed', read_only=True),
    Param('allow_runtime_xacro', False,
          'expand a .xacro file set as robot_description_file at run time (a xacro file is a '
          'program; any peer on the domain may set parameters)', read_only=True),
    Param('qos_depth', 1000,
          f'depth of the joint_states subscription (1 to {QOS_DEPTH_MAX})', read_only=True),
    Param('input_thread', True,
          'take joint states in a thread of their own (true) or in the executor', read_only=True),
    Param('input_batch_ms', INPUT_BATCH_MS_DEFAULT,
          'with input_thread: after an update the input thread looks for the next joint states '
          'this much later (ms; 0: at once): one wake-up serves several messages above 1 / this '
          'rate, adding at most this much latency', read_only=True),
    Param('joint_states_reliability', 'best_effort',
          'best_effort (matches reliable and best-effort publishers) | reliable', read_only=True),
)


@dataclass(frozen=True)
class NodeParameters:
    """
    One value of each of dq_fk_node's parameters (:data:`NODE_PARAMETERS`), checked.

    Build with :meth:`from_values`; a change makes a new object (:meth:`changed`).
    """

    robot_description_file: str = ''
    robot_description: str = ''
    urdf_base_link: str = ''
    urdf_tip_link: str = ''
    publish_frequency: float = PUBLISH_FREQUENCY_DEFAULT
    ignore_timestamp: bool = False
    publish_dh_frames: bool | None = None
    frame_prefix: str = ''
    publish_tf: bool = True
    publish_poses: bool = True
    publish_robot_description: bool = True
    publish_unread_topics: bool = False
    publish_twist: bool = True
    use_joint_state_stamp: bool = True
    max_publish_rate_hz: float = 0.0
    out_of_limits: str = 'warn'
    robot_description_dirs: str = ''
    allow_runtime_xacro: bool = False
    qos_depth: int = 1000
    input_thread: bool = True
    input_batch_ms: float = INPUT_BATCH_MS_DEFAULT
    joint_states_reliability: str = 'best_effort'

    @classmethod
    def from_values(cls, values) -> 'NodeParameters':
        """
        Return the parameters ``{name: value}`` (names not given keep their defaults).

        :raises ParameterError: for a value the node cannot use (one line).
        """
        known = {f.name for f in fields(cls)}
        check_values({k: v for k, v in values.items() if k in known})
        return cls(**{k: v for k, v in values.items() if k in known})

    def changed(self, new) -> 'NodeParameters':
        """
        Return these parameters with the changes ``{name: value}`` (others are ignored).

        :raises ParameterError: for a value the node cannot use (one line).
        """
        known = {f.name for f in fields(self)}
        changes = {k: v for k, v in new.items() if k in known}
        check_values(changes)
        return replace(self, **changes)

    @property
    def robot_inputs(self) -> dict:
        """Return the parameters that say which robot, ``{name: value}`` (ROBOT_PARAMETERS)."""
        return {name: getattr(self, name) for name in ROBOT_PARAMETERS}

    def file_access(self, xacro_limit_s, cancelled) -> FileAccess:
        """
        Return what a robot file set at run time may be (a :class:`FileAccess`).

        Under ``robot_description_dirs`` (default: the start-up file's folder) or the shipped
        robots; a xacro only if ``allow_runtime_xacro``, stopped after ``xacro_limit_s``
        or when ``cancelled()`` says so.

        :raises ParameterError: for a folder that is not one.
        """
        dirs = [d for d in self.robot_description_dirs.split(os.pathsep) if d]
        if not dirs:
            start = self.robot_description_file
            if start and not self.robot_description.strip():
                dirs.append(os.path.dirname(os.path.realpath(resolve_robot(start))))
        for folder in dirs:
            if not os.path.isdir(folder):
                raise ParameterError(f'parameter robot_description_dirs: '
                                     f'{printable_line(folder, 70)!r} is not a folder')
        dirs = [os.path.realpath(d) for d in dirs] + [shipped_robots_dir()]
        return FileAccess(tuple(dict.fromkeys(dirs)), self.allow_runtime_xacro, xacro_limit_s,
                          cancelled)


def _check_choice(name, value, allowed):
    if value not in allowed:
        raise ParameterError(f'parameter {name} is {value!r}; allowed: {", ".join(allowed)}')


def check_values(new) -> None:
    """Raise ParameterError (one line) for a value in ``{name: value}`` the node cannot use."""
    dh_frames = new.get('publish_dh_frames')
    if dh_frames is not None and not isinstance(dh_frames, bool):
        shown = printable_line(repr(dh_frames), 70)
        raise ParameterError(f'parameter publish_dh_frames is {shown}; allowed: true, false')
    if 'out_of_limits' in new:
        _check_choice('out_of_limits', new['out_of_limits'], OUT_OF_LIMITS_POLICIES)
    if 'joint_states_reliability' in new:
        _check_choice('joint_states_reliability', new['joint_states_reliability'],
                      RELIABILITIES)
    for name in ('max_publish_rate_hz', 'publish_frequency'):
        rate = new.get(name, 0.0)
        if not (rate == 0.0 or MIN_RATE_HZ <= rate <= MAX_RATE_HZ):
            raise ParameterError(f'parameter {name} must be 0 (publish every update) or from '
                                 f'{MIN_RATE_HZ:g} to {MAX_RATE_HZ:g}, got {rate:g}')
    for name in ('urdf_base_link', 'urdf_tip_link'):
        link = new.get(name, '')
        if link and (len(link) > MAX_NAME_CHARS or not TF_FRAME_ID.fullmatch(tf_name(link))):
            raise ParameterError(
                f'parameter {name} {printable_line(link, 70)!r} is not a link name tf2 '
                f'takes (printable ASCII without spaces; at most {MAX_NAME_CHARS})')
    depth = new.get('qos_depth', 1)
    if not 1 <= depth <= QOS_DEPTH_MAX:
        raise ParameterError(f'parameter qos_depth must be an integer from 1 to '
                             f'{QOS_DEPTH_MAX}, got {depth}')
    batch_ms = new.get('input_batch_ms', 0.0)
    if not (math.isfinite(batch_ms) and 0.0 <= batch_ms <= INPUT_BATCH_MS_MAX):
        raise ParameterError(f'parameter input_batch_ms must be a number from 0 to '
                             f'{INPUT_BATCH_MS_MAX:g} (0: take each joint state at once), '
                             f'got {batch_ms}')
    prefix = new.get('frame_prefix', '')
    if prefix and (len(prefix) > MAX_FRAME_PREFIX_CHARS or
                   not FRAME_ID.fullmatch(prefix + 'x')):
        raise ParameterError(
            f'parameter frame_prefix {printable_line(prefix, 70)!r} would not give valid frame '
            f'ids: use letters, digits, underscores and inner slashes, e.g. robot1/ (at most '
            f'{MAX_FRAME_PREFIX_CHARS})')


def load_robot_of(inputs: dict, packages, log, access=None) -> object:
    """
    Return the model of the robot the node's parameters name (RobotDescriptionError).

    :param inputs: :attr:`NodeParameters.robot_inputs`; ``packages``: the package paths;
        ``log``: the node's logger (the conversion's summary, the warnings).
    :param access: for a file named at run time: where it may be (see FileAccess).
    """
    base = inputs['urdf_base_link'] or None
    tip = inputs['urdf_tip_link'] or None
    if inputs['robot_description'].strip():
        robot = robot_from_urdf_text(inputs['robot_description'], 'parameter robot_description',
                                     base, tip, options=NODE_OPTIONS)
    else:
        robot = load_robot(inputs['robot_description_file'] or 'rl15', base, tip,
                           access=access, packages=packages, options=NODE_OPTIONS)
    if robot.conversion is not None:
        log.info(robot.summary())
    for line in robot.warnings:
        log.warn(line)
    # the kernel's copy of the robot (or the straight-line code) made now, outside the
    # node's lock, not at the first update (250 frames: tens of ms the first updates wait)
    robot.model.frame_pose_arrays(np.zeros(robot.model.dof))
    robot.model.transform_pose_array(np.zeros(robot.model.dof))
    return robot.model


def refusal(exc: BaseException, quote: bool = False) -> str:
    """
    Return the one-line reason a parameter change is refused for ``exc``.

    :param quote: whether an unexpected exception's text may be shown (not while a file
        is read: it may hold the file's text).
    """
    if isinstance(exc, DqFkError):  # a robot file's error, a parameter's
        return printable_line(exc.public)
    if quote and str(exc).strip():
        return f'{type(exc).__name__}: {printable_line(first_line(exc))}'
    return f'{type(exc).__name__} while applying the change'


__all__ = ['check_values', 'load_robot_of', 'NODE_PARAMETERS', 'NodeParameters', 'refusal',
           'ROBOT_PARAMETERS']
