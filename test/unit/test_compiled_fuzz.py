"""
No Python value crashes the C extensions: a hypothesis fuzz of every public compiled entry point.

``_kernel.Chain`` (made, ``frames``, ``end``, ``frames_batch``, ``end_batch``, ``jacobian``),
``_kernel.Model`` (made, ``poses``, ``poses_batch``, ``frames``), ``_cdr.Template`` (made,
``one``, ``each``), ``_cdr.JointStateReader`` (made, ``read``), ``_cdr.Runs`` (made,
``match``, ``match_many``) and ``_mcap`` (``scan``,
``gather``, ``Rows`` made and ``fill``, ``reserve``) get random shapes (0, 1,
huge, 2**62), dtypes, strides (negative, non-contiguous, overlapping input and output,
read-only out), wrong types, and objects whose dunder methods mutate the callee or its other
arguments while the arguments are read. Every call either works or raises one of ALLOWED;
``make sanitize`` runs this file under AddressSanitizer and UndefinedBehaviorSanitizer,
where any memory error or undefined behaviour aborts the run (docs/security.md).
"""

import math
import os
import tempfile

from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.kinematics.chain_engines import kernel_chain_args
from dq_fk_ros.kinematics.dh import DHJoint, KinematicChain
from dq_fk_ros.kinematics.kernel import kernel_info
from dq_fk_ros.messages.cdr import COMPILED
from dq_fk_ros.messages.cdr_templates import pose_stamped_template, tf_message_template
from hypothesis import given, strategies as st
import numpy as np
import pytest
from test_joint_states import reader_arguments

pytestmark = pytest.mark.skipif(
    kernel_info()['active'] != 'c' or COMPILED is None,
    reason='the Python paths are active (DQ_FK_PURE_PYTHON or no compiler): nothing to fuzz')

ALLOWED = (ValueError, TypeError, IndexError, OverflowError, MemoryError, BufferError)

SIZES = [0, 1, 2, 3, 6, 7, 8, 10, 16, 17, 64, 65]
# rows of an empty array whose product with a C size wraps (numpy takes at most 2**60 / 8)
HUGE_ROWS = [2**31, 2**52, 2**57, 2**59]
ODD_FLOATS = [math.nan, math.inf, -math.inf, 1e300, -1e300, -0.0, 0.5, -1.0, -2.0, 2.0**53,
              2.0**63, 1e18, 3.0, 127.0, 4096.0]


def attempt(call, *args, **kwargs):
    """Call; a refusal of ALLOWED is an answer, anything else (or a crash) is a failure."""
    try:
        return call(*args, **kwargs)
    except ALLOWED:
        return None


class Mutator:
    """Run ``action`` first in __index__, __float__ and __bool__ (the hostile part)."""

    def __init__(self, value, action):
        self.value, self.action = value, action

    def _act(self):
        try:
            self.action()
        except Exception:  # noqa: B902 -- what the action raises is not the call's answer
            pass

    def __index__(self):
        self._act()
        return int(self.value)

    __int__ = __index__

    def __float__(self):
        self._act()
        return float(self.value)

    def __bool__(self):
        self._act()
        return bool(self.value)


class FloatWithDel(float):
    """A float whose __del__ empties the list it was put in: the reader must survive it."""

    def __new__(cls, value, victim):
        """Make the float, remembering the list it will empty."""
        made = super().__new__(cls, value)
        made.victim = victim
        return made

    def __del__(self):
        self.victim.clear()


@st.composite
def hostile_arrays(draw, like=None):
    """Draw an array, or something else, of the kinds a buffer argument must survive."""
    kind = draw(st.sampled_from(['like', 'like', 'like', 'shape', 'huge', 'float32', 'int64',
                                 'big_endian', 'object', 'reversed', 'strided', 'read_only',
                                 'scalar', 'list', 'bytes', 'bytearray', 'none', 'int']))
    if like is not None and kind == 'like':
        arr = np.array(like, dtype=float, copy=True)
        if arr.size and draw(st.booleans()):
            flat = arr.reshape(-1)
            for _ in range(draw(st.integers(1, 3))):
                flat[draw(st.integers(0, flat.size - 1))] = draw(st.sampled_from(ODD_FLOATS))
        return arr
    shape = tuple(draw(st.lists(st.sampled_from(SIZES), min_size=1, max_size=3)))
    if kind in ('shape', 'like'):
        return np.zeros(shape)
    if kind == 'huge':  # a shape whose product wraps, of no size at all
        rest = tuple(draw(st.lists(st.sampled_from([16, 8, 7, 1]), max_size=2)))
        huge = draw(st.sampled_from(HUGE_ROWS).filter(
            lambda h: h * int(np.prod(rest)) * 8 < 2**63))  # numpy's own limit
        return np.empty((huge, 0) + rest)
    if kind == 'float32':
        return np.zeros(shape, np.float32)
    if kind == 'int64':
        return np.zeros(shape, np.int64)
    if kind == 'big_endian':
        return np.zeros(shape, '>f8')
    if kind == 'object':
        return np.full(shape, None, dtype=object)
    if kind == 'reversed':
        return np.zeros(shape)[::-1]
    if kind == 'strided':
        return np.zeros(shape + (2,))[..., 0]
    if kind == 'read_only':
        arr = np.zeros(shape)
        arr.setflags(write=False)
        return arr
    if kind == 'scalar':
        return np.float64(1.0)
    if kind == 'list':
        return [0.0] * shape[0]
    if kind == 'bytes':
        return bytes(8 * shape[0])
    if kind == 'bytearray':
        return bytearray(8 * shape[0])
    if kind == 'none':
        return None
    return 3


def chain_parts(chain):
    """Return the arguments a KinematicChain gives _kernel.Chain."""
    return kernel_chain_args(chain.table)


CHAINS = [
    KinematicChain([DHJoint(a=0.2, alpha=0.3, name='a'),
                    DHJoint(d=0.1, joint_type='prismatic', name='b')]),
    KinematicChain([DHJoint(a=0.1, d=0.01 * i, joint_type='fixed') for i in range(15)]),
    KinematicChain([DHJoint(a=0.3, alpha=-0.5, name=f'j{i}') for i in range(6)],
                   convention='modified'),
    parse_robot_description(open('config/rl15.yaml', encoding='utf-8').read()).chain,
]


@given(st.data())
def test_a_chain_survives_any_arguments(data):
    chain = data.draw(st.sampled_from(CHAINS))
    program, base, tool, dof, rows, modified = chain_parts(chain)
    args = [data.draw(hostile_arrays(program)), data.draw(hostile_arrays(base)),
            data.draw(st.one_of(st.none(), hostile_arrays(tool if tool is not None else base))),
            data.draw(st.sampled_from([dof, dof, 0, 1, -1, 2**62, 2**63 - 1, 1 << 21])),
            data.draw(st.one_of(st.none(), hostile_arrays(rows))), modified]
    from dq_fk_ros.kinematics import _kernel
    made = attempt(_kernel.Chain, *args)
    made_from = args
    if made is None:
        made_from = [program, base, tool, dof, rows, modified]
        made = _kernel.Chain(*made_from)
    n_frames, dof = made.n_frames, made.dof
    single = (np.zeros(dof), np.empty((n_frames, 8)))
    for _ in range(data.draw(st.integers(1, 4))):
        method = data.draw(st.sampled_from(['frames', 'end', 'frames_batch', 'end_batch',
                                            'jacobian']))
        n = data.draw(st.sampled_from([0, 1, 3, 64, 65]))
        shapes = {'frames': ((dof,), (n_frames, 8)), 'end': ((dof,), (8,)),
                  'frames_batch': ((n, dof), (n, n_frames, 8)), 'end_batch': ((n, dof), (n, 8)),
                  'jacobian': ((dof,), (6, dof))}[method]
        q = data.draw(hostile_arrays(np.zeros(shapes[0])))
        out = data.draw(st.one_of(hostile_arrays(np.zeros(shapes[1])),
                                  st.just('overlap')))
        if isinstance(out, str) and isinstance(q, np.ndarray) and q.dtype == float:
            out = q  # input and output the same memory
        elif isinstance(out, np.ndarray) and out is not q:
            out = np.ascontiguousarray(out) if data.draw(st.booleans()) else out
        attempt(getattr(made, method), q, out)
        attempt(getattr(made, method), *single)
        if data.draw(st.booleans()):
            attempt(made.__init__, *args)  # refused: the state is set once
    out = np.empty((n_frames, 8))
    made.frames(np.zeros(dof), out)  # the chain is what it was made as, after all of it
    same = _kernel.Chain(*made_from)  # what it was made from, made again
    again = np.empty((n_frames, 8))
    same.frames(np.zeros(dof), again)
    np.testing.assert_array_equal(out, again)  # (NaN equals NaN here)


DUAL_ARM = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())


def model_parts(model):
    """Return the arguments RobotModel gives _kernel.Model, as lists one can break."""
    kernel = model.kinematics.engine.model
    assert kernel is not None
    index = {name: k for k, name in enumerate(model.frame_names)}
    index[model.fixed_frame] = -1
    chains = [[chain.engine.kernel_chain, index[parent], np.array(q_map, dtype=float),
               np.array(chain.table.pose_rows, dtype=float).reshape(-1, 10),
               chain.convention == 'standard']
              for (parent, chain, _), q_map in zip(model.chains, model._q_maps)]
    return chains, kernel


@given(st.data())
def test_a_model_survives_any_arguments(data):
    from dq_fk_ros.kinematics import _kernel
    model = data.draw(st.sampled_from([DUAL_ARM, parse_robot_description(
        open('config/rl15.yaml', encoding='utf-8').read())]))
    chains, kernel = model_parts(model)
    good_links = np.array([[0.0, -1.0, 1, 0, 0, 0, 0, 0, 0, 0, 0.0, 0, 0, 1, 0.0, 1.0, 0.0]])
    chain_list = []
    for parts in chains:
        parts = list(parts)
        if data.draw(st.integers(0, 3)) == 0:
            at = data.draw(st.integers(0, 4))
            parts[at] = data.draw(st.one_of(
                hostile_arrays(parts[at] if at in (2, 3) else None),
                st.sampled_from([-2, -1, 0, 10**6, 2**62, None, 'x', 0.5])))
        if data.draw(st.integers(0, 5)) == 0:  # a parent whose __index__ breaks the rest
            parts[1] = Mutator(parts[1], chain_list.clear)
        if data.draw(st.integers(0, 5)) == 0:  # a standard whose __bool__ re-makes the model
            parts[4] = Mutator(parts[4], lambda: kernel.__init__(chain_list, good_links, 1))
        chain_list.append(tuple(parts) if data.draw(st.integers(0, 9)) else parts)
    links = data.draw(st.one_of(hostile_arrays(good_links), hostile_arrays(np.zeros((0, 17)))))
    dof = data.draw(st.sampled_from([model.dof, model.dof, 0, -1, 2**62,
                                     Mutator(model.dof, chain_list.clear)]))
    made = attempt(_kernel.Model, chain_list if data.draw(st.booleans()) else
                   tuple(chain_list), links, dof)
    if made is None:
        made = kernel
    n, r, d = made.n_frames, made.n_relative, model.dof
    for _ in range(data.draw(st.integers(1, 4))):
        method = data.draw(st.sampled_from(['poses', 'poses_batch', 'frames']))
        b = data.draw(st.sampled_from([0, 1, 3]))
        shapes = {'poses': ((d,), (n, 7), (r, 7)), 'frames': ((d,), (n, 8)),
                  'poses_batch': ((b, d), (b, n, 7), (b, r, 7))}[method]
        args = [data.draw(hostile_arrays(np.zeros(s))) for s in shapes]
        if method != 'frames' and data.draw(st.booleans()):
            args[1] = None
        if data.draw(st.integers(0, 4)) == 0 and isinstance(args[0], np.ndarray):
            args[-1] = args[0]  # overlapping input and output
        attempt(getattr(made, method), *args)
    relative = np.empty((kernel.n_relative, 7))
    kernel.poses(np.zeros(model.dof), None, relative)  # the robot's own model is unchanged
    expected = np.empty_like(relative)
    model.kinematics.engine.model.poses(np.zeros(model.dof), None, expected)
    np.testing.assert_array_equal(relative, expected)


def _tf_template():
    return tf_message_template([('a', 'b'), ('a', 'c')])


@given(st.data())
def test_a_template_survives_any_arguments(data):
    from dq_fk_ros.messages import _cdr
    template = data.draw(st.sampled_from([pose_stamped_template('world'), _tf_template()]))
    buf = bytes(template.buf)
    slots = [at for at, _ in template.floats]
    victim = list(slots)
    args = [data.draw(st.sampled_from([buf, bytearray(buf), b'', b'\x00\x00\x00\x00',
                                       b'\x00\x01', 'text', None, memoryview(buf)[::2]])),
            data.draw(st.sampled_from([template.stamps, [], [0], [len(buf)], [-1], [2**62],
                                       ['x'], 5, None,
                                       [Mutator(4, victim.clear)]])),
            data.draw(st.sampled_from([victim, slots, [len(buf) - 56], [2**63 - 1], ['x'], None,
                                       [Mutator(slots[0], victim.clear)] + slots[1:]])),
            data.draw(st.sampled_from([7, 7, 0, 1, 65, -1, 2**62, Mutator(7, victim.clear)]))]
    made = attempt(_cdr.Template, *args)
    if made is None:
        made = _cdr.Template(buf, template.stamps, slots, 7)
    for _ in range(data.draw(st.integers(1, 4))):
        n = data.draw(st.sampled_from([0, 1, 3, 8]))
        values = data.draw(hostile_arrays(np.zeros((n, 7))))
        rows = list(range(min(n, len(slots)))) + data.draw(
            st.lists(st.sampled_from([0, 1, 2, -1, n, 2**62, 2**63 - 1, 'x', None]),
                     max_size=2))
        if data.draw(st.booleans()):
            rows = [Mutator(rows[0], rows.clear) if rows else Mutator(0, rows.clear)] + rows[1:]
        sec = data.draw(st.sampled_from([0, 1, -1, 2**31, -2**31, 2**64, 'x', 1.5,
                                         Mutator(1, rows.clear)]))
        nsec = data.draw(st.sampled_from([0, 999999999, -1, 2**32, 2**64, None]))
        method = data.draw(st.sampled_from(['one', 'each']))
        result = attempt(getattr(made, method), sec, nsec, values, rows)
        if method == 'one' and isinstance(result, bytes):
            assert len(result) == len(buf)
        if data.draw(st.booleans()):
            attempt(made.__init__, *args)
    again = _cdr.Template(buf, template.stamps, slots, 7)  # (made's slots: what it was given)
    assert len(again.one(1, 2, np.zeros((len(slots), 7)), list(range(len(slots))))) == len(buf)
    attempt(made.one, 1, 2, np.zeros((len(slots), 7)), list(range(len(slots))))


READER_PARTS = reader_arguments() if COMPILED is not None else ({}, b'')


@given(st.data())
def test_a_joint_state_reader_survives_any_arguments(data):
    from dq_fk_ros.messages import _cdr
    good, raw = READER_PARTS
    kwargs = dict(good)
    victim = list(good['order'])
    kwargs['order'] = victim
    for _ in range(data.draw(st.integers(0, 3))):
        field = data.draw(st.sampled_from(sorted(good)))
        kwargs[field] = data.draw(st.sampled_from([
            -1, 0, 4, 2**31, 2**62, 2**63 - 8, 2**63 - 1, None, 'x', b'', b'\xff' * 3,
            bytes(10**3), [], [0, 1], [0, 1, 2, 3], [-1, 0, 1], [2**62] * 3,
            [Mutator(0, victim.clear), 1, 2], Mutator(good[field], victim.clear)
            if isinstance(good[field], int) else good[field]]))
    made = attempt(_cdr.JointStateReader, **kwargs)
    if made is None:
        made = _cdr.JointStateReader(**good)
    for _ in range(data.draw(st.integers(1, 4))):
        dof = data.draw(st.sampled_from([3, 3, 0, 2, 4]))
        q = [0.0] * dof
        qdot = [0.0] * data.draw(st.sampled_from([dof, dof, 0, 5]))
        if data.draw(st.integers(0, 3)) == 0:   # aliasing: one list for both
            qdot = q
        if dof and data.draw(st.booleans()):
            at = data.draw(st.integers(0, dof - 1))
            q[at] = FloatWithDel(0.5, q)
        last = data.draw(st.sampled_from([None, 0, 10, -2**63, 2**63 - 1, 2**64, 'x',
                                          Mutator(5, q.clear), Mutator(5, qdot.clear),
                                          Mutator(5, lambda: made.__init__(**good))]))
        message = data.draw(st.sampled_from([raw, bytearray(raw), raw[:-1], raw + b'\x00',
                                             b'', bytes(len(raw)), 'text', None]))
        q_out = data.draw(hostile_arrays(np.zeros(3)))
        qdot_out = data.draw(st.one_of(hostile_arrays(np.zeros(3)), st.just('same')))
        if isinstance(qdot_out, str):
            qdot_out = q_out
        attempt(made.read, message, last, q, qdot, q_out, qdot_out)
    q, qdot = [0.0] * 3, [0.0] * 3
    out = np.empty(3)
    assert _cdr.JointStateReader(**good).read(raw, None, q, qdot, out, np.empty(3)) == 10
    assert q == [0.1, 0.2, 0.3]


try:
    from dq_fk_ros.storage import _mcap as MCAP
except ImportError:  # not built: nothing of it to fuzz
    MCAP = None
needs_mcap = pytest.mark.skipif(MCAP is None, reason='the C extension _mcap is not built')


def _records(data):
    """Draw the records of a chunk: messages, other records, cut or with a byte changed."""
    out = b''
    for _ in range(data.draw(st.integers(0, 6))):
        body = data.draw(st.binary(max_size=40))
        if data.draw(st.booleans()):
            body = bytes(data.draw(st.binary(min_size=22, max_size=22))) + body
        length = data.draw(st.sampled_from([len(body), len(body), 2**63, 2**64 - 1, 21,
                                            len(body) + 1]))
        out += bytes([data.draw(st.sampled_from([5, 5, 6, 0, 255]))]) + \
            (length % 2**64).to_bytes(8, 'little') + body
    return out[:data.draw(st.integers(0, len(out)))] if data.draw(st.booleans()) else out


@needs_mcap
@given(st.data())
def test_the_mcap_scan_and_gather_survive_any_arguments(data):
    records = _records(data)
    victim = bytearray(records)
    args = [data.draw(st.sampled_from([records, victim, memoryview(records)[::2], None, 'x'])),
            data.draw(st.sampled_from([b'\x01' * 65536, bytes(65536), bytes(10), None])),
            data.draw(st.sampled_from([-2**63, 0, 5, 2**63 - 1, 2**64, 'x',
                                       Mutator(0, victim.clear)])),
            data.draw(st.sampled_from([2**63 - 1, 0, -1, None, Mutator(9, victim.clear)]))]
    room = len(records) // 31 + 1
    for _ in range(4):
        args.append(data.draw(st.one_of(
            st.just(np.zeros(room, np.int64)), st.just(np.zeros(0, np.int64)),
            hostile_arrays(np.zeros(room)))))
    n = attempt(MCAP.scan, *args)
    if n is not None:
        assert 0 <= n <= room
    src = data.draw(st.sampled_from([records, victim, b'', None]))
    offsets = data.draw(st.one_of(
        st.lists(st.sampled_from([0, 1, 5, -1, 2**62, 2**63 - 1]), max_size=4).map(
            lambda x: np.array(x, np.int64)), hostile_arrays(np.zeros(2))))
    lengths = data.draw(st.one_of(
        st.lists(st.sampled_from([0, 1, 3, -1, 2**62, 2**63 - 1]), max_size=4).map(
            lambda x: np.array(x, np.int64)), hostile_arrays(np.zeros(2))))
    dst = data.draw(st.sampled_from([bytearray(8), bytearray(0), victim, b'read only', None,
                                     np.zeros(4, np.uint8)]))
    if data.draw(st.booleans()):   # aliasing: arguments sharing one buffer, overlapping
        shared = bytearray(data.draw(st.binary(min_size=64, max_size=64)))
        spans = np.ndarray((4,), np.int64, buffer=shared)
        spans[:] = data.draw(st.lists(st.sampled_from([0, 8, 16, 24, 2**62]), min_size=4,
                                      max_size=4))
        view = data.draw(st.sampled_from([0, 8, 16]))
        offsets = np.ndarray((2,), np.int64, buffer=shared, offset=view)
        lengths = np.ndarray((2,), np.int64, buffer=shared, offset=data.draw(
            st.sampled_from([0, 8, 16])))
        dsts = [shared, memoryview(shared)[8:], memoryview(shared)[:40], offsets, lengths]
        dst = dsts[data.draw(st.integers(0, len(dsts) - 1))]
        srcs = [shared, bytes(shared), memoryview(shared)[16:], src]
        src = srcs[data.draw(st.integers(0, len(srcs) - 1))]
    total = attempt(MCAP.gather, src, offsets, lengths, dst)
    if total is not None:
        assert 0 <= total <= (len(dst) if isinstance(dst, (bytes, bytearray)) else
                              memoryview(dst).nbytes)


@needs_mcap
@given(st.data())
def test_mcap_reserve_survives_any_arguments(data):
    """Only a file of the test's own, or no file, is handed over: never the run's streams."""
    with tempfile.TemporaryFile(dir=os.environ.get('TMPDIR', '/tmp')) as f:
        # (sizes a disk refuses at once, or small ones: nothing big is ever reserved)
        numbers = [0, 1, 4096, -1, 2**63 - 1, 2**63, -2**63, 2**64]
        fd = data.draw(st.sampled_from([f.fileno(), 2**31 - 1, 2**31, -1, 2**64, None, 1.0,
                                        'x', Mutator(f.fileno(), f.close)]))
        offset = data.draw(st.sampled_from(numbers + [2**62, None, 0.5, Mutator(0, f.close)]))
        length = data.draw(st.sampled_from(numbers + [b'1', Mutator(1, f.close)]))
        done = attempt(MCAP.reserve, fd, offset, length)
        assert done in (None, True, False)
        if not f.closed:
            assert os.fstat(f.fileno()).st_size == 0   # its size kept, whatever was reserved


@needs_mcap
@given(st.data())
def test_mcap_rows_survive_any_arguments(data):
    templates = [_tf_template(), pose_stamped_template('world')]
    good = ([1, 2], [bytes(t.buf) for t in templates], [t.stamps for t in templates],
            [[at for at, _ in t.floats] for t in templates], [7, 7])
    args = list(good)
    victim = list(good[0])
    args[0] = victim
    for _ in range(data.draw(st.integers(0, 3))):
        at = data.draw(st.integers(0, 4))
        args[at] = data.draw(st.sampled_from([
            [], [1], [1, 2, 3], [-1, 2], [2**16, 2], [b'', b'\x00\x01\x00\x00'], [None, None],
            [[4], [2**62]], [[-1], [4]], [[0, 1], []], [0, 7], [7, 65],
            [Mutator(1, victim.clear), 2], None, 'xy', 3]))
    made = attempt(MCAP.Rows, *args)
    if made is None:
        made = MCAP.Rows(*good)
    for _ in range(data.draw(st.integers(1, 4))):
        n = data.draw(st.sampled_from([0, 1, 3]))
        out = data.draw(st.sampled_from([np.zeros(n * made.row_bytes, np.uint8),
                                         bytearray(n * made.row_bytes), bytearray(3),
                                         b'\x00' * (n * made.row_bytes), None]))
        stamps = data.draw(st.one_of(st.just(np.full(n, -2**63, np.int64)),
                                     st.just(np.arange(n, dtype=np.int64) * 10**9 - 1),
                                     hostile_arrays(np.zeros(n))))
        times = data.draw(st.one_of(st.just(np.zeros(n, np.int64)), hostile_arrays(np.zeros(n))))
        values = [data.draw(hostile_arrays(np.zeros((n, 7 * k)))) for k in (2, 1)]
        if data.draw(st.booleans()):
            values = data.draw(st.sampled_from([values[:1], values + values, None, 'ab',
                                                [np.zeros((2**52, 0))] * 2]))
        attempt(made.fill, out, stamps, times, values)
        if data.draw(st.booleans()):
            attempt(made.__init__, *good)
    fresh = MCAP.Rows(*good)
    out = np.zeros(2 * fresh.row_bytes, np.uint8)
    fresh.fill(out, np.zeros(2, np.int64), np.zeros(2, np.int64),
               [np.zeros((2, 14)), np.zeros((2, 7))])
    assert out[0] == 5


@given(st.data())
def test_runs_survive_any_arguments(data):
    from dq_fk_ros.messages import _cdr
    victim = [0, 4]
    args = [data.draw(st.sampled_from([victim, [0], [], [-1], [2**62], ['x'], None, 7,
                                       [Mutator(3, victim.clear), 4]])),
            data.draw(st.sampled_from([[2, 3], [2], [0, 0], [-1, 1], [2**62, 1], None,
                                       [Mutator(2, victim.clear), 3]])),
            data.draw(st.sampled_from([b'abxyz', b'', b'ab', bytearray(b'abxyz'), 'text',
                                       None, memoryview(b'abxyz')[::2]]))]
    made = attempt(_cdr.Runs, *args)
    if made is None:
        made = _cdr.Runs([0, 4], [2, 3], b'abxyz')
    for _ in range(data.draw(st.integers(1, 4))):
        raw = data.draw(st.sampled_from([b'ab..xyz', b'ab..xy', b'', b'abab', None, 3,
                                         bytearray(b'ab..xyz'), np.zeros(9, np.uint8),
                                         memoryview(b'ab..xyz..')[::2]]))
        result = attempt(made.match, raw)
        assert result in (None, True, False)
        # the batch form: spans anywhere (negative, past the end, huge), odd arrays
        spans = data.draw(st.sampled_from([
            np.array([0, 2], np.int64), np.array([-1], np.int64), np.array([2**62], np.int64),
            np.array([2**63 - 1, 0], np.int64), np.zeros(0, np.int64), np.zeros(2, np.int32),
            np.zeros((2, 1), np.int64), np.arange(4, dtype=np.int64)[::2], [0, 1], None]))
        lengths = data.draw(st.sampled_from([
            np.array([7, 7], np.int64), np.array([2**63 - 1, 1], np.int64),
            np.array([-5], np.int64), np.zeros(2, np.int64), np.zeros(1, np.float64), 3]))
        size = data.draw(st.sampled_from([7, 0, -1, 2**62, 2**70, 'x', Mutator(7, victim.clear)]))
        many = attempt(made.match_many, raw, spans, lengths, size)
        assert many is None or (isinstance(many, bytes) and set(many) <= {0, 1})
        if data.draw(st.booleans()):
            attempt(made.__init__, *args)
    assert _cdr.Runs([0, 4], [2, 3], b'abxyz').match(b'ab..xyz') is True


# -- transforms/_tf: tf2's walk over BufferCore's caches ------------------------------------
class HostileCache:
    """A cache whose attributes are anything, and whose reading may change the caches list."""

    def __init__(self, static, parent, values, stamps, parents, start, victim=None):
        self._static, self._parent, self._values = static, parent, values
        self._stamps, self._parents, self._start, self._victim = stamps, parents, start, victim
        self.count = start

    def _hit(self):
        if self._victim is not None:
            self._victim.clear()   # the caches list emptied while it is read

    @property
    def static(self):
        self._hit()
        return self._static

    parent = property(lambda self: self._parent)
    values = property(lambda self: self._values)
    start = property(lambda self: self._start)

    @property
    def stamps(self):
        self._hit()
        return self._stamps

    parents = property(lambda self: self._parents)


@st.composite
def tf_caches(draw):
    """Draw a caches list of real caches, hostile ones and None, and how many frames."""
    from array import array
    from dq_fk_ros.transforms.edges import MovingEdge, StaticEdge
    n = draw(st.integers(1, 8))
    caches = [None]
    for k in range(1, n):
        kind = draw(st.sampled_from(['none', 'static', 'dynamic', 'hostile']))
        parent = draw(st.integers(0, n)) if draw(st.booleans()) else max(0, k - 1)
        if kind == 'none':
            caches.append(None)
        elif kind == 'static':
            caches.append(StaticEdge(parent, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)))
        elif kind == 'dynamic':
            cache = MovingEdge(10**9)
            for j in range(draw(st.integers(0, 4))):
                turn = draw(st.sampled_from([0.0, 1.0]))
                cache.insert(draw(st.integers(-5, 5)), parent,
                             (0.0, 1.0, 0.0, 0.0, 0.0, turn, 1.0))
            if draw(st.booleans()):
                cache.start = draw(st.sampled_from([-1, 0, 1, 3, 10, 2**62]))
            caches.append(cache)
        else:
            length = draw(st.sampled_from([0, 1, 2, 3]))
            stamps = draw(st.sampled_from([array('q', range(length)), array('d', [0.0] * length),
                                           array('i', range(length)), b'\x00' * 8, None,
                                           np.arange(length)[::-1], [1, 2]]))
            parents = draw(st.sampled_from([array('q', [1] * length),
                                            array('q', [1] * (length + 1)), 'x']))
            values = draw(st.sampled_from([array('d', [0.0] * (7 * length)),
                                           array('d', [0.0] * 6), (0.0,) * 7, (1,) * 7,
                                           (0.0,) * 6, None]))
            caches.append(HostileCache(
                draw(st.sampled_from([True, False, 1, None, Mutator(1, lambda: None)])),
                draw(st.sampled_from([1, -1, 2**70, 1.0, 'p', Mutator(1, lambda: None)])),
                values, stamps, parents,
                draw(st.sampled_from([0, -1, 1, 2**64, 1.5, None])),
                caches if draw(st.booleans()) else None))
    return caches, n


@given(st.data())
def test_the_tf_walk_survives_any_caches(data):
    from dq_fk_ros.transforms.buffer_core import COMPILED
    if COMPILED is None:
        pytest.fail('transforms/_tf is not built')
    caches, n = data.draw(tf_caches())
    ids = st.one_of(st.integers(-2, n + 2), st.sampled_from([2**63, -2**63, 1.0, None, 'a']))
    time = st.one_of(st.integers(-10, 10), st.sampled_from([2**63, -2**63 - 1, 0, 1.5, None]))
    attempt(COMPILED.lookup, caches, data.draw(ids), data.draw(ids), data.draw(time))
    attempt(COMPILED.lookup, data.draw(st.sampled_from([(), None, [1], caches])), 1, 2, 0)
    # many stamps: edges of any ids, any arrays, out/ok/stamps overlapping (one buffer)
    edges = st.lists(st.one_of(st.tuples(st.integers(-1, n + 1), st.integers(-1, n + 1)),
                               st.sampled_from([(1,), (1, 2, 3), 'ab', None, (1.0, 2)])),
                     max_size=4)
    count = data.draw(st.sampled_from([0, 1, 3, 8]))
    shared = np.zeros(8 * count + 8, np.uint8)
    stamps = data.draw(st.sampled_from([
        np.arange(count, dtype=np.int64), np.arange(count, dtype=np.int32),
        shared[:8 * count].view(np.int64) if count else np.zeros(0, np.int64),
        np.arange(2 * count, dtype=np.int64)[::2], None]))
    out = data.draw(st.sampled_from([
        np.zeros((count, 7)), np.zeros((count, 6)), np.zeros(count * 7, np.float32),
        shared[:8 * count].view(np.float64) if count else np.zeros(0), np.zeros((count, 7))[::-1],
        bytes(56 * count)]))
    ok = data.draw(st.sampled_from([np.zeros(count, np.uint8), shared[:count],
                                    np.zeros(count, np.int64), bytearray(count),
                                    np.zeros(count + 1, np.uint8)]))
    attempt(COMPILED.lookup_many, caches, data.draw(edges), data.draw(edges), stamps, out, ok)


@given(st.data())
def test_the_csv_writer_survives_any_arguments(data):
    from dq_fk_ros.transforms.buffer_core import COMPILED
    if COMPILED is None:
        pytest.fail('transforms/_tf is not built')
    stamps = data.draw(hostile_arrays(like=np.zeros(3)))
    if isinstance(stamps, np.ndarray) and stamps.dtype == np.float64 and data.draw(st.booleans()):
        stamps = stamps.astype(np.int64)
    poses = data.draw(hostile_arrays(like=np.zeros((3, 7))))
    attempt(COMPILED.csv_rows, stamps, poses)
    shared = np.zeros(64)
    attempt(COMPILED.csv_rows, shared[:8].view(np.int64), shared.reshape(8, 8)[:, :7].copy())
