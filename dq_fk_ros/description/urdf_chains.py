"""
Which joints of a URDF tree are published, and how the tree is cut into DH chains.

The choice of chains of :mod:`.from_urdf` (whose module doc gives the rules): the joints
robot_state_publisher would publish below the base (:func:`publishable_joints`; mimics
followed to their source, :func:`mimic_source`), the longest paths of moving joints
(:func:`longest_path`), the chains after the first (:func:`branch_plans`), and a chain split
where two axes are too nearly parallel for DH (:func:`split_chain`). Plain Python, no ROS.
"""

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

from dq_fk_ros.description.dh_fit import normal_feet
from dq_fk_ros.description.robot_model import JOINT_NAME, MAX_NAME_CHARS, TF_FRAME_ID
from dq_fk_ros.description.urdf_reader import MOVING, UrdfTree

FAR_NORMAL_M = 10.0         # a common normal this far from the joints splits the chain


@dataclass(frozen=True)
class ChainPlan:
    """One DH chain of the tree: its joints (fixed ones too) from ``anchor`` to ``tip``."""

    anchor: str      # the link its first joint hangs from (frame 0 is placed in its axes)
    parent: str      # the same link; its DH frame is the chain's parent
    path: tuple      # the joints from anchor down to tip
    tip: str

    @property
    def moving(self) -> list:
        """Return the moving joints of the path (one DH row each)."""
        return [j for j in self.path if j.kind in MOVING]


def split_chain(plan: ChainPlan, pose: Mapping) -> list[ChainPlan]:
    """
    Split a chain where two axes are so nearly parallel that DH would lose precision.

    Such axes (Romeo's thumbs: 1e-7 rad apart, 18 mm) have their common normal
    :data:`FAR_NORMAL_M` or more away: rows with offsets of kilometres, whose rounding
    shows at 1e-9 m. The rest of the chain becomes a chain of its own, hanging from the
    DH frame before (its base transform is exact).
    """
    moving = [k for k, j in enumerate(plan.path) if j.kind in MOVING]
    for a, b in zip(moving, moving[1:]):
        first, second = plan.path[a], plan.path[b]
        m1 = pose[first.parent] @ first.origin
        m2 = pose[second.parent] @ second.origin
        feet = normal_feet(m1[:3, 3], m1[:3, :3] @ first.axis, m2[:3, 3],
                           m2[:3, :3] @ second.axis)
        if feet is not None and max(abs(feet[0]), abs(feet[1])) > FAR_NORMAL_M:
            head = ChainPlan(plan.anchor, plan.parent, plan.path[:b], plan.path[b - 1].child)
            tail = ChainPlan(second.parent, second.parent, plan.path[b:], plan.tip)
            return [head] + split_chain(tail, pose)
    return [plan]


def publishable_joints(tree: UrdfTree, base: str) -> set:
    """
    Return the names of the joints below ``base`` that get a transform.

    Every joint of robot_state_publisher (a floating one gets a frame but no transform),
    but joints with names this package cannot publish, and mimics of joints that are not
    published (followed to their source through chains of mimics).
    """
    ok, stack = set(), [base]
    while stack:
        link = stack.pop()
        for j in tree.children.get(link, []):
            if len(j.child) > MAX_NAME_CHARS or not TF_FRAME_ID.fullmatch(j.child):
                continue
            if j.kind in MOVING and j.mimic is None and not JOINT_NAME.fullmatch(j.name):
                continue
            ok.add(j.name)
            stack.append(j.child)
    while True:  # mimics whose source is not published are not either (nor what is below)
        bad = {name for name, good in mimic_sources_ok(tree, ok).items() if not good}
        if not bad:
            return reachable(tree, base, ok)
        ok -= bad
        ok = reachable(tree, base, ok)


def reachable(tree: UrdfTree, base: str, ok: set) -> set:
    """Return the joints of ``ok`` reached from ``base`` through joints of ``ok``."""
    out, stack = set(), [base]
    while stack:
        for j in tree.children.get(stack.pop(), []):
            if j.name in ok:
                out.add(j.name)
                stack.append(j.child)
    return out


def mimic_sources_ok(tree: UrdfTree, published: set) -> dict:
    """
    Say per mimic joint of ``published`` whether it leads to a published joint of its own.

    Each joint is looked at once (a chain of mimics is walked once, not once per member):
    linear in the URDF, however long its chains of mimics.
    """
    known = {}
    for name in published:
        path, at = [], tree.by_name[name]
        while at.mimic is not None and at.name not in known:
            if at.name in path:  # a loop of mimics
                break
            path.append(at.name)
            source = tree.by_name.get(at.mimic[0])
            if source is None or source.kind not in MOVING or source.name not in published:
                at = None
                break
            at = source
        if at is None or (at.mimic is not None and at.name not in known):
            good = False
        else:
            good = known.get(at.name, True)
        for member in path:
            known[member] = good
    return {name: good for name, good in known.items() if name in published}


def mimic_source(tree: UrdfTree, joint: object, published: set) -> tuple:
    """
    Return ``(source, multiplier, offset)``: a mimic joint followed to a joint of its own.

    Chains of mimics compose (``m2 (m1 q + o1) + o2``); ``(None, ...)`` when the source is
    not a published joint, the chain loops, or a joint is not moving.
    """
    multiplier, offset, seen = 1.0, 0.0, set()
    while joint.mimic is not None:
        if joint.name in seen:
            return None, 0.0, 0.0
        seen.add(joint.name)
        name, m, o = joint.mimic
        # this joint is m * q(name) + o, and the first one multiplier * q(this) + offset
        multiplier, offset = multiplier * m, offset + multiplier * o
        source = tree.by_name.get(name)
        if source is None or source.kind not in MOVING or name not in published:
            return None, 0.0, 0.0
        joint = source
    return joint.name, multiplier, offset


def links_below(tree: UrdfTree, base: str, published: set) -> Iterator[str]:
    """Yield the links below ``base`` reached through published joints, parents first."""
    order = [base]
    for link in order:
        for j in tree.children.get(link, []):
            if j.name in published:
                order.append(j.child)
                yield j.child


def longest_path(tree: UrdfTree, link: str, published: set) -> list:
    """Return the joints of the path below ``link`` with most moving joints (first on ties)."""
    best = []
    best_count = 0
    stack = [(link, [])]
    while stack:
        at, path = stack.pop()
        count = sum(j.kind in MOVING for j in path)
        if count > best_count:
            best, best_count = path, count
        for j in reversed(tree.children.get(at, [])):
            if j.name in published and j.kind != 'floating':  # no chain crosses one
                stack.append((j.child, path + [j]))
    while best and best[-1].kind not in MOVING:
        best = best[:-1]
    return best


def branch_plans(tree: UrdfTree, base: str, main_path: Sequence,
                 published: set) -> list[ChainPlan]:
    """
    Return the other chains of the tree: every moving joint not on the first chain is on one.

    Walking the URDF from ``base`` (parents first, the URDF's order), a moving joint not yet
    on a chain starts one: it and the longest path of moving joints below it.
    """
    covered = {j.name for j in main_path}
    plans = []
    for link in [base] + list(links_below(tree, base, published)):
        for j in tree.children.get(link, []):
            if j.name not in published or j.name in covered or j.kind not in MOVING:
                continue
            path = [j] + longest_path(tree, j.child, published)
            covered.update(joint.name for joint in path)
            plans.append(ChainPlan(link, link, tuple(path), path[-1].child))
    return plans


__all__ = ['branch_plans', 'ChainPlan', 'FAR_NORMAL_M', 'links_below', 'longest_path',
           'mimic_source', 'mimic_sources_ok', 'publishable_joints', 'reachable',
           'split_chain']
