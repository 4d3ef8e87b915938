"""Twists of frames moving with a chain's end: the batch is the single form; the poses' rate."""

from dq_fk_ros.description.loading import load_robot
from dq_fk_ros.kinematics.twists import frame_twists, frame_twists_batch
import numpy as np
import pytest


def rotation(pose):
    """Return the rotation matrix of ``(x, y, z, qx, qy, qz, qw)``."""
    x, y, z, w = pose[3:]
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize('robot', ['rl15', 'ur5e', 'puma560'])
def test_twists_are_the_rate_of_the_frames_poses_and_the_batch_is_the_single_form(robot):
    model = load_robot(robot).model
    chain, dof = model.chain, model.chain.dof
    end = model.n_chain_frames - 1
    frames = list(range(1, model.n_chain_frames))   # every frame moving with some joint
    rng = np.random.default_rng(3)
    q, qdot = rng.uniform(-1, 1, (5, model.dof)), rng.uniform(-1, 1, (5, model.dof))
    absolute = np.array([model.frame_pose_arrays(row)[0] for row in q])
    batch = frame_twists_batch(chain, q[:, :dof], qdot[:, :dof], absolute[:, end, :3],
                               absolute[:, frames, :3])
    h = 1e-6
    for i in range(len(q)):
        single = frame_twists(chain, q[i, :dof], qdot[i, :dof], absolute[i, end, :3],
                              absolute[i, frames, :3])
        assert single.tobytes() == batch[i].tobytes()   # the same arithmetic, row by row
        # the frames that move with the end (the end itself here) by central differences
        ahead = model.frame_pose_arrays(q[i] + h * qdot[i])[0]
        behind = model.frame_pose_arrays(q[i] - h * qdot[i])[0]
        v = (ahead[end, :3] - behind[end, :3]) / (2 * h)
        turn = rotation(ahead[end]) @ rotation(behind[end]).T   # exp([w] 2h)
        w = np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0],
                      turn[1, 0] - turn[0, 1]]) / (4 * h)
        k = frames.index(end)
        np.testing.assert_allclose(single[k, :3], v, atol=1e-7)
        np.testing.assert_allclose(single[k, 3:], w, atol=1e-7)


def test_a_point_off_the_end_moves_with_it():
    """A point fixed to the end frame: its velocity is the rate of its position."""
    model = load_robot('rl15').model
    chain, end = model.chain, model.n_chain_frames - 1
    q, qdot = np.full(chain.dof, 0.3), np.linspace(-1, 1, chain.dof)
    offset = np.array([0.1, -0.2, 0.3])   # in the end frame

    def point(at):
        pose = model.frame_pose_arrays(at)[0][end]
        return pose[:3] + rotation(pose) @ offset, pose[:3]
    p, p_end = point(q)
    h = 1e-6
    rate = (point(q + h * qdot)[0] - point(q - h * qdot)[0]) / (2 * h)
    twist = frame_twists(chain, q, qdot, p_end, p[None, :])[0]
    np.testing.assert_allclose(twist[:3], rate, atol=1e-7)
