"""
Which optional joints each frame of a robot waits for, before it can be published.

A frame's pose needs the joints of the moving rows and links between the fixed frame and it
(:func:`frame_needs_of`); its TF transform only those between its TF parent and it
(:func:`edge_needs_of`), as robot_state_publisher sends a joint's transform once a message
names that joint. Only optional joints count (``RobotModel.optional_joints``): the
required ones come in every accepted message.
"""

from typing import Protocol, Sequence


class RobotModel(Protocol):
    """What is read of a ``description.robot_model.RobotModel`` (which imports this module)."""

    fixed_frame: str
    chains: Sequence[tuple]          # (parent frame name, KinematicChain, first frame index)
    links: Sequence                  # each with .parent, .frame, .motion
    frame_names: Sequence[str]
    parent_frames: Sequence[str]
    optional_joints: Sequence[str]


def _paths(model: RobotModel) -> tuple[dict, dict]:
    """
    ``(paths, reads)``: per frame name, the moving rows and links its pose depends on.

    ``paths[frame]`` is a frozenset of moving elements (``(chain, row)`` or ``('link',
    k)``) between the fixed frame and it; ``reads[element]`` the joints that one reads.
    """
    paths = {model.fixed_frame: frozenset()}
    reads = {}
    for c, (parent, chain, start) in enumerate(model.chains):
        here = paths[parent]
        paths[model.frame_names[start]] = here
        for i, joint in enumerate(chain.joints):
            if joint.joint_type != 'fixed':
                reads[(c, i)] = frozenset(
                    chain.joint_names[int(k)] for k in
                    (chain.table.theta_index[i], chain.table.d_index[i]) if k >= 0)
                here = here | {(c, i)}
            paths[model.frame_names[start + i + 1]] = here
        if chain.tool is not None:
            paths[model.frame_names[start + chain.n_frames - 1]] = here
    for k, link in enumerate(model.links):
        here = paths[link.parent]
        if link.motion is not None:
            reads[('link', k)] = frozenset((link.motion[2],))
            here = here | {('link', k)}
        paths[link.frame] = here
    return paths, reads


def _needs(reads: dict, optional: set, elements: frozenset) -> frozenset:
    return frozenset().union(*(reads[e] for e in elements)) & optional


def frame_needs_of(model: RobotModel) -> tuple[frozenset, ...]:
    """Per frame of a ``RobotModel``: the optional joints its pose depends on."""
    paths, reads = _paths(model)
    optional = set(model.optional_joints)
    return tuple(_needs(reads, optional, paths[name]) for name in model.frame_names)


def edge_needs_of(model: RobotModel) -> tuple[frozenset, ...]:
    """Per frame of a ``RobotModel``: the optional joints its TF transform depends on."""
    paths, reads = _paths(model)
    optional = set(model.optional_joints)
    return tuple(_needs(reads, optional, paths[name] ^ paths[parent])
                 for name, parent in zip(model.frame_names, model.parent_frames))
