"""
The YAML robot description file, read: text in, a validated :class:`RobotModel` out.

The format is documented in ``docs/robot_description.md``. Every length and angle in the
file is in the file's ``units``; the model holds metres and radians only (REP 103). Any
mistake raises :class:`~dq_fk_ros.errors.RobotDescriptionError` with a single
line naming the file, the place (row index and frame), the field, what was found and what
is allowed. Plain Python (PyYAML + numpy), no ROS.

The field checks and the YAML loader are :mod:`.yaml_fields`.
"""

import math
import os

from dq_fk_ros.description.robot_model import (
    Branch, global_joint_names, JOINT_NAME, LinkFrame, MAX_DESCRIPTION_CHARS, MAX_FILE_BYTES,
    MAX_NAME_CHARS, MAX_ROWS, pose_topic_name, RobotModel, rpy_matrix)
from dq_fk_ros.description.yaml_fields import FieldReader, UniqueKeyLoader

from dq_fk_ros.errors import describe, listing, RobotDescriptionError, short
from dq_fk_ros.kinematics.dh import CONVENTIONS, DHJoint, JOINT_TYPES, KinematicChain
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion, quat_from_matrix
import numpy as np
import yaml

LENGTH_UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001}
ANGLE_UNITS = {'rad': 1.0, 'deg': math.pi / 180.0}
ROW_TYPES = JOINT_TYPES  # a row's type is its joint's
TOP_FIELDS = ('robot', 'description', 'convention', 'units', 'fixed_frame', 'base', 'chain',
              'tool', 'chains', 'links', 'end_effector', 'publish_dh_frames')
CHAIN_FIELDS = ('parent', 'base', 'chain', 'tool')
LINK_FIELDS = ('frame', 'parent', 'tf_parent', 'xyz', 'rpy', 'quaternion', 'type', 'axis',
               'joint', 'limits', 'max_velocity', 'mimic')
LINK_TYPES = ('fixed', 'revolute', 'prismatic', 'floating')
UNIT_FIELDS = ('length', 'angle')
TRANSFORM_FIELDS = ('frame', 'xyz', 'rpy', 'quaternion')
ROW_FIELDS = ('frame', 'joint', 'type', 'theta', 'd', 'a', 'alpha', 'scale', 'limits',
              'max_velocity', 'mimic', 'd_joint', 'd_limits', 'd_max_velocity')
MIMIC_FIELDS = ('joint', 'multiplier', 'offset')


def load_robot_description(path: str | os.PathLike) -> RobotModel:
    """Read and validate a robot description file; raise :class:`RobotDescriptionError`."""
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isdir(path) and not os.path.isfile(path):
        # a FIFO or a device would block the reader or never end
        raise RobotDescriptionError(f'{path}: not a regular file')
    try:
        with open(path, encoding='utf-8') as stream:
            text = stream.read(MAX_FILE_BYTES + 1)
        if len(text) > MAX_FILE_BYTES:
            raise RobotDescriptionError(f'{path}: larger than {MAX_FILE_BYTES // 1024} KiB; '
                                        f'a robot description file is at most that big')
    except FileNotFoundError:
        raise RobotDescriptionError(f'{path}: no such file') from None
    except IsADirectoryError:
        raise RobotDescriptionError(f'{path}: is a directory, not a robot description file') \
            from None
    except UnicodeDecodeError as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc})',
                                    f'{path}: not UTF-8 text') from None
    except (OSError, ValueError) as exc:
        raise RobotDescriptionError(f'{path}: cannot be read ({exc})',
                                    f'{path}: cannot be read') from None
    return parse_robot_description(text, path)


def parse_robot_description(text: str, source: str = '<string>') -> RobotModel:
    """
    Validate the YAML text of a robot description; ``source`` names it in errors.

    Every problem, whatever the text holds, is a :class:`RobotDescriptionError` with one
    line (the limits: :data:`MAX_FILE_BYTES`, :data:`MAX_ROWS`, :data:`MAX_NAME_CHARS`).
    """
    if len(text) > MAX_FILE_BYTES:
        raise RobotDescriptionError(f'{source}: larger than {MAX_FILE_BYTES // 1024} KiB; a '
                                    f'robot description is at most that big')
    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise RobotDescriptionError(f'{source}: not valid YAML{where}: {problem}',
                                    f'{source}: not valid YAML{where}') from None
    except RecursionError:
        raise RobotDescriptionError(f'{source}: YAML nested too deeply to be a robot '
                                    f'description') from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. a 5000-digit integer
        problem = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise RobotDescriptionError(f'{source}: not valid YAML: {problem}',
                                    f'{source}: not valid YAML') from None
    if not _looks_like_description(data):
        public = (f'{source}: not a robot description (a YAML mapping with the fields robot, '
                  f'base and chain (or chains), and no others than {", ".join(TOP_FIELDS)})')
        try:
            _Parser(source).robot(data)
        except RecursionError:
            raise RobotDescriptionError(public) from None
        except RobotDescriptionError as exc:
            raise RobotDescriptionError(str(exc), public) from None
    try:
        return _Parser(source).robot(data)
    except RecursionError:  # a value nested so deeply that describing it recurses
        raise RobotDescriptionError(f'{source}: YAML nested too deeply to be a robot '
                                    f'description') from None


def _looks_like_description(data):
    """Say whether YAML data is a robot description at its top: then errors may quote it."""
    return isinstance(data, dict) and all(isinstance(k, str) and k in TOP_FIELDS for k in data) \
        and 'robot' in data and (all(k in data for k in ('base', 'chain')) or 'chains' in data)


class _Parser(FieldReader):
    """Walks the YAML data section by section, converting units; errors in one line."""

    # -- sections ------------------------------------------------------------------------
    def robot(self, data):
        data = self.mapping(data, '', TOP_FIELDS, required=('robot',))
        name = data['robot']
        if not isinstance(name, str) or not name.strip() or not name.isprintable() or \
                len(name) > MAX_NAME_CHARS:
            self.fail('', f"field 'robot' must be a non-empty name of printable characters "
                      f'(at most {MAX_NAME_CHARS}), got {describe(name)}')
        text = data.get('description', '')
        if not isinstance(text, str) or len(text) > MAX_DESCRIPTION_CHARS or \
                not text.replace('\n', ' ').replace('\t', ' ').isprintable():
            self.fail('', f"field 'description' must be text of printable characters (at "
                      f'most {MAX_DESCRIPTION_CHARS}), got {describe(text)}')
        convention = self.choice(data.get('convention', 'standard'), '', 'convention',
                                 CONVENTIONS)
        units = self.mapping(data.get('units', {}), 'units', UNIT_FIELDS)
        self.length = LENGTH_UNITS[self.choice(units.get('length', 'm'), 'units', 'length',
                                               tuple(LENGTH_UNITS))]
        self.angle = ANGLE_UNITS[self.choice(units.get('angle', 'rad'), 'units', 'angle',
                                             tuple(ANGLE_UNITS))]
        fixed_frame = self.frame(data.get('fixed_frame', 'world'), '', 'fixed_frame')
        seen = {fixed_frame: 'fixed_frame'}
        specs = self.chain_specs(data, fixed_frame, seen)
        link_rows = data.get('links', [])
        if not isinstance(link_rows, list):
            self.fail('links', f'expected a list of {{frame, parent, xyz, rpy | quaternion}}, '
                      f'got {describe(link_rows)}')
        if len(link_rows) > MAX_ROWS:
            self.fail('links', f'{len(link_rows)} links; a robot description has at most '
                      f'{MAX_ROWS}')

        # the rigid body each frame moves with: a moving row starts a new one
        body = {fixed_frame: 0}
        frames, parents, moving = [], [], []
        for spec in specs:
            chain_frames = spec['frames']
            body[chain_frames[0]] = body[spec['parent']]
            for k, p in enumerate(spec['parsed']):
                body[p['frame']] = (spec['prefix'], k) if p['type'] != 'fixed' \
                    else body[chain_frames[k]]
            if spec['tool_frame']:
                body[spec['tool_frame']] = body[chain_frames[len(spec['parsed'])]]
            frames += chain_frames
            parents += [spec['parent']] + chain_frames[:-1]
            moving += [False] + [p['type'] != 'fixed' for p in spec['parsed']] + \
                ([False] if spec['tool_frame'] else [])
        links = []
        for k, row in enumerate(link_rows):
            link = self.link(row, k, seen)
            seen[link.frame] = f'links[{k}]'
            # a link that moves (a mimic) is a rigid body of its own
            body[link.frame] = body[link.parent] if link.motion is None else f'links[{k}]'
            links.append(link)
        end_effector = specs[0]['frames'][-1]
        if 'end_effector' in data:
            end_effector = self.frame(data['end_effector'], '', 'end_effector')
            if end_effector not in seen or end_effector == fixed_frame:
                self.fail('', f"field 'end_effector' names {end_effector!r}, which is not a "
                          f'frame of the robot; frames: {listing(list(seen)[1:])}')
        dh_frames = data.get('publish_dh_frames', True)
        if not isinstance(dh_frames, bool):
            self.fail('', f"field 'publish_dh_frames' must be true or false, got "
                      f'{describe(dh_frames)}')

        chains = self.chains(specs, convention)
        chain = chains[0][1]
        branches = tuple(Branch(parent, c, external) for parent, c, external in chains[1:])
        joint_names = list(global_joint_names(chain, branches))
        for k, link in enumerate(links):
            if link.joint:
                if link.joint in joint_names:
                    self.fail(f'links[{k}] (frame {short(link.frame)})',
                              f'joint {link.joint!r} is already a joint of the robot; joint '
                              f'names must be unique')
                joint_names.append(link.joint)
        for k, link in enumerate(links):
            if link.motion is not None and not link.joint and \
                    link.motion[2] not in joint_names:
                self.fail(f'links[{k}] (frame {short(link.frame)}) mimic',
                          f"field 'joint' names {link.motion[2]!r}, which no row or link "
                          f'has; joints: {listing(joint_names)}')
        velocity = {}
        for spec in specs:
            for p in spec['parsed']:
                velocity.update(p['velocity'])
        velocity.update((link.joint, link.max_velocity) for link in links if link.joint)
        moving += [body[link.frame] != body[link.tf_parent] for link in links]
        topics = {}
        for frame in frames + [link.frame for link in links]:
            topic = pose_topic_name(frame)
            if topic in topics:
                self.fail('', f'frames {topics[topic]!r} and {frame!r} would both publish on '
                          f'~/pose/{topic} (topic names take letters, digits and _); rename '
                          f'one')
            topics[topic] = frame
        return RobotModel(
            name=name, source=self.source, fixed_frame=fixed_frame,
            frame_names=tuple(frames + [link.frame for link in links]),
            parent_frames=tuple(parents + [link.tf_parent for link in links]),
            moving=tuple(moving), chain=chain,
            max_velocity=np.array([velocity.get(n, math.inf) for n in joint_names]),
            links=tuple(links), end_effector=end_effector, branches=branches,
            publish_dh_frames=dh_frames)

    def chain_specs(self, data, fixed_frame, seen):
        """Parse ``base``/``chain``/``tool`` or ``chains``: one dict per chain, frames noted."""
        if 'chains' in data:
            for field in ('base', 'chain', 'tool'):
                if field in data:
                    self.fail('', f"field {field!r} goes inside an entry of 'chains' when the "
                              f"file has 'chains' (give either chains, or base and chain)")
            entries = data['chains']
            if not isinstance(entries, list) or not entries:
                self.fail('chains', f'expected a non-empty list of {{parent, base, chain, '
                          f'tool}}, got {describe(entries)}')
            if len(entries) > MAX_ROWS:
                self.fail('chains', f'{len(entries)} chains; a robot description has at '
                          f'most {MAX_ROWS}')
            entries = [(self.mapping(e, f'chains[{c}]', CHAIN_FIELDS,
                                     required=('parent', 'base', 'chain')), f'chains[{c}].')
                       for c, e in enumerate(entries)]
        else:
            for field in ('base', 'chain'):
                if field not in data:
                    self.fail('', f'missing field {field!r} (required: robot, base, chain; '
                              f'or robot, chains)')
            entries = [({'parent': fixed_frame, **{f: data[f] for f in ('base', 'chain', 'tool')
                                                   if f in data}}, '')]
        specs, total = [], 0
        for c, (entry, prefix) in enumerate(entries):
            parent = self.frame(entry['parent'], prefix[:-1], 'parent')
            if c == 0 and parent != fixed_frame:
                self.fail(prefix[:-1], f"field 'parent' of the first chain must be the fixed "
                          f'frame {fixed_frame!r}, got {parent!r}')
            if parent not in seen:
                self.fail(prefix[:-1], f"field 'parent' names {parent!r}, which is not the "
                          f'fixed frame or a frame of an earlier chain; frames so far: '
                          f'{listing(seen)}')
            base_frame, base = self.transform(entry['base'], prefix + 'base')
            rows = entry['chain']
            if not isinstance(rows, list) or not rows:
                self.fail(prefix + 'chain', f'expected a non-empty list of DH rows, got '
                          f'{describe(rows)}')
            total += len(rows)
            if total > MAX_ROWS:
                self.fail(prefix + 'chain', f'{total} rows; a robot description has at most '
                          f'{MAX_ROWS}')
            parsed = [self.row(row, k, prefix) for k, row in enumerate(rows)]
            tool_frame, tool = (self.transform(entry['tool'], prefix + 'tool')
                                if 'tool' in entry else (None, None))
            frames = [base_frame] + [p['frame'] for p in parsed]
            if tool_frame:
                frames.append(tool_frame)
            places = [prefix + 'base'] + [p['where'] for p in parsed] + [prefix + 'tool']
            for frame, place in zip(frames, places):
                if frame in seen:
                    self.fail(place, f'frame {frame!r} is already used by {seen[frame]}; '
                              f'frame names must be unique')
                seen[frame] = place
            specs.append({'parent': parent, 'prefix': prefix, 'base': base, 'tool': tool,
                          'parsed': parsed, 'frames': frames, 'tool_frame': tool_frame})
        return specs

    def chains(self, specs, convention):
        """Return ``[(parent, KinematicChain, external variables), ...]`` of the specs."""
        owners, chain_of = {}, {}
        for c, spec in enumerate(specs):
            for p in spec['parsed']:
                for key in ('joint', 'd_joint'):
                    if key in p:
                        if p[key] in owners:
                            self.fail(p['where'], f'joint {p[key]!r} is already read by '
                                      f'{owners[p[key]]}; joint names must be unique')
                        owners[p[key]] = p['where']
                        chain_of[p[key]] = c
        out = []
        for c, spec in enumerate(specs):
            joints, external = [], []
            for p in spec['parsed']:
                follows, name = p.get('follows', ''), p.get('joint', '')
                if follows and follows not in owners:
                    self.fail(p['where'] + ' mimic', f"field 'joint' names {follows!r}, "
                              f'which no row reads; joints: {listing(owners) or "none"}')
                if follows and chain_of[follows] != c:
                    if c == 0:
                        self.fail(p['where'] + ' mimic', f"field 'joint' names {follows!r}, "
                                  f"a joint of another chain; the first chain's rows mimic "
                                  f'its own joints')
                    if follows not in external:  # the row reads that joint's value itself
                        external.append(follows)
                        follows, name = '', follows
                limits = p.get('limits')
                if p['type'] == 'cylindrical':
                    limits = (limits, p.get('d_limits'))
                joints.append(DHJoint(
                    a=p['a'], alpha=p['alpha'], d=p['d'], theta=p['theta'],
                    joint_type=p['type'], scale=p['scale'], name=name,
                    d_name=p.get('d_joint', ''), follows=follows, limits=limits))
            try:
                chain = KinematicChain(joints, convention, base=spec['base'], tool=spec['tool'])
            except ValueError as exc:  # anything the core refuses that the checks missed
                self.fail(spec['prefix'] + 'chain', str(exc))
            out.append((spec['parent'], chain, tuple(external)))
        return out

    def link(self, row, k, seen):
        """One entry of ``links``: a frame fixed to an earlier frame (``seen``: name -> place)."""
        where = f'links[{k}]'
        if isinstance(row, dict) and isinstance(row.get('frame'), str):
            where = f"links[{k}] (frame {short(row['frame'])})"
        row = self.mapping(row, where, LINK_FIELDS, required=('frame', 'parent'))
        frame, offset = self.transform({f: v for f, v in row.items() if f in TRANSFORM_FIELDS},
                                       where)
        if frame in seen:
            self.fail(where, f'frame {frame!r} is already used by {seen[frame]}; frame names '
                      f'must be unique')
        parents = {}
        for field in ('parent', 'tf_parent'):
            parents[field] = self.frame(row.get(field, row['parent']), where, field)
            if parents[field] not in seen:
                self.fail(where, f'field {field!r} names {parents[field]!r}, which is not an '
                          f'earlier frame; frames so far: {listing(seen)}')
        kind = self.choice(row.get('type', 'fixed'), where, 'type', LINK_TYPES)
        if kind in ('fixed', 'floating'):
            for field in ('axis', 'joint', 'limits', 'max_velocity', 'mimic'):
                if field in row:
                    self.fail(where, f'field {field!r} applies only to a link of type revolute '
                              f'or prismatic')
            return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'],
                             floating=kind == 'floating')
        if ('mimic' in row) == ('joint' in row):
            given = 'both' if 'mimic' in row else 'neither'
            self.fail(where, f"a {kind} link takes either 'joint' (a joint of its own) or "
                      f"'mimic' (moving with another joint), not {given}")
        axis = np.array(self.vector(row.get('axis', [0, 0, 1]), where, 'axis', 3))
        largest = float(np.max(np.abs(axis)))
        if not largest > 0.0 or not np.linalg.norm(axis / largest) * largest > 1e-9:
            self.fail(where, "field 'axis' must not be all zeros")
        axis = axis / largest  # no overflow for huge components
        axis = tuple((axis / np.linalg.norm(axis)).tolist())
        unit = self.length if kind == 'prismatic' else self.angle
        if 'joint' in row:
            joint = self.name(row['joint'], where, 'joint', JOINT_NAME, 'a joint name')
            speed = {}
            self.max_velocity(row, where, 'max_velocity', unit, joint, {'velocity': speed})
            return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'],
                             (kind, axis, joint, 1.0, 0.0), joint,
                             self.limits(row, where, 'limits', unit) or (-math.inf, math.inf),
                             speed.get(joint, math.inf))
        for field in ('limits', 'max_velocity'):
            if field in row:
                self.fail(where, f"field {field!r} does not go with 'mimic' (the link moves "
                          f'with its source joint)')
        mimic = self.mapping(row['mimic'], where + ' mimic', MIMIC_FIELDS, required=('joint',))
        joint = self.name(mimic['joint'], where + ' mimic', 'joint', JOINT_NAME, 'a joint name')
        multiplier = self.number(mimic.get('multiplier', 1.0), where + ' mimic', 'multiplier')
        value_offset = self.number(mimic.get('offset', 0.0), where + ' mimic', 'offset', unit)
        return LinkFrame(frame, parents['parent'], offset, parents['tf_parent'],
                         (kind, axis, joint, multiplier, value_offset))

    def transform(self, value, where):
        value = self.mapping(value, where, TRANSFORM_FIELDS, required=('frame',))
        frame = self.frame(value['frame'], where)
        xyz = value.get('xyz', [0, 0, 0])
        self.vector(xyz, where, 'xyz', 3)
        xyz = [self.offset(v, where, f'xyz[{k}]') for k, v in enumerate(xyz)]
        if 'rpy' in value and 'quaternion' in value:
            self.fail(where, "give either 'rpy' or 'quaternion', not both")
        if 'quaternion' in value:
            xyzw = self.vector(value['quaternion'], where, 'quaternion', 4)
            largest = max(abs(c) for c in xyzw)
            if largest == 0.0 or math.sqrt(sum(c * c for c in xyzw)) < 1e-9:
                self.fail(where, "field 'quaternion' (x, y, z, w) must not be all zeros")
            xyzw = [c / largest for c in xyzw]  # no overflow for huge components
            norm = math.sqrt(sum(c * c for c in xyzw))
            rotation = (xyzw[3] / norm, xyzw[0] / norm, xyzw[1] / norm, xyzw[2] / norm)
        else:
            roll, pitch, yaw = self.vector(value.get('rpy', [0, 0, 0]), where, 'rpy', 3,
                                           self.angle)
            rotation = quat_from_matrix(rpy_matrix(roll, pitch, yaw))
        return frame, DualQuaternion.from_pose(rotation, xyz)

    def row(self, row, k, prefix=''):
        where = f'{prefix}chain[{k}]'
        if isinstance(row, dict) and isinstance(row.get('frame'), str):
            where = f"{prefix}chain[{k}] (frame {short(row['frame'])})"
        row = self.mapping(row, where, ROW_FIELDS, required=('frame', 'theta', 'd', 'a',
                                                             'alpha'))
        frame = self.frame(row['frame'], where)
        kind = self.choice(row.get('type', 'revolute'), where, 'type', ROW_TYPES)
        out = {'frame': frame, 'type': kind, 'where': where, 'velocity': {},
               'theta': self.number(row['theta'], where, 'theta', self.angle),
               'd': self.offset(row['d'], where, 'd'),
               'a': self.offset(row['a'], where, 'a'),
               'alpha': self.number(row['alpha'], where, 'alpha', self.angle)}
        scale = self.number(row.get('scale', 1.0), where, 'scale')
        if scale == 0.0:
            self.fail(where, "field 'scale' must not be 0 (it multiplies the joint value)")
        out['scale'] = scale
        var_unit = self.length if kind == 'prismatic' else self.angle
        if kind == 'fixed':
            for field in ('joint', 'limits', 'max_velocity', 'mimic', 'd_joint', 'd_limits',
                          'd_max_velocity', 'scale'):
                if field in row:
                    self.fail(where, f'field {field!r} does not apply to a fixed row')
            return out
        if kind != 'cylindrical':
            for field in ('d_joint', 'd_limits', 'd_max_velocity'):
                if field in row:
                    self.fail(where, f'field {field!r} applies only to a cylindrical row')
        if 'mimic' in row:
            if kind == 'cylindrical':
                self.fail(where, "field 'mimic' does not apply to a cylindrical row")
            for field in ('joint', 'limits', 'max_velocity', 'scale'):
                if field in row:
                    self.fail(where, f"field {field!r} does not go with 'mimic' (the row "
                              f'moves with its source joint)')
            mimic = self.mapping(row['mimic'], where + ' mimic', MIMIC_FIELDS,
                                 required=('joint',))
            out['follows'] = self.name(mimic['joint'], where + ' mimic', 'joint', JOINT_NAME,
                                       'a joint name')
            out['scale'] = self.number(mimic.get('multiplier', 1.0), where + ' mimic',
                                       'multiplier')
            offset = self.number(mimic.get('offset', 0.0), where + ' mimic', 'offset',
                                 var_unit)
            out['theta' if kind == 'revolute' else 'd'] += offset
            return out
        if 'joint' not in row:
            self.fail(where, f"missing field 'joint' (the JointState name a {kind} row "
                      f"reads; or give 'mimic')")
        out['joint'] = self.name(row['joint'], where, 'joint', JOINT_NAME, 'a joint name')
        out['limits'] = self.limits(row, where, 'limits', var_unit)
        self.max_velocity(row, where, 'max_velocity', var_unit, out['joint'], out)
        if kind == 'cylindrical':
            if 'd_joint' not in row:
                self.fail(where, "missing field 'd_joint' (a cylindrical row reads two "
                          "joints: 'joint' for theta, 'd_joint' for d)")
            out['d_joint'] = self.name(row['d_joint'], where, 'd_joint', JOINT_NAME,
                                       'a joint name')
            out['d_limits'] = self.limits(row, where, 'd_limits', self.length)
            self.max_velocity(row, where, 'd_max_velocity', self.length, out['d_joint'], out)
        return out

    def limits(self, row, where, field, unit):
        if field not in row:
            return None
        lower, upper = self.vector(row[field], where, field, 2, unit)
        if lower > upper:
            self.fail(where, f'field {field!r} has lower {short(row[field][0])} above upper '
                      f'{short(row[field][1])}; give [lower, upper]')
        return (lower, upper)

    def max_velocity(self, row, where, field, unit, joint, out):
        if field not in row:
            return
        value = self.number(row[field], where, field, unit)
        if value <= 0.0:
            self.fail(where, f'field {field!r} must be a positive speed (per second), '
                      f'got {short(row[field])}')
        out['velocity'][joint] = value


__all__ = ['load_robot_description', 'parse_robot_description']
