"""
One DH row (:class:`DHJoint`) and the names a chain is built from: conventions, joint types.

Lengths are metres, angles radians; the conventions are those of
:mod:`dq_fk_ros.kinematics.dh`.
"""

from dataclasses import dataclass
import math

CONVENTIONS = ('standard', 'modified')
JOINT_TYPES = ('revolute', 'prismatic', 'cylindrical', 'fixed')


@dataclass(frozen=True)
class DHJoint:
    """
    One DH row: a (m), alpha (rad), d (m), theta (rad), and which of them move.

    ``joint_type``: ``revolute`` (theta = scale*q + theta), ``prismatic``
    (d = scale*q + d), ``cylindrical`` (both: two joint variables, theta's then d's, the
    RRC robot's third joint in [Radavelli2014]) or ``fixed`` (no variable).
    ``name`` names the joint variable (cylindrical rows get ``name`` and ``name + '_d'``
    unless ``d_name`` is given). ``follows`` makes the row read another joint's variable
    instead of having its own (a mimic joint: ``scale`` is the multiplier).
    ``limits``: ``(lower, upper)`` of the row's own variable, in joint units.
    """

    a: float = 0.0
    alpha: float = 0.0
    d: float = 0.0
    theta: float = 0.0
    joint_type: str = 'revolute'
    scale: float = 1.0
    name: str = ''
    d_name: str = ''
    follows: str = ''
    limits: tuple = None

    def __post_init__(self):
        """Reject unknown joint types and non-finite numbers."""
        if self.joint_type not in JOINT_TYPES:
            raise ValueError(f'joint_type {self.joint_type!r} is not one of {JOINT_TYPES}')
        for field in ('a', 'alpha', 'd', 'theta', 'scale'):
            value = getattr(self, field)
            if not math.isfinite(value):
                raise ValueError(f'DH parameter {field} must be finite, got {value!r}')
        if self.follows and self.joint_type not in ('revolute', 'prismatic'):
            raise ValueError('only revolute and prismatic rows can follow another joint')


__all__ = ['CONVENTIONS', 'DHJoint', 'JOINT_TYPES']
