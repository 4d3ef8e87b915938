"""
dq_fk_view's joint panel (``--joint-panel``; ``dq_fk show``): joint_state_publisher_gui's.

A slider per moving joint of the current URDF within its limits (a continuous joint:
-pi..pi; a joint without limits: -pi..pi rad or -1..1 m), each starting at 0 (the middle of
its range when 0 is outside it, as joint_state_publisher). A mimic joint of a moving joint
has no slider: the page shows it following (``multiplier * q + offset``) and the node
computes it, so the JointState holds the independent joints only. A page's message
``{"type": "joints", "positions": {name: value}}`` moves sliders: names not on the panel,
values not finite numbers or more names than the panel has are refused as a whole; values
are clamped to the limits. Plain Python, thread-safe; the view publishes :meth:`joint_state`.
"""

import math
import threading

from dq_fk_ros.description.urdf_reader import parse_urdf
from dq_fk_ros.errors import RobotDescriptionError

MOVING = ('revolute', 'continuous', 'prismatic')
NO_LIMIT = {'prismatic': (-1.0, 1.0)}   # metres; rad: -pi..pi


class JointPanel:
    """The panel's joints, limits and positions (see the module doc)."""

    def __init__(self):
        """Start with no robot: no joints."""
        self.lock = threading.Lock()
        self.joints = []      # [(name, lower, upper, start)] of the sliders, URDF order
        self.mimics = []      # [(name, source, multiplier, offset)]
        self.positions = {}   # name -> value, one per slider
        self.version = 0      # changes when a page moves a slider

    def take_description(self, text: str) -> None:
        """Make the sliders of a new URDF (one that does not parse: none); keep known values."""
        try:
            tree = parse_urdf(text, 'robot_description')
        except RobotDescriptionError:
            tree = None
        joints, mimics = [], []
        moving = {j.name for j in tree.joints.values() if j.kind in MOVING} if tree else set()
        for joint in (tree.joints.values() if tree else ()):
            if joint.kind not in MOVING:
                continue
            if joint.mimic is not None and joint.mimic[0] in moving and \
                    joint.mimic[0] != joint.name:
                mimics.append((joint.name, joint.mimic[0], joint.mimic[1], joint.mimic[2]))
                continue
            lower, upper = joint.lower, joint.upper
            if joint.kind == 'continuous' or lower is None or upper is None or \
                    not lower < upper:
                lower, upper = NO_LIMIT.get(joint.kind, (-math.pi, math.pi))
            start = 0.0 if lower <= 0.0 <= upper else 0.5 * (lower + upper)
            joints.append((joint.name, lower, upper, start))
        with self.lock:
            old = self.positions
            self.joints, self.mimics = joints, mimics
            self.positions = {n: min(max(old.get(n, s), lo), hi) for n, lo, hi, s in joints}
            self.version += 1

    def spec(self) -> dict:
        """Return what the page builds the panel from: joints, limits, start values, mimics."""
        with self.lock:
            return {'joints': [[n, lo, hi, s, self.positions[n]] for n, lo, hi, s in self.joints],
                    'mimics': [list(m) for m in self.mimics]}

    def take_page(self, message) -> bool:
        """Apply a page's ``joints`` message; return False (nothing changed) if refused."""
        positions = message.get('positions') if isinstance(message, dict) else None
        if not isinstance(positions, dict):
            return False
        with self.lock:
            limits = {n: (lo, hi) for n, lo, hi, _ in self.joints}
            if len(positions) > len(limits):
                return False
            clean = {}
            for name, value in positions.items():
                if name not in limits or type(value) not in (int, float):
                    return False
                try:
                    value = float(value)   # an int of 400 digits: OverflowError
                except OverflowError:
                    return False
                if not math.isfinite(value):
                    return False
                lower, upper = limits[name]
                clean[name] = min(max(value, lower), upper)
            self.positions.update(clean)
            self.version += 1
        return True

    def joint_state(self) -> tuple[list[str], list[float]]:
        """Return ``(names, positions)`` of the sliders, in URDF order (empty: no robot)."""
        with self.lock:
            names = [n for n, _, _, _ in self.joints]
            return names, [self.positions[n] for n in names]


__all__ = ['JointPanel']
