"""Pinocchio as an independent URDF oracle for the tests (a test-only dependency)."""

import numpy as np
import pinocchio as pin


def urdf_model(urdf_text, mimic=False):
    """Build a pinocchio model of a URDF text (urdfdom's parser, as ROS uses)."""
    return pin.buildModelFromXML(urdf_text, mimic=mimic) if mimic else \
        pin.buildModelFromXML(urdf_text)


def configuration(model, values):
    """
    Return pinocchio's ``q`` for joint values by URDF joint name.

    A continuous joint is ``(cos, sin)`` in pinocchio; a joint missing from ``values`` (a
    mimic joint in a model built without mimic support) takes ``values[name]`` from the
    caller's mapping anyway, so pass every joint.
    """
    q = pin.neutral(model)
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        name = model.names[joint_id]
        if name not in values:
            continue
        value = values[name]
        if joint.nq == 0:  # a mimic joint (mimic=True): pinocchio moves it with its joint
            continue
        if joint.nq == 1:
            q[joint.idx_q] = value
        elif joint.nq == 2:  # continuous: cos, sin
            q[joint.idx_q], q[joint.idx_q + 1] = np.cos(value), np.sin(value)
        else:
            raise AssertionError(f'unexpected joint {name} with nq {joint.nq}')
    return q


_last_data = [None, None]   # (model, its Data): a Data costs more than the FK of 100 links


def link_placements(model, q, links):
    """Return ``{link: 4x4}`` of each link's frame in the root, by pinocchio's FK."""
    if _last_data[0] is not model:
        _last_data[:] = [model, model.createData()]
    data = _last_data[1]
    pin.framesForwardKinematics(model, data, q)
    return {link: data.oMf[model.getFrameId(link, pin.FrameType.BODY)].homogeneous
            for link in links}
