"""
The compiled kernel equals the numpy reference on any DH chain, and refuses what it refuses.

The reference is a chain's numpy engine (``ReferenceEngine``...); hypothesis
draws chains (standard and modified, every row type, mimic rows, base and tool, degenerate
ones: prismatic only, fixed only, a base turned half a turn so that w = 0), joint values and
batches. The whole kinematics suite also runs with ``DQ_FK_PURE_PYTHON=1``
(scripts/run_tests), so both paths pass the same tests.
"""

from functools import partial
import math
import os
import subprocess
import sys

from dq_fk_ros.kinematics.chain_batches import (
    forward_all_batch_reference, forward_batch_reference)
from dq_fk_ros.kinematics.chain_engines import (
    CompiledEngine, kernel_chain_args, ReferenceEngine)
from dq_fk_ros.kinematics.chain_jacobians import jacobian_geometric_reference
from dq_fk_ros.kinematics.dh import DHJoint, KinematicChain
from dq_fk_ros.kinematics.dual_quaternion import DualQuaternion
from dq_fk_ros.kinematics.kernel import kernel_info
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

needs_kernel = pytest.mark.skipif(kernel_info()['active'] != 'c',
                                  reason='the numpy path is active: nothing to compare')
finite = st.floats(-3.0, 3.0, allow_nan=False)


@st.composite
def chains(draw):
    n = draw(st.integers(1, 7))
    kinds = draw(st.lists(st.sampled_from(['revolute', 'prismatic', 'cylindrical', 'fixed']),
                          min_size=n, max_size=n))
    rows = []
    for i, kind in enumerate(kinds):
        follows = ''
        earlier = [r.name for r in rows if r.joint_type in ('revolute', 'prismatic')
                   and not r.follows]
        if kind in ('revolute', 'prismatic') and earlier and draw(st.booleans()):
            follows = draw(st.sampled_from(earlier))
        rows.append(DHJoint(a=draw(finite), alpha=draw(finite), d=draw(finite),
                            theta=draw(finite), joint_type=kind, name=f'j{i}',
                            scale=draw(st.sampled_from([1.0, -1.0, 0.5])),
                            follows=follows))
    half_turn = draw(st.booleans())  # a base whose real part has w = 0
    base = DualQuaternion.from_rotation([0.0, 0.0, 1.0], math.pi) if half_turn else \
        DualQuaternion.from_pose(translation=[draw(finite), draw(finite), draw(finite)])
    tool = DualQuaternion.from_rotation([1.0, 0.0, 0.0], draw(finite)) \
        if draw(st.booleans()) else None
    return KinematicChain(rows, draw(st.sampled_from(['standard', 'modified'])), base, tool)


@needs_kernel
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(chains(), st.data())
def test_the_kernel_equals_the_numpy_reference_on_any_chain(chain, data):
    """The two engines of the same table, method by method; the chain runs the compiled one."""
    compiled, reference = CompiledEngine(chain.table), ReferenceEngine(chain.table)
    assert type(chain.engine) is CompiledEngine
    q = np.array(data.draw(st.lists(finite, min_size=chain.dof, max_size=chain.dof)))
    for method in ('frames', 'end', 'jacobian'):
        np.testing.assert_allclose(getattr(compiled, method)(q), getattr(reference, method)(q),
                                   rtol=0, atol=1e-12, err_msg=method)
    np.testing.assert_array_equal(chain.forward_all(q), compiled.frames(q))
    np.testing.assert_array_equal(chain.forward(q).coeffs, compiled.end(q))
    np.testing.assert_array_equal(chain.jacobian_geometric(q), compiled.jacobian(q))
    rows = data.draw(st.lists(st.lists(finite, min_size=chain.dof, max_size=chain.dof),
                              max_size=9))
    batch = np.array(rows, dtype=float).reshape(len(rows), chain.dof)
    for method in ('frames_batch', 'end_batch'):
        np.testing.assert_allclose(getattr(compiled, method)(batch),
                                   getattr(reference, method)(batch), rtol=0, atol=1e-12,
                                   err_msg=method)
    np.testing.assert_array_equal(chain.forward_all_batch(batch), compiled.frames_batch(batch))
    np.testing.assert_array_equal(chain.forward_batch(batch), compiled.end_batch(batch))


@needs_kernel
def test_fixed_only_and_prismatic_only_chains():
    fixed = KinematicChain([DHJoint(a=0.3, alpha=1.0, joint_type='fixed')] * 3)
    assert fixed.dof == 0
    np.testing.assert_array_equal(fixed.forward_all([]), ReferenceEngine(fixed.table).frames([]))
    assert fixed.forward_all_batch(np.zeros((4, 0))).shape == (4, 4, 8)
    slide = KinematicChain([DHJoint(d=0.1, joint_type='prismatic', name=f'p{i}')
                            for i in range(3)], 'modified')
    q = [0.1, -0.2, 0.3]
    np.testing.assert_array_equal(slide.forward_all(q), ReferenceEngine(slide.table).frames(q))


@needs_kernel
def test_bad_input_is_refused_as_the_numpy_path_refuses_it():
    chain = KinematicChain([DHJoint(a=0.2, name='a'), DHJoint(d=0.1, name='b')])
    for bad in ([0.1], [0.1, 0.2, 0.3], np.zeros((2, 1))):
        for path in (chain.forward_all, ReferenceEngine(chain.table).frames, chain.forward,
                     chain.jacobian_geometric, partial(jacobian_geometric_reference, chain.table)):
            with pytest.raises(ValueError, match='expected 2 joint values'):
                path(bad)
    with pytest.raises(ValueError):
        chain.forward_all(['x', 'y'])
    with pytest.raises(ValueError):
        ReferenceEngine(chain.table).frames(['x', 'y'])
    for bad in (np.zeros(2), np.zeros((3, 3))):
        for path in (chain.forward_all_batch, partial(forward_all_batch_reference, chain.table)):
            with pytest.raises(ValueError, match=r'expected an \(N, 2\) array'):
                path(bad)
    # NaN in, NaN out on both paths; non-contiguous and read-only inputs are taken
    assert np.isnan(chain.forward_all([math.nan, 0.0])).any()
    q = np.zeros((4, 4))[::2, ::2]
    q.setflags(write=False)
    np.testing.assert_array_equal(chain.forward_all_batch(q),
                                  forward_all_batch_reference(chain.table, q))
    np.testing.assert_array_equal(chain.forward_all(q[0]),
                                  ReferenceEngine(chain.table).frames(q[0]))


@needs_kernel
def test_the_kernel_chain_refuses_buffers_it_cannot_use():
    from dq_fk_ros.kinematics import _kernel
    chain = KinematicChain([DHJoint(a=0.2, name='a')])
    program, base, tool = kernel_chain_args(chain.table)[:3]
    rows = chain.table.jacobian_rows
    good_out = np.empty((2, 8))
    made = [
        (program[:, :5].copy(), base, tool, 1),      # not (n, 7)
        (program, base[:4].copy(), tool, 1),         # base not 8
        (np.full_like(program, np.nan), base, tool, 1),
        (program, base, tool, 0),                    # the program reads q[0]
        (program.astype(np.float32), base, tool, 1),
    ]
    for args in made:
        with pytest.raises(ValueError):
            _kernel.Chain(*args)
    for bad_rows in (rows[:, :2].copy(), np.array([[5.0, -1.0, 1.0]]), np.zeros((2, 3)),
                     np.array([[np.nan, -1.0, 1.0]])):
        with pytest.raises(ValueError):
            _kernel.Chain(program, base, tool, 1, bad_rows)
    kernel_chain = _kernel.Chain(program, base, tool, 1, rows)
    calls = [
        (np.zeros(1, np.float32), good_out),      # wrong dtype
        (np.zeros(1), np.empty((3, 8))),          # wrong size
        (np.zeros(1), np.empty((2, 8))[:, ::2]),  # not contiguous
        (np.zeros(0), good_out),                  # too few joint values
    ]
    for args in calls:
        with pytest.raises(ValueError):
            kernel_chain.frames(*args)
    with pytest.raises(ValueError, match='q must be 1 joint values'):
        kernel_chain.frames(np.zeros(2), good_out)
    read_only = np.empty((2, 8))
    read_only.setflags(write=False)
    with pytest.raises(ValueError, match='writable'):
        kernel_chain.frames(np.zeros(1), read_only)
    with pytest.raises(TypeError):
        kernel_chain.frames(program)
    with pytest.raises(ValueError):
        kernel_chain.jacobian(np.zeros(1), np.empty((5, 1)))
    with pytest.raises(ValueError, match='without rows'):
        _kernel.Chain(program, base, tool, 1).jacobian(np.zeros(1), np.empty((6, 1)))


def test_a_chain_pickles_and_computes_the_same_after():
    import pickle
    chain = KinematicChain([DHJoint(a=0.2, alpha=0.5, name='a'), DHJoint(d=0.1, name='b',
                                                                         joint_type='prismatic')])
    again = pickle.loads(pickle.dumps(chain))
    np.testing.assert_array_equal(again.forward_all([0.3, 0.2]), chain.forward_all([0.3, 0.2]))


@needs_kernel
def test_the_kernel_chain_is_set_once():
    """A second __init__ is refused and changes nothing; __new__ alone checks everything."""
    from dq_fk_ros.kinematics import _kernel
    chain = KinematicChain([DHJoint(a=0.2, name='a')])
    program, base, tool = kernel_chain_args(chain.table)[:3]
    kernel_chain = _kernel.Chain(program, base, tool, 1)
    with pytest.raises(TypeError, match='set once'):
        kernel_chain.__init__(program[:0].copy(), base, None, 0)
    out = np.empty((2, 8))
    kernel_chain.frames(np.zeros(1), out)
    np.testing.assert_array_equal(out, ReferenceEngine(chain.table).frames([0.0]))
    with pytest.raises(TypeError):
        _kernel.Chain.__new__(_kernel.Chain)  # no state without its arguments
    made = _kernel.Chain.__new__(_kernel.Chain, program, base, tool, 1)  # no __init__ needed
    made.frames(np.zeros(1), out)
    np.testing.assert_array_equal(out, ReferenceEngine(chain.table).frames([0.0]))
    with pytest.raises(TypeError):
        kernel_chain.end(np.zeros(1))


def test_dq_fk_pure_python_forces_the_numpy_path():
    code = ('import dq_fk_ros; i = dq_fk_ros.kernel_info(); print(i["active"], i["why"])')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, env=dict(os.environ, DQ_FK_PURE_PYTHON='1')).stdout
    assert out.split()[0] == 'numpy' and 'DQ_FK_PURE_PYTHON=1' in out, out


def test_batches_fill_the_callers_buffers():
    chain = KinematicChain([DHJoint(a=0.2, alpha=0.5, name='a'), DHJoint(d=0.1, name='b')])
    q = np.random.default_rng(3).uniform(-2, 2, (5, 2))
    out = np.full((5, 8), np.nan)
    assert chain.forward_batch(q, out=out) is out
    np.testing.assert_allclose(out, forward_batch_reference(chain.table, q), rtol=0, atol=1e-12)
    frames = np.full((5, chain.n_frames, 8), np.nan)
    assert chain.forward_all_batch(q, out=frames) is frames
    np.testing.assert_allclose(frames, forward_all_batch_reference(chain.table, q), rtol=0,
                               atol=1e-12)
    for bad in (np.empty((4, 8)), np.empty((5, 8), np.float32), np.empty((5, 16))[:, ::2]):
        with pytest.raises(ValueError):
            chain.forward_batch(q, out=bad)


@pytest.mark.parametrize('pure', ['', '1'])
def test_dq_fk_list_verbose_says_which_paths_run(pure):
    from importlib.util import find_spec
    out = subprocess.run([sys.executable, '-m', 'dq_fk_ros.cli.dq_fk', 'list', '--verbose'],
                         capture_output=True, text=True, check=True,
                         env=dict(os.environ, DQ_FK_PURE_PYTHON=pure)).stdout.splitlines()
    fk = next(line for line in out if line.startswith('FK kernel: '))
    cdr = next(line for line in out if line.startswith('CDR writer and JointState reader'))
    if pure:
        assert 'numpy: DQ_FK_PURE_PYTHON=1' in fk and 'python: DQ_FK_PURE_PYTHON=1' in cdr
    else:
        # (this process may run with DQ_FK_PURE_PYTHON=1: ask whether they are built)
        assert (' c: ' in fk) == (find_spec('dq_fk_ros.kinematics._kernel') is not None)
        assert (' c: ' in cdr) == (find_spec('dq_fk_ros.messages._cdr') is not None)
