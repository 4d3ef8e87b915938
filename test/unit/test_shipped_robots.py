"""Every robot shipped in config/ against numbers from its source."""

import math
import os

from dq_fk_ros.description.schema import load_robot_description
from dq_fk_ros.description.shipped import shipped_robot_path, shipped_robots
from dq_fk_ros.kinematics.dh import homogeneous_from_dq
import homogeneous as hm
import numpy as np
import pytest

DEG = math.pi / 180.0


def robot(name):
    return load_robot_description(shipped_robot_path(name))


def test_the_library_is_complete():
    assert set(shipped_robots()) >= {'rl15', 'puma560', 'anthropomorphic_arm', 'rrc',
                                     'human_centrifuge', 'ur5e', 'panda'}


@pytest.mark.parametrize('name', ['rl15', 'puma560', 'anthropomorphic_arm', 'rrc',
                                  'human_centrifuge', 'ur5e', 'panda'])
def test_shipped_files_load_and_every_frame_matches_matrices(name):
    """The YAML model's frames equal the 4x4 reference built from the file's own rows."""
    model = robot(name)
    assert len(model.frame_names) == model.chain.n_frames
    assert model.parent_frames[0] == model.fixed_frame
    rng = np.random.default_rng(4)
    step = hm.dh_standard if model.chain.convention == 'standard' else hm.dh_modified
    for q in rng.uniform(-2, 2, size=(50, model.chain.dof)):
        value = dict(zip(model.joint_names, q))
        acc = model.chain.base.to_matrix()
        frames = homogeneous_from_dq(model.chain.forward_all(q))
        np.testing.assert_allclose(frames[0], acc, atol=1e-12)
        for i, j in enumerate(model.chain.joints):
            # the row's DH values at q, read from the row itself (not the chain's index map)
            theta = j.theta + (j.scale * value[j.name]
                               if j.joint_type in ('revolute', 'cylindrical') else 0.0)
            d = j.d + (j.scale * value[j.d_name if j.joint_type == 'cylindrical' else j.name]
                       if j.joint_type in ('prismatic', 'cylindrical') else 0.0)
            acc = acc @ step(theta, d, j.a, j.alpha)
            np.testing.assert_allclose(frames[i + 1], acc, atol=1e-12)


@pytest.mark.parametrize('name', shipped_robots())
def test_the_nodes_frame_poses_are_the_general_path_to_the_bit(name):
    """The unrolled frame_poses the node publishes from: the looping path's exact floats."""
    chain = robot(name).chain
    for q in np.random.default_rng(6).uniform(-3, 3, size=(300, chain.dof)):
        assert chain.frame_poses(q) == chain.frame_poses_general(q)


def test_rl15_is_the_papers_robot_with_its_frame_names():
    model = robot('rl15')
    assert model.frame_names[-1] == 'eeCarry_seg6'
    assert model.parent_frames[-1] == 'wrist_seg5'
    pose = model.chain.forward(np.zeros(6)).to_pose_xyzw()
    np.testing.assert_allclose(pose[:3], [1.025, 0, 1.445], atol=1e-12)
    np.testing.assert_allclose(pose[3:], [0.707107, 0, 0.707107, 0], atol=5e-7)


def test_puma560_matches_corke():
    """Corke, Robotics Vision and Control: fkine(qz) and fkine(qn) with frame 0 at the shoulder."""
    model = robot('puma560')
    np.testing.assert_allclose(model.chain.forward(np.zeros(6)).translation,
                               [0.4521, -0.1500, 0.4318], atol=1e-3)
    qn = np.array([0, 45, 180, 0, 45, 0]) * DEG
    np.testing.assert_allclose(model.chain.forward(qn).translation, [0.5963, -0.1501, -0.0144],
                               atol=1e-4)
    np.testing.assert_allclose(np.degrees(model.limits[1]), [-45, 225])


@pytest.mark.parametrize('q_deg, xyz_mm', [
    ((45, 0, 0, 0, 0, 0), (35.3553, 35.3553, -50.0000)),
    ((30, 30, 30, 22.8, 3.6, 0.5), (75.7150, 43.1522, 1.0223)),
    ((12, 77.12, 0, 89.9, 1.3, 163), (58.6684, 12.0065, 37.5984)),
    ((125, 160, 90, 8.1, 78.5, 23), (51.3364, -68.5015, 10.4925)),
])
def test_anthropomorphic_arm_examples(q_deg, xyz_mm):
    model = robot('anthropomorphic_arm')
    np.testing.assert_allclose(model.chain.forward(np.radians(q_deg)).translation * 1000.0,
                               xyz_mm, atol=5e-5)


def test_rrc_eq_5():
    model = robot('rrc')
    l1, l2 = 0.4, 0.3
    assert model.joint_names == ('theta_1', 'theta_2', 'theta_3', 'd_3')
    for t1, t2, t3, d3 in np.random.default_rng(3).uniform(-3, 3, size=(100, 4)):
        c, s = math.cos(t1 + t2 - t3), math.sin(t1 + t2 - t3)
        expected = [[c, s, 0, l1 * math.cos(t1) + l2 * math.cos(t1 + t2)],
                    [s, -c, 0, l1 * math.sin(t1) + l2 * math.sin(t1 + t2)],
                    [0, 0, -1, -d3], [0, 0, 0, 1]]
        np.testing.assert_allclose(model.chain.forward([t1, t2, t3, d3]).to_matrix(), expected,
                                   atol=1e-12)


def test_human_centrifuge_eqs_63_and_72():
    model = robot('human_centrifuge')
    a1 = 8.0
    for q1, q2, q3 in np.random.default_rng(63).uniform(-3, 3, size=(200, 3)):
        c1, s1, c2, s2, c3, s3 = (math.cos(q1), math.sin(q1), math.cos(q2), math.sin(q2),
                                  math.cos(q3), math.sin(q3))
        r63 = [[c1 * c2, -s1 * c3 - c1 * s2 * s3, s1 * s3 - c1 * s2 * c3],
               [s1 * c2, c1 * c3 - s1 * s2 * s3, -c1 * s3 - s1 * s2 * c3],
               [s2, c2 * s3, c2 * c3]]
        m = model.chain.forward([q1, q2, q3]).to_matrix()
        np.testing.assert_allclose(m[:3, :3], r63, atol=1e-12)
        np.testing.assert_allclose(m[:3, 3], [a1 * c1, a1 * s1, 0], atol=1e-12)


def test_ur5e_zero_pose():
    """At zero the flange is at (a2 + a3, -(d4 + d6), d1 - d5) of UR's published table."""
    model = robot('ur5e')
    np.testing.assert_allclose(model.chain.forward(np.zeros(6)).translation,
                               [-0.425 - 0.3922, -(0.1333 + 0.0996), 0.1625 - 0.0997],
                               atol=1e-12)


def test_panda_zero_pose_flange():
    """Franka's zero pose: flange at x = 0.088, z = 0.333 + 0.316 + 0.384 - 0.107, facing down."""
    model = robot('panda')
    m = model.chain.forward(np.zeros(7)).to_matrix()
    np.testing.assert_allclose(m[:3, 3], [0.088, 0, 0.926], atol=1e-12)
    np.testing.assert_allclose(m[:3, 2], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(model.limits[3], [-3.0718, -0.0698])


def test_a_pip_install_finds_its_robots_in_the_environments_data_folder(tmp_path, monkeypatch):
    """``pip install`` (not editable) puts config/ under ``<prefix>/share/dq_fk_ros``."""
    import sysconfig

    from dq_fk_ros.description import shipped
    folder = tmp_path / 'share' / 'dq_fk_ros' / 'config'
    folder.mkdir(parents=True)
    (folder / 'only_installed.yaml').write_text('robot: {}\n')
    monkeypatch.setattr(sysconfig, 'get_path', lambda name: str(tmp_path))
    monkeypatch.setenv('AMENT_PREFIX_PATH', '')
    assert shipped.shipped_robot_path('only_installed') == str(folder / 'only_installed.yaml')
    candidates = shipped.share_folders('web')
    assert candidates[0] == str(tmp_path / 'share' / 'dq_fk_ros' / 'web')
    # the source tree (an editable install) stays the last candidate
    assert candidates[-1].endswith(os.path.join('', 'web')) and 'share' not in candidates[-1]
