"""
The compiled short path of a JointState merge: a repeated complete layout read in C.

Once ``JointStateMerger.merge`` has accepted a message that names every joint once
(its own short path, ``_merge_complete``), :func:`learn_layout` builds the C reader of that
layout (``_cdr.JointStateReader``) and :func:`merge_raw` merges the next messages from their
bytes. The reference is ``JointStateMerger.merge`` (test_joint_states.py's
``test_the_compiled_path_merges_as_merge_does``).
"""

import math
from typing import Optional

from dq_fk_ros.messages.cdr import COMPILED
from dq_fk_ros.messages.joint_state_rules import PUBLISH, TIME_JUMP_BACK_NS
from dq_fk_ros.messages.merge_state import MergeState


def learn_layout(state: MergeState, layout: object) -> None:
    """
    Take messages of ``layout`` by the compiled short path from now on (:func:`merge_raw`).

    :param layout: the parse cache's layout of the message just merged
        (``JointStateNames.layout``); nothing happens unless it names the complete set
        of joints ``JointStateMerger.merge`` takes its own short path for.
    """
    complete = state.complete
    if COMPILED is None or layout is None or complete is None or \
            layout.names != complete.names:
        return  # (without the C reader every message takes merge())
    order, lower, upper = complete.order, complete.lower, complete.upper
    if lower is None:
        lower, upper = [-math.inf] * len(order), [math.inf] * len(order)
    state.raw_reader = layout.compiled_reader(order, lower, upper, TIME_JUMP_BACK_NS)
    state.raw_velocities = layout.velocities[1] > 0


def merge_raw(state: MergeState, raw: bytes) -> Optional[tuple]:
    """
    Merge a serialized JointState of the learnt layout: ``(stamp_ns, q, qdot)`` or None.

    The compiled short path of ``JointStateMerger.merge`` (the reference; test_joint_states.py's
    ``test_the_compiled_path_merges_as_merge_does``): it takes a message only when
    ``merge`` would publish it with nothing to report (the same frame id, names and
    array lengths as the learnt layout; every position finite and within its limits,
    every velocity finite; no jump back in time). None: nothing was done, call
    ``JointStateMerger.merge``. ``q`` and ``qdot`` (None without velocities) are the state's
    buffers, valid until the next merge.
    """
    reader = state.raw_reader
    if reader is None:
        return None
    last = state.last_stamp_ns
    stamp_ns = reader.read(raw, last, state.q, state.qdot, state.q_out, state.qdot_out)
    if stamp_ns is None:
        return None
    if stamp_ns:
        state.last_stamp_ns = stamp_ns if last is None else max(stamp_ns, last)
    counts = state.counts
    counts['received'] += 1
    counts[PUBLISH] += 1
    return stamp_ns, state.q_out, state.qdot_out if state.raw_velocities else None
