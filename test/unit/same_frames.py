"""A tests' helper: two robot models give the same frames (a conversion's round trip)."""

from dq_fk_ros.kinematics.dh import homogeneous_from_dq
import numpy as np


def assert_same_frames(original, again, qs, atol=1e-12):
    """
    Every frame of model ``original`` is the same in ``again`` at the configurations ``qs``.

    ``qs`` are in ``original``'s joint order; ``again`` may order its joints otherwise.
    """
    assert sorted(again.joint_names) == sorted(original.joint_names)
    before = homogeneous_from_dq(original.forward_all_batch(qs))
    after = homogeneous_from_dq(again.forward_all_batch(
        qs[:, [original.joint_names.index(n) for n in again.joint_names]]))
    for k, frame in enumerate(original.frame_names):
        np.testing.assert_allclose(after[:, again.frame_names.index(frame)], before[:, k],
                                   rtol=0, atol=atol, err_msg=frame)
    return before
