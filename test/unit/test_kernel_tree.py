"""
The compiled kernel's tree (``_kernel.Model``) equals the general path on any robot.

The reference is :meth:`RobotModel.frame_poses_general` (plain Python floats, looping over
the chains and links). Hypothesis writes robot description files: trees of chains hanging
from any earlier frame (every row type, mimic rows, tools or none, a frame 0 turned half a
turn so that w = 0), links fixed or moving (a joint of their own or a mimic, revolute or
prismatic) under any earlier frame with any earlier TF parent. Every URDF of
example-robot-data is checked too. On the numpy path (``DQ_FK_PURE_PYTHON=1``)
``frame_pose_arrays`` is the straight-line code, held to the same reference.
"""

import glob
import math
import os
import sysconfig

from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.description.schema import parse_robot_description
from dq_fk_ros.kinematics.kernel import kernel_info
from dq_fk_ros.kinematics.tree_engines import ReferenceTreeEngine
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
import yaml

finite = st.floats(-3.0, 3.0, allow_nan=False)
needs_kernel = pytest.mark.skipif(kernel_info()['active'] != 'c',
                                  reason='the numpy path is active: nothing to compare')


@st.composite
def robot_files(draw):
    """Return the text of a random tree robot description (metres, radians)."""
    frames, joints = ['world'], {'revolute': [], 'prismatic': []}
    chains = []
    for c in range(draw(st.integers(1, 4))):
        parent = draw(st.sampled_from(frames))
        half_turn = draw(st.booleans())
        base = {'frame': f'c{c}_base', 'rpy': [0.0, 0.0, math.pi] if half_turn else
                [draw(finite), draw(finite), draw(finite)],
                'xyz': [draw(finite), draw(finite), draw(finite)]}
        frames.append(base['frame'])
        rows = []
        for i in range(draw(st.integers(1, 4))):
            kind = draw(st.sampled_from(['revolute', 'prismatic', 'cylindrical', 'fixed']))
            row = {'frame': f'c{c}_f{i}', 'type': kind, 'theta': draw(finite),
                   'd': draw(finite), 'a': draw(finite), 'alpha': draw(finite)}
            if kind in joints and joints[kind] and draw(st.booleans()):
                row['mimic'] = {'joint': draw(st.sampled_from(joints[kind])),
                                'multiplier': draw(st.sampled_from([1.0, -1.0, 0.5]))}
            elif kind != 'fixed':
                row['joint'] = f'c{c}_j{i}'
                if kind == 'cylindrical':
                    row['d_joint'] = f'c{c}_j{i}_d'
                if kind in joints:
                    joints[kind].append(row['joint'])
            rows.append(row)
            frames.append(row['frame'])
        chain = {'parent': parent, 'base': base, 'chain': rows}
        if draw(st.booleans()):
            chain['tool'] = {'frame': f'c{c}_tool', 'xyz': [draw(finite), 0.0, draw(finite)],
                             'rpy': [draw(finite), 0.0, 0.0]}
            frames.append(chain['tool']['frame'])
        chains.append(chain)
    links = []
    for k in range(draw(st.integers(0, 5))):
        link = {'frame': f'link{k}', 'parent': draw(st.sampled_from(frames)),
                'tf_parent': draw(st.sampled_from(frames)),
                'xyz': [draw(finite), draw(finite), draw(finite)],
                'rpy': [draw(finite), draw(finite), draw(finite)],
                'type': draw(st.sampled_from(['fixed', 'revolute', 'prismatic']))}
        if link['type'] != 'fixed':
            link['axis'] = [draw(finite), draw(finite), 1.0]
            sources = joints[link['type']]
            if sources and draw(st.booleans()):
                link['mimic'] = {'joint': draw(st.sampled_from(sources)),
                                 'multiplier': draw(st.sampled_from([1.0, -2.0])),
                                 'offset': draw(finite)}
            else:
                link['joint'] = f'link{k}_joint'
        links.append(link)
        frames.append(link['frame'])
    return yaml.safe_dump({'robot': 'drawn', 'convention': draw(st.sampled_from(
        ['standard', 'modified'])), 'units': {'length': 'm', 'angle': 'rad'},
        'fixed_frame': 'world', 'chains': chains, 'links': links})


def assert_equals_the_general_path(model, q):
    absolute, relative = model.frame_poses_general(q)
    fast_absolute, fast_relative = model.frame_pose_arrays(q)
    np.testing.assert_allclose(fast_absolute, np.array(absolute), rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast_relative, np.array(relative).reshape(-1, 7), rtol=0,
                               atol=1e-12)
    np.testing.assert_array_equal(model.transform_pose_array(q), fast_relative)
    # forward_all: the same frames as coefficients (w >= 0; either sign where w = 0)
    coeffs = model.forward_all(q)
    assert coeffs.shape == (len(model.frame_names), 8) and (coeffs[:, 0] >= 0).all()
    w, x, y, z, dw, dx, dy, dz = coeffs.T
    position = 2.0 * np.stack([dx * w - dw * x - dy * z + dz * y,
                               dy * w - dw * y + dx * z - dz * x,
                               dz * w - dw * z - dx * y + dy * x], axis=1)
    np.testing.assert_allclose(position, np.array(absolute)[:, :3], rtol=0, atol=1e-12)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(robot_files(), st.data())
def test_the_model_kernel_equals_the_general_path(text, data):
    model = parse_robot_description(text)
    q = np.array(data.draw(st.lists(finite, min_size=model.dof, max_size=model.dof)))
    assert_equals_the_general_path(model, q)


def example_robot_data_urdfs():
    root = os.path.join(sysconfig.get_paths()['purelib'], 'cmeel.prefix', 'share',
                        'example-robot-data', 'robots')
    return sorted(glob.glob(os.path.join(root, '**', '*.urdf'), recursive=True))


def test_every_vendor_urdf_equals_the_general_path():
    files = example_robot_data_urdfs()
    assert len(files) > 60, 'example-robot-data is a test requirement'
    rng = np.random.default_rng(7)
    checked = 0
    for path in files:
        with open(path, encoding='utf-8') as f:
            if '<link' not in f.read():  # a xacro include saved as .urdf (ur3.urdf)
                continue
        model = load_robot(path).model
        for q in rng.uniform(-2.0, 2.0, size=(3, model.dof)):
            assert_equals_the_general_path(model, q)
        checked += 1
    assert checked > 60


@needs_kernel
def test_bad_input_is_refused_as_the_numpy_path_refuses_it():
    model = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())
    for bad in ([0.1], np.zeros(model.dof + 1), np.zeros((2, model.dof))):
        for path in (model.frame_pose_arrays, model.frame_poses, model.transform_pose_array,
                     model.forward_all):
            with pytest.raises(ValueError, match=f'expected {model.dof} joint values'):
                path(bad)
    with pytest.raises(ValueError):
        model.frame_pose_arrays(['x'] * model.dof)
    with pytest.raises(ValueError):
        model.frame_poses(['x'] * model.dof)
    # lists, other dtypes, non-contiguous and read-only q are taken; NaN in, NaN out
    q = np.zeros((model.dof, 2))[:, 0]
    q.setflags(write=False)
    reference = np.array(model.frame_poses_general(q)[0])
    for given_q in (q, q.tolist(), q.astype(np.float32)):
        np.testing.assert_array_equal(model.frame_pose_arrays(given_q)[0], reference)
    assert np.isnan(model.frame_pose_arrays([math.nan] * model.dof)[0]).any()
    # the caller's buffers: the right size, float64, C-contiguous and writable, or refused
    n, r = len(model.frame_names), model.n_transforms
    read_only = np.empty((n, 7))
    read_only.setflags(write=False)
    for absolute, relative in ((np.empty((n - 1, 7)), np.empty((r, 7))),
                               (np.empty((n, 7)), np.empty((r, 7), np.float32)),
                               (np.empty((n, 14))[:, ::2], np.empty((r, 7))),
                               (read_only, np.empty((r, 7)))):
        with pytest.raises(ValueError):
            model.frame_pose_arrays(np.zeros(model.dof), absolute, relative)


@needs_kernel
def test_the_kernel_model_refuses_what_it_cannot_use():
    from dq_fk_ros.kinematics import _kernel
    model = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())
    kernel = model.kinematics.engine.model
    assert (kernel.n_frames, kernel.n_relative) == (len(model.frame_names), model.n_transforms)
    chain = model.chain
    good = (chain.engine.kernel_chain, -1, np.array([0.0]),
            np.array(chain.table.pose_rows, dtype=float).reshape(-1, 10), True)
    no_links = np.zeros((0, 17))
    _kernel.Model([good], no_links, 1)
    link = np.array([[0.0, -1.0, 1, 0, 0, 0, 0, 0, 0, 0, 0.0, 0, 0, 1, 0.0, 1.0, 0.0]])
    _kernel.Model([good], link, 1)
    bad_cases = [
        ([], no_links, 1),                                              # no chain
        ([good[:1] + (5,) + good[2:]], no_links, 1),                    # parent not yet made
        ([good[:2] + (np.array([3.0]),) + good[3:]], no_links, 1),      # q index past q
        ([good[:2] + (np.array([0.5]),) + good[3:]], no_links, 1),      # not an index
        ([good[:3] + (np.zeros((1, 9)),) + good[4:]], no_links, 1),     # rows not (m, 10)
        ([good], np.zeros((1, 16)), 1),                                 # links not (n, 17)
        ([good], np.where(np.arange(17) == 0, 9.0, link), 1),           # attached to later
        ([good], np.where(np.arange(17) == 10, 2.0, link), 1),          # no such motion
        ([good], np.where(np.arange(17) == 14, 4.0, link), 1),          # joint past q
        ([('not a chain',) + good[1:]], no_links, 1),
    ]
    for args in bad_cases:
        with pytest.raises((ValueError, TypeError)):
            _kernel.Model(*args)
    with pytest.raises(TypeError):
        _kernel.Model.__new__(_kernel.Model)  # no state without its arguments
    made = _kernel.Model([good], no_links, 1)
    with pytest.raises(TypeError, match='set once'):  # a second __init__ changes nothing
        made.__init__([], no_links, 1)
    relative = np.empty((1, 7))
    made.poses(np.zeros(1), None, relative)
    with pytest.raises(TypeError):
        kernel.poses(np.zeros(model.dof))


def test_a_model_pickles_and_computes_the_same_after():
    import pickle
    model = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())
    q = np.linspace(-1.0, 1.0, model.dof)
    before = model.frame_pose_arrays(q)
    model.frame_poses(q)  # its straight-line code made (a function: not pickled)
    model.chain.frame_poses(q[:model.chain.dof])
    again = pickle.loads(pickle.dumps(model))
    for a, b in zip(again.frame_pose_arrays(q), before):
        np.testing.assert_array_equal(a, b)


def same_rotations(a, b):
    """Return ``b`` with each quaternion's sign taken from ``a`` where ``qw`` is 0 (q ~ -q)."""
    flip = (a[..., 6] == 0.0) & (np.sign(a[..., 3:6]) != np.sign(b[..., 3:6])).any(axis=-1)
    b = b.copy()
    b[..., 3:][flip] *= -1.0
    return b


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(robot_files(), st.data())
def test_batches_equal_the_numpy_batch(text, data):
    model = parse_robot_description(text)
    rows = data.draw(st.lists(st.lists(finite, min_size=model.dof, max_size=model.dof),
                              max_size=6))
    q = np.array(rows, dtype=float).reshape(len(rows), model.dof)
    absolute, relative = model.frame_pose_arrays_batch(q)
    ref_absolute, ref_relative = model.kinematics.frame_pose_arrays_batch_reference(q)
    assert absolute.shape == (len(q), len(model.frame_names), 7)
    assert relative.shape == (len(q), model.n_transforms, 7)
    np.testing.assert_allclose(absolute, same_rotations(absolute, ref_absolute), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(relative, same_rotations(relative, ref_relative), rtol=0,
                               atol=1e-12)
    for k in range(len(q)):  # and configuration by configuration, the single call
        single = model.frame_pose_arrays(q[k])
        np.testing.assert_allclose(absolute[k], same_rotations(absolute[k], single[0]),
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(relative[k], same_rotations(relative[k], single[1]),
                                   rtol=0, atol=1e-12)


def test_a_batch_refuses_what_the_numpy_batch_refuses():
    model = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())
    for bad in (np.zeros(model.dof), np.zeros((2, model.dof + 1)), np.zeros((2, 2, 2))):
        for path in (model.frame_pose_arrays_batch,
                     model.kinematics.frame_pose_arrays_batch_reference):
            with pytest.raises(ValueError, match=rf'expected an \(N, {model.dof}\) array'):
                path(bad)
    empty = model.frame_pose_arrays_batch(np.zeros((0, model.dof)))
    assert empty[0].shape == (0, len(model.frame_names), 7)
    q = np.zeros((6, model.dof * 2))[::2, ::2]  # not contiguous: copied, then taken
    np.testing.assert_array_equal(model.frame_pose_arrays_batch(q)[0],
                                  model.frame_pose_arrays_batch(q.copy())[0])


@pytest.mark.parametrize('compiled', [True, False])
def test_a_batch_into_kept_arrays_equals_a_fresh_one(compiled, monkeypatch):
    """The bag tool's reused FK arrays: the first N rows written, the rest left alone."""
    model = parse_robot_description(open('config/dual_arm.yaml', encoding='utf-8').read())
    if not compiled:
        tree = model.kinematics
        monkeypatch.setattr(tree, 'engine', ReferenceTreeEngine(
            tree.layout, tree.frame_poses, tree.transform_poses))
    rng = np.random.default_rng(7)
    kept = (np.full((5, len(model.frame_names), 7), 7.0),
            np.full((5, model.n_transforms, 7), 7.0))
    fresh = []
    for n in (5, 3):  # a full batch, then a shorter last one
        q = rng.uniform(-2, 2, (n, model.dof))
        absolute, relative = model.frame_pose_arrays_batch(q, kept)
        fresh.append(model.frame_pose_arrays_batch(q))
        assert absolute.base is kept[0] and relative.base is kept[1]
        np.testing.assert_array_equal(absolute, fresh[-1][0])
        np.testing.assert_array_equal(relative, fresh[-1][1])
    np.testing.assert_array_equal(kept[0][3:], fresh[0][0][3:])
    for bad in ((kept[0][:2], kept[1]), (kept[0], kept[1][:, :-1]),
                (kept[0].astype(np.float32), kept[1]), (kept[0][:, ::-1], kept[1])):
        with pytest.raises(ValueError, match='out: .* must be a writable C-contiguous'):
            model.frame_pose_arrays_batch(np.zeros((3, model.dof)), bad)
